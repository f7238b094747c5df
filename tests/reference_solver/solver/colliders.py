"""Collider poses per frame (docs/solver.md §G.2) and per step (§G.3), one slot per (team, collider).

``ColliderSlots`` maps the scene's ``ColliderSet`` onto per-team slots; the kernels keep
each slot's frame history (shifted with the team's inertia shift, reset with the team) and
build the step's work data (old/new endpoints, scaled radii, swept bounds) read by
``constraints/collision.py``.
"""
from __future__ import annotations

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels.math3d import (
    q_slerp,
    load3, load4, q_inverse, q_mul, q_normalize, q_rotate, shift_position, store3,
    store4, v_add, v_lerp, v_scale, v_sub,
)

SPHERE = 0
CAPSULE = 1
PLANE = 2


@kernel
def _sign(x):
    return -1.0 if x < 0.0 else 1.0


@kernel
def collider_frame_team(cs, ts, team, world_position, world_rotation, lossy_scale):
    """G.2 for the slots of one team: this frame's pose and the history update."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    cs_first_frame, cs_frame_pos, cs_frame_rot = cs.first_frame, cs.frame_pos, cs.frame_rot
    cs_frame_scale, cs_local_center, cs_now_pos = cs.frame_scale, cs.local_center, cs.now_pos
    cs_now_rot, cs_old_frame_pos, cs_old_frame_rot = cs.now_rot, cs.old_frame_pos, cs.old_frame_rot
    cs_old_pos, cs_old_rot, cs_scale_suspend = cs.old_pos, cs.old_rot, cs.scale_suspend
    cs_transform, ts_collider_count = cs.transform, ts.collider_count
    reset = ts.reset[team] != 0
    shift = ts.inertia_shift[team] != 0
    pivot = load3(ts.old_component_pos, team)
    vec = load3(ts.frame_shift_vector, team)
    srot = load4(ts.frame_shift_rotation, team)
    c0 = ts.collider_start[team]
    for k in range(c0, c0 + ts_collider_count[team]):
        i = cs_transform[k]
        pos = load3(world_position, i)
        rot = load4(world_rotation, i)
        s = load3(lossy_scale, i)
        suspend = False
        sx = s[0]
        sy = s[1]
        sz = s[2]
        if abs(sx) < 1e-6:
            sx = 1e-6
            suspend = True
        if abs(sy) < 1e-6:
            sy = 1e-6
            suspend = True
        if abs(sz) < 1e-6:
            sz = 1e-6
            suspend = True
        cs_scale_suspend[k] = 1 if suspend else 0
        center = (cs_local_center[k, 0] * _sign(sx), cs_local_center[k, 1] * _sign(sy),
                  cs_local_center[k, 2] * _sign(sz))
        rc = q_rotate(rot, center)
        fpos = (pos[0] + rc[0] * abs(sx), pos[1] + rc[1] * abs(sy), pos[2] + rc[2] * abs(sz))
        store3(cs_frame_pos, k, fpos)
        store4(cs_frame_rot, k, rot)
        store3(cs_frame_scale, k, (sx, sy, sz))
        if reset or cs_first_frame[k] != 0 or suspend:
            store3(cs_old_frame_pos, k, fpos)
            store3(cs_now_pos, k, fpos)
            store3(cs_old_pos, k, fpos)
            store4(cs_old_frame_rot, k, rot)
            store4(cs_now_rot, k, rot)
            store4(cs_old_rot, k, rot)
            cs_first_frame[k] = 0
        elif shift:
            store3(cs_old_frame_pos, k, shift_position(load3(cs_old_frame_pos, k), pivot, vec, srot))
            store3(cs_now_pos, k, shift_position(load3(cs_now_pos, k), pivot, vec, srot))
            store3(cs_old_pos, k, shift_position(load3(cs_old_pos, k), pivot, vec, srot))
            store4(cs_old_frame_rot, k, q_mul(srot, load4(cs_old_frame_rot, k)))
            store4(cs_now_rot, k, q_mul(srot, load4(cs_now_rot, k)))
            store4(cs_old_rot, k, q_mul(srot, load4(cs_old_rot, k)))


@kernel
def capsule_ends(pos, rot, direction, reverse, aligned, size, s):
    """Start and end sphere centres and radii (start, end, rs, re) of a capsule at pose
    (pos, rot) (G.3 steps 1-5): ``direction`` its local axis (0 x, 1 y, 2 z), ``s`` the frame
    scale along it, ``size`` (start radius, end radius, length)."""
    axis = (1.0, 0.0, 0.0) if direction == 0 else ((0.0, 1.0, 0.0) if direction == 1 else (0.0, 0.0, 1.0))
    axis = v_scale(axis, _sign(s))
    scale = abs(s)
    if reverse:
        axis = v_scale(axis, -1.0)
    rs = size[0] * scale
    re = size[1] * scale
    length = size[2] * scale
    if aligned:
        a = length * 0.5
        b = length * 0.5
    else:
        a = 0.0
        b = length - rs
    a = max(a - rs, 0.0)
    b = max(b - re, 0.0)
    return (v_add(pos, q_rotate(rot, v_scale(axis, a))), v_sub(pos, q_rotate(rot, v_scale(axis, b))), rs, re)


@kernel
def collider_step_pose(old_frame_pos, frame_pos, old_frame_rot, frame_rot, old_pos, old_rot, t, mv, rv):
    """G.3 pose of one slot: (now_pos, now_rot, old_pos, old_rot, inverse old_rot) at frame
    interpolation t, the old pose pulled towards the new one by the team's local inertia ratios
    (mv, rv: ``step_move/rotation_inertia_ratio``)."""
    now_pos = v_lerp(old_frame_pos, frame_pos, t)
    now_rot = q_normalize(q_slerp(old_frame_rot, frame_rot, t))
    old_pos = v_lerp(old_pos, now_pos, mv)
    old_rot = q_normalize(q_slerp(old_rot, now_rot, rv))
    return now_pos, now_rot, old_pos, old_rot, q_inverse(old_rot)


@kernel
def swept_bounds(so, sn, eo, en, rs, re):
    """(aabb_min, aabb_max) of a capsule (or sphere: start == end) swept from old to new."""
    lo = (min(min(so[0], sn[0]) - rs, min(eo[0], en[0]) - re), min(min(so[1], sn[1]) - rs, min(eo[1], en[1]) - re),
          min(min(so[2], sn[2]) - rs, min(eo[2], en[2]) - re))
    hi = (max(max(so[0], sn[0]) + rs, max(eo[0], en[0]) + re), max(max(so[1], sn[1]) + rs, max(eo[1], en[1]) + re),
          max(max(so[2], sn[2]) + rs, max(eo[2], en[2]) + re))
    return lo, hi


@kernel
def sphere_bounds(old_pos, now_pos, r):
    """(aabb_min, aabb_max) of a sphere of radius r swept from old_pos to now_pos."""
    lo = (min(old_pos[0], now_pos[0]) - r, min(old_pos[1], now_pos[1]) - r, min(old_pos[2], now_pos[2]) - r)
    hi = (max(old_pos[0], now_pos[0]) + r, max(old_pos[1], now_pos[1]) + r, max(old_pos[2], now_pos[2]) + r)
    return lo, hi


@kernel
def collider_step_team(cs, ts, team, frame_interpolation):
    """G.3 at the start of a step: step pose, local-inertia shift of the old pose, work data
    (per slot: ``collider_step_pose``, ``capsule_ends``, ``swept_bounds``)."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    cs_aabb_max, cs_aabb_min, cs_aligned_on_center = cs.aabb_max, cs.aabb_min, cs.aligned_on_center
    cs_direction, cs_end_new, cs_end_old, cs_frame_pos = cs.direction, cs.end_new, cs.end_old, cs.frame_pos
    cs_frame_rot, cs_frame_scale, cs_inverse_old_rot = cs.frame_rot, cs.frame_scale, cs.inverse_old_rot
    cs_now_pos, cs_now_rot, cs_old_frame_pos = cs.now_pos, cs.now_rot, cs.old_frame_pos
    cs_old_frame_rot, cs_old_pos, cs_old_rot = cs.old_frame_rot, cs.old_pos, cs.old_rot
    cs_plane_normal, cs_radius_end, cs_radius_start = cs.plane_normal, cs.radius_end, cs.radius_start
    cs_reverse_direction, cs_shape, cs_size = cs.reverse_direction, cs.shape, cs.size
    cs_start_new, cs_start_old, ts_collider_count = cs.start_new, cs.start_old, ts.collider_count
    t = frame_interpolation
    mv = ts.step_move_inertia_ratio[team]
    rv = ts.step_rotation_inertia_ratio[team]
    c0 = ts.collider_start[team]
    for k in range(c0, c0 + ts_collider_count[team]):
        now_pos, now_rot, old_pos, old_rot, inverse_old_rot = collider_step_pose(
            load3(cs_old_frame_pos, k), load3(cs_frame_pos, k), load4(cs_old_frame_rot, k), load4(cs_frame_rot, k),
            load3(cs_old_pos, k), load4(cs_old_rot, k), t, mv, rv)
        store3(cs_now_pos, k, now_pos)
        store4(cs_now_rot, k, now_rot)
        store3(cs_old_pos, k, old_pos)
        store4(cs_old_rot, k, old_rot)
        store4(cs_inverse_old_rot, k, inverse_old_rot)
        shape = cs_shape[k]
        if shape == SPHERE:
            r = cs_size[k, 0] * abs(cs_frame_scale[k, 0])
            cs_radius_start[k] = r
            cs_radius_end[k] = r
            store3(cs_start_old, k, old_pos)
            store3(cs_end_old, k, old_pos)
            store3(cs_start_new, k, now_pos)
            store3(cs_end_new, k, now_pos)
            lo, hi = sphere_bounds(old_pos, now_pos, r)
            store3(cs_aabb_min, k, lo)
            store3(cs_aabb_max, k, hi)
        elif shape == CAPSULE:
            d = cs_direction[k]
            size = (cs_size[k, 0], cs_size[k, 1], cs_size[k, 2])
            reverse = cs_reverse_direction[k] != 0
            aligned = cs_aligned_on_center[k] != 0
            so, eo, rs, re = capsule_ends(old_pos, old_rot, d, reverse, aligned, size, cs_frame_scale[k, d])
            sn, en, rs, re = capsule_ends(now_pos, now_rot, d, reverse, aligned, size, cs_frame_scale[k, d])
            cs_radius_start[k] = rs
            cs_radius_end[k] = re
            store3(cs_start_old, k, so)
            store3(cs_end_old, k, eo)
            store3(cs_start_new, k, sn)
            store3(cs_end_new, k, en)
            lo, hi = swept_bounds(so, sn, eo, en, rs, re)
            store3(cs_aabb_min, k, lo)
            store3(cs_aabb_max, k, hi)
        else:
            sy = _sign(cs_frame_scale[k, 1])
            store3(cs_plane_normal, k, q_rotate(now_rot, (0.0, sy, 0.0)))
            store3(cs_start_new, k, now_pos)
            store3(cs_start_old, k, old_pos)


