"""Accuracy and stability metrics over recorded particle trajectories (docs/BENCHMARKS.md).

Everything here is plain numpy over arrays recorded by ``bench.variants.run_variant``; no
kernel, no scene. Conventions: world space, metres, seconds; ``positions`` is (F, N, 3)
(frames x particles) or (N, 3) for one frame; ``times`` (F,) is the unscaled time at the
end of each frame. Lengths are normalised by the *chain length* of each particle's team
(the largest rest arc length from a root, ``ChainGeometry.length_scale``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from magica_py.build.proxy import MOVE

ZERO_LENGTH = 1e-9      # m; rest lengths below this are zero-length bones: no stretch ratio


@dataclass(frozen=True)
class ChainGeometry:
    """Rest geometry of the simulated particles, taken from the bones' world rest pose.

    ``edges`` (E,2) int: global particle pairs; ``edge_rest`` (E,) m;
    ``root_index`` (N,) int: root particle of a moving particle, -1 otherwise;
    ``root_rest`` (N,) m: rest distance to that root (0 where none);
    ``arc_length`` (N,) m: rest arc length from the root along parents;
    ``length_scale`` (N,) m: the chain length of the particle's team (max arc length, >= 1e-9);
    ``moving`` (N,) bool: Move particles (not fixed, not invalid);
    ``team`` (N,) int, ``team_length`` (T,) m.
    """

    edges: np.ndarray
    edge_rest: np.ndarray
    root_index: np.ndarray
    root_rest: np.ndarray
    arc_length: np.ndarray
    length_scale: np.ndarray
    moving: np.ndarray
    team: np.ndarray
    team_length: np.ndarray

    @property
    def chain_length(self) -> float:
        """The longest chain of the scene (m)."""
        return float(self.team_length.max()) if self.team_length.size else 0.0


def chain_geometry(model, rest_positions: np.ndarray) -> ChainGeometry:
    """Geometry of a ``solver.views.TeamModel`` (``ClothSystem.model``: global indices) at ``rest_positions``
    (N,3): the world positions of ``model.transform_index`` at the rest pose."""
    rest = np.asarray(rest_positions, dtype=np.float64)
    n = rest.shape[0]
    edges = np.asarray(model.edges, dtype=np.int64).reshape(-1, 2)
    edge_rest = np.linalg.norm(rest[edges[:, 1]] - rest[edges[:, 0]], axis=1) if edges.size else np.zeros(0)
    parent = np.asarray(model.parent, dtype=np.int64)
    root = np.asarray(model.root_index, dtype=np.int64)
    moving = (np.asarray(model.attribute) & MOVE) != 0
    root = np.where(moving, root, -1)
    root_rest = np.where(root >= 0, np.linalg.norm(rest - rest[np.maximum(root, 0)], axis=1), 0.0)
    arc = np.zeros(n)
    done = parent < 0
    # parents precede children in RenderSetupData order, but do not rely on it: relax
    for _ in range(n):
        if done.all():
            break
        ready = ~done & done[np.maximum(parent, 0)]
        p = parent[ready]
        arc[ready] = arc[p] + np.linalg.norm(rest[ready] - rest[p], axis=1)
        done |= ready
    team = np.asarray(model.particle_team, dtype=np.int64)
    team_count = int(np.asarray(model.team_particle_count).shape[0])
    team_length = np.zeros(team_count)
    np.maximum.at(team_length, team, arc)
    team_length = np.maximum(team_length, 1e-9)
    return ChainGeometry(edges, edge_rest, root, root_rest, arc, team_length[team], moving, team, team_length)


# ----------------------------------------------------------------------------- stretch
def edge_stretch(positions: np.ndarray, geometry: ChainGeometry) -> np.ndarray:
    """Relative edge length change ``|p1 - p0| / rest - 1`` (..., E); 0 for zero-length edges."""
    e = geometry.edges
    if e.shape[0] == 0:
        return np.zeros(positions.shape[:-2] + (0,))
    length = np.linalg.norm(positions[..., e[:, 1], :] - positions[..., e[:, 0], :], axis=-1)
    rest = geometry.edge_rest
    ok = rest > ZERO_LENGTH
    return np.where(ok, length / np.where(ok, rest, 1.0) - 1.0, 0.0)


def root_distance_stretch(positions: np.ndarray, geometry: ChainGeometry) -> np.ndarray:
    """Relative change of each moving particle's distance to its root (..., N); 0 elsewhere."""
    root = geometry.root_index
    ok = (root >= 0) & (geometry.root_rest > ZERO_LENGTH)
    d = np.linalg.norm(positions - positions[..., np.maximum(root, 0), :], axis=-1)
    return np.where(ok, d / np.where(ok, geometry.root_rest, 1.0) - 1.0, 0.0)


