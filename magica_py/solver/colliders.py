"""Collider poses per frame (docs/solver.md §G.2) and per step (§G.3), one slot per (team, collider).

``ColliderSlots`` maps the scene's ``ColliderSet`` onto per-team slots; the kernels keep
each slot's frame history (shifted with the team's inertia shift, reset with the team) and
build the step's work data (old/new endpoints, scaled radii, swept bounds) read by
``constraints/collision.py``.
"""
from __future__ import annotations

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels.streams import READ, open_streams, sload, sload3, sload4, sstore, sstore3, sstore4
from magica_py.solver.batched.transfer import in3, in4, out3, out4
from magica_py.kernels.math3d import (
    load3, load4, q_inverse, q_mul, q_normalize, q_rotate, shift_position, store3,
    slerp_is_near, slerp_near, store4, v_add, v_lerp, v_scale, v_sub,
)
from magica_py.solver.team_step import LANES, LANES_NEAR, SCALAR, slerp_in_mode

SPHERE = 0
CAPSULE = 1
PLANE = 2


@kernel
def _sign(x):
    return -1.0 if x < 0.0 else 1.0


@kernel
def collider_frame_team(cs, ts, team, world_position, world_rotation, lossy_scale):
    """G.2 for the slots of one team: this frame's pose and the history update."""
    reset = ts.reset[team] != 0
    shift = ts.inertia_shift[team] != 0
    pivot = load3(ts.old_component_pos, team)
    vec = load3(ts.frame_shift_vector, team)
    srot = load4(ts.frame_shift_rotation, team)
    c0 = ts.collider_start[team]
    for k in range(c0, c0 + ts.collider_count[team]):
        i = cs.transform[k]
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
        cs.scale_suspend[k] = 1 if suspend else 0
        center = (cs.local_center[k, 0] * _sign(sx), cs.local_center[k, 1] * _sign(sy),
                  cs.local_center[k, 2] * _sign(sz))
        rc = q_rotate(rot, center)
        fpos = (pos[0] + rc[0] * abs(sx), pos[1] + rc[1] * abs(sy), pos[2] + rc[2] * abs(sz))
        store3(cs.frame_pos, k, fpos)
        store4(cs.frame_rot, k, rot)
        store3(cs.frame_scale, k, (sx, sy, sz))
        if reset or cs.first_frame[k] != 0 or suspend:
            store3(cs.old_frame_pos, k, fpos)
            store3(cs.now_pos, k, fpos)
            store3(cs.old_pos, k, fpos)
            store4(cs.old_frame_rot, k, rot)
            store4(cs.now_rot, k, rot)
            store4(cs.old_rot, k, rot)
            cs.first_frame[k] = 0
        elif shift:
            store3(cs.old_frame_pos, k, shift_position(load3(cs.old_frame_pos, k), pivot, vec, srot))
            store3(cs.now_pos, k, shift_position(load3(cs.now_pos, k), pivot, vec, srot))
            store3(cs.old_pos, k, shift_position(load3(cs.old_pos, k), pivot, vec, srot))
            store4(cs.old_frame_rot, k, q_mul(srot, load4(cs.old_frame_rot, k)))
            store4(cs.now_rot, k, q_mul(srot, load4(cs.now_rot, k)))
            store4(cs.old_rot, k, q_mul(srot, load4(cs.old_rot, k)))


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


