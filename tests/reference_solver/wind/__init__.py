"""Wind (docs/solver.md §C, §D.1; docs/scene-format.md `wind`): MagicaCloth2's wind zones.

* ``noise`` — Unity.Mathematics' classic Perlin noise ``cnoise`` (the wind's noise wave);
* ``zones`` — zone specs and table, their world pose per frame, ``WindField`` (events, update);
* ``selection`` — per frame, the zones each team feels (smallest containing area zone, up to
  three additive zones, phases carried over);
* ``force`` — per step, ``wind_team``: phase advance, moving wind, the per-particle force.
"""
