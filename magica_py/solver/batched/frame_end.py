"""The end-of-frame stages of a running block in block form: guards, display (docs/solver.md §E.1), line
and triangle rotations (§E.2, §E.3) and transform data (§E.4) for every lane at once, lanes
innermost on the block rows, after the steps and before the scatter.

``end_frame_block`` runs them and returns True; the scatter (``transfer.scatter_block_end``)
then carries their results to the team rows, and after the barrier each lane's team keeps only
the write-back through its transform indices, A.7 and the colliders' end of frame
(``frame.end_frame_lane``). It returns False, having changed nothing, when the block must take
the per-team path this frame (``frame.end_frame_stages_team`` for each lane):

* a lane's guard trips (non-finite state or a speed excess: the per-team path resets it);
* quality mode's time-based smoothing (``display_team``'s other extrapolation; the crowd does
  not use it; the other quality options keep a team out of blocks altogether);
* a moving particle whose root is itself (never built: E.1's root read would alias its store).

Each stage calls the per-element functions of its per-team stage (``display_extrapolated``,
``line_child_pose``, ``triangle_frame_from``, ``bone_rotation``, ...) with the same inputs in
the same order per lane: the same bits (tests/test_batched_frame_end.py). Values that differ
between lanes (blend weight, running, frame interpolation, speed bound) come from lane arrays
filled by ``_lane_values``; values equal in every lane (topology, rest pose, uv, v2t, the
parameters) are read once from the block's exemplar (``blocks.END_MODEL_FIELDS`` are part of
the block signature). E.2's degenerate cases (an opposite edge: pi about a fallback axis) are
left out of the vector pass and redone lane by lane (``angle._entry_lanes``' scheme).

Lane loops load and store through ``kernels/streams``; each states its streams. A loop's claim
holds for every execution: the rows it writes are those of one particle (or one triangle, one
lane array) and every other row it reads is of another particle (a child is never its parent,
a root never its own particle: checked), or an array it does not write.
"""
from __future__ import annotations

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels.math3d import q_inverse, q_rotate, v_add, v_lerp, v_sub
from magica_py.kernels.streams import READ, open_streams, sload, sload3, sload4, sstore, sstore3, sstore4
from magica_py.solver.display import display_clamped, display_extrapolated, display_fraction
from magica_py.solver.guards import particle_verdict, speed_limit_sq
from magica_py.solver.rotations import (
    TRIANGLES_PER_VERTEX, add_flipped, line_blend, line_child_pose, line_child_rotation, line_turn,
    triangle_frame_from, vertex_frame_rotation,
)
from magica_py.kernels.rows import flat
from magica_py.solver.writeback import bone_rotation, finite3, finite4, fixed_bone_local, moving_bone_local

FIXED = 0x01
MOVE = 0x02
ZERO_DISTANCE = 0x20
INCLUDE_LINE = 0x01
ZERO3 = (0.0, 0.0, 0.0)


@kernel
def end_frame_block(m, ps, prm, ts, tt, h, blk, bs, b, fi):
    """Guards and E.1-E.4 for every lane of block b on its block rows; False (nothing changed)
    when the block takes the per-team path this frame (see the module docstring)."""
    ex = blk.block_exemplar[b]
    if prm.time_based_smoothing[ex] != 0:
        return False
    p0 = m.team_particle_start[ex]
    for p in range(blk.block_particle_count[b]):
        r = m.root_index[p0 + p]
        if (m.attribute[p0 + p] & MOVE) != 0 and r == p0 + p:
            return False
    all_running, all_blend_one = _lane_values(m, ts, tt, blk, bs, b, fi.dt)
    if guards_trip_block(blk, bs, b):
        return False
    display_block(m, ps, blk, bs, b, fi.dt, all_running)
    if m.team_has_lines[ex] != 0:
        line_rotations_block(m, prm, blk, bs, b, all_blend_one)
    if m.team_triangle_count[ex] > 0:
        triangle_rotations_block(m, blk, bs, b)
    transform_data_block(m, blk, bs, b)
    bone_local_pose_block(m, blk, bs, b, h.parent, h.world_rotation, h.lossy_scale)
    return True


@kernel
def _lane_values(m, ts, tt, blk, bs, b, dt):
    """The lane arrays of the end stages from each lane's team and team-time rows; returns
    (every lane running, every lane's blend weight 1)."""
    lanes = blk.block_lane_base[b]
    all_running = True
    all_blend_one = True
    for i in range(blk.block_width[b]):
        L = lanes + i
        t = blk.lane_team[L]
        bs.lane_guard_limit_sq[L] = speed_limit_sq(ts.scale_ratio[t])
        bs.lane_display_t[L] = display_fraction(dt, tt.time[t], tt.old_time[t], tt.now_update_time[t])
        bs.lane_end_blend_weight[L] = ts.blend_weight[t]
        bs.lane_end_running[L] = 1 if tt.running[t] else 0
        bs.lane_transform_ok[L] = 1
        bs.lane_particle_start[L] = m.team_particle_start[t]
        all_running = all_running and tt.running[t]
        all_blend_one = all_blend_one and ts.blend_weight[t] == 1.0
    return all_running, all_blend_one