@kernel(inline="always")  # numba-level: too big for LLVM's inliner, and a call stops vectorisation
def collider_step_pose(old_frame_pos, frame_pos, old_frame_rot, frame_rot, old_pos, old_rot, t, mv, rv, mode):
    """G.3 pose of one slot: (now_pos, now_rot, old_pos, old_rot, inverse old_rot) at frame
    interpolation t, the old pose pulled towards the new one by the team's local inertia ratios
    (mv, rv: ``step_move/rotation_inertia_ratio``). ``mode`` (a literal) as in
    ``team_step``: SCALAR per team, LANES branch-free, LANES_NEAR where both slerps are near."""
    now_pos = v_lerp(old_frame_pos, frame_pos, t)
    now_rot = q_normalize(slerp_in_mode(old_frame_rot, frame_rot, t, mode))
    old_pos = v_lerp(old_pos, now_pos, mv)
    old_rot = q_normalize(slerp_in_mode(old_rot, now_rot, rv, mode))
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
    (block form: ``collider_step_block``, the same per-slot functions)."""
    t = frame_interpolation
    mv = ts.step_move_inertia_ratio[team]
    rv = ts.step_rotation_inertia_ratio[team]
    c0 = ts.collider_start[team]
    for k in range(c0, c0 + ts.collider_count[team]):
        now_pos, now_rot, old_pos, old_rot, inverse_old_rot = collider_step_pose(
            load3(cs.old_frame_pos, k), load3(cs.frame_pos, k), load4(cs.old_frame_rot, k), load4(cs.frame_rot, k),
            load3(cs.old_pos, k), load4(cs.old_rot, k), t, mv, rv, SCALAR)
        store3(cs.now_pos, k, now_pos)
        store4(cs.now_rot, k, now_rot)
        store3(cs.old_pos, k, old_pos)
        store4(cs.old_rot, k, old_rot)
        store4(cs.inverse_old_rot, k, inverse_old_rot)
        shape = cs.shape[k]
        if shape == SPHERE:
            r = cs.size[k, 0] * abs(cs.frame_scale[k, 0])
            cs.radius_start[k] = r
            cs.radius_end[k] = r
            store3(cs.start_old, k, old_pos)
            store3(cs.end_old, k, old_pos)
            store3(cs.start_new, k, now_pos)
            store3(cs.end_new, k, now_pos)
            lo, hi = sphere_bounds(old_pos, now_pos, r)
            store3(cs.aabb_min, k, lo)
            store3(cs.aabb_max, k, hi)
        elif shape == CAPSULE:
            d = cs.direction[k]
            size = (cs.size[k, 0], cs.size[k, 1], cs.size[k, 2])
            reverse = cs.reverse_direction[k] != 0
            aligned = cs.aligned_on_center[k] != 0
            so, eo, rs, re = capsule_ends(old_pos, old_rot, d, reverse, aligned, size, cs.frame_scale[k, d])
            sn, en, rs, re = capsule_ends(now_pos, now_rot, d, reverse, aligned, size, cs.frame_scale[k, d])
            cs.radius_start[k] = rs
            cs.radius_end[k] = re
            store3(cs.start_old, k, so)
            store3(cs.end_old, k, eo)
            store3(cs.start_new, k, sn)
            store3(cs.end_new, k, en)
            lo, hi = swept_bounds(so, sn, eo, en, rs, re)
            store3(cs.aabb_min, k, lo)
            store3(cs.aabb_max, k, hi)
        else:
            sy = _sign(cs.frame_scale[k, 1])
            store3(cs.plane_normal, k, q_rotate(now_rot, (0.0, sy, 0.0)))
            store3(cs.start_new, k, now_pos)
            store3(cs.start_old, k, old_pos)


# ----------------------------------------------------------------------------- block form
@kernel
def _scale_component(shape, direction):
    """The frame-scale component a slot's G.3 reads: x (sphere radius), the capsule's axis,
    y (plane normal)."""
    return 0 if shape == SPHERE else (direction if shape == CAPSULE else 1)


@kernel
def collider_step_copy_in(cs, ts, blk, bs, b):
    """Each lane's slots into the lane-collider arrays (``bs.col_*``): the G.3 inputs, and the
    work fields a slot's shape does not write (so that ``col_*`` holds every slot field as
    ``transfer.load_lanes`` copies it)."""
    width = blk.block_width[b]
    lanes = blk.block_lane_base[b]
    cbase = blk.block_collider_base[b]
    e0 = ts.collider_start[blk.block_exemplar[b]]
    for j in range(blk.block_collider_count[b]):
        shape = cs.shape[e0 + j]  # the same in every lane (block formation)
        component = _scale_component(shape, cs.direction[e0 + j])
        for i in range(width):
            s = ts.collider_start[blk.lane_team[lanes + i]] + j
            k = cbase + j * width + i
            bs.col_shape[k] = cs.shape[s]
            bs.col_scale_suspend[k] = cs.scale_suspend[s]
            in3(bs.col_old_frame_pos, k, cs.old_frame_pos, s)
            in3(bs.col_frame_pos, k, cs.frame_pos, s)
            in4(bs.col_old_frame_rot, k, cs.old_frame_rot, s)
            in4(bs.col_frame_rot, k, cs.frame_rot, s)
            in3(bs.col_old_pos, k, cs.old_pos, s)
            in4(bs.col_old_rot, k, cs.old_rot, s)
            bs.col_axis_scale[k] = cs.frame_scale[s, component]
            if shape == PLANE:
                bs.col_radius_start[k] = cs.radius_start[s]
                bs.col_radius_end[k] = cs.radius_end[s]
                in3(bs.col_end_old, k, cs.end_old, s)
                in3(bs.col_end_new, k, cs.end_new, s)
                in3(bs.col_aabb_min, k, cs.aabb_min, s)
                in3(bs.col_aabb_max, k, cs.aabb_max, s)
            else:
                in3(bs.col_plane_normal, k, cs.plane_normal, s)


@kernel
def collider_step_copy_out(cs, ts, blk, bs, b):
    """The slot fields G.3 writes, from the lane-collider arrays back to each lane's slots, with
    the end of step (``collider_end_step_team``: old pose = now pose) folded in: nothing reads a
    slot's old pose from ColliderState during a block step (the block stages read ``bs.col_*``),
    so it is stored once, as the step leaves it."""
    width = blk.block_width[b]
    lanes = blk.block_lane_base[b]
    cbase = blk.block_collider_base[b]
    e0 = ts.collider_start[blk.block_exemplar[b]]
    for j in range(blk.block_collider_count[b]):
        plane = cs.shape[e0 + j] == PLANE
        for i in range(width):
            s = ts.collider_start[blk.lane_team[lanes + i]] + j
            k = cbase + j * width + i
            out3(cs.now_pos, s, bs.col_now_pos, k)
            out4(cs.now_rot, s, bs.col_now_rot, k)
            out3(cs.old_pos, s, bs.col_now_pos, k)
            out4(cs.old_rot, s, bs.col_now_rot, k)
            out4(cs.inverse_old_rot, s, bs.col_inverse_old_rot, k)
            out3(cs.start_old, s, bs.col_start_old, k)
            out3(cs.start_new, s, bs.col_start_new, k)
            if plane:
                out3(cs.plane_normal, s, bs.col_plane_normal, k)
            else:
                cs.radius_start[s] = bs.col_radius_start[k]
                cs.radius_end[s] = bs.col_radius_end[k]
                out3(cs.end_old, s, bs.col_end_old, k)
                out3(cs.end_new, s, bs.col_end_new, k)
                out3(cs.aabb_min, s, bs.col_aabb_min, k)
                out3(cs.aabb_max, s, bs.col_aabb_max, k)


@kernel
def collider_step_lanes(cs, ts, blk, bs, b):
    """G.3 of every lane's slots of block b on the lane-collider arrays, slot by slot (a slot's
    shape and size are the same in every lane: the exemplar's), lanes innermost. Reads the
    lanes' C.3 results (``bs.lane_step_*_inertia_ratio``, ``team_step.team_step_block``).

    Streams (``kernels/streams``; every access is to row k = base + j * width + i of one
    lane-collider array or lane i of a lane array, arrays distinct): now_pos 1-3, now_rot 4-7,
    old_pos 8-10 and old_rot 11-14 (read and written in place), inverse_old_rot 15-18,
    radius_start 19, radius_end 20, start_old 21-23, end_old 24-26, start_new 27-29, end_new
    30-32, aabb_min 33-35, aabb_max 36-38; a plane's loop writes no bounds and its normal
    takes 33-35; everything else is read only."""
    width = blk.block_width[b]
    lanes = np.uint64(blk.block_lane_base[b])
    cbase = blk.block_collider_base[b]
    e0 = ts.collider_start[blk.block_exemplar[b]]
    interpolation, move_ratio, rotation_ratio = (bs.lane_frame_interpolation, bs.lane_step_move_inertia_ratio,
                                                 bs.lane_step_rotation_inertia_ratio)
    old_frame_pos_a, frame_pos_a, old_frame_rot_a, frame_rot_a = (bs.col_old_frame_pos, bs.col_frame_pos,
                                                                  bs.col_old_frame_rot, bs.col_frame_rot)
    now_pos_a, now_rot_a, old_pos_a, old_rot_a, inverse_a = (bs.col_now_pos, bs.col_now_rot, bs.col_old_pos,
                                                             bs.col_old_rot, bs.col_inverse_old_rot)
    radius_start_a, radius_end_a, axis_scale_a = bs.col_radius_start, bs.col_radius_end, bs.col_axis_scale
    start_old_a, end_old_a, start_new_a, end_new_a = bs.col_start_old, bs.col_end_old, bs.col_start_new, bs.col_end_new
    aabb_min_a, aabb_max_a, plane_normal_a = bs.col_aabb_min, bs.col_aabb_max, bs.col_plane_normal
    # the arrays as one tuple (numba's inliner refuses calls of more than 30 arguments)
    arrays = (old_frame_pos_a, frame_pos_a, old_frame_rot_a, frame_rot_a, now_pos_a, now_rot_a, old_pos_a, old_rot_a, inverse_a, radius_start_a, radius_end_a, axis_scale_a, start_old_a, end_old_a, start_new_a, end_new_a, aabb_min_a, aabb_max_a, plane_normal_a, interpolation, move_ratio, rotation_ratio)
    for j in range(blk.block_collider_count[b]):
        e = e0 + j
        shape = cs.shape[e]
        direction = cs.direction[e]
        reverse = cs.reverse_direction[e] != 0
        aligned = cs.aligned_on_center[e] != 0
        size = (cs.size[e, 0], cs.size[e, 1], cs.size[e, 2])
        geometry = (direction, reverse, aligned, size)
        k0 = np.uint64(cbase + j * width)
        # every lane's slerps near (the usual case): their lerp path alone; the second slerp's
        # target is the first's result (read only, no stores)
        far = 0
        for i in range(width):
            k = k0 + np.uint64(i)
            far += 0 if slerp_is_near(sload4(old_frame_rot_a, k, READ), sload4(frame_rot_a, k, READ)) else 1
        if far == 0:
            for i in range(width):
                k = k0 + np.uint64(i)
                now_rot = q_normalize(slerp_near(sload4(old_frame_rot_a, k, READ), sload4(frame_rot_a, k, READ),
                                                      sload(interpolation, lanes + np.uint64(i), READ)))
                far += 0 if slerp_is_near(sload4(old_rot_a, k, READ), now_rot) else 1
        # one lane loop per (shape, mode), both constant in each: their branches fold away
        open_streams()
        if shape == SPHERE and far == 0:
            _slot_loop(arrays, k0, lanes, width, SPHERE, LANES_NEAR, geometry)
        elif shape == SPHERE:
            _slot_loop(arrays, k0, lanes, width, SPHERE, LANES, geometry)
        elif shape == CAPSULE and far == 0:
            _slot_loop(arrays, k0, lanes, width, CAPSULE, LANES_NEAR, geometry)
        elif shape == CAPSULE:
            _slot_loop(arrays, k0, lanes, width, CAPSULE, LANES, geometry)
        elif far == 0:
            _slot_loop(arrays, k0, lanes, width, PLANE, LANES_NEAR, geometry)
        else:
            _slot_loop(arrays, k0, lanes, width, PLANE, LANES, geometry)


@kernel(inline="always")
def _slot_loop(arrays, k0, lanes, width, shape, mode, geometry):
    """``collider_step_lanes``' lane loop of one slot (rows k0 + i, lanes + i); ``shape`` and
    ``mode`` are literals, ``arrays`` the lane and lane-collider arrays in ``_slot_lane``'s order."""
    for i in range(width):
        _slot_lane(arrays, k0 + np.uint64(i), lanes + np.uint64(i), shape, geometry, mode)


