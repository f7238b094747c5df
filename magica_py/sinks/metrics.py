"""Cloth quality metrics computed by the sink from what it logs, for a batch of frames at once.

* ``max_edge_stretch``  max over proxy edges of ``|length / rest − 1|`` (a ratio; logged in %)
* ``max_penetration``   m (logged in mm), max over (Move particle, collider of its cloth) pairs of the overlap
                        ``R + r − distance`` (sphere / capsule) or ``r − signed distance`` (plane),
                        clamped at 0: how far a particle's sphere is inside a collider
* ``max_speed``         m/s, max ``|x_t − x_{t−1}| / delta_time`` of the display positions
                        (0 on the first frame and when delta_time is 0)

They are measured on display positions at the frame pose, so they are what the viewer shows,
independent of the solver's internals. Static index arrays are built once in ``__init__``;
``compute`` runs one numba kernel per metric over a (B, P, 3) batch of frames.
"""
from __future__ import annotations

import numpy as np

from magica_py.build.proxy import DISABLE_COLLISION, MOVE
from magica_py.jit import kernel
from magica_py.sinks.base import ClothTopology
from magica_py.sinks.shapes import CAPSULE, PLANE, SPHERE


# ----------------------------------------------------------------------------- kernels
# One pass per batch, no temporaries: the numpy versions (kept in tests as the oracle)
# cost ~8 ms per frame on the 7,800-particle crowd.
@kernel
def max_edge_stretch(x, edges, rest, out):
    """out[b] = max_e |‖x[b,e0] − x[b,e1]‖ / rest[e] − 1|."""
    for b in range(x.shape[0]):
        worst = 0.0
        for e in range(edges.shape[0]):
            i, j = edges[e, 0], edges[e, 1]
            dx = x[b, i, 0] - x[b, j, 0]
            dy = x[b, i, 1] - x[b, j, 1]
            dz = x[b, i, 2] - x[b, j, 2]
            s = abs(np.sqrt(dx * dx + dy * dy + dz * dz) / rest[e] - 1.0)
            if s > worst:
                worst = s
        out[b] = worst


@kernel
def max_displacement(x, previous, out):
    """out[b] = max_p ‖x[b,p] − x[b−1,p]‖ (previous = the frame before x[0])."""
    for b in range(x.shape[0]):
        worst = 0.0
        for p in range(x.shape[1]):
            if b == 0:
                dx = x[0, p, 0] - previous[p, 0]
                dy = x[0, p, 1] - previous[p, 1]
                dz = x[0, p, 2] - previous[p, 2]
            else:
                dx = x[b, p, 0] - x[b - 1, p, 0]
                dy = x[b, p, 1] - x[b - 1, p, 1]
                dz = x[b, p, 2] - x[b - 1, p, 2]
            d = dx * dx + dy * dy + dz * dz
            if d > worst:
                worst = d
        out[b] = np.sqrt(worst)


@kernel
def sphere_penetration(x, particle, slot, radius, center, sphere_radius, out):
    """out[b] = max(out[b], max over pairs of R + r − ‖x − c‖)."""
    for b in range(x.shape[0]):
        worst = out[b]
        for k in range(particle.shape[0]):
            p, c = particle[k], slot[k]
            dx = x[b, p, 0] - center[b, c, 0]
            dy = x[b, p, 1] - center[b, c, 1]
            dz = x[b, p, 2] - center[b, c, 2]
            depth = sphere_radius[b, c] + radius[p] - np.sqrt(dx * dx + dy * dy + dz * dz)
            if depth > worst:
                worst = depth
        out[b] = worst


@kernel
def capsule_penetration(x, particle, slot, radius, start, end, start_radius, end_radius, out):
    """Like sphere_penetration against the closest point of the segment, radius lerped."""
    for b in range(x.shape[0]):
        worst = out[b]
        for k in range(particle.shape[0]):
            p, c = particle[k], slot[k]
            ax, ay, az = start[b, c, 0], start[b, c, 1], start[b, c, 2]
            ex, ey, ez = end[b, c, 0] - ax, end[b, c, 1] - ay, end[b, c, 2] - az
            px, py, pz = x[b, p, 0] - ax, x[b, p, 1] - ay, x[b, p, 2] - az
            denom = ex * ex + ey * ey + ez * ez
            t = 0.0
            if denom > 1e-18:
                t = (px * ex + py * ey + pz * ez) / denom
                t = min(max(t, 0.0), 1.0)
            dx, dy, dz = px - ex * t, py - ey * t, pz - ez * t
            r = start_radius[b, c] + (end_radius[b, c] - start_radius[b, c]) * t
            depth = r + radius[p] - np.sqrt(dx * dx + dy * dy + dz * dz)
            if depth > worst:
                worst = depth
        out[b] = worst