# ----------------------------------------------------------------------------- guards
@kernel
def guards_trip_block(blk, bs, b):
    """True when any lane's guard trips (``guards.check_team`` of some lane would be non-zero).
    Read-only; the verdicts OR-ed over every particle and lane (the lane loop vectorises)."""
    width = blk.block_width[b]
    lanes = np.uint64(blk.block_lane_base[b])
    old_pos, real_velocity, velocity, disp_pos = bs.old_pos, bs.real_velocity, bs.velocity, bs.disp_pos
    limit_sq = bs.lane_guard_limit_sq
    bad = 0
    for p in range(blk.block_particle_count[b]):
        k0 = np.uint64(blk.block_row_base[b] + p * width)
        for i in range(width):
            k = k0 + np.uint64(i)
            non_finite, too_fast = particle_verdict(sload3(old_pos, k, READ), sload3(real_velocity, k, READ),
                                                    sload3(velocity, k, READ), sload3(disp_pos, k, READ),
                                                    sload(limit_sq, lanes + np.uint64(i), READ))
            bad |= 1 if (non_finite | too_fast) else 0
    return bad != 0


# ----------------------------------------------------------------------------- E.1
@kernel
def display_block(m, ps, blk, bs, b, dt, all_running):
    """E.1 (``display.display_team`` without time-based smoothing) for every lane, in particle
    order (a moving root reads its already updated display, as per team).

    The next frame's history (disp_pos, old_position, old_rotation) goes straight to the team
    rows (the block stages do not read it again; the next gather does): stores through each
    lane's first particle row, instead of block stores and a scatter pass."""
    ex = blk.block_exemplar[b]
    p0 = m.team_particle_start[ex]
    width = blk.block_width[b]
    lanes = np.uint64(blk.block_lane_base[b])
    row_base = blk.block_row_base[b]
    a = (bs.position, bs.rotation, bs.disp_pos, bs.old_pos, bs.real_velocity, flat(ps.disp_pos),
         flat(ps.old_position), flat(ps.old_rotation), bs.base_pos_buffer, bs.base_rot_buffer, bs.lane_display_t,
         bs.lane_end_blend_weight, bs.lane_end_running, bs.lane_particle_start)
    for p in range(blk.block_particle_count[b]):
        k0 = np.uint64(row_base + p * width)
        r = m.root_index[p0 + p]
        kr0 = np.uint64(row_base + (r - p0) * width) if r >= 0 else k0
        move = (m.attribute[p0 + p] & MOVE) != 0
        # literal flags: each variant is its own loop without the others' maths
        if all_running:
            if not move:
                _display_lanes(a, k0, kr0, p, lanes, width, dt, False, False, True)
            elif r >= 0:
                _display_lanes(a, k0, kr0, p, lanes, width, dt, True, True, True)
            else:
                _display_lanes(a, k0, kr0, p, lanes, width, dt, True, False, True)
        else:
            if not move:
                _display_lanes(a, k0, kr0, p, lanes, width, dt, False, False, False)
            elif r >= 0:
                _display_lanes(a, k0, kr0, p, lanes, width, dt, True, True, False)
            else:
                _display_lanes(a, k0, kr0, p, lanes, width, dt, True, False, False)