@kernel(inline="always")
def _slot_lane(arrays, k, L, shape, geometry, mode):
    """``collider_step_team``'s slot body on lane-collider row k, lane L (streams: see
    ``collider_step_lanes``); ``shape`` and ``mode`` are constant at each call site, ``geometry``
    the slot's (direction, reverse, aligned, size)."""
    (old_frame_pos_a, frame_pos_a, old_frame_rot_a, frame_rot_a, now_pos_a, now_rot_a, old_pos_a, old_rot_a, inverse_a, radius_start_a, radius_end_a, axis_scale_a, start_old_a, end_old_a, start_new_a, end_new_a, aabb_min_a, aabb_max_a, plane_normal_a, interpolation, move_ratio, rotation_ratio) = arrays
    direction, reverse, aligned, size = geometry
    now_pos, now_rot, old_pos, old_rot, inverse_old_rot = collider_step_pose(
        sload3(old_frame_pos_a, k, READ), sload3(frame_pos_a, k, READ), sload4(old_frame_rot_a, k, READ),
        sload4(frame_rot_a, k, READ), sload3(old_pos_a, k, 8), sload4(old_rot_a, k, 11),
        sload(interpolation, L, READ), sload(move_ratio, L, READ), sload(rotation_ratio, L, READ), mode)
    sstore3(now_pos_a, k, now_pos, 1)
    sstore4(now_rot_a, k, now_rot, 4)
    sstore3(old_pos_a, k, old_pos, 8)
    sstore4(old_rot_a, k, old_rot, 11)
    sstore4(inverse_a, k, inverse_old_rot, 15)
    s = sload(axis_scale_a, k, READ)
    if shape == SPHERE:
        r = size[0] * abs(s)
        lo, hi = sphere_bounds(old_pos, now_pos, r)
        sstore(radius_start_a, k, r, 19)
        sstore(radius_end_a, k, r, 20)
        sstore3(start_old_a, k, old_pos, 21)
        sstore3(end_old_a, k, old_pos, 24)
        sstore3(start_new_a, k, now_pos, 27)
        sstore3(end_new_a, k, now_pos, 30)
        sstore3(aabb_min_a, k, lo, 33)
        sstore3(aabb_max_a, k, hi, 36)
    elif shape == CAPSULE:
        so, eo, rs, re = capsule_ends(old_pos, old_rot, direction, reverse, aligned, size, s)
        sn, en, rs, re = capsule_ends(now_pos, now_rot, direction, reverse, aligned, size, s)
        lo, hi = swept_bounds(so, sn, eo, en, rs, re)
        sstore(radius_start_a, k, rs, 19)
        sstore(radius_end_a, k, re, 20)
        sstore3(start_old_a, k, so, 21)
        sstore3(end_old_a, k, eo, 24)
        sstore3(start_new_a, k, sn, 27)
        sstore3(end_new_a, k, en, 30)
        sstore3(aabb_min_a, k, lo, 33)
        sstore3(aabb_max_a, k, hi, 36)
    else:
        sstore3(plane_normal_a, k, q_rotate(now_rot, (0.0, _sign(s), 0.0)), 33)
        sstore3(start_new_a, k, now_pos, 27)
        sstore3(start_old_a, k, old_pos, 21)


