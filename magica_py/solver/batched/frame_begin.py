"""The begin of frame of a running block (docs/solver.md §C.1-§C.5, §G.2), lanes innermost.

``frame.begin_frame_team`` for every lane of block b, with the per-particle work on the
block's rows instead of the team rows:

0. per lane, scalar, ``frame.begin_frame_prelude_team`` (running flag, first-frame build
   reset; first, as in the per-team order);
1. ``skin_block`` (C.1, after ``touch_bones_block``: see there): every lane's skinned pose straight into ``bs.position`` /
   ``bs.rotation`` (``center.skin_bound_vertex``; each lane reads its own bone matrices, a
   gather per lane, and the constant half of C.1, ``center.bind_point`` of its vertex, from
   ``bs.skin_bound_*``, which ``bind_rows_block`` fills when the blocks are formed);
2. ``center_sums_block`` (C.2): the sums of ``center.center_fixed_terms`` over the
   center-fixed vertices into the lane arrays (in the fixed list's order, from 0: the per-team
   sums' bits);
3. per lane, scalar, the rest of the team-level part, ``begin_lane_team`` (C.2 component pose
   and center from the sums, C.4 ``center.inertia_team``, G.2 ``collider_frame_team``, the
   lane's C.5 values);
4. ``gather_shift_block`` (C.5 and the gather, after ``touch_history_block``): the history (old_pos, old_position, disp_pos,
   old_rotation, velocity) read from the team rows, shifted (``center.shift_history``) in the
   lanes that shift, stored in the block rows, with ``transfer.gather_block``'s plain copies
   (collision normal, friction, static friction) in the same pass;
5. ``snap_lane_block`` (C.5 Reset) for a lane that resets (rare: a per-lane loop).

The begin leaves the team rows alone: the block holds the frame until the scatters after
the steps and the end of frame in block form (``frame_end``; its per-team fallback copies the
rows it reads first, ``transfer.scatter_block_end_inputs``).

The whole sequence is ``frame.begin_frame_block`` (frame.py: the prelude lives there).

Bits: the same per-element functions with the same inputs as the per-team stages
(tests/test_batched_frame_begin.py). The real velocity is not shifted: a running block runs at
least one step, whose D.10 writes it before anything reads it.
"""
from __future__ import annotations

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels.math3d import load3, load4
from magica_py.kernels.rows import flat
from magica_py.kernels.streams import READ, open_streams, sload, sload3, sload4, sstore, sstore3, sstore4
from magica_py.solver.center import (
    bind_point, center_fixed_terms, center_from_sums, component_pose_team, inertia_team, shift_history,
    skin_bound_vertex,
)
from magica_py.solver.batched.transfer import bload3
from magica_py.solver.colliders import collider_frame_team

SHIFT_KEEP = 0    # C.5: the history stays as it is
SHIFT_MOVE = 1    # C.5: inertia shift of the history
SHIFT_RESET = 2   # C.5: Reset, every history value at the skinned pose


@kernel
def _select3(c, a, b):
    return (a[0] if c else b[0], a[1] if c else b[1], a[2] if c else b[2])


@kernel
def _select4(c, a, b):
    return (a[0] if c else b[0], a[1] if c else b[1], a[2] if c else b[2], a[3] if c else b[3])


@kernel
def _read4(a, i):
    """``a[i : i + 4]`` of a flat array (unsigned i) in the READ stream."""
    return (sload(a, i, READ), sload(a, i + np.uint64(1), READ), sload(a, i + np.uint64(2), READ),
            sload(a, i + np.uint64(3), READ))


@kernel
def _read3(a, i):
    return sload(a, i, READ), sload(a, i + np.uint64(1), READ), sload(a, i + np.uint64(2), READ)


@kernel
def lane_starts_block(m, blk, bs, b):
    """``bs.lane_particle_start``: each lane's first model row (its team's particle start)."""
    lanes = blk.block_lane_base[b]
    for i in range(blk.block_width[b]):
        bs.lane_particle_start[lanes + i] = m.team_particle_start[blk.lane_team[lanes + i]]