@kernel(inline="always")
def _display_lanes(a, k0, kr0, p, lanes, width, dt, move, rooted, all_running):
    """One particle (rows k0 + lane; its root's rows kr0 + lane; team row p of each lane)
    over every lane.

    Streams: position 4-6, base_pos_buffer 14-16, base_rot_buffer 17-20 (the particle's block
    rows); the team rows' disp_pos 21-23, old_position 24-26, old_rotation 27-30 (one row per
    lane, of distinct teams); the root's position (another particle) and everything else read
    only."""
    (position, rotation, disp_pos, old_pos, real_velocity, team_disp_pos, team_old_position, team_old_rotation,
     base_pos_buffer, base_rot_buffer, display_t, blend, running, particle_start) = a
    open_streams()
    for i in range(width):
        k = k0 + np.uint64(i)
        L = lanes + np.uint64(i)
        r = np.uint64(sload(particle_start, L, READ) + p)
        v = np.uint64(3) * r
        q = np.uint64(4) * r
        pos0 = sload3(position, k, 4)
        rot0 = sload4(rotation, k, READ)
        f = pos0
        if move:
            f = display_extrapolated(sload3(old_pos, k, READ), sload3(real_velocity, k, READ),
                                     sload3(disp_pos, k, READ), dt, sload(display_t, L, READ))
            if rooted:
                f = display_clamped(f, sload3(position, kr0 + np.uint64(i), READ), pos0)
            sstore3(position, k, v_lerp(pos0, f, sload(blend, L, READ)), 4)
        sstore(team_disp_pos, v, f[0], 21)
        sstore(team_disp_pos, v + np.uint64(1), f[1], 22)
        sstore(team_disp_pos, v + np.uint64(2), f[2], 23)
        old_p = pos0
        old_r = rot0
        if not all_running:
            run = sload(running, L, READ) != 0
            kept_p = (sload(team_old_position, v, 24), sload(team_old_position, v + np.uint64(1), 25),
                      sload(team_old_position, v + np.uint64(2), 26))
            kept_r = (sload(team_old_rotation, q, 27), sload(team_old_rotation, q + np.uint64(1), 28),
                      sload(team_old_rotation, q + np.uint64(2), 29), sload(team_old_rotation, q + np.uint64(3), 30))
            old_p = (pos0[0] if run else kept_p[0], pos0[1] if run else kept_p[1], pos0[2] if run else kept_p[2])
            old_r = (rot0[0] if run else kept_r[0], rot0[1] if run else kept_r[1], rot0[2] if run else kept_r[2],
                     rot0[3] if run else kept_r[3])
        sstore(team_old_position, v, old_p[0], 24)
        sstore(team_old_position, v + np.uint64(1), old_p[1], 25)
        sstore(team_old_position, v + np.uint64(2), old_p[2], 26)
        sstore(team_old_rotation, q, old_r[0], 27)
        sstore(team_old_rotation, q + np.uint64(1), old_r[1], 28)
        sstore(team_old_rotation, q + np.uint64(2), old_r[2], 29)
        sstore(team_old_rotation, q + np.uint64(3), old_r[3], 30)
        sstore3(base_pos_buffer, k, pos0, 14)
        sstore4(base_rot_buffer, k, rot0, 17)