def zero_length_drift(positions: np.ndarray, geometry: ChainGeometry) -> float:
    """Largest length (m) reached by an edge whose rest length is zero (coincident bones)."""
    e = geometry.edges[geometry.edge_rest <= ZERO_LENGTH]
    if e.shape[0] == 0:
        return 0.0
    return float(np.linalg.norm(positions[..., e[:, 1], :] - positions[..., e[:, 0], :], axis=-1).max())


# ----------------------------------------------------------------------------- colliders
def particle_collider_pairs(particle_team: np.ndarray, team_colliders: list) -> tuple[np.ndarray, np.ndarray]:
    """Every (particle, collider) pair the solver checks: each particle against its team's
    colliders (``team_colliders[t]``: indices into the scene's ``ColliderSet``)."""
    pi, ci = [], []
    for t, cols in enumerate(team_colliders):
        members = np.nonzero(particle_team == t)[0]
        for c in cols:
            pi.append(members)
            ci.append(np.full(members.shape[0], int(c)))
    if not pi:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    return np.concatenate(pi).astype(np.int64), np.concatenate(ci).astype(np.int64)


def pair_depths(positions: np.ndarray, particle_radius: np.ndarray, pairs, shapes) -> np.ndarray:
    """Signed depth (m, > 0 inside, < 0 the gap) of each checked (particle, collider) pair's
    particle inside the shell "collider surface + particle radius" (the surface the solver
    projects onto, docs/solver.md §D.8); (P,) in the order of ``pairs``.

    ``pairs`` is ``(particle index (P,), collider index (P,))``; ``shapes`` has per collider
    ``shape`` (0 sphere, 1 capsule, 2 plane), ``position``, ``start``/``end`` (capsule end
    centres), ``radius``/``end_radius`` (m), ``normal`` (plane, unit) and ``suspended``: a
    ``ColliderSet.world_shapes(hierarchy)`` (§G.2) or a solver step's collider slots
    (``bench.mocap_suite.step_collider_shapes``). Capsules use the radius interpolated along
    the axis at the closest point; planes are one-sided (+normal is out); suspended colliders
    give -inf (never inside). With ``particle_radius`` 0 the depth is the centre's.
    """
    return pair_contacts(positions, particle_radius, pairs, shapes)[0]


def pair_contacts(positions: np.ndarray, particle_radius: np.ndarray, pairs, shapes
                  ) -> tuple[np.ndarray, np.ndarray]:
    """``pair_depths`` and the outward unit normal of the collider surface nearest to each
    pair's particle ((P,3); zero where undefined: a centre on a sphere's centre or a capsule's
    axis, a suspended collider)."""
    pi, ci = pairs
    d = np.full(pi.shape[0], -np.inf)
    normal = np.zeros((pi.shape[0], 3))
    if pi.shape[0] == 0:
        return d, normal

    def unit(v):
        length = np.linalg.norm(v, axis=1)
        return np.where(length[:, None] > 1e-12, v / np.maximum(length, 1e-12)[:, None], 0.0), length

    p = positions[pi]
    r = particle_radius[pi]
    shape = np.where(shapes.suspended[ci], -1, shapes.shape[ci])
    # sphere
    s = shape == 0
    if s.any():
        normal[s], dist = unit(p[s] - shapes.position[ci[s]])
        d[s] = shapes.radius[ci[s]] + r[s] - dist
    # capsule (two radii): closest point on the start-end segment
    c = shape == 1
    if c.any():
        a, b = shapes.start[ci[c]], shapes.end[ci[c]]
        ab = b - a
        len2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-18)
        u = np.clip(np.einsum("ij,ij->i", p[c] - a, ab) / len2, 0.0, 1.0)
        closest = a + ab * u[:, None]
        rad = shapes.radius[ci[c]] + (shapes.end_radius[ci[c]] - shapes.radius[ci[c]]) * u
        normal[c], dist = unit(p[c] - closest)
        d[c] = rad + r[c] - dist
    # plane: signed distance along the normal
    q = shape == 2
    if q.any():
        d[q] = r[q] - np.einsum("ij,ij->i", p[q] - shapes.position[ci[q]], shapes.normal[ci[q]])
        normal[q] = shapes.normal[ci[q]]
    return d, normal


def penetration_depth(positions: np.ndarray, particle_radius: np.ndarray, pairs, shapes) -> np.ndarray:
    """Depth (m, >= 0) of each particle inside the shell "collider surface + particle radius",
    max over its colliders (``pair_depths``); (N,)."""
    depth = np.zeros(positions.shape[0])
    pi = pairs[0]
    if pi.shape[0] == 0:
        return depth
    np.maximum.at(depth, pi, np.maximum(pair_depths(positions, particle_radius, pairs, shapes), 0.0))
    return depth


