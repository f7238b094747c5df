"""Per-frame team stages before the steps (docs/solver.md §C.1, §C.2, §C.4, §C.5, §H.1).

``skin_team`` (C.1) computes every particle's animated base pose from the bones read this
frame; ``center_and_inertia_team`` (C.2 + C.4) the center, anchor, teleport test, movement
smoothing, world inertia and speed limits, producing the frame shift; ``reset_or_shift_team``
(C.5) applies the reset or the shift to the particle history.
"""
from __future__ import annotations

import math


from magica_py.jit import kernel
from magica_py.kernels.math3d import (
    clamp_length, lerp, load3, load4, q_angle, q_from_to, q_inverse, q_mul, q_normal_axis,
    q_rotate, q_slerp, q_tangent_axis, rot_from_normal_tangent, saturate, shift_position,
    store3, store4, unlerp, v_add, v_length, v_lerp, v_normalize, v_scale, v_sub,
)
from reference_solver.solver.maths import matrix_row
from reference_solver.solver.rotations import normalize_or_zero, rot_from_normal_tangent_select
from magica_py.kernels import portable
from reference_solver.solver.parameters import length_unit

MOVE = 0x02
IDENTITY = (0.0, 0.0, 0.0, 1.0)
TELEPORT_RESET = 1
TELEPORT_KEEP = 2


@kernel
def bind_point(b0, b1, b2, b3, v, w):
    """``B @ (v, w)`` with ``B`` the bind pose (rows b0..b3, 4-tuples): the 4-vector C.1 then
    takes to world space with the bone's matrix (``world_point``)."""
    return (b0[0] * v[0] + b0[1] * v[1] + b0[2] * v[2] + b0[3] * w,
            b1[0] * v[0] + b1[1] * v[1] + b1[2] * v[2] + b1[3] * w,
            b2[0] * v[0] + b2[1] * v[1] + b2[2] * v[2] + b2[3] * w,
            b3[0] * v[0] + b3[1] * v[1] + b3[2] * v[2] + b3[3] * w)


@kernel
def world_point(l0, l1, l2, x):
    """The first three rows l0..l2 of ``L`` (4-tuples) applied to the 4-vector x."""
    return (l0[0] * x[0] + l0[1] * x[1] + l0[2] * x[2] + l0[3] * x[3],
            l1[0] * x[0] + l1[1] * x[1] + l1[2] * x[2] + l1[3] * x[3],
            l2[0] * x[0] + l2[1] * x[1] + l2[2] * x[2] + l2[3] * x[3])


@kernel
def skin_bound_vertex(l0, l1, l2, bound_position, bound_normal, bound_tangent):
    """C.1 for one vertex from its ``bind_point`` 4-vectors (position w = 1, normal and tangent
    w = 0) and its bone's local-to-world rows l0..l2. Branch-free (a loop vectorises)."""
    pos = world_point(l0, l1, l2, bound_position)
    nor = normalize_or_zero(world_point(l0, l1, l2, bound_normal))
    tan = normalize_or_zero(world_point(l0, l1, l2, bound_tangent))
    return pos, rot_from_normal_tangent_select(nor, tan)


@kernel
def skin_vertex(l0, l1, l2, b0, b1, b2, b3, local_position, local_normal, local_tangent):
    """C.1 for one vertex: world (position, rotation) from its bone's local-to-world rows
    l0..l2 and its bind pose rows b0..b3. Branch-free (a loop over vertices vectorises)."""
    return skin_bound_vertex(l0, l1, l2, bind_point(b0, b1, b2, b3, local_position, 1.0),
                             bind_point(b0, b1, b2, b3, local_normal, 0.0),
                             bind_point(b0, b1, b2, b3, local_tangent, 0.0))


@kernel
def skin_team(m, ps, local_to_world, team):
    """C.1: one-bone skinning of every vertex with this frame's bone matrices (a read-only pass
    over the model and the bone matrices, writing position and rotation)."""
    node_of, bind = m.transform_index, m.skin_bind_pose
    local_position, local_normal, local_tangent = m.local_position, m.local_normal, m.local_tangent
    position, rotation = ps.position, ps.rotation
    start = m.team_particle_start[team]
    for p in range(start, start + m.team_particle_count[team]):
        node = node_of[p]
        pos, rot = skin_vertex(matrix_row(local_to_world, node, 0), matrix_row(local_to_world, node, 1),
                               matrix_row(local_to_world, node, 2),
                               matrix_row(bind, p, 0), matrix_row(bind, p, 1), matrix_row(bind, p, 2),
                               matrix_row(bind, p, 3),
                               load3(local_position, p), load3(local_normal, p), load3(local_tangent, p))
        store3(position, p, pos)
        store4(rotation, p, rot)