# ----------------------------------------------------------------------------- E.2
@kernel
def line_rotations_block(m, prm, blk, bs, b, all_blend_one, chains=True):
    """E.2 (``rotations.line_rotations_team``) for every lane: the same walk (IncludeLine
    baselines, entries parent-first, children in order), each step a loop over the lanes.
    An entry's sums over its children (``ctv``, ``cv``) live in the lane arrays."""
    ex = blk.block_exemplar[b]
    p0 = m.team_particle_start[ex]
    width = blk.block_width[b]
    lanes = np.uint64(blk.block_lane_base[b])
    row_base = blk.block_row_base[b]
    ri = prm.rotational_interpolation[ex]
    rr = prm.root_rotation[ex]
    a = prm.animation_pose_ratio[ex]
    a_zero = a == 0.0
    arrays = (bs.position, bs.rotation, bs.base_pos_buffer, bs.base_rot_buffer, bs.lane_line_ctv, bs.lane_line_cv,
              bs.lane_end_blend_weight)
    rest_position, rest_rotation = m.baseline_local_position, m.baseline_local_rotation
    b0 = m.team_baseline_start[ex]
    for bl in range(b0, b0 + m.team_baseline_count[ex]):
        if (m.baseline_flags[bl] & INCLUDE_LINE) == 0:
            continue
        e0 = m.baseline_start[bl]
        for e in range(e0, e0 + m.baseline_count[bl]):
            x = m.baseline_data[e]
            kx0 = np.uint64(row_base + (x - p0) * width)
            attr = m.attribute[x]
            cn = m.child_count[x]
            t = ri if (attr & MOVE) != 0 else rr
            # ``chains`` False (tests): every entry through the general child / turn loops
            single = chains and cn == 1 and (m.attribute[m.child_data[m.child_start[x]]] & MOVE) != 0
            if single and (attr & (FIXED | MOVE)) != 0:
                # one moving child (a chain): the child, the sums and the turn in one loop
                c = m.child_data[m.child_start[x]]
                child = (kx0, np.uint64(row_base + (c - p0) * width),
                         (rest_position[c, 0], rest_position[c, 1], rest_position[c, 2]),
                         (rest_rotation[c, 0], rest_rotation[c, 1], rest_rotation[c, 2], rest_rotation[c, 3]),
                         a, (m.attribute[c] & ZERO_DISTANCE) != 0)
                if a_zero:
                    if all_blend_one:
                        rare = _line_chain_lanes(arrays, child, t, lanes, width, True, True)
                    else:
                        rare = _line_chain_lanes(arrays, child, t, lanes, width, False, True)
                elif all_blend_one:
                    rare = _line_chain_lanes(arrays, child, t, lanes, width, True, False)
                else:
                    rare = _line_chain_lanes(arrays, child, t, lanes, width, False, False)
                lane = 0
                while rare != 0:  # an opposite edge or turn: this lane with every case
                    if (rare & np.uint64(1)) != 0:
                        if a_zero:
                            _line_chain_lane(arrays, child, t, lanes, lane, False, False, True)
                        else:
                            _line_chain_lane(arrays, child, t, lanes, lane, False, False, False)
                    rare >>= np.uint64(1)
                    lane += 1
            elif cn > 0 and (attr & (FIXED | MOVE)) != 0:
                _clear_sums(arrays, lanes, width)
                c0 = m.child_start[x]
                for kk in range(c0, c0 + cn):
                    c = m.child_data[kk]
                    kc0 = np.uint64(row_base + (c - p0) * width)
                    rp = (rest_position[c, 0], rest_position[c, 1], rest_position[c, 2])
                    rq = (rest_rotation[c, 0], rest_rotation[c, 1], rest_rotation[c, 2], rest_rotation[c, 3])
                    zero = (m.attribute[c] & ZERO_DISTANCE) != 0
                    child = (kx0, kc0, rp, rq, a, zero)
                    if (m.attribute[c] & MOVE) != 0:
                        if a_zero:
                            rare = _line_child_lanes(arrays, child, lanes, width, True, True)
                        else:
                            rare = _line_child_lanes(arrays, child, lanes, width, True, False)
                        lane = 0
                        while rare != 0:  # an opposite edge: this lane's rotation with full_swing
                            if (rare & np.uint64(1)) != 0:
                                if a_zero:
                                    _line_child_lane(arrays, child, lane, lanes, False, True, True)
                                else:
                                    _line_child_lane(arrays, child, lane, lanes, False, True, False)
                            rare >>= np.uint64(1)
                            lane += 1
                    elif a_zero:
                        _line_child_lanes(arrays, child, lanes, width, False, True)
                    else:
                        _line_child_lanes(arrays, child, lanes, width, False, False)
                if all_blend_one:
                    rare = _line_turn_lanes(arrays, kx0, t, lanes, width, True)
                else:
                    rare = _line_turn_lanes(arrays, kx0, t, lanes, width, False)
                lane = 0
                while rare != 0:  # an opposite turn: this lane with from_to_rotation
                    if (rare & np.uint64(1)) != 0:
                        _line_turn_lane(arrays, kx0 + np.uint64(lane), lanes + np.uint64(lane), t, False)
                    rare >>= np.uint64(1)
                    lane += 1
            elif not all_blend_one:
                _line_blend_lanes(arrays, kx0, lanes, width)


@kernel(inline="always")
def _line_chain_lanes(arrays, child, t, lanes, width, blend_one, a_zero):
    """An entry with one moving child over every lane (vector pass): returns the lanes that
    need an opposite case, left unchanged.

    Streams: the entry's rotation 1-4, the child's rotation 5-8; all else read only."""
    rare_lanes = np.uint64(0)
    open_streams()
    for i in range(width):
        rare = _line_chain_lane(arrays, child, t, lanes, i, True, blend_one, a_zero)
        rare_lanes |= np.uint64(1 if rare else 0) << np.uint64(i)
    return rare_lanes


@kernel(inline="always")
def _line_chain_lane(arrays, child, t, lanes, i, vector, blend_one, a_zero):
    """``line_rotations_team``'s entry body for an entry with one moving child, lane i: the
    child's rotation, the sums (0 + the one term, as per team) and the entry's turn and blend.
    ``vector`` True: without the opposite cases; a lane that needs one is left unchanged
    (True returned) and redone with ``vector`` False."""
    position, rotation, base_pos_buffer, base_rot_buffer, _ctv, _cv, blend = arrays
    kx0, kc0, rest_position, rest_rotation, a, zero = child
    kx = kx0 + np.uint64(i)
    kc = kc0 + np.uint64(i)
    pos = sload3(position, kx, READ)
    q = sload4(rotation, kx, 1)
    bp = sload3(base_pos_buffer, kx, READ)
    bq = sload4(base_rot_buffer, kx, READ)
    lp, lq = line_child_pose(q_inverse(bq), bp, rest_position, rest_rotation, sload3(base_pos_buffer, kc, READ),
                             sload4(base_rot_buffer, kc, READ), a, a_zero)
    tv = ZERO3 if zero else q_rotate(q, lp)
    cur = v_sub(sload3(position, kc, READ), pos)
    qc, rare_child = line_child_rotation(q, lq, tv, cur, zero, vector)
    turned, rare_turn = line_turn(q, v_add(ZERO3, tv), v_add(ZERO3, cur), t, vector)
    if not blend_one:
        turned = line_blend(bq, turned, sload(blend, lanes + np.uint64(i), READ))
    rare = rare_child | rare_turn
    keep = vector & rare
    sstore4(rotation, kc, sload4(rotation, kc, 5) if keep else qc, 5)
    sstore4(rotation, kx, q if keep else turned, 1)
    return rare


