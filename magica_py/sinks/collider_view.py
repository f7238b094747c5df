"""Colliders as the viewer draws them: one entity per collider, so any can be hidden alone.

Each collider entity (``world/colliders/<name>``, or under its character in a crowd) carries

* per frame a ``Transform3D`` (display frame): sphere at its centre; capsule at its start cap
  centre with +Z turned onto start -> end; plane at the point of the plane under the
  characters' box centre, +Y turned onto the normal;
* its shape in that local frame, logged at the first frame and again only when it changes
  (an animated scale): ``Ellipsoids3D`` (sphere), ``Capsules3D`` (equal radii), ``Mesh3D``
  (a tapered capsule: both cap radii, the cone tangent to both caps), a ``LineStrips3D`` grid
  for a plane (a patch the size of the characters' box, following them).

A collider with a radius over MagicaCloth2's 0.5 m cap (an authoring quirk, e.g. Godette's
1 m head sphere) is drawn as a wireframe in a paler colour so it hides nothing.
"""
from __future__ import annotations

import numpy as np

from magica_py.sinks import layout as L
from magica_py.sinks.shapes import CAPSULE, PLANE, SPHERE, from_y_rotation, from_z_rotation

RING_SEGMENTS = 24          # around a capsule's axis
CAP_STEPS = 6               # latitude steps per end cap
PLANE_GRID_STEP = 0.5       # m between the lines of a plane's patch
SOLID = "transparentfillmajorwireframe"   # a light fill and its outline: the cloth stays visible inside


def tapered_capsule_profile(start_radius: float, end_radius: float, length: float) -> np.ndarray:
    """(k, 2) (z, rho) outline of a capsule along +Z from its start cap centre (z = 0) to its
    end cap centre (z = length), with the cone tangent to both caps."""
    sin_phi = 0.0 if length <= 1e-12 else float(np.clip((start_radius - end_radius) / length, -1.0, 1.0))
    phi = float(np.arcsin(sin_phi))
    start = np.linspace(0.0, np.pi / 2 + phi, CAP_STEPS + 1)            # polar angle from -Z
    end = np.linspace(np.pi / 2 - phi, 0.0, CAP_STEPS + 1)              # polar angle from +Z
    zs = np.concatenate([-start_radius * np.cos(start), length + end_radius * np.cos(end)])
    rho = np.concatenate([start_radius * np.sin(start), end_radius * np.sin(end)])
    return np.stack([zs, rho], axis=1)