@kernel
def bind_rows_block(m, blk, bs):
    """``bs.skin_bound_*`` of every block: ``center.bind_point`` of each lane's vertex (its
    team's model rows), lane-innermost (model data; run when the blocks are formed)."""
    for b in range(blk.block_width.shape[0]):
        width = blk.block_width[b]
        lanes = blk.block_lane_base[b]
        for p in range(blk.block_particle_count[b]):
            for i in range(width):
                r = m.team_particle_start[blk.lane_team[lanes + i]] + p
                k = blk.block_row_base[b] + p * width + i
                b0, b1, b2, b3 = (load4(m.skin_bind_pose[r], 0), load4(m.skin_bind_pose[r], 1),
                                  load4(m.skin_bind_pose[r], 2), load4(m.skin_bind_pose[r], 3))
                bp = bind_point(b0, b1, b2, b3, load3(m.local_position, r), 1.0)
                bn = bind_point(b0, b1, b2, b3, load3(m.local_normal, r), 0.0)
                bt = bind_point(b0, b1, b2, b3, load3(m.local_tangent, r), 0.0)
                for c in range(4):
                    bs.skin_bound_position[c, k] = bp[c]
                    bs.skin_bound_normal[c, k] = bn[c]
                    bs.skin_bound_tangent[c, k] = bt[c]


@kernel
def touch_bones_block(m, local_to_world, blk, bs, b):
    """Reads each lane's bone matrices (one load per cache line) in lane order, sequentially:
    the lane loop of ``skin_block`` then gathers them across characters, which the hardware
    prefetcher does not follow when they are cold (real frames: the cold skinning of the crowd
    ran ~1.8x slower without this pass). The sum goes to ``bs.lane_touch`` (a sink, never read:
    unused loads would be removed)."""
    l2w = flat(local_to_world)
    node_of = m.transform_index
    lanes = blk.block_lane_base[b]
    for i in range(blk.block_width[b]):
        start = bs.lane_particle_start[lanes + i]
        acc = 0.0
        for p in range(blk.block_particle_count[b]):
            node = np.uint64(16) * np.uint64(node_of[start + p])
            acc += l2w[node] + l2w[node + np.uint64(8)]
        bs.lane_touch[lanes + i] = acc


@kernel
def touch_history_block(ps, blk, bs, b):
    """``touch_bones_block`` for the team rows ``gather_shift_block`` reads (one load per cache
    line of each field, each lane's rows in order; cold, the gather ran ~1.8x slower without)."""
    old_pos, old_position, disp_pos = flat(ps.old_pos), flat(ps.old_position), flat(ps.disp_pos)
    old_rotation, velocity, normal = flat(ps.old_rotation), flat(ps.velocity), flat(ps.collision_normal)
    friction, static_friction = ps.friction, ps.static_friction
    lanes = blk.block_lane_base[b]
    n = blk.block_particle_count[b]
    for i in range(blk.block_width[b]):
        start = bs.lane_particle_start[lanes + i]
        acc = 0.0
        for j in range(3 * start, 3 * (start + n), 8):
            acc += old_pos[j] + old_position[j] + disp_pos[j] + velocity[j] + normal[j]
        for j in range(4 * start, 4 * (start + n), 8):
            acc += old_rotation[j]
        for j in range(start, start + n, 8):
            acc += friction[j] + static_friction[j]
        bs.lane_touch[lanes + i] += acc


@kernel
def skin_block(m, local_to_world, blk, bs, b):
    """C.1 of every lane of block b into the block rows (``center.skin_team``'s maths, its
    constant half ``bind_point`` read from ``bs.skin_bound_*``).

    Streams (``kernels/streams``): block position 1-3, rotation 4-7 (row k of the loop's
    particle); every load is READ (bound rows, bone matrices, model and lane rows: arrays the
    loop does not write)."""
    l2w = flat(local_to_world)          # (nodes * 16,) bone matrices, gathered per lane
    node_of = m.transform_index
    bound_position, bound_normal, bound_tangent = bs.skin_bound_position, bs.skin_bound_normal, bs.skin_bound_tangent
    position, rotation = bs.position, bs.rotation
    starts = bs.lane_particle_start
    width = blk.block_width[b]
    lanes = np.uint64(blk.block_lane_base[b])
    for p in range(blk.block_particle_count[b]):
        k0 = np.uint64(blk.block_row_base[b] + p * width)
        open_streams()
        for i in range(width):
            r = np.uint64(sload(starts, lanes + np.uint64(i), READ)) + np.uint64(p)
            node = np.uint64(16) * np.uint64(sload(node_of, r, READ))
            k = k0 + np.uint64(i)
            pos, rot = skin_bound_vertex(_read4(l2w, node), _read4(l2w, node + np.uint64(4)),
                                         _read4(l2w, node + np.uint64(8)), sload4(bound_position, k, READ),
                                         sload4(bound_normal, k, READ), sload4(bound_tangent, k, READ))
            sstore3(position, k, pos, 1)
            sstore4(rotation, k, rot, 4)