@kernel
def plane_penetration(x, particle, slot, radius, point, normal, out):
    for b in range(x.shape[0]):
        worst = out[b]
        for k in range(particle.shape[0]):
            p, c = particle[k], slot[k]
            signed = ((x[b, p, 0] - point[b, c, 0]) * normal[b, c, 0] + (x[b, p, 1] - point[b, c, 1]) * normal[b, c, 1]
                      + (x[b, p, 2] - point[b, c, 2]) * normal[b, c, 2])
            depth = radius[p] - signed
            if depth > worst:
                worst = depth
        out[b] = worst


class FrameMetrics:
    def __init__(self, cloths: list[ClothTopology], collider_kind: np.ndarray, collider_slot: np.ndarray):
        counts = [c.particle_count for c in cloths]
        offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self.particle_count = int(offsets[-1])
        edges = [np.asarray(c.edges, np.int64).reshape(-1, 2) + offsets[i] for i, c in enumerate(cloths)]
        rest = [np.asarray(c.rest_length, dtype=np.float64).reshape(-1) for c in cloths]
        self.edges = np.concatenate(edges) if edges else np.zeros((0, 2), np.int64)
        self.rest = np.concatenate(rest) if rest else np.zeros(0)
        keep = self.rest > 1e-9
        self.edges, self.rest = self.edges[keep], self.rest[keep]
        radius = [np.asarray(c.radius, dtype=np.float64).reshape(-1) for c in cloths]
        self.radius = np.concatenate(radius) if radius else np.zeros(0)
        # (particle, collider slot) pairs per shape kind: the particles D.8 collides (Move, collision not disabled)
        pairs = {SPHERE: ([], []), CAPSULE: ([], []), PLANE: ([], [])}
        for i, c in enumerate(cloths):
            attribute = np.asarray(c.attribute)
            movable = np.flatnonzero(((attribute & MOVE) != 0) & ((attribute & DISABLE_COLLISION) == 0)) + offsets[i]
            for col in np.asarray(c.colliders, dtype=np.int64):
                if not 0 <= col < len(collider_kind):   # a collider the sink was not told about
                    continue
                kind = int(collider_kind[col])
                pairs[kind][0].append(movable)
                pairs[kind][1].append(np.full(movable.size, collider_slot[col], np.int64))
        self.pairs = {k: (np.concatenate(p) if p else np.zeros(0, np.int64),
                          np.concatenate(s) if s else np.zeros(0, np.int64))
                      for k, (p, s) in pairs.items()}
        self.has_collision = any(p.size for p, _ in self.pairs.values())   # any particle meets a collider
        self.previous = None          # (P, 3) last frame of the previous batch

    def compute(self, x: np.ndarray, shapes: dict, delta_time: np.ndarray) -> dict[str, np.ndarray]:
        """x: (B, P, 3) float64; shapes: name -> (B, k, ...) arrays as buffered by the sink
        (``sphere_center``, ``sphere_radius``, ``capsule_start``, ...); delta_time (B,).
        Returns name -> (B,) float64."""
        x = np.ascontiguousarray(x, np.float64)
        b = x.shape[0]
        out = {"max_edge_stretch": np.zeros(b), "max_penetration": np.zeros(b), "max_speed": np.zeros(b)}
        if self.particle_count == 0 or b == 0:
            return out
        if self.edges.size:
            max_edge_stretch(x, self.edges, self.rest, out["max_edge_stretch"])
        pen = out["max_penetration"]
        p, s = self.pairs[SPHERE]
        if p.size and "sphere_center" in shapes:
            sphere_penetration(x, p, s, self.radius, _c(shapes["sphere_center"]), _c(shapes["sphere_radius"]), pen)
        p, s = self.pairs[CAPSULE]
        if p.size and "capsule_start" in shapes:
            capsule_penetration(x, p, s, self.radius, _c(shapes["capsule_start"]), _c(shapes["capsule_end"]),
                                _c(shapes["capsule_start_radius"]), _c(shapes["capsule_end_radius"]), pen)
        p, s = self.pairs[PLANE]
        if p.size and "plane_point" in shapes:
            plane_penetration(x, p, s, self.radius, _c(shapes["plane_point"]), _c(shapes["plane_normal"]), pen)
        np.maximum(pen, 0.0, out=pen)
        moved = np.zeros(b)
        max_displacement(x, x[0] if self.previous is None else self.previous, moved)
        positive = delta_time > 0.0
        out["max_speed"][positive] = moved[positive] / delta_time[positive]
        self.previous = x[-1].copy()
        return out


def _c(a):
    return np.ascontiguousarray(a, np.float64)
