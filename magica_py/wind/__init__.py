"""Wind (docs/solver.md §C, §D.1; docs/scene-format.md `wind`): MagicaCloth2's wind zones.

* ``noise`` — Unity.Mathematics' classic Perlin noise ``cnoise`` (the wind's noise wave);
* ``zones`` — zone specs and the packed zone table, their world pose per frame, ``WindField``
  (events, update);
* ``selection`` — per frame, the zones each team (each lane of a block) feels (smallest
  containing area zone, up to three additive zones, phases carried over);
* ``force`` — per step, ``wind_block``: phase advance, moving wind, the per-particle force of
  every lane of a block.
"""