@kernel
def center_sums_block(m, blk, bs, b):
    """C.2 sums of every lane (``center.center_pose_team``'s loop) into the lane arrays.

    The center-fixed list is part of the topology (the exemplar's list, local indices, is every
    lane's). Streams: the three sums 1-3, 4-6, 7-9 (row L, read and written in place); the
    block's pose and the model's bind rotations are READ."""
    ex = blk.block_exemplar[b]
    width = blk.block_width[b]
    lanes = np.uint64(blk.block_lane_base[b])
    p0 = m.team_particle_start[ex]
    c0 = m.team_center_start[ex]
    position, rotation = bs.position, bs.rotation
    bind = flat(m.bind_rotation)
    starts = bs.lane_particle_start
    sum_pos, sum_nor, sum_tan = bs.lane_center_position_sum, bs.lane_center_normal_sum, bs.lane_center_tangent_sum
    for i in range(width):
        L = lanes + np.uint64(i)
        for c in range(3):
            sum_pos[c, L] = 0.0
            sum_nor[c, L] = 0.0
            sum_tan[c, L] = 0.0
    for j in range(m.team_center_count[ex]):
        f = m.center_fixed[c0 + j] - p0          # local index of the fixed vertex
        k0 = np.uint64(blk.block_row_base[b] + f * width)
        open_streams()
        for i in range(width):
            L = lanes + np.uint64(i)
            k = k0 + np.uint64(i)
            r = np.uint64(sload(starts, L, READ)) + np.uint64(f)
            pos, nor, tan = center_fixed_terms(sload3(position, k, READ), sload4(rotation, k, READ),
                                               _read4(bind, np.uint64(4) * r))
            sp = sload3(sum_pos, L, 1)
            sn = sload3(sum_nor, L, 4)
            st = sload3(sum_tan, L, 7)
            sstore3(sum_pos, L, (sp[0] + pos[0], sp[1] + pos[1], sp[2] + pos[2]), 1)
            sstore3(sum_nor, L, (sn[0] + nor[0], sn[1] + nor[1], sn[2] + nor[2]), 4)
            sstore3(sum_tan, L, (st[0] + tan[0], st[1] + tan[1], st[2] + tan[2]), 7)


@kernel
def begin_lane_team(m, prm, ts, cs, tt, h, fi, bs, L, t, since_last_step):
    """Lane L (team t): ``frame.begin_frame_team``'s team-level stages after the prelude, the
    center from the lane's sums (``center_sums_block``), and the lane's C.5 values."""
    cpos, crot, cscl, ratio = component_pose_team(m, ts, t, h.world_position, h.world_rotation, h.lossy_scale)
    center_pos, center_rot = cpos, crot
    count = m.team_center_count[t]
    if count > 0:
        center_pos, center_rot = center_from_sums(bload3(bs.lane_center_position_sum, L),
                                                  bload3(bs.lane_center_normal_sum, L),
                                                  bload3(bs.lane_center_tangent_sum, L), count)
    inertia_team(prm, ts, t, cpos, crot, cscl, ratio, center_pos, center_rot, h.world_position, h.world_rotation,
                 tt.frame_delta_time[t], tt.now_time_scale[t], tt.skip_count[t], tt.running[t], fi.dt,
                 since_last_step)
    collider_frame_team(cs, ts, t, h.world_position, h.world_rotation, h.lossy_scale)
    # C.5 of the lane (center.reset_or_shift_team's decision)
    mode = SHIFT_KEEP
    if ts.reset[t] != 0:
        mode = SHIFT_RESET
    elif ts.inertia_shift[t] != 0:
        mode = SHIFT_MOVE
    bs.lane_shift_mode[L] = mode
    pivot = load3(ts.old_component_pos, t)
    vec = load3(ts.frame_shift_vector, t)
    rot = load4(ts.frame_shift_rotation, t)
    for c in range(3):
        bs.lane_shift_pivot[c, L] = pivot[c]
        bs.lane_shift_vector[c, L] = vec[c]
    for c in range(4):
        bs.lane_shift_rotation[c, L] = rot[c]


