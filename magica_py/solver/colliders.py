"""Collider poses per frame (docs/solver.md §G.2) and per step (§G.3), one slot per (team, collider).

A block's collider slots (``blocks.BI_COLLIDER0`` + k) hold, lane by lane, the colliders of
its teams in the order of their cloth's collider list; their shapes, capsule axes and flags
are the block's (``collider_shape`` ... segments of its topology: part of the block key), the
hierarchy node each lane's collider rides on is ``collider_transform[slot, lane]``. The
kernels keep each slot's frame history (shifted with the team's inertia shift, reset with
the team) and build the step's work data (old/new endpoints, scaled radii, swept bounds)
read by ``constraints/collision.py``.
"""
from __future__ import annotations

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels.math3d import (
    q_inverse, q_mul, q_normalize, q_rotate, q_slerp, shift_position, v_add, v_lerp, v_scale, v_sub,
)
from magica_py.solver import blocks as bk
from magica_py.solver import state as st
from magica_py.solver.center import world_pose_rows
from magica_py.solver.lanes import get1, get3, get4, put1, put3, put4

SPHERE = 0
CAPSULE = 1
PLANE = 2


@kernel
def _sign(x):
    return -1.0 if x < 0.0 else 1.0


@kernel(forceinline=False)
def collider_frame_block(CS, TS, TI, BI, CT, b, w, world_position, world_rotation, lossy_scale):
    """G.2 for the collider slots of every active lane of block b (its first ``w`` lanes): this
    frame's pose and the history update. The lane loop is here, not in the caller, so that
    numba counts this function's array arguments once a block, not once a lane."""
    for l in range(w):
        if TI[b, bk.TI_TEAM + l] < 0 or get1(TS, b, st.ACTIVE, l) == 0.0:
            continue
        reset = get1(TS, b, st.RESET, l) != 0.0
        shift = get1(TS, b, st.INERTIA_SHIFT, l) != 0.0
        pivot = get3(TS, b, st.OLD_COMPONENT_POS, l)
        vec = get3(TS, b, st.FRAME_SHIFT_VECTOR, l)
        srot = get4(TS, b, st.FRAME_SHIFT_ROTATION, l)
        c0 = BI[b, bk.BI_COLLIDER0]
        for k in range(c0, c0 + BI[b, bk.BI_COLLIDERS]):
            pos, rot, (sx, sy, sz) = world_pose_rows(world_position, world_rotation, lossy_scale, np.int64(CT[k, l]))
            suspend = False
            if abs(sx) < 1e-6:
                sx = 1e-6
                suspend = True
            if abs(sy) < 1e-6:
                sy = 1e-6
                suspend = True
            if abs(sz) < 1e-6:
                sz = 1e-6
                suspend = True
            put1(CS, k, st.SCALE_SUSPEND, l, 1.0 if suspend else 0.0)
            lc = get3(CS, k, st.LOCAL_CENTER, l)
            center = (lc[0] * _sign(sx), lc[1] * _sign(sy), lc[2] * _sign(sz))
            rc = q_rotate(rot, center)
            fpos = (pos[0] + rc[0] * abs(sx), pos[1] + rc[1] * abs(sy), pos[2] + rc[2] * abs(sz))
            put3(CS, k, st.FRAME_POS, l, fpos)
            put4(CS, k, st.FRAME_ROT, l, rot)
            put3(CS, k, st.FRAME_SCALE, l, (sx, sy, sz))
            if reset or get1(CS, k, st.FIRST_FRAME, l) != 0.0 or suspend:
                put3(CS, k, st.OLD_FRAME_POS, l, fpos)
                put3(CS, k, st.NOW_POS, l, fpos)
                put3(CS, k, st.C_OLD_POS, l, fpos)
                put4(CS, k, st.OLD_FRAME_ROT, l, rot)
                put4(CS, k, st.NOW_ROT, l, rot)
                put4(CS, k, st.C_OLD_ROT, l, rot)
                put1(CS, k, st.FIRST_FRAME, l, 0.0)
            elif shift:
                put3(CS, k, st.OLD_FRAME_POS, l, shift_position(get3(CS, k, st.OLD_FRAME_POS, l), pivot, vec, srot))
                put3(CS, k, st.NOW_POS, l, shift_position(get3(CS, k, st.NOW_POS, l), pivot, vec, srot))
                put3(CS, k, st.C_OLD_POS, l, shift_position(get3(CS, k, st.C_OLD_POS, l), pivot, vec, srot))
                put4(CS, k, st.OLD_FRAME_ROT, l, q_mul(srot, get4(CS, k, st.OLD_FRAME_ROT, l)))
                put4(CS, k, st.NOW_ROT, l, q_mul(srot, get4(CS, k, st.NOW_ROT, l)))
                put4(CS, k, st.C_OLD_ROT, l, q_mul(srot, get4(CS, k, st.C_OLD_ROT, l)))


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