SMOOTHING_REFERENCE_RATE = 90.0   # 1/s: the frame rate at which the C.4 ratio is taken as is


@kernel
def smoothing_time_constant(s):
    """Time constant (s) of movement smoothing ``s``: C.4's per-frame ratio
    ``a = (1-s)^3 0.99 + 0.01`` read as the ratio of one 1/90 s frame, ``1 - a = exp(-h/tau)``.
    0 when there is no smoothing (a = 1)."""
    a = saturate((1.0 - s) ** 3 * 0.99 + 0.01)
    if a >= 1.0:
        return 0.0
    return -1.0 / (SMOOTHING_REFERENCE_RATE * portable.log(1.0 - a))


@kernel
def time_based_smoothing(ts, team, delta, frame_delta_time, s, speed_limit):
    """Quality-mode C.4 smoothing: the smoothed component velocity is an exponential filter
    with the time constant of ``smoothing_time_constant(s)``, integrated exactly over the frame
    for the frame's mean velocity (piecewise constant input), every frame with time.

    After a reset the filter state is NaN (set by the reset branch below) and starts in steady
    state, ``sv0 = v``: the cloth is not made to feel a velocity ramp that would start at the
    reset frame's time, i.e. at a different time at each frame rate (tail: 1.25 -> 0.83 % of
    frame-rate spread over the whole run).

    Returns the displacement the cloth feels this frame (the rest is shifted rigidly) and
    updates ``ts.smoothing_velocity``; independent of how the time is cut into frames for a
    constant input, first order in the frame time otherwise."""
    h = frame_delta_time
    if h <= 0.0:
        return (0.0, 0.0, 0.0)
    v = v_scale(delta, 1.0 / h)
    if speed_limit >= 0.0:
        v = clamp_length(v, speed_limit)
    tau = smoothing_time_constant(s)
    sv0 = load3(ts.smoothing_velocity, team)
    if math.isnan(sv0[0]):  # first frame after a reset: the filter starts in steady state
        sv0 = v
    if tau <= 0.0:
        store3(ts.smoothing_velocity, team, v)
        return v_scale(v, h)
    decay = portable.exp(-h / tau)
    lag = v_sub(sv0, v)
    store3(ts.smoothing_velocity, team, v_add(v, v_scale(lag, decay)))
    # integral over the frame of v + (sv0 - v) exp(-t/tau)
    return v_add(v_scale(v, h), v_scale(lag, tau * (1.0 - decay)))


@kernel
def mean_velocity_weight(w0, stabilization_time, span):
    """Quality mode: the stabilisation weight averaged over the frame's simulated time span
    (it ramps by dt/stab per step, C.3), so that the forced shift of C.4 removes the same
    share of the motion however the time is cut into frames (faithful: the weight at the
    start of the frame, a 1/30 s frame is shifted rigidly as a whole after a reset)."""
    if span <= 0.0:
        return w0
    if stabilization_time <= 1e-6:
        return 1.0
    t1 = (1.0 - w0) * stabilization_time  # time to reach 1
    if span <= t1:
        return w0 + span / (2.0 * stabilization_time)
    return ((w0 + 1.0) * 0.5 * t1 + (span - t1)) / span


@kernel
def center_fixed_terms(position, rotation, bind_rotation):
    """C.2 terms of one center-fixed vertex: its position and the normal and tangent axes of
    ``rotation * bind_rotation`` (summed over the fixed list by ``center_pose_team``). Branch-free."""
    q = q_mul(rotation, bind_rotation)
    return position, q_normal_axis(q), q_tangent_axis(q)


@kernel
def center_from_sums(position_sum, normal_sum, tangent_sum, count):
    """C.2 center pose from the sums of ``center_fixed_terms`` over ``count`` > 0 vertices."""
    return (v_scale(position_sum, 1.0 / count),
            rot_from_normal_tangent(v_normalize(normal_sum), v_normalize(tangent_sum)))