@kernel
def snap_lane_block(blk, bs, b, i):
    """C.5 Reset of lane i of block b (``center.snap_particles_to_base_pose`` on the block
    rows): every position history at the skinned pose, velocities, friction and normals zero.
    The team rows are left alone (the scatters after the steps write what the rest of the
    frame reads)."""
    width = blk.block_width[b]
    for p in range(blk.block_particle_count[b]):
        k = blk.block_row_base[b] + p * width + i
        for c in range(3):
            pos = bs.position[c, k]
            bs.next_pos[c, k] = pos
            bs.old_pos[c, k] = pos
            bs.base_pos[c, k] = pos
            bs.old_position[c, k] = pos
            bs.velocity_pos[c, k] = pos
            bs.disp_pos[c, k] = pos
            bs.velocity[c, k] = 0.0
            bs.real_velocity[c, k] = 0.0
            bs.collision_normal[c, k] = 0.0
        for c in range(4):
            bs.base_rot[c, k] = bs.rotation[c, k]
            bs.old_rotation[c, k] = bs.rotation[c, k]
        bs.friction[k] = 0.0
        bs.static_friction[k] = 0.0


@kernel
def gather_shift_block(m, ps, blk, bs, b):
    """C.5 inertia shift while gathering the history into the block: for every lane, its team
    rows' old_pos, old_position, disp_pos, old_rotation and velocity, shifted
    (``center.shift_history`` with the lane's pivot, vector and rotation) when the lane shifts,
    as they are otherwise, into the block rows (``center.reset_or_shift_team``'s loop).

    The rest of the state the steps read from the team rows (``transfer.gather_block``'s
    collision normal, friction and static friction) is copied in the same pass.

    Streams: old_pos 1-3, old_position 4-6, disp_pos 7-9, old_rotation 10-13, velocity 14-16,
    collision normal 17-19, friction 20, static friction 21 (block row k); the team rows and
    lane values are READ (the loop does not write them: storing the shifted history back in
    place would stop its vectorisation; the scatters after the steps write the team rows)."""
    old_pos, old_position, disp_pos = flat(ps.old_pos), flat(ps.old_position), flat(ps.disp_pos)
    old_rotation, velocity = flat(ps.old_rotation), flat(ps.velocity)
    normal, friction, static_friction = flat(ps.collision_normal), ps.friction, ps.static_friction
    b_old_pos, b_old_position, b_disp_pos = bs.old_pos, bs.old_position, bs.disp_pos
    b_old_rotation, b_velocity = bs.old_rotation, bs.velocity
    b_normal, b_friction, b_static_friction = bs.collision_normal, bs.friction, bs.static_friction
    modes, pivots = bs.lane_shift_mode, bs.lane_shift_pivot
    vectors, rotations = bs.lane_shift_vector, bs.lane_shift_rotation
    starts = bs.lane_particle_start
    width = blk.block_width[b]
    lanes = np.uint64(blk.block_lane_base[b])
    for p in range(blk.block_particle_count[b]):
        k0 = np.uint64(blk.block_row_base[b] + p * width)
        open_streams()
        for i in range(width):
            L = lanes + np.uint64(i)
            r = np.uint64(sload(starts, L, READ)) + np.uint64(p)
            v = np.uint64(3) * r
            q = np.uint64(4) * r
            a0, b0, c0, r0, u0 = (_read3(old_pos, v), _read3(old_position, v), _read3(disp_pos, v),
                                  _read4(old_rotation, q), _read3(velocity, v))
            a, bb, c, rr, u = shift_history(a0, b0, c0, r0, u0, sload3(pivots, L, READ), sload3(vectors, L, READ),
                                            sload4(rotations, L, READ))
            move = sload(modes, L, READ) == SHIFT_MOVE
            k = k0 + np.uint64(i)
            sstore3(b_old_pos, k, _select3(move, a, a0), 1)
            sstore3(b_old_position, k, _select3(move, bb, b0), 4)
            sstore3(b_disp_pos, k, _select3(move, c, c0), 7)
            sstore4(b_old_rotation, k, _select4(move, rr, r0), 10)
            sstore3(b_velocity, k, _select3(move, u, u0), 14)
            sstore3(b_normal, k, _read3(normal, v), 17)
            sstore(b_friction, k, sload(friction, r, READ), 20)
            sstore(b_static_friction, k, sload(static_friction, r, READ), 21)
