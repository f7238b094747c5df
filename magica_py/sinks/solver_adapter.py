"""Snapshot provider over the solver's ``ClothSystem`` (magica_py/solver/system.py).

The solver keeps its state in packed lane tables (``solver/lanes.py``); its team-ordered view
``system.particles`` gathers one field of every live team's particles into one (P, 3) array,
teams contiguous in team order, so the sink gathers each field once per frame whatever the
number of cloths (a cloth's frame is a slice of it). What is read (all world space, after
LATE_UPDATE):

* ``particles.position``        display positions (docs/solver.md §E.1 overwrites the base pose with them;
  a team not simulated this frame, culled or disabled, at its bones: ``display_positions``)
* ``particles.base_pos_buffer`` the animated base pose of this frame (§C.1, kept for §E.2)
* ``time_state.update_count``   steps each team ran this frame (§A.4)

Topology comes from the team-ordered model (``system.model``, a ``views.TeamModel``: global
indices, per-team ranges; a removed cloth has no particles) and
the per-team radius curve (``system.parameters.radius_curve``, evaluated at each particle's
depth as §D.8 does, without the scale ratio).
"""
from __future__ import annotations

import numpy as np

from magica_py.sinks.base import ClothFrame, ClothTopology


def _curve(table: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """numpy twin of params.curves.evaluate_curve (piecewise linear over 16 samples)."""
    d = np.asarray(depth, np.float64)
    sd = np.clip(d, 0.0, 1.0)
    i = (sd * 15.0).astype(np.int64)
    u = (d - i / 15.0) * 15.0
    j = np.minimum(i + 1, 15)
    return table[i] + (table[j] - table[i]) * u


class ClothSystemSnapshots:
    def __init__(self, system):
        self.system = system
        self._topologies = None

    def cloth_topologies(self) -> list[ClothTopology]:
        if self._topologies is None:
            self._topologies = self._build()
        return self._topologies

    def _build(self) -> list[ClothTopology]:
        s, m = self.system, self.system.model
        out = []
        radius_table = getattr(getattr(s, "parameters", None), "radius_curve", None)
        for t, name in enumerate(s.team_names):
            start, count = int(m.team_particle_start[t]), int(m.team_particle_count[t])
            sl = slice(start, start + count)
            parent = np.asarray(m.parent[sl], np.int32).copy()
            parent[parent >= 0] -= start
            e0, ec = int(m.team_edge_start[t]), int(m.team_edge_count[t])
            edges = np.asarray(m.edges[e0:e0 + ec], np.int32) - start
            t0, tc = int(m.team_triangle_start[t]), int(m.team_triangle_count[t])
            triangles = np.asarray(m.triangles[t0:t0 + tc], np.int32) - start
            local = np.asarray(m.local_position[sl]) * np.asarray(m.team_init_scale[t])
            rest = np.linalg.norm(local[edges[:, 0]] - local[edges[:, 1]], axis=1) if len(edges) else np.zeros(0)
            depth = np.asarray(m.depth[sl])
            radius = _curve(np.asarray(radius_table[t]), depth) if radius_table is not None else np.full(count, 0.02)
            spec = s.specs[t] if t < len(getattr(s, "specs", [])) else None
            colliders = np.asarray(getattr(spec, "colliders", ()) or (), np.int32)
            out.append(ClothTopology(name=str(name), attribute=np.asarray(m.attribute[sl], np.uint8),
                                     radius=np.maximum(radius, 1e-4), parent=parent, edges=edges,
                                     triangles=triangles, rest_length=rest,
                                     transform_index=np.asarray(m.transform_index[sl], np.int32),
                                     colliders=colliders))
        return out

    # fast path used by the recorder: one array for every cloth
    def particle_positions(self) -> np.ndarray:
        return self._positions()

    def _positions(self) -> np.ndarray:
        """Display positions; a team not simulated this frame (culled, disabled) at its bones
        (``ClothSystem.display_positions``)."""
        display = getattr(self.system, "display_positions", None)
        return display() if display is not None else self.system.particles.position

    def particle_base_positions(self) -> np.ndarray:
        return self.system.particles.base_pos_buffer

    def steps(self) -> int:
        counts = self.system.time_state.update_count
        return int(np.max(counts)) if len(counts) else 0

    def wind_frame(self):
        """The frame's wind zones and felt winds (``wind_view.WindFrame``), or None."""
        from magica_py.sinks.wind_view import wind_frame

        return wind_frame(self.system)

    def cloth_frames(self) -> list[ClothFrame]:
        s, m = self.system, self.system.model
        position = self._positions()             # one gather per field for every cloth
        base = s.particles.base_pos_buffer
        frames = []
        for t in range(len(s.team_names)):
            start, count = int(m.team_particle_start[t]), int(m.team_particle_count[t])
            sl = slice(start, start + count)
            frames.append(ClothFrame(positions=position[sl], base_positions=base[sl],
                                     steps=int(s.time_state.update_count[t])))
        return frames


def adapt(owner):
    """A provider for ``owner`` if it looks like the solver's ClothSystem, else None."""
    needed = ("model", "particles", "team_names", "time_state")
    if all(hasattr(owner, a) for a in needed):
        return ClothSystemSnapshots(owner)
    return None