@kernel(inline="always")
def _clear_sums(arrays, lanes, width):
    ctv, cv = arrays[4], arrays[5]
    open_streams()
    for i in range(width):
        L = lanes + np.uint64(i)
        sstore3(ctv, L, ZERO3, 1)
        sstore3(cv, L, ZERO3, 4)


@kernel(inline="always")
def _line_child_lanes(arrays, child, lanes, width, move, a_zero):
    """One child of the entry over every lane: the sums, and for a moving child its rotation
    (vector pass). Returns the lanes (bit mask) whose rotation needs the opposite case.

    Streams: ctv 1-3, cv 4-6 (lane arrays), the child's rotation 7-10; the parent's rotation
    (another particle), positions and base buffers read only."""
    rare_lanes = np.uint64(0)
    open_streams()
    for i in range(width):
        rare = _line_child_lane(arrays, child, i, lanes, True, move, a_zero)
        rare_lanes |= np.uint64(1 if rare else 0) << np.uint64(i)
    return rare_lanes


@kernel(inline="always")
def _line_child_lane(arrays, child, i, lanes, vector, move, a_zero):
    """``line_rotations_team``'s child body for lane i. ``vector`` True: the vector pass (sums,
    and the rotation without the opposite case; returns True where it is needed); False: the
    rotation alone with ``full_swing`` (the sums are already done)."""
    position, rotation, base_pos_buffer, base_rot_buffer, ctv, cv, _blend = arrays
    kx0, kc0, rest_position, rest_rotation, a, zero = child
    kx = kx0 + np.uint64(i)
    kc = kc0 + np.uint64(i)
    L = lanes + np.uint64(i)
    pos = sload3(position, kx, READ)
    q = sload4(rotation, kx, READ)
    bp = sload3(base_pos_buffer, kx, READ)
    ibq = q_inverse(sload4(base_rot_buffer, kx, READ))
    lp, lq = line_child_pose(ibq, bp, rest_position, rest_rotation, sload3(base_pos_buffer, kc, READ),
                             sload4(base_rot_buffer, kc, READ), a, a_zero)
    tv = ZERO3 if zero else q_rotate(q, lp)
    rare = False
    if move:
        cur = v_sub(sload3(position, kc, READ), pos)
        qc, rare = line_child_rotation(q, lq, tv, cur, zero, vector)
        if vector:
            sstore3(ctv, L, v_add(sload3(ctv, L, 1), tv), 1)
            sstore3(cv, L, v_add(sload3(cv, L, 4), cur), 4)
            sstore4(rotation, kc, sload4(rotation, kc, 7) if rare else qc, 7)
        else:
            sstore4(rotation, kc, qc, 7)
    else:
        sstore3(ctv, L, v_add(sload3(ctv, L, 1), tv), 1)
        sstore3(cv, L, v_add(sload3(cv, L, 4), tv), 4)
    return rare


@kernel(inline="always")
def _line_turn_lanes(arrays, kx0, t, lanes, width, blend_one):
    """The entry's own rotation over every lane: turned towards its children, blended (vector
    pass; returns the lanes whose turn needs the opposite case, left unchanged).

    Streams: the entry's rotation 1-4; sums, base rotation and blend weights read only."""
    position, rotation, base_pos_buffer, base_rot_buffer, ctv, cv, blend = arrays
    rare_lanes = np.uint64(0)
    open_streams()
    for i in range(width):
        kx = kx0 + np.uint64(i)
        L = lanes + np.uint64(i)
        q0 = sload4(rotation, kx, 1)
        q, rare = line_turn(q0, sload3(ctv, L, READ), sload3(cv, L, READ), t, True)
        if not blend_one:
            q = line_blend(sload4(base_rot_buffer, kx, READ), q, sload(blend, L, READ))
        sstore4(rotation, kx, q0 if rare else q, 1)
        rare_lanes |= np.uint64(1 if rare else 0) << np.uint64(i)
    return rare_lanes