@kernel
def component_pose_team(m, ts, team, world_position, world_rotation, lossy_scale):
    """C.2 component pose of one team (stored in ``ts``): (position, rotation, scale, scale ratio)."""
    comp = m.team_component_transform[team]
    cpos = load3(world_position, comp)
    crot = load4(world_rotation, comp)
    cscl = load3(lossy_scale, comp)
    store3(ts.component_pos, team, cpos)
    store4(ts.component_rot, team, crot)
    store3(ts.component_scale, team, cscl)
    init_len = v_length(load3(m.team_init_scale, team))
    ratio = v_length(cscl) / init_len if init_len > 0.0 else 1.0
    ts.component_scale_ratio[team] = ratio
    return cpos, crot, cscl, ratio


@kernel
def center_pose_team(m, ps, team, cpos, crot):
    """C.2 center of one team from its skinned pose in the team rows (the component pose when
    the team has no center-fixed vertex)."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_bind_rotation, m_center_fixed, ps_position = m.bind_rotation, m.center_fixed, ps.position
    ps_rotation = ps.rotation
    c0 = m.team_center_start[team]
    cn = m.team_center_count[team]
    if cn == 0:
        return cpos, crot
    sp = (0.0, 0.0, 0.0)
    sn = (0.0, 0.0, 0.0)
    st = (0.0, 0.0, 0.0)
    for k in range(c0, c0 + cn):
        f = m_center_fixed[k]
        pos, nor, tan = center_fixed_terms(load3(ps_position, f), load4(ps_rotation, f), load4(m_bind_rotation, f))
        sp = v_add(sp, pos)
        sn = v_add(sn, nor)
        st = v_add(st, tan)
    return center_from_sums(sp, sn, st, cn)


@kernel
def center_and_inertia_team(m, ps, prm, ts, team, world_position, world_rotation, lossy_scale,
                            frame_delta_time, now_time_scale, skip_count, running, dt, since_last_step=0.0):
    """C.2 and C.4 for one team: center, anchor, teleport, smoothing, world inertia, shift.

    ``since_last_step``: team time (s) from the last step to the start of this frame; quality
    mode uses it to read the stabilisation ramp, which C.3 advances per step, in continuous
    time (the ramp at the frame's start, not at the last step before it)."""
    cpos, crot, cscl, ratio = component_pose_team(m, ts, team, world_position, world_rotation, lossy_scale)
    center_pos, center_rot = center_pose_team(m, ps, team, cpos, crot)
    ts.length_unit[team] = length_unit(m, prm, team)
    inertia_team(prm, ts, team, cpos, crot, cscl, ratio, center_pos, center_rot, world_position, world_rotation,
                 frame_delta_time, now_time_scale, skip_count, running, dt, since_last_step)


@kernel
def inertia_team(prm, ts, team, cpos, crot, cscl, ratio, center_pos, center_rot, world_position, world_rotation,
                 frame_delta_time, now_time_scale, skip_count, running, dt, since_last_step):
    """C.4 for one team once its component pose and center (C.2) are known: anchor, teleport,
    smoothing, world inertia, speed limits, the frame shift (see ``center_and_inertia_team``)."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    prm_time_based_smoothing, ts_frame_shift_vector = prm.time_based_smoothing, ts.frame_shift_vector
    ts_now_world_pos, ts_old_frame_world_pos = ts.now_world_pos, ts.old_frame_world_pos
    ts_old_frame_world_scale, ts_old_world_pos = ts.old_frame_world_scale, ts.old_world_pos
    ts_smoothing_velocity = ts.smoothing_velocity
    store3(ts.frame_world_pos, team, center_pos)
    store4(ts.frame_world_rot, team, center_rot)
    store3(ts.frame_world_scale, team, cscl)

    pivot = load3(ts.old_component_pos, team)      # raw previous component position
    old_pos = pivot
    old_rot = load4(ts.old_component_rot, team)
    reset = ts.reset[team] != 0
    shift = False
    # 1. anchor
    anchor_delta = (0.0, 0.0, 0.0)
    anchor_rot = IDENTITY
    anchor = prm.anchor_transform[team]
    if anchor >= 0:
        apos = load3(world_position, anchor)
        arot = load4(world_rotation, anchor)
        if reset or ts.anchor_valid[team] == 0:
            store3(ts.anchor_component_local_pos, team, q_rotate(q_inverse(arot), v_sub(cpos, apos)))
            store4(ts.old_anchor_rot, team, arot)
            ts.anchor_valid[team] = 1
        anchor_center = v_add(apos, q_rotate(arot, load3(ts.anchor_component_local_pos, team)))
        a = prm.anchor_inertia[team]
        anchor_delta = v_scale(v_sub(anchor_center, old_pos), 1.0 - a)
        anchor_rot = q_slerp(IDENTITY, q_from_to(load4(ts.old_anchor_rot, team), arot), 1.0 - a)
        old_pos = v_add(old_pos, anchor_delta)
        old_rot = q_mul(anchor_rot, old_rot)
        store4(ts.old_anchor_rot, team, arot)
        shift = True
    else:
        ts.anchor_valid[team] = 0
    # 2. teleport
    keep = ts.keep_teleport[team] != 0
    mode = prm.teleport_mode[team]
    if mode != 0 and not reset:
        delta = v_length(v_sub(cpos, old_pos))
        angle = math.degrees(q_angle(old_rot, crot))
        if delta >= prm.teleport_distance[team] * ratio * ts.length_unit[team] or angle >= prm.teleport_rotation[team]:
            if mode == TELEPORT_RESET:
                reset = True
                ts.reset[team] = 1
            elif mode == TELEPORT_KEEP:
                keep = True
                ts.keep_teleport[team] = 1
    # 3. movement smoothing
    smooth_delta = (0.0, 0.0, 0.0)
    s = prm.movement_smoothing[team]
    limit = prm.movement_speed_limit[team]
    if s >= 1e-6 and not reset and not keep:
        if prm_time_based_smoothing[team] != 0:
            felt = time_based_smoothing(ts, team, v_sub(cpos, old_pos), frame_delta_time, s,
                                        limit * ratio * ts.length_unit[team] if limit >= 0.0 else -1.0)
            smooth_pos = v_sub(cpos, felt)
        else:
            if math.isnan(ts_smoothing_velocity[team, 0]):  # quality switched off after a reset
                store3(ts_smoothing_velocity, team, (0.0, 0.0, 0.0))
            if running:
                v = (0.0, 0.0, 0.0)
                if frame_delta_time > 0.0:
                    v = v_scale(v_sub(cpos, old_pos), 1.0 / frame_delta_time)
                if limit >= 0.0:
                    v = clamp_length(v, limit * ratio)
                a = saturate((1.0 - s) ** 3 * 0.99 + 0.01)
                store3(ts_smoothing_velocity, team, v_lerp(load3(ts_smoothing_velocity, team), v, a))
            smooth_pos = v_sub(cpos, v_scale(load3(ts_smoothing_velocity, team), frame_delta_time))
        smooth_delta = v_sub(smooth_pos, old_pos)
        old_pos = smooth_pos
        shift = True
    # 4. reset: every history value becomes the current one
    if reset:
        for c in range(3):
            ts_old_frame_world_pos[team, c] = center_pos[c]
            ts_now_world_pos[team, c] = center_pos[c]
            ts_old_world_pos[team, c] = center_pos[c]
            ts_old_frame_world_scale[team, c] = cscl[c]
            ts_smoothing_velocity[team, c] = math.nan if prm_time_based_smoothing[team] != 0 else 0.0
            ts_frame_shift_vector[team, c] = 0.0
        store4(ts.old_frame_world_rot, team, center_rot)
        store4(ts.now_world_rot, team, center_rot)
        store4(ts.old_world_rot, team, center_rot)
        store4(ts.frame_shift_rotation, team, IDENTITY)
        ts.inertia_shift[team] = 0
        ts.frame_moving_speed[team] = 0.0
        store3(ts.frame_moving_direction, team, (0.0, 0.0, 0.0))
    else:
        # 5. world shift
        shift_vec = v_sub(cpos, old_pos)
        shift_rot = q_from_to(old_rot, crot)
        ms = 1.0 - prm.world_inertia[team]
        rs = ms
        if keep:
            ms = 1.0
            rs = 1.0
        work_pos = old_pos
        work_rot = old_rot
        if ms > 1e-8 or rs > 1e-8:
            shift = True
            work_pos = v_lerp(old_pos, cpos, ms)
            work_rot = q_slerp(old_rot, crot, rs)
        if frame_delta_time > 0.0:
            if limit >= 0.0:
                speed = v_length(v_sub(cpos, work_pos)) / frame_delta_time
                limit_s = limit * ratio * ts.length_unit[team]
                if speed > limit_s:
                    k = saturate((speed - limit_s) / speed)
                    ms = lerp(ms, 1.0, k)
                    work_pos = v_lerp(work_pos, cpos, k)
                    shift = True
            rlimit = prm.rotation_speed_limit[team]
            if rlimit >= 0.0:
                speed = math.degrees(q_angle(work_rot, crot)) / frame_delta_time
                if speed > rlimit:
                    k = saturate((speed - rlimit) / speed)
                    rs = lerp(rs, 1.0, k)
                    work_rot = q_slerp(work_rot, crot, k)
                    shift = True
        o = 0.0
        if skip_count > 0 and frame_delta_time * now_time_scale > 0.0:
            o = lerp(o, 1.0, saturate(skip_count * dt / (frame_delta_time * now_time_scale)))
        if ts.velocity_weight[team] < 1.0:
            w = ts.velocity_weight[team]
            if prm_time_based_smoothing[team] != 0:
                stab = prm.stabilization_time[team]
                if stab > 1e-6:  # the ramp in continuous time: it rose since the last step too
                    w = saturate(w + max(since_last_step, 0.0) / stab)
                w = mean_velocity_weight(w, stab, frame_delta_time * now_time_scale)
            o = lerp(o, 1.0, 1.0 - w)
        if now_time_scale < 1.0:
            o = lerp(o, 1.0, 1.0 - now_time_scale)
        if o > 0.0:
            ms = lerp(ms, 1.0, o)
            rs = lerp(rs, 1.0, o)
            work_pos = v_lerp(work_pos, cpos, o)
            work_rot = q_slerp(work_rot, crot, o)
            shift = True
        if shift:
            vec = v_add(v_add(v_scale(shift_vec, ms), anchor_delta), smooth_delta)
            rot = q_mul(anchor_rot, q_slerp(IDENTITY, shift_rot, rs))
            store3(ts_frame_shift_vector, team, vec)
            store4(ts.frame_shift_rotation, team, rot)
            store3(ts_old_frame_world_pos, team, shift_position(load3(ts_old_frame_world_pos, team), pivot, vec, rot))
            store4(ts.old_frame_world_rot, team, q_mul(rot, load4(ts.old_frame_world_rot, team)))
            store3(ts_now_world_pos, team, shift_position(load3(ts_now_world_pos, team), pivot, vec, rot))
            store4(ts.now_world_rot, team, q_mul(rot, load4(ts.now_world_rot, team)))
            ts.inertia_shift[team] = 1
        # 6. wind bookkeeping
        speed = 0.0
        if frame_delta_time > 0.0 and now_time_scale > 1e-6:
            speed = v_length(v_sub(cpos, work_pos)) / frame_delta_time / now_time_scale
        ts.frame_moving_speed[team] = speed
        moving = v_sub(cpos, work_pos)
        moving_length = v_length(moving)
        store3(ts.frame_moving_direction, team,
               v_scale(moving, 1.0 / moving_length) if moving_length > 1e-6 else (0.0, 0.0, 0.0))
    # 7. reset consequences
    if reset or ts.time_reset[team] != 0:
        ts.velocity_weight[team] = 0.0 if prm.stabilization_time[team] > 1e-6 else 1.0
        ts.blend_weight[team] = ts.velocity_weight[team]


@kernel
def snap_particles_to_base_pose(ps, start, end):
    """C.5 Reset of particles [start, end): every position history at this frame's animated
    pose, velocities, friction and collision normals zero (also used by the guards)."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    ps_base_pos, ps_base_rot, ps_collision_normal = ps.base_pos, ps.base_rot, ps.collision_normal
    ps_disp_pos, ps_friction, ps_next_pos, ps_old_pos = ps.disp_pos, ps.friction, ps.next_pos, ps.old_pos
    ps_old_position, ps_old_rotation, ps_position = ps.old_position, ps.old_rotation, ps.position
    ps_real_velocity, ps_rotation, ps_static_friction = ps.real_velocity, ps.rotation, ps.static_friction
    ps_velocity, ps_velocity_pos, ps_display_history = ps.velocity, ps.velocity_pos, ps.display_history
    for p in range(start, end):
        pos = load3(ps_position, p)
        rot = load4(ps_rotation, p)
        for c in range(3):
            ps_next_pos[p, c] = pos[c]
            ps_old_pos[p, c] = pos[c]
            ps_base_pos[p, c] = pos[c]
            ps_old_position[p, c] = pos[c]
            ps_velocity_pos[p, c] = pos[c]
            ps_disp_pos[p, c] = pos[c]
            ps_velocity[p, c] = 0.0
            ps_real_velocity[p, c] = 0.0
            ps_collision_normal[p, c] = 0.0
        store4(ps_base_rot, p, rot)
        store4(ps_old_rotation, p, rot)
        ps_friction[p] = 0.0
        ps_static_friction[p] = 0.0
        ps_display_history[p] = 0   # quality display: no step state since the reset


@kernel
def shift_history(old_pos, old_position, disp_pos, old_rotation, velocity, pivot, vec, rot):
    """C.5 inertia shift of one particle's history but its real velocity: positions moved
    rigidly about the pivot, rotation and velocity turned (no branch: a loop vectorises)."""
    return (shift_position(old_pos, pivot, vec, rot), shift_position(old_position, pivot, vec, rot),
            shift_position(disp_pos, pivot, vec, rot), q_mul(rot, old_rotation), q_rotate(rot, velocity))


@kernel
def shift_particle(old_pos, old_position, disp_pos, old_rotation, velocity, real_velocity, pivot, vec, rot):
    """C.5 inertia shift of one particle's history (``shift_history``) and its real velocity."""
    a, b, c, r, u = shift_history(old_pos, old_position, disp_pos, old_rotation, velocity, pivot, vec, rot)
    return a, b, c, r, u, q_rotate(rot, real_velocity)


@kernel
def reset_or_shift_team(m, ps, ts, team):
    """C.5: snap the particles to the base pose (Reset) or shift their history rigidly."""
    start = m.team_particle_start[team]
    end = start + m.team_particle_count[team]
    if ts.reset[team] != 0:
        snap_particles_to_base_pose(ps, start, end)
    elif ts.inertia_shift[team] != 0:
        pivot = load3(ts.old_component_pos, team)
        vec = load3(ts.frame_shift_vector, team)
        rot = load4(ts.frame_shift_rotation, team)
        old_pos, old_position, disp_pos = ps.old_pos, ps.old_position, ps.disp_pos
        old_rotation, velocity, real_velocity = ps.old_rotation, ps.velocity, ps.real_velocity
        for p in range(start, end):
            a, b, c, r, u, w = shift_particle(load3(old_pos, p), load3(old_position, p), load3(disp_pos, p),
                                              load4(old_rotation, p), load3(velocity, p), load3(real_velocity, p),
                                              pivot, vec, rot)
            store3(old_pos, p, a)
            store3(old_position, p, b)
            store3(disp_pos, p, c)
            store4(old_rotation, p, r)
            store3(velocity, p, u)
            store3(real_velocity, p, w)


@kernel
def distance_culling_team(prm, ts, team, world_position, component_transform):
    """H.1 distance culling: returns True when the team is beyond the culling length, and
    updates the fade weight ``distance_weight`` (1 inside, 0 at the limit)."""
    length = prm.culling_length[team]
    ref = prm.culling_reference[team]
    if length < 0.0 or ref < 0:
        ts.distance_weight[team] = 1.0
        return False
    d = v_length(v_sub(load3(world_position, component_transform), load3(world_position, ref)))
    if d >= length:
        ts.distance_weight[team] = 0.0
        return True
    fade = saturate(prm.culling_fade_ratio[team]) * length
    ts.distance_weight[team] = 1.0 - saturate(unlerp(length - fade, length, d))
    return False


@kernel
def end_frame_team(ts, team, running):
    """A.7: remember this frame's component and center, clear the per-frame flags."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    ts_component_pos, ts_component_rot = ts.component_pos, ts.component_rot
    ts_component_scale, ts_external_force = ts.component_scale, ts.external_force
    ts_frame_world_pos, ts_frame_world_rot = ts.frame_world_pos, ts.frame_world_rot
    ts_frame_world_scale, ts_old_component_pos = ts.frame_world_scale, ts.old_component_pos
    ts_old_component_rot, ts_old_component_scale = ts.old_component_rot, ts.old_component_scale
    ts_old_frame_world_pos, ts_old_frame_world_rot = ts.old_frame_world_pos, ts.old_frame_world_rot
    ts_old_frame_world_scale = ts.old_frame_world_scale
    for c in range(3):
        ts_old_component_pos[team, c] = ts_component_pos[team, c]
        ts_old_component_scale[team, c] = ts_component_scale[team, c]
        if running:
            ts_old_frame_world_pos[team, c] = ts_frame_world_pos[team, c]
            ts_old_frame_world_scale[team, c] = ts_frame_world_scale[team, c]
            ts_external_force[team, c] = 0.0
    for c in range(4):
        ts_old_component_rot[team, c] = ts_component_rot[team, c]
        if running:
            ts_old_frame_world_rot[team, c] = ts_frame_world_rot[team, c]
    if running:
        ts.external_force_mode[team] = 0
    ts.reset[team] = 0
    ts.time_reset[team] = 0
    ts.keep_teleport[team] = 0
    ts.inertia_shift[team] = 0
    ts.running[team] = 0
