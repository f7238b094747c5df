"""Per-frame cloth quality metrics computed by the sink from what it logs (numpy, all cloths at once).

* ``max_edge_stretch``  max over proxy edges of ``|length / rest − 1|`` (dimensionless)
* ``max_penetration``   m, max over (Move particle, collider of its cloth) pairs of the overlap
                        ``R + r − distance`` (sphere / capsule) or ``r − signed distance`` (plane),
                        clamped at 0: how far a particle's sphere is inside a collider
* ``max_speed``         m/s, max ``|x_t − x_{t−1}| / delta_time`` of the display positions
                        (0 on the first frame and when delta_time is 0)

They are measured on display positions at the frame pose, so they are what the viewer shows,
independent of the solver's internals. Static index arrays are built once in ``__init__``.
"""
from __future__ import annotations

import numpy as np

from magica_py.sinks.base import ClothTopology, ColliderShapes
from magica_py.sinks.shapes import CAPSULE, PLANE, SPHERE

MOVE = 0x02
INVALID = 0x08


class FrameMetrics:
    def __init__(self, cloths: list[ClothTopology], collider_kind: np.ndarray, collider_slot: np.ndarray):
        counts = [c.particle_count for c in cloths]
        offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self.particle_count = int(offsets[-1])
        self.offsets = offsets
        edges = [c.edges.reshape(-1, 2).astype(np.int64) + offsets[i] for i, c in enumerate(cloths)]
        rest = [np.asarray(c.rest_length, dtype=np.float64).reshape(-1) for c in cloths]
        self.edges = np.concatenate(edges) if edges else np.zeros((0, 2), np.int64)
        self.rest = np.concatenate(rest) if rest else np.zeros(0)
        keep = self.rest > 1e-9
        self.edges, self.rest = self.edges[keep], self.rest[keep]
        radius = [np.asarray(c.radius, dtype=np.float64).reshape(-1) for c in cloths]
        self.radius = np.concatenate(radius) if radius else np.zeros(0)
        # (particle, collider slot) pairs per shape kind, Move and not Invalid particles only
        pairs = {SPHERE: ([], []), CAPSULE: ([], []), PLANE: ([], [])}
        for i, c in enumerate(cloths):
            movable = np.flatnonzero((c.attribute & MOVE) != 0) if c.attribute.size else np.zeros(0, np.int64)
            movable = movable[(c.attribute[movable] & INVALID) == 0] + offsets[i]
            for col in np.asarray(c.colliders, dtype=np.int64):
                kind = int(collider_kind[col])
                pairs[kind][0].append(movable)
                pairs[kind][1].append(np.full(movable.size, collider_slot[col], np.int64))
        self.pairs = {k: (np.concatenate(p) if p else np.zeros(0, np.int64),
                          np.concatenate(s) if s else np.zeros(0, np.int64))
                      for k, (p, s) in pairs.items()}
        self.previous = np.zeros((self.particle_count, 3))
        self.has_previous = False

    def compute(self, positions: np.ndarray, shapes: ColliderShapes, delta_time: float) -> dict[str, float]:
        """positions: (P,3) all cloths concatenated in topology order."""
        out = {"max_edge_stretch": 0.0, "max_penetration": 0.0, "max_speed": 0.0}
        if self.particle_count == 0:
            return out
        if self.edges.size:
            d = positions[self.edges[:, 0]] - positions[self.edges[:, 1]]
            length = np.sqrt(np.einsum("ij,ij->i", d, d))
            out["max_edge_stretch"] = float(np.max(np.abs(length / self.rest - 1.0)))
        out["max_penetration"] = self._penetration(positions, shapes)
        if self.has_previous and delta_time > 0.0:
            step = positions - self.previous
            out["max_speed"] = float(np.sqrt(np.max(np.einsum("ij,ij->i", step, step)))) / delta_time
        self.previous[:] = positions
        self.has_previous = True
        return out

    def _penetration(self, x: np.ndarray, shapes: ColliderShapes) -> float:
        worst = 0.0
        p, s = self.pairs[SPHERE]
        if p.size:
            dist = np.linalg.norm(x[p] - shapes.sphere_center[s], axis=1)
            worst = max(worst, float(np.max(shapes.sphere_radius[s] + self.radius[p] - dist)))
        p, s = self.pairs[CAPSULE]
        if p.size:
            a, b = shapes.capsule_start[s], shapes.capsule_end[s]
            ab = b - a
            denom = np.einsum("ij,ij->i", ab, ab)
            t = np.where(denom > 1e-18, np.einsum("ij,ij->i", x[p] - a, ab) / np.maximum(denom, 1e-18), 0.0)
            t = np.clip(t, 0.0, 1.0)
            closest = a + ab * t[:, None]
            R = shapes.capsule_start_radius[s] + (shapes.capsule_end_radius[s] - shapes.capsule_start_radius[s]) * t
            dist = np.linalg.norm(x[p] - closest, axis=1)
            worst = max(worst, float(np.max(R + self.radius[p] - dist)))
        p, s = self.pairs[PLANE]
        if p.size:
            signed = np.einsum("ij,ij->i", x[p] - shapes.plane_point[s], shapes.plane_normal[s])
            worst = max(worst, float(np.max(self.radius[p] - signed)))
        return max(worst, 0.0)