@kernel(inline="always")
def _line_turn_lane(arrays, kx, L, t, vector):
    """``_line_turn_lanes``' body for one lane with ``from_to_rotation`` (every case)."""
    position, rotation, base_pos_buffer, base_rot_buffer, ctv, cv, blend = arrays
    q, _rare = line_turn(sload4(rotation, kx, 1), sload3(ctv, L, READ), sload3(cv, L, READ), t, vector)
    sstore4(rotation, kx, line_blend(sload4(base_rot_buffer, kx, READ), q, sload(blend, L, READ)), 1)


@kernel(inline="always")
def _line_blend_lanes(arrays, kx0, lanes, width):
    """An entry without children (or neither fixed nor moving): only its blend."""
    position, rotation, base_pos_buffer, base_rot_buffer, ctv, cv, blend = arrays
    open_streams()
    for i in range(width):
        kx = kx0 + np.uint64(i)
        sstore4(rotation, kx, line_blend(sload4(base_rot_buffer, kx, READ), sload4(rotation, kx, 1),
                                         sload(blend, lanes + np.uint64(i), READ)), 1)


# ----------------------------------------------------------------------------- E.3
@kernel
def triangle_rotations_block(m, blk, bs, b):
    """E.3 (``rotations.triangle_rotations_team``) for every lane: each triangle's frame once
    (block triangle rows), then each vertex's sums over its triangles in order (lane arrays)
    and its rotation where the frame is valid. Vertices with more than
    ``TRIANGLES_PER_VERTEX`` triangles sum in the lane arrays (per team: its scalar pass)."""
    ex = blk.block_exemplar[b]
    p0 = m.team_particle_start[ex]
    t0 = m.team_triangle_start[ex]
    width = blk.block_width[b]
    lanes = np.uint64(blk.block_lane_base[b])
    row_base = blk.block_row_base[b]
    tri_base = blk.block_triangle_base[b]
    position, rotation = bs.position, bs.rotation
    triangle_normal, triangle_tangent = bs.triangle_normal, bs.triangle_tangent
    ns, ts_ = bs.lane_vertex_ns, bs.lane_vertex_ts
    for j in range(m.team_triangle_count[ex]):
        tri = t0 + j
        k0 = np.uint64(row_base + (m.triangles[tri, 0] - p0) * width)
        k1 = np.uint64(row_base + (m.triangles[tri, 1] - p0) * width)
        k2 = np.uint64(row_base + (m.triangles[tri, 2] - p0) * width)
        uv0 = (m.triangle_uv[tri, 0, 0], m.triangle_uv[tri, 0, 1])
        uv1 = (m.triangle_uv[tri, 1, 0], m.triangle_uv[tri, 1, 1])
        uv2 = (m.triangle_uv[tri, 2, 0], m.triangle_uv[tri, 2, 1])
        kt0 = np.uint64(tri_base + j * width)
        # streams: the triangle's normal 1-3 and tangent 4-6; positions read only
        open_streams()
        for i in range(width):
            u = np.uint64(i)
            tn, tt = triangle_frame_from(sload3(position, k0 + u, READ), sload3(position, k1 + u, READ),
                                         sload3(position, k2 + u, READ), uv0, uv1, uv2)
            sstore3(triangle_normal, kt0 + u, tn, 1)
            sstore3(triangle_tangent, kt0 + u, tt, 4)
    for p in range(blk.block_particle_count[b]):
        n = m.vertex_triangle_count[p0 + p]
        if n == 0:
            continue  # per team: zero sums, not valid, rotation kept
        e0 = m.vertex_triangle_start[p0 + p]
        kp0 = np.uint64(row_base + p * width)
        if n <= TRIANGLES_PER_VERTEX:
            # the sums in registers over TRIANGLES_PER_VERTEX slots, the unused ones on the
            # first triangle and selected away (``triangle_rotations_team``'s vector pass)
            slots = (_slot(m, e0, 0, n, t0, tri_base, width), _slot(m, e0, 1, n, t0, tri_base, width),
                     _slot(m, e0, 2, n, t0, tri_base, width), _slot(m, e0, 3, n, t0, tri_base, width),
                     _slot(m, e0, 4, n, t0, tri_base, width), _slot(m, e0, 5, n, t0, tri_base, width))
            # streams: the vertex's rotation 1-4; triangle frames read only
            open_streams()
            for i in range(width):
                u = np.uint64(i)
                sn = ZERO3
                st = ZERO3
                for k in range(TRIANGLES_PER_VERTEX):
                    kt, flip_normal, flip_tangent, used = slots[k]
                    sn_k = add_flipped(sn, sload3(triangle_normal, kt + u, READ), flip_normal)
                    st_k = add_flipped(st, sload3(triangle_tangent, kt + u, READ), flip_tangent)
                    sn = (sn_k[0] if used else sn[0], sn_k[1] if used else sn[1], sn_k[2] if used else sn[2])
                    st = (st_k[0] if used else st[0], st_k[1] if used else st[1], st_k[2] if used else st[2])
                _vertex_rotation_lane(rotation, kp0 + u, sn, st)
            continue
        # a crowded vertex: the sums in the lane arrays, one triangle at a time
        # streams: the sums 1-3 and 4-6 (lane arrays); triangle frames read only
        open_streams()
        for i in range(width):
            L = lanes + np.uint64(i)
            sstore3(ns, L, ZERO3, 1)
            sstore3(ts_, L, ZERO3, 4)
        for e in range(e0, e0 + n):
            kt0 = np.uint64(tri_base + (m.vertex_triangle_data[e] - t0) * width)
            flip = m.vertex_triangle_flip[e]
            flip_normal = (flip & 1) != 0
            flip_tangent = (flip & 2) != 0
            open_streams()
            for i in range(width):
                u = np.uint64(i)
                L = lanes + u
                sstore3(ns, L, add_flipped(sload3(ns, L, 1), sload3(triangle_normal, kt0 + u, READ), flip_normal), 1)
                sstore3(ts_, L, add_flipped(sload3(ts_, L, 4), sload3(triangle_tangent, kt0 + u, READ), flip_tangent), 4)
        # streams: the vertex's rotation 1-4; the sums read only
        open_streams()
        for i in range(width):
            u = np.uint64(i)
            _vertex_rotation_lane(rotation, kp0 + u, sload3(ns, lanes + u, READ), sload3(ts_, lanes + u, READ))