@kernel(inline="always")
def collider_step_pose(old_frame_pos, frame_pos, old_frame_rot, frame_rot, old_pos, old_rot, t, mv, rv):
    """G.3 pose of one slot: (now_pos, now_rot, old_pos, old_rot, inverse old_rot) at frame
    interpolation t, the old pose pulled towards the new one by the team's local inertia ratios
    (mv, rv: ``step_move/rotation_inertia_ratio``)."""
    now_pos = v_lerp(old_frame_pos, frame_pos, t)
    now_rot = q_normalize(q_slerp(old_frame_rot, frame_rot, t))
    old_pos = v_lerp(old_pos, now_pos, mv)
    old_rot = q_normalize(q_slerp(old_rot, now_rot, rv))
    return now_pos, now_rot, old_pos, old_rot, q_inverse(old_rot)


@kernel(inline="always")
def swept_bounds(so, sn, eo, en, rs, re):
    """(aabb_min, aabb_max) of a capsule (or sphere: start == end) swept from old to new."""
    lo = (min(min(so[0], sn[0]) - rs, min(eo[0], en[0]) - re), min(min(so[1], sn[1]) - rs, min(eo[1], en[1]) - re),
          min(min(so[2], sn[2]) - rs, min(eo[2], en[2]) - re))
    hi = (max(max(so[0], sn[0]) + rs, max(eo[0], en[0]) + re), max(max(so[1], sn[1]) + rs, max(eo[1], en[1]) + re),
          max(max(so[2], sn[2]) + rs, max(eo[2], en[2]) + re))
    return lo, hi


@kernel(inline="always")
def sphere_bounds(old_pos, now_pos, r):
    """(aabb_min, aabb_max) of a sphere of radius r swept from old_pos to now_pos."""
    lo = (min(old_pos[0], now_pos[0]) - r, min(old_pos[1], now_pos[1]) - r, min(old_pos[2], now_pos[2]) - r)
    hi = (max(old_pos[0], now_pos[0]) + r, max(old_pos[1], now_pos[1]) + r, max(old_pos[2], now_pos[2]) + r)
    return lo, hi


@kernel(forceinline=False)
def collider_step_block(CS, TS, BI, topology, b):
    """G.3 at the start of a step, every collider slot and running lane of block b: step pose,
    local-inertia shift of the old pose, work data (``collider_step_pose``, ``capsule_ends``,
    ``swept_bounds``)."""
    c0 = BI[b, bk.BI_COLLIDER0]
    w = bk.lane_width(BI, b)
    shapes, directions = BI[b, bk.BI_COLLIDER_SHAPE], BI[b, bk.BI_COLLIDER_DIRECTION]
    reverses, aligns = BI[b, bk.BI_COLLIDER_REVERSE], BI[b, bk.BI_COLLIDER_ALIGNED]
    for c in range(BI[b, bk.BI_COLLIDERS]):
        k = c0 + c
        shape = topology[shapes + c]
        d = topology[directions + c]
        reverse = topology[reverses + c] != 0
        aligned = topology[aligns + c] != 0
        for l in range(w):
            now_pos, now_rot, old_pos, old_rot, inverse_old_rot = collider_step_pose(
                get3(CS, k, st.OLD_FRAME_POS, l), get3(CS, k, st.FRAME_POS, l), get4(CS, k, st.OLD_FRAME_ROT, l),
                get4(CS, k, st.FRAME_ROT, l), get3(CS, k, st.C_OLD_POS, l), get4(CS, k, st.C_OLD_ROT, l),
                get1(TS, b, st.FRAME_INTERPOLATION, l), get1(TS, b, st.STEP_MOVE_INERTIA_RATIO, l),
                get1(TS, b, st.STEP_ROTATION_INERTIA_RATIO, l))
            put3(CS, k, st.NOW_POS, l, now_pos)
            put4(CS, k, st.NOW_ROT, l, now_rot)
            put3(CS, k, st.C_OLD_POS, l, old_pos)
            put4(CS, k, st.C_OLD_ROT, l, old_rot)
            put4(CS, k, st.INVERSE_OLD_ROT, l, inverse_old_rot)
            size = get3(CS, k, st.SIZE, l)
            scale = get3(CS, k, st.FRAME_SCALE, l)
            if shape == SPHERE:
                r = size[0] * abs(scale[0])
                put1(CS, k, st.RADIUS_START, l, r)
                put1(CS, k, st.RADIUS_END, l, r)
                put3(CS, k, st.START_OLD, l, old_pos)
                put3(CS, k, st.END_OLD, l, old_pos)
                put3(CS, k, st.START_NEW, l, now_pos)
                put3(CS, k, st.END_NEW, l, now_pos)
                lo, hi = sphere_bounds(old_pos, now_pos, r)
                put3(CS, k, st.AABB_MIN, l, lo)
                put3(CS, k, st.AABB_MAX, l, hi)
            elif shape == CAPSULE:
                s = scale[0] if d == 0 else (scale[1] if d == 1 else scale[2])
                so, eo, rs, re = capsule_ends(old_pos, old_rot, d, reverse, aligned, size, s)
                sn, en, rs, re = capsule_ends(now_pos, now_rot, d, reverse, aligned, size, s)
                put1(CS, k, st.RADIUS_START, l, rs)
                put1(CS, k, st.RADIUS_END, l, re)
                put3(CS, k, st.START_OLD, l, so)
                put3(CS, k, st.END_OLD, l, eo)
                put3(CS, k, st.START_NEW, l, sn)
                put3(CS, k, st.END_NEW, l, en)
                lo, hi = swept_bounds(so, sn, eo, en, rs, re)
                put3(CS, k, st.AABB_MIN, l, lo)
                put3(CS, k, st.AABB_MAX, l, hi)
            else:
                put3(CS, k, st.PLANE_NORMAL, l, q_rotate(now_rot, (0.0, _sign(scale[1]), 0.0)))
                put3(CS, k, st.START_NEW, l, now_pos)
                put3(CS, k, st.START_OLD, l, old_pos)