@kernel
def collider_end_step_team(cs, ts, team):
    """G.3 end of step: old = now."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    cs_now_pos, cs_now_rot, cs_old_pos, cs_old_rot = cs.now_pos, cs.now_rot, cs.old_pos, cs.old_rot
    ts_collider_count = ts.collider_count
    c0 = ts.collider_start[team]
    for k in range(c0, c0 + ts_collider_count[team]):
        for c in range(3):
            cs_old_pos[k, c] = cs_now_pos[k, c]
        for c in range(4):
            cs_old_rot[k, c] = cs_now_rot[k, c]


@kernel
def collider_end_frame_team(cs, ts, team, running):
    """End of frame: if the team ran, the frame pose becomes the old frame pose."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    cs_frame_pos, cs_frame_rot, cs_old_frame_pos = cs.frame_pos, cs.frame_rot, cs.old_frame_pos
    cs_old_frame_rot, ts_collider_count = cs.old_frame_rot, ts.collider_count
    if not running:
        return
    c0 = ts.collider_start[team]
    for k in range(c0, c0 + ts_collider_count[team]):
        for c in range(3):
            cs_old_frame_pos[k, c] = cs_frame_pos[k, c]
        for c in range(4):
            cs_old_frame_rot[k, c] = cs_frame_rot[k, c]