def revolve(profile: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Surface of revolution about +Z: (vertices (k*R, 3), triangles (m, 3))."""
    angle = np.linspace(0.0, 2 * np.pi, RING_SEGMENTS, endpoint=False)
    k = profile.shape[0]
    x = profile[:, 1:2] * np.cos(angle)[None, :]
    y = profile[:, 1:2] * np.sin(angle)[None, :]
    z = np.repeat(profile[:, 0:1], RING_SEGMENTS, axis=1)
    vertices = np.stack([x, y, z], axis=2).reshape(-1, 3)
    tris = []
    for i in range(k - 1):
        for j in range(RING_SEGMENTS):
            a, b = i * RING_SEGMENTS + j, i * RING_SEGMENTS + (j + 1) % RING_SEGMENTS
            c, d = a + RING_SEGMENTS, b + RING_SEGMENTS
            tris.append((a, c, b))
            tris.append((b, c, d))
    return vertices, np.array(tris, np.uint32)


def wire_strips(profile: np.ndarray) -> list[np.ndarray]:
    """Wireframe of a surface of revolution: a ring per profile point, 8 meridians."""
    vertices, _ = revolve(profile)
    grid = vertices.reshape(profile.shape[0], RING_SEGMENTS, 3)
    rings = [np.vstack([g, g[:1]]) for g in grid[:: max(1, CAP_STEPS // 3)]]
    meridians = [grid[:, j] for j in range(0, RING_SEGMENTS, RING_SEGMENTS // 8)]
    return rings + meridians


def plane_grid(half: float) -> list[np.ndarray]:
    """Lines of a square patch in the local XZ plane (Y is the normal)."""
    ticks = np.arange(-half, half + 1e-9, PLANE_GRID_STEP)
    strips = [np.array([[t, 0.0, -half], [t, 0.0, half]]) for t in ticks]
    strips += [np.array([[-half, 0.0, t], [half, 0.0, t]]) for t in ticks]
    return strips


class ColliderView:
    """The drawing of every collider of a scene (built once; ``send`` per batch of frames)."""

    def __init__(self, names, kinds: np.ndarray, slots: np.ndarray, groups):
        self.entries = []
        used = set()
        for name, kind, slot, group in zip(names, kinds, slots, groups):
            path = L.collider_path(name, group)
            while path in used:           # two colliders of the same name: keep both
                path += "_"
            used.add(path)
            self.entries.append((path, int(kind), int(slot)))
        self.last: dict[str, tuple] = {}          # path -> shape parameters last logged
        self.plane_half = None

    def send(self, rr, rec, index, frames: np.ndarray, times: np.ndarray, shapes: dict, focus: np.ndarray) -> None:
        """``shapes``: the sink's per-kind (n, k, ...) arrays (scene frame); ``focus``: (n, 2, 3)
        box of the characters per frame (scene frame); ``index`` the batch's time columns."""
        mirror = np.array(L.DISPLAY_MIRROR)
        center = focus.mean(axis=1)
        if self.plane_half is None and len(focus):
            size = float(np.max(focus[0, 1] - focus[0, 0]))
            self.plane_half = float(np.clip(np.ceil((0.6 * size + 0.75) / PLANE_GRID_STEP) * PLANE_GRID_STEP,
                                            1.0, 25.0))
        for path, kind, slot in self.entries:
            if kind == SPHERE and "sphere_center" in shapes:
                translation = shapes["sphere_center"][:, slot] * mirror
                quaternion = None
                params = shapes["sphere_radius"][:, slot][:, None]
            elif kind == CAPSULE and "capsule_start" in shapes:
                start = shapes["capsule_start"][:, slot] * mirror
                end = shapes["capsule_end"][:, slot] * mirror
                translation, quaternion = start, from_z_rotation(end - start)
                length = np.sqrt(np.sum((end - start) ** 2, axis=1))
                params = np.stack([shapes["capsule_start_radius"][:, slot], shapes["capsule_end_radius"][:, slot],
                                   length], axis=1)
            elif kind == PLANE and "plane_point" in shapes:
                point, normal = shapes["plane_point"][:, slot], shapes["plane_normal"][:, slot]
                under = center - np.sum((center - point) * normal, axis=1)[:, None] * normal
                translation, quaternion = under * mirror, from_y_rotation(normal * mirror)
                params = np.full((len(frames), 1), self.plane_half)
            else:
                continue
            columns = {"translation": np.ascontiguousarray(translation, np.float32)}
            if quaternion is not None:
                columns["quaternion"] = np.ascontiguousarray(quaternion, np.float32)
            rec.send_columns(path, indexes=index, columns=rr.Transform3D.columns(**columns))
            self._send_shape_changes(rr, rec, path, kind, params, frames, times)

    def _send_shape_changes(self, rr, rec, path, kind, params, frames, times) -> None:
        for row in range(params.shape[0]):
            p = tuple(float(v) for v in params[row])
            last = self.last.get(path)
            if last is not None and np.allclose(p, last, rtol=1e-6, atol=1e-9):
                continue
            self.last[path] = p
            rec.set_time(L.TIMELINE_FRAME, sequence=int(frames[row]))
            rec.set_time(L.TIMELINE_SIM_TIME, duration=float(times[row]))
            rec.log(path, self._shape(rr, kind, p))

    @staticmethod
    def _shape(rr, kind, p):
        if kind == SPHERE:
            r = p[0]
            big = r > L.OVERSIZED_COLLIDER_RADIUS
            return rr.Ellipsoids3D(half_sizes=[[r, r, r]], fill_mode="majorwireframe" if big else SOLID,
                                   colors=[L.COLOR_COLLIDER_OVERSIZED if big else L.COLOR_COLLIDER])
        if kind == CAPSULE:
            start_radius, end_radius, length = p
            big = max(start_radius, end_radius) > L.OVERSIZED_COLLIDER_RADIUS
            color = L.COLOR_COLLIDER_OVERSIZED if big else L.COLOR_COLLIDER
            if abs(start_radius - end_radius) <= 1e-6 * max(start_radius, end_radius, 1e-9):
                return rr.Capsules3D(lengths=[length], radii=[start_radius], colors=[color],
                                     fill_mode="majorwireframe" if big else SOLID)
            profile = tapered_capsule_profile(start_radius, end_radius, length)
            if big:
                return rr.LineStrips3D([s.astype(np.float32) for s in wire_strips(profile)], colors=[color],
                                       radii=0.003)
            vertices, triangles = revolve(profile)
            return rr.Mesh3D(vertex_positions=vertices.astype(np.float32), triangle_indices=triangles,
                             albedo_factor=color)
        return rr.LineStrips3D([s.astype(np.float32) for s in plane_grid(p[0])], colors=[L.COLOR_PLANE],
                               radii=0.002)