@kernel(forceinline=False)
def collider_end_step_block(CS, BI, b):
    """G.3 end of step: old = now, every slot and lane of block b."""
    c0 = BI[b, bk.BI_COLLIDER0]
    w = bk.lane_width(BI, b)
    for k in range(c0, c0 + BI[b, bk.BI_COLLIDERS]):
        for l in range(w):
            put3(CS, k, st.C_OLD_POS, l, get3(CS, k, st.NOW_POS, l))
            put4(CS, k, st.C_OLD_ROT, l, get4(CS, k, st.NOW_ROT, l))


@kernel(forceinline=False)
def collider_end_frame_block(CS, TS, TI, BI, b, w, running):
    """End of frame of every active lane of block b whose team ran steps (``running``: the team
    clocks' flags): the frame pose becomes the old frame pose."""
    c0 = BI[b, bk.BI_COLLIDER0]
    for l in range(w):
        t = TI[b, bk.TI_TEAM + l]
        if t < 0 or get1(TS, b, st.ACTIVE, l) == 0.0 or not running[t]:
            continue
        for k in range(c0, c0 + BI[b, bk.BI_COLLIDERS]):
            put3(CS, k, st.OLD_FRAME_POS, l, get3(CS, k, st.FRAME_POS, l))
            put4(CS, k, st.OLD_FRAME_ROT, l, get4(CS, k, st.FRAME_ROT, l))


def collider_shapes(collider_set, indices) -> list[tuple[int, int, int, int]]:
    """``(shape, direction, reverse, aligned)`` of each collider of a cloth (its block key)."""
    return [(int(collider_set.shape[ci]), int(collider_set.direction[ci]),
             1 if collider_set.reverse_direction[ci] else 0, 1 if collider_set.aligned_on_center[ci] else 0)
            for ci in indices]


def fill_slots(CS, slots: np.ndarray, lane: int, collider_set, indices) -> None:
    """Write the static description (local center, radii, length) of a cloth's colliders
    ``indices`` into ``slots`` of lane ``lane`` and mark them fresh (first frame)."""
    for k, ci in zip(slots, indices):
        st.COLLIDER.reset_lanes(CS, int(k), lane)
        st.COLLIDER.write(CS, "local_center", [int(k)], lane, np.asarray(collider_set.center[ci], dtype=np.float64))
        radius = float(collider_set.radius[ci])
        end = getattr(collider_set, "end_radius", None)
        end_radius = float(end[ci]) if end is not None else radius
        st.COLLIDER.write(CS, "size", [int(k)], lane, [radius, end_radius, float(collider_set.length[ci])])