def rigid_point_velocity(points: np.ndarray, pose_before, pose_after, dt: float) -> np.ndarray:
    """Velocity (m/s, (P,3)) of body points that are at ``points`` (P,3) now, the body having
    moved rigidly from ``pose_before`` to ``pose_after`` over ``dt`` s; a pose is (position
    (P,3) m, rotation (P,4) xyzw), one row per point (its body's pose). The point's previous
    place is its body-local coordinates taken back to the earlier pose: a body part's speed
    where a particle touches it, rotation included (a spinning head's surface moves)."""
    from magica_py.scene.colliders import _rotation_matrices

    p0, q0 = pose_before
    p1, q1 = pose_after
    if points.shape[0] == 0 or dt <= 0.0:
        return np.zeros_like(points)
    r0, r1 = _rotation_matrices(np.asarray(q0)), _rotation_matrices(np.asarray(q1))
    local = np.einsum("pji,pj->pi", r1, points - p1)            # R1^T (x - p1)
    before = p0 + np.einsum("pij,pj->pi", r0, local)
    return (points - before) / dt


def ejection_speeds(velocity: np.ndarray, body_velocity: np.ndarray, normal: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For particles touching a body part ((P,3) each, m/s; ``normal`` the body's outward unit
    normal at the particle): their speed relative to it ``|v - v_body|``, their excess speed
    ``|v| - |v_body|`` (issue 16's bound: at most 2 m/s) and their ejection, the speed at
    which they leave the surface beyond the body's own push, ``v.n - max(v_body.n, 0)``: a
    particle thrown out of a thigh counts its whole outward speed above the thigh's, one
    carried along (or swinging along the surface) 0, and one left behind by a body moving
    away from it (a head dropping away under the hair) its own outward speed only, not the
    body's retreat; (P,) each."""
    relative = np.linalg.norm(velocity - body_velocity, axis=1)
    excess = np.linalg.norm(velocity, axis=1) - np.linalg.norm(body_velocity, axis=1)
    outward = np.einsum("ij,ij->i", velocity, normal) - np.maximum(np.einsum("ij,ij->i", body_velocity, normal), 0.0)
    return relative, excess, outward


def particle_radius(model, parameters, scale_ratio=None) -> np.ndarray:
    """Collision radius (m) of each particle: the team's radius depth table (§0.3, 16
    samples, piecewise linear) at the particle's depth, times the team's scale ratio."""
    team = np.asarray(model.particle_team, dtype=np.int64)
    depth = np.clip(np.asarray(model.depth, dtype=np.float64), 0.0, 1.0)
    table = np.asarray(parameters.radius_curve)[team]           # (N, 16)
    x = depth * 15.0
    i = np.minimum(x.astype(np.int64), 15)
    j = np.minimum(i + 1, 15)
    u = x - i
    rows = np.arange(team.shape[0])
    radius = table[rows, i] + (table[rows, j] - table[rows, i]) * u
    if scale_ratio is not None:
        radius = radius * np.asarray(scale_ratio)[team]
    return radius


# ----------------------------------------------------------------------------- motion
def frame_speeds(positions: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Display speed (m/s) of each particle between consecutive frames, (F, N); the first
    frame is 0. Frames with no time step (time scale 0) give 0."""
    speed = np.zeros(positions.shape[:2])
    if positions.shape[0] < 2:
        return speed
    dt = np.diff(times)
    step = np.linalg.norm(np.diff(positions, axis=0), axis=-1)
    ok = dt > 1e-12
    speed[1:][ok] = step[ok] / dt[ok, None]
    return speed


def energy_envelope(positions: np.ndarray, times: np.ndarray, moving: np.ndarray, gravity: float,
                    gravity_direction=(0.0, -1.0, 0.0)) -> np.ndarray:
    """Specific mechanical energy (J/kg summed over moving particles) per frame: kinetic
    from the frame speeds plus ``gravity`` x height above the lowest point of the run."""
    g_dir = np.asarray(gravity_direction, dtype=np.float64)
    norm = np.linalg.norm(g_dir)
    g_dir = g_dir / norm if norm > 0 else g_dir
    v = frame_speeds(positions, times)[:, moving]
    height = -np.einsum("fnk,k->fn", positions[:, moving], g_dir)
    height = height - height.min() if height.size else height
    return (0.5 * v * v + gravity * height).sum(axis=1)


def kinetic_envelope(positions: np.ndarray, times: np.ndarray, moving: np.ndarray,
                     team: np.ndarray | None = None, window: int = 1) -> np.ndarray:
    """Specific kinetic energy (J/kg, summed over the moving particles) per frame, from the
    frame speeds: a statistic that stays comparable when trajectories diverge.

    With ``team`` (N,) the mean velocity of each team's moving particles is removed first
    (the energy of the cloth's own swing, not of the character carrying it); ``window`` > 1
    takes the running maximum over that many frames (the envelope)."""
    vel = np.zeros(positions.shape)
    if positions.shape[0] > 1:
        dt = np.diff(times)
        ok = dt > 1e-12
        vel[1:][ok] = np.diff(positions, axis=0)[ok] / dt[ok, None, None]
    vel = vel[:, moving]
    if team is not None:
        t = np.asarray(team)[moving]
        for k in np.unique(t):
            members = t == k
            vel[:, members] -= vel[:, members].mean(axis=1, keepdims=True)
    energy = 0.5 * (vel * vel).sum(axis=(1, 2))
    if window > 1 and energy.size:
        energy = np.array([energy[max(0, i - window + 1):i + 1].max() for i in range(energy.shape[0])])
    return energy


def settling_time(values: np.ndarray, times: np.ndarray, threshold: float, after: float = 0.0) -> float:
    """Time (s, relative to ``after``) from which ``values`` stays at or below ``threshold``
    until the end of the run; ``inf`` when it never settles, 0 when it never exceeds."""
    values = np.asarray(values)
    times = np.asarray(times)
    idx = np.nonzero(times >= after - 1e-12)[0]
    if idx.size == 0:
        return math.inf
    above = np.nonzero(values[idx] > threshold)[0]
    if above.size == 0:
        return 0.0
    last = idx[above[-1]]
    if last + 1 >= times.shape[0]:
        return math.inf
    return float(times[last + 1] - after)


def sample_at(times: np.ndarray, values: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Linear interpolation of ``values`` (F, ...) recorded at increasing ``times`` (F,)
    at ``query`` times (Q,) -> (Q, ...); queries outside the record are clamped."""
    times = np.asarray(times, dtype=np.float64)
    query = np.asarray(query, dtype=np.float64)
    flat = np.asarray(values, dtype=np.float64).reshape(times.shape[0], -1)
    i = np.clip(np.searchsorted(times, query, side="right") - 1, 0, times.shape[0] - 1)
    j = np.minimum(i + 1, times.shape[0] - 1)
    span = times[j] - times[i]
    u = np.where(span > 0, (query - times[i]) / np.where(span > 0, span, 1.0), 0.0)
    u = np.clip(u, 0.0, 1.0)[:, None]
    out = flat[i] + (flat[j] - flat[i]) * u
    return out.reshape((query.shape[0],) + np.asarray(values).shape[1:])


def common_times(records: list, period: float) -> np.ndarray:
    """Times every record covers, every ``period`` s (records are ``times`` arrays)."""
    start = max(float(t[0]) for t in records)
    end = min(float(t[-1]) for t in records)
    if end < start:
        return np.zeros(0)
    count = int(math.floor((end - start) / period + 1e-9)) + 1
    return start + period * np.arange(count)


def frame_rate_spread(records: list, length: float, period: float = 1.0 / 120.0) -> float:
    """Largest distance between the tip positions of several runs of the same scene at
    different render rates, sampled at common times, over ``length`` (chain length).

    ``records``: list of ``(times (F,), tips (F, K, 3))``; the spread at a time is the
    largest pairwise distance of any tip, and the result the maximum over time."""
    t = common_times([r[0] for r in records], period)
    if t.size == 0 or len(records) < 2:
        return 0.0
    sampled = np.stack([sample_at(r[0], r[1], t) for r in records])      # (R, Q, K, 3)
    worst = 0.0
    for a in range(len(records)):
        for b in range(a + 1, len(records)):
            worst = max(worst, float(np.linalg.norm(sampled[a] - sampled[b], axis=-1).max()))
    return worst / max(length, 1e-12)


# ----------------------------------------------------------------------------- error
def frame_errors(positions: np.ndarray, reference: np.ndarray, length_scale: np.ndarray,
                 mask: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame RMS and max of ``|p - p_ref| / chain length`` over the particles selected
    by ``mask`` (moving particles usually); two (F,) arrays."""
    diff = np.linalg.norm(positions - reference, axis=-1) / length_scale
    if mask is not None:
        diff = diff[:, mask]
    if diff.shape[1] == 0:
        z = np.zeros(diff.shape[0])
        return z, z
    return np.sqrt(np.mean(diff * diff, axis=1)), diff.max(axis=1)
