"""Collider world shapes for drawing and for the penetration metric (numpy, all colliders at once).

The shapes are those of docs/solver.md §G.2/§G.3 at the frame pose (no step interpolation): for a
collider on node t with world position P, rotation R and lossy scale S (|S| < 1e-6 -> 1e-6)

* frame position   ``framePos = P + (R·(center ∘ sign S)) ∘ |S|``
* sphere           centre framePos, radius ``radius·|S.x|``
* capsule          axis = local X/Y/Z · sign(S_axis) (negated when ``reverse_direction``),
                   k = |S_axis|, (rs, re, L) = (radius, end_radius, length)·k; aligned on
                   centre: a = b = L/2, else a = 0, b = L − rs; a = max(a − rs, 0),
                   b = max(b − re, 0); start = framePos + R·axis·a, end = framePos − R·axis·b
                   (the centres of the two end caps)
* plane            point framePos, normal ``R·(0, sign S.y, 0)``
"""
from __future__ import annotations

import numpy as np

from magica_py.sinks.base import ColliderShapes

SPHERE, CAPSULE, PLANE = 0, 1, 2


def collider_shapes(colliders, hierarchy) -> ColliderShapes:
    """World shapes of every collider of a ``ColliderSet`` at the hierarchy's current pose.

    Uses ``ColliderSet.world_shapes`` (scene/colliders.py, the project's numpy oracle of §G.2/§G.3)
    and splits it by shape kind."""
    if colliders is None or len(colliders.names) == 0:
        return ColliderShapes.empty()
    w = colliders.world_shapes(hierarchy)
    shape = np.asarray(w.shape)
    sph, cap, pl = shape == SPHERE, shape == CAPSULE, shape == PLANE
    return ColliderShapes(
        sphere_center=w.position[sph], sphere_radius=w.radius[sph],
        capsule_start=w.start[cap], capsule_end=w.end[cap],
        capsule_start_radius=w.radius[cap], capsule_end_radius=w.end_radius[cap],
        plane_point=w.position[pl], plane_normal=w.normal[pl])


def shape_slots(colliders) -> tuple[np.ndarray, np.ndarray]:
    """(kind, slot) per collider: its shape and its row in the ColliderShapes arrays of that kind."""
    shape = np.asarray(colliders.shape) if colliders is not None else np.zeros(0, np.int8)
    slot = np.zeros(shape.size, np.int64)
    for kind in (SPHERE, CAPSULE, PLANE):
        sel = shape == kind
        slot[sel] = np.arange(int(sel.sum()))
    return shape.astype(np.int64), slot


def from_z_rotation(d: np.ndarray) -> np.ndarray:
    """Quaternions (k,4) rotating +Z onto the directions d (k,3); identity for zero vectors."""
    return from_to_rotation(np.array([0.0, 0.0, 1.0]), d)


def from_y_rotation(d: np.ndarray) -> np.ndarray:
    """Quaternions (k,4) rotating +Y onto the directions d (k,3)."""
    return from_to_rotation(np.array([0.0, 1.0, 0.0]), d)


def from_to_rotation(a: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Shortest-arc quaternions from the unit vector a to each direction d (opposite: 180° about a normal axis)."""
    k = d.shape[0]
    out = np.zeros((k, 4))
    out[:, 3] = 1.0
    norm = np.linalg.norm(d, axis=1)
    ok = norm > 1e-12
    u = np.zeros_like(d)
    u[ok] = d[ok] / norm[ok, None]
    c = u @ a
    axis = np.cross(np.broadcast_to(a, u.shape), u)
    half = np.sqrt(np.maximum((1.0 + c) * 2.0, 0.0))
    regular = ok & (c > -1.0 + 1e-9)
    out[regular, :3] = axis[regular] / half[regular, None]
    out[regular, 3] = half[regular] * 0.5
    opposite = ok & ~regular
    if opposite.any():  # any axis normal to a
        perp = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        perp = perp - a * (perp @ a)
        out[opposite, :3] = perp / np.linalg.norm(perp)
        out[opposite, 3] = 0.0
    return out


class ColliderBatch:
    """``world_shapes`` for a whole batch of frames in one numpy evaluation.

    Per frame the sink only copies the world pose of the collider transforms (``capture``);
    at flush ``shapes`` evaluates the ColliderSet tiled once per frame on those poses, which
    costs about as much as one frame did (numpy overhead per call dominates at 300 colliders).
    """

    def __init__(self, colliders):
        self.colliders = colliders
        self.nodes = np.asarray(colliders.transform, np.int64)
        self.count = int(self.nodes.size)
        shape = np.asarray(colliders.shape)
        self.masks = {SPHERE: shape == SPHERE, CAPSULE: shape == CAPSULE, PLANE: shape == PLANE}
        self._tiled: dict[int, object] = {}

    def capture(self, hierarchy) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n = self.nodes
        return hierarchy.world_position[n], hierarchy.world_rotation[n], hierarchy.lossy_scale[n]

    def _tiled_set(self, frames: int):
        tiled = self._tiled.get(frames)
        if tiled is None:
            import dataclasses

            sub = self.colliders.subset(np.tile(np.arange(self.count), frames))
            tiled = dataclasses.replace(sub, transform=np.arange(frames * self.count, dtype=np.int32))
            self._tiled[frames] = tiled
        return tiled

    def shapes(self, position: np.ndarray, rotation: np.ndarray, scale: np.ndarray) -> dict[str, np.ndarray]:
        """(n, C, 3|4) poses -> the sink's per-kind (n, k, ...) shape arrays."""
        from types import SimpleNamespace

        n = position.shape[0]
        pose = SimpleNamespace(world_position=position.reshape(-1, 3), world_rotation=rotation.reshape(-1, 4),
                               lossy_scale=scale.reshape(-1, 3))
        w = self._tiled_set(n).world_shapes(pose)

        def per_frame(values, kind):
            return values.reshape((n, self.count) + values.shape[1:])[:, self.masks[kind]]

        out = {}
        if self.masks[SPHERE].any():
            out["sphere_center"] = per_frame(w.position, SPHERE)
            out["sphere_radius"] = per_frame(w.radius, SPHERE)
        if self.masks[CAPSULE].any():
            out["capsule_start"] = per_frame(w.start, CAPSULE)
            out["capsule_end"] = per_frame(w.end, CAPSULE)
            out["capsule_start_radius"] = per_frame(w.radius, CAPSULE)
            out["capsule_end_radius"] = per_frame(w.end_radius, CAPSULE)
        if self.masks[PLANE].any():
            out["plane_point"] = per_frame(w.position, PLANE)
            out["plane_normal"] = per_frame(w.normal, PLANE)
        return out