@kernel(inline="always")
def _slot(m, e0, k, n, t0, tri_base, width):
    """Slot k of a vertex's triangle sums: (first block triangle row, flip normal, flip
    tangent, used); an unused slot reads the vertex's first triangle."""
    e = e0 + (k if k < n else 0)
    flip = m.vertex_triangle_flip[e]
    return (np.uint64(tri_base + (m.vertex_triangle_data[e] - t0) * width), (flip & 1) != 0, (flip & 2) != 0,
            k < n)


@kernel(inline="always")
def _vertex_rotation_lane(rotation, k, sn, st):
    """E.3's rotation of the vertex at row k from its sums, where valid."""
    valid, q = vertex_frame_rotation(sn, st)
    q0 = sload4(rotation, k, 1)
    sstore4(rotation, k, (q[0] if valid else q0[0], q[1] if valid else q0[1],
                          q[2] if valid else q0[2], q[3] if valid else q0[3]), 1)


# ----------------------------------------------------------------------------- E.4
@kernel
def transform_data_block(m, blk, bs, b):
    """E.4 (``writeback.transform_data_team``) for every lane: the bone rotation of every
    particle into ``bs.transform_rotation`` (the bone position is the particle's), and each
    lane's verdict (every value finite) into ``bs.lane_transform_ok``."""
    ex = blk.block_exemplar[b]
    p0 = m.team_particle_start[ex]
    width = blk.block_width[b]
    lanes = np.uint64(blk.block_lane_base[b])
    position, rotation, transform_rotation, ok = bs.position, bs.rotation, bs.transform_rotation, bs.lane_transform_ok
    v2t_rows = m.vertex_to_transform_rotation
    for p in range(blk.block_particle_count[b]):
        v2t = (v2t_rows[p0 + p, 0], v2t_rows[p0 + p, 1], v2t_rows[p0 + p, 2], v2t_rows[p0 + p, 3])
        k0 = np.uint64(blk.block_row_base[b] + p * width)
        # streams: the bone rotation 1-4, the lane verdicts 5; positions and rotations read only
        open_streams()
        for i in range(width):
            k = k0 + np.uint64(i)
            L = lanes + np.uint64(i)
            pos = sload3(position, k, READ)
            rot = bone_rotation(sload4(rotation, k, READ), v2t)
            sstore4(transform_rotation, k, rot, 1)
            finite = finite3(pos) & finite4(rot)
            sstore(ok, L, sload(ok, L, 5) & (1 if finite else 0), 5)