def fill_slots(cs, team_slots: list[tuple[int, list[int]]], collider_set) -> None:
    """Copy the static collider description into slots: ``team_slots`` is
    ``[(team, [collider indices]), ...]`` in slot order."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    cs_aligned_on_center, cs_collider_index = cs.aligned_on_center, cs.collider_index
    cs_direction, cs_first_frame, cs_local_center = cs.direction, cs.first_frame, cs.local_center
    cs_reverse_direction, cs_shape, cs_size, cs_team = cs.reverse_direction, cs.shape, cs.size, cs.team
    cs_transform = cs.transform
    k = 0
    for team, indices in team_slots:
        for ci in indices:
            cs_collider_index[k] = ci
            cs_team[k] = team
            cs_shape[k] = int(collider_set.shape[ci])
            cs_transform[k] = int(collider_set.transform[ci])
            cs_local_center[k] = np.asarray(collider_set.center[ci], dtype=np.float64)
            radius = float(collider_set.radius[ci])
            end = getattr(collider_set, "end_radius", None)
            end_radius = float(end[ci]) if end is not None else radius
            cs_size[k] = (radius, end_radius, float(collider_set.length[ci]))
            cs_direction[k] = int(collider_set.direction[ci])
            cs_reverse_direction[k] = 1 if collider_set.reverse_direction[ci] else 0
            cs_aligned_on_center[k] = 1 if collider_set.aligned_on_center[ci] else 0
            cs_first_frame[k] = 1
            k += 1