@kernel
def collider_step_block(cs, ts, blk, bs, b):
    """G.3 of every lane of block b (``collider_step_team`` for each lane's team, the same
    bits), after the block's C.3 (``team_step.team_step_block``): slots written as there and
    this step's lane-collider values (``bs.col_*``) filled. The slots' old pose is left as the
    step's end leaves it (``collider_end_step_team`` included: the block step does not call it)."""
    collider_step_copy_in(cs, ts, blk, bs, b)
    collider_step_lanes(cs, ts, blk, bs, b)
    collider_step_copy_out(cs, ts, blk, bs, b)


@kernel
def collider_end_step_team(cs, ts, team):
    """G.3 end of step: old = now."""
    c0 = ts.collider_start[team]
    for k in range(c0, c0 + ts.collider_count[team]):
        for c in range(3):
            cs.old_pos[k, c] = cs.now_pos[k, c]
        for c in range(4):
            cs.old_rot[k, c] = cs.now_rot[k, c]


@kernel
def collider_end_frame_team(cs, ts, team, running):
    """End of frame: if the team ran, the frame pose becomes the old frame pose."""
    if not running:
        return
    c0 = ts.collider_start[team]
    for k in range(c0, c0 + ts.collider_count[team]):
        for c in range(3):
            cs.old_frame_pos[k, c] = cs.frame_pos[k, c]
        for c in range(4):
            cs.old_frame_rot[k, c] = cs.frame_rot[k, c]


def fill_slots(cs, team_slots: list[tuple[int, list[int]]], collider_set) -> None:
    """Copy the static collider description into slots: ``team_slots`` is
    ``[(team, [collider indices]), ...]`` in slot order."""
    k = 0
    for team, indices in team_slots:
        for ci in indices:
            cs.collider_index[k] = ci
            cs.team[k] = team
            cs.shape[k] = int(collider_set.shape[ci])
            cs.transform[k] = int(collider_set.transform[ci])
            cs.local_center[k] = np.asarray(collider_set.center[ci], dtype=np.float64)
            radius = float(collider_set.radius[ci])
            end = getattr(collider_set, "end_radius", None)
            end_radius = float(end[ci]) if end is not None else radius
            cs.size[k] = (radius, end_radius, float(collider_set.length[ci]))
            cs.direction[k] = int(collider_set.direction[ci])
            cs.reverse_direction[k] = 1 if collider_set.reverse_direction[ci] else 0
            cs.aligned_on_center[k] = 1 if collider_set.aligned_on_center[ci] else 0
            cs.first_frame[k] = 1
            k += 1