# ----------------------------------------------------------------------------- write-back
@kernel
def bone_local_pose_block(m, blk, bs, b, parent_node, world_rotation, lossy_scale):
    """The maths of E.4's write-back (``writeback.write_transforms_team``) for every lane, before
    the barrier: each bone's local pose under its parent particle's bone (moving) or its
    parent node's world rotation (fixed) into ``bs.bone_local_position/rotation``. The
    hierarchy values it reads (lossy scale, world rotation) are not written in the frame
    kernel; the stores through the transform indices wait for ``write_transforms_block``."""
    ex = blk.block_exemplar[b]
    p0 = m.team_particle_start[ex]
    width = blk.block_width[b]
    lanes = np.uint64(blk.block_lane_base[b])
    row_base = blk.block_row_base[b]
    h = (flat(world_rotation), flat(lossy_scale), parent_node)
    a = (bs.position, bs.transform_rotation, bs.lane_particle_start, m.transform_index, bs.bone_local_position,
         bs.bone_local_rotation)
    for p in range(blk.block_particle_count[b]):
        attr = m.attribute[p0 + p]
        k0 = np.uint64(row_base + p * width)
        if (attr & MOVE) != 0:
            pp = m.parent[p0 + p]
            if pp >= 0:
                # streams: the local position 1-3 and rotation 4-7 of the bone; all else read only
                open_streams()
                for i in range(width):
                    _moving_bone_lane(h, a, k0, np.uint64(row_base + (pp - p0) * width), pp - p0, lanes, i)
        elif (attr & FIXED) != 0:
            open_streams()
            for i in range(width):
                _fixed_bone_lane(h, a, k0, p, lanes, i)


@kernel(inline="always")
def _moving_bone_lane(h, a, k0, kp0, pp, lanes, i):
    world_rot, scale, parent_node = h
    position, transform_rotation, particle_start, node_of, local_position, local_rotation = a
    u = np.uint64(i)
    start = sload(particle_start, lanes + u, READ)
    pnode = np.uint64(3) * np.uint64(sload(node_of, np.uint64(start + pp), READ))
    lp, lq = moving_bone_local(sload4(transform_rotation, kp0 + u, READ), sload3(position, kp0 + u, READ),
                               sload4(transform_rotation, k0 + u, READ), sload3(position, k0 + u, READ),
                               (sload(scale, pnode, READ), sload(scale, pnode + np.uint64(1), READ),
                                sload(scale, pnode + np.uint64(2), READ)))
    sstore3(local_position, k0 + u, lp, 1)
    sstore4(local_rotation, k0 + u, lq, 4)


@kernel(inline="always")
def _fixed_bone_lane(h, a, k0, p, lanes, i):
    world_rot, scale, parent_node = h
    position, transform_rotation, particle_start, node_of, local_position, local_rotation = a
    u = np.uint64(i)
    start = sload(particle_start, lanes + u, READ)
    parent = sload(parent_node, np.uint64(sload(node_of, np.uint64(start + p), READ)), READ)
    has_parent = parent >= 0
    w = np.uint64(4) * np.uint64(parent if has_parent else 0)   # a valid row when there is none
    parent_rotation = (sload(world_rot, w, READ), sload(world_rot, w + np.uint64(1), READ),
                       sload(world_rot, w + np.uint64(2), READ), sload(world_rot, w + np.uint64(3), READ))
    sstore4(local_rotation, k0 + u, fixed_bone_local(sload4(transform_rotation, k0 + u, READ), parent_rotation,
                                                     has_parent), 4)


@kernel
def write_transforms_block(m, blk, bs, b, local_position, local_rotation):
    """E.4's write-back (``writeback.write_transforms_team``) of every lane whose bone values are
    all finite (``bs.lane_transform_ok``): the local poses ``bone_local_pose_block`` computed,
    stored through each lane's transform indices into the hierarchy. After the barrier
    (``frame._worker_end``); the block rows stay the frame's until the next gather. Scalar
    (stores through indices)."""
    ex = blk.block_exemplar[b]
    p0 = m.team_particle_start[ex]
    width = blk.block_width[b]
    lanes = blk.block_lane_base[b]
    row_base = blk.block_row_base[b]
    out_position, out_rotation = flat(local_position), flat(local_rotation)
    bone_position, bone_rotation_rows = bs.bone_local_position, bs.bone_local_rotation
    node_of, particle_start, ok = m.transform_index, bs.lane_particle_start, bs.lane_transform_ok
    for p in range(blk.block_particle_count[b]):
        attr = m.attribute[p0 + p]
        moving = (attr & MOVE) != 0 and m.parent[p0 + p] >= 0
        if not moving and (attr & FIXED) == 0:
            continue
        k0 = row_base + p * width
        for i in range(width):
            if ok[lanes + i] == 0:
                continue
            node = np.uint64(node_of[particle_start[lanes + i] + p])
            k = k0 + i
            if moving:
                v = np.uint64(3) * node
                out_position[v] = bone_position[0, k]
                out_position[v + np.uint64(1)] = bone_position[1, k]
                out_position[v + np.uint64(2)] = bone_position[2, k]
            q = np.uint64(4) * node
            out_rotation[q] = bone_rotation_rows[0, k]
            out_rotation[q + np.uint64(1)] = bone_rotation_rows[1, k]
            out_rotation[q + np.uint64(2)] = bone_rotation_rows[2, k]
            out_rotation[q + np.uint64(3)] = bone_rotation_rows[3, k]
