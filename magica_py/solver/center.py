"""Per-frame team stages before the steps (docs/solver.md §C.1, §C.2, §C.4, §C.5, §H.1, §A.7).

``skin_block`` (C.1) computes every particle's animated base pose from the bones read this
frame; ``center_and_inertia_lane`` (C.2 + C.4) the center, anchor, teleport test, movement
smoothing, world inertia and speed limits of one lane's team, producing the frame shift;
``reset_or_shift_block`` (C.5) applies the reset or the shift to the particle history.

Every function works on one block ``b`` of the packed tables (``solver/lanes.py``): particle
stages loop over the block's particles and, innermost, its lanes (vectorised across teams);
team stages run lane by lane (``*_lane``: a team's branches differ from its neighbours'),
taking the frame's arrays as one object (``frame_call.FrameArrays``), or loop over a block's
lanes themselves (``*_block``): an array argument of a function called once a lane would cost
a reference count at every call (docs/architecture.md, *Calling the frame kernel*).
"""
from __future__ import annotations

import math

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels import portable
from magica_py.kernels.math3d import (
    clamp_length, lerp, q_angle, q_from_to, q_inverse, q_mul, q_normal_axis, q_rotate, q_slerp,
    q_tangent_axis, rot_from_normal_tangent, saturate, shift_position, unlerp, v_add, v_length, v_lerp,
    v_normalize, v_normalize_select, v_scale, v_sub,
)
from magica_py.solver import blocks as bk
from magica_py.solver import state as st
from magica_py.solver.lanes import LANES, get1, get3, get4, put1, put3, put4
from magica_py.solver.parameters import (
    PRM_ANCHOR_INERTIA, PRM_CULLING_FADE_RATIO, PRM_CULLING_LENGTH, PRM_MOVEMENT_SMOOTHING,
    PRM_MOVEMENT_SPEED_LIMIT, PRM_QUALITY, PRM_ROTATION_SPEED_LIMIT, PRM_STABILIZATION_TIME,
    PRM_TELEPORT_DISTANCE, PRM_TELEPORT_MODE, PRM_TELEPORT_ROTATION, PRM_TIME_BASED_SMOOTHING, PRM_WORLD_INERTIA,
    length_unit,
)
from magica_py.solver.rotations import rot_from_normal_tangent_select

IDENTITY = (0.0, 0.0, 0.0, 1.0)
ZERO3 = (0.0, 0.0, 0.0)
TELEPORT_RESET = 1
TELEPORT_KEEP = 2


@kernel
def world_point(l0, l1, l2, x):
    """The first three rows l0..l2 of ``L`` (4-tuples) applied to the 4-vector x."""
    return (l0[0] * x[0] + l0[1] * x[1] + l0[2] * x[2] + l0[3] * x[3],
            l1[0] * x[0] + l1[1] * x[1] + l1[2] * x[2] + l1[3] * x[3],
            l2[0] * x[0] + l2[1] * x[1] + l2[2] * x[2] + l2[3] * x[3])


@kernel(inline="always")
def skin_bound_vertex(l0, l1, l2, bound_position, bound_normal, bound_tangent):
    """C.1 for one vertex from its bound 4-vectors (``bound_vectors``: its bind pose applied to
    its build position, normal and tangent) and its bone's local-to-world rows l0..l2.
    Branch-free (a loop vectorises)."""
    pos = world_point(l0, l1, l2, bound_position)
    nor = v_normalize_select(world_point(l0, l1, l2, bound_normal))
    tan = v_normalize_select(world_point(l0, l1, l2, bound_tangent))
    return pos, rot_from_normal_tangent_select(nor, tan)


MATRIX_ROW = 4 * LANES   # columns from one row of a row-major 4x4 matrix field to the next


@kernel(forceinline=False)
def skin_block(PS, PM, BI, PT, local_to_world, b, l0, l1):
    """C.1: one-bone skinning of every vertex of block b's lanes ``l0 .. l1 - 1`` with the bone
    matrices ``local_to_world`` (this frame's; quality mode's build reset passes the build
    pose's): a read-only pass over the model (each vertex's bind pose already applied to it,
    ``bound_vectors``) and the matrices, writing position and rotation.
    Each vertex's bone matrix is first copied next to it (``BONE_MATRIX``; a gather through the
    bone's node), so that the skinning loop reads one particle slot per table."""
    l1 = min(l1, LANES)
    g0 = BI[b, bk.BI_G0]
    for j in range(BI[b, bk.BI_N]):
        g = g0 + j
        for l in range(l0, l1):
            node = PT[g, l]
            for k in range(3):
                for c in range(4):
                    PS[g, st.BONE_MATRIX + (4 * k + c) * LANES + l] = local_to_world[node, k, c]
        for l in range(l0, l1):
            m0, m1, m2 = bone_rows(PS, g, l)
            pos, rot = skin_bound_vertex(m0, m1, m2, get4(PM, g, bk.SKIN_BOUND_POSITION, l),
                                         get4(PM, g, bk.SKIN_BOUND_NORMAL, l), get4(PM, g, bk.SKIN_BOUND_TANGENT, l))
            put3(PS, g, st.POSITION, l, pos)
            put4(PS, g, st.ROTATION, l, rot)


@kernel(inline="always")
def bone_rows(PS, g, l):
    """The three top rows of lane l's gathered bone matrix (``BONE_MATRIX``, row major)."""
    c = st.BONE_MATRIX
    return get4(PS, g, c, l), get4(PS, g, c + MATRIX_ROW, l), get4(PS, g, c + 2 * MATRIX_ROW, l)


SMOOTHING_REFERENCE_RATE = 90.0   # 1/s: the frame rate at which the C.4 ratio is taken as is


@kernel(inline="always")
def smoothing_ratio(s):
    """C.4's per-frame ratio of movement smoothing ``s``: ``a = (1-s)^3 0.99 + 0.01``. The cube
    is written as two products, which is what numba compiles ``x ** 3`` to, while Python and
    numpy call ``pow``, whose bits differ for about a quarter of the inputs (``0.6 ** 3``:
    0.21599999999999997 against 0.216): so the interpreted first run (``magica_py/first_run.py``)
    gives the compiled bits."""
    r = 1.0 - s
    return saturate(r * r * r * 0.99 + 0.01)


@kernel
def smoothing_time_constant(s):
    """Time constant (s) of movement smoothing ``s``: C.4's per-frame ratio ``smoothing_ratio``
    read as the ratio of one 1/90 s frame, ``1 - a = exp(-h/tau)``. 0 when there is no
    smoothing (a = 1)."""
    a = smoothing_ratio(s)
    if a >= 1.0:
        return 0.0
    return -1.0 / (SMOOTHING_REFERENCE_RATE * portable.log(1.0 - a))


@kernel(inline="always")
def time_based_smoothing(TS, b, l, delta, frame_delta_time, s, speed_limit):
    """Quality-mode C.4 smoothing: the smoothed component velocity is an exponential filter
    with the time constant of ``smoothing_time_constant(s)``, integrated exactly over the frame
    for the frame's mean velocity (piecewise constant input), every frame with time.

    After a reset the filter state is NaN (set by the reset branch of ``inertia_lane``) and
    starts in steady state, ``sv0 = v``: the cloth is not made to feel a velocity ramp that
    would start at the reset frame's time, i.e. at a different time at each frame rate (tail:
    1.25 -> 0.83 % of frame-rate spread over the whole run).

    Returns the displacement the cloth feels this frame (the rest is shifted rigidly) and
    updates the lane's ``SMOOTHING_VELOCITY``; independent of how the time is cut into frames
    for a constant input, first order in the frame time otherwise."""
    h = frame_delta_time
    if h <= 0.0:
        return ZERO3
    v = v_scale(delta, 1.0 / h)
    if speed_limit >= 0.0:
        v = clamp_length(v, speed_limit)
    tau = smoothing_time_constant(s)
    sv0 = get3(TS, b, st.SMOOTHING_VELOCITY, l)
    if math.isnan(sv0[0]):  # first frame after a reset: the filter starts in steady state
        sv0 = v
    if tau <= 0.0:
        put3(TS, b, st.SMOOTHING_VELOCITY, l, v)
        return v_scale(v, h)
    decay = portable.exp(-h / tau)
    lag = v_sub(sv0, v)
    put3(TS, b, st.SMOOTHING_VELOCITY, l, v_add(v, v_scale(lag, decay)))
    # integral over the frame of v + (sv0 - v) exp(-t/tau)
    return v_add(v_scale(v, h), v_scale(lag, tau * (1.0 - decay)))


@kernel(inline="always")
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


@kernel(inline="always")
def center_fixed_terms(position, rotation, bind_rotation):
    """C.2 terms of one center-fixed vertex: its position and the normal and tangent axes of
    ``rotation * bind_rotation`` (summed over the fixed list by ``center_pose_lane``). Branch-free."""
    q = q_mul(rotation, bind_rotation)
    return position, q_normal_axis(q), q_tangent_axis(q)


@kernel(inline="always")
def center_from_sums(position_sum, normal_sum, tangent_sum, count):
    """C.2 center pose from the sums of ``center_fixed_terms`` over ``count`` > 0 vertices."""
    return (v_scale(position_sum, 1.0 / count),
            rot_from_normal_tangent(v_normalize(normal_sum), v_normalize(tangent_sum)))


@kernel
def world_pose_rows(world_position, world_rotation, lossy_scale, node):
    """(position, rotation, lossy scale) of hierarchy node ``node``: the rows C.2 and C.4 read
    of a team's component and anchor. Straight-line (no count of the arrays is kept)."""
    return ((world_position[node, 0], world_position[node, 1], world_position[node, 2]),
            (world_rotation[node, 0], world_rotation[node, 1], world_rotation[node, 2], world_rotation[node, 3]),
            (lossy_scale[node, 0], lossy_scale[node, 1], lossy_scale[node, 2]))


@kernel
def team_world_poses(TI, b, l, world_position, world_rotation, lossy_scale):
    """The world poses ``center_and_inertia_lane`` takes for lane l's team: its component's
    (position, rotation, lossy scale) and its anchor's (position, rotation); the anchor's are
    the first node's when the team has none (then not used)."""
    component = world_pose_rows(world_position, world_rotation, lossy_scale, np.int64(TI[b, bk.TI_COMPONENT + l]))
    anchor = world_pose_rows(world_position, world_rotation, lossy_scale, max(np.int64(TI[b, bk.TI_ANCHOR + l]), 0))
    return component, (anchor[0], anchor[1])


@kernel
def scale_ratio_of(scale, init_length):
    """|scale| / |build scale| (1 when the build scale is zero)."""
    return v_length(scale) / init_length if init_length > 0.0 else 1.0


@kernel(forceinline=False)
def component_pose_lane(F, b, l, cpos, crot, cscl):
    """C.2 component pose of lane l's team (stored in ``TS``); returns its scale ratio."""
    TS = F.TS
    put3(TS, b, st.COMPONENT_POS, l, cpos)
    put4(TS, b, st.COMPONENT_ROT, l, crot)
    put3(TS, b, st.COMPONENT_SCALE, l, cscl)
    ratio = scale_ratio_of(cscl, v_length(get3(F.TM, b, bk.INIT_SCALE, l)))
    put1(TS, b, st.COMPONENT_SCALE_RATIO, l, ratio)
    return ratio


@kernel(forceinline=False)
def center_pose_lane(F, b, l, cpos, crot):
    """C.2 center of lane l's team from its skinned pose (the component pose when the team
    has no center-fixed vertex)."""
    cn = F.BI[b, bk.BI_CENTERS]
    if cn == 0:
        return cpos, crot
    g0 = F.BI[b, bk.BI_G0]
    at = F.BI[b, bk.BI_CENTER_FIXED]
    sp = ZERO3
    sn = ZERO3
    st_ = ZERO3
    for k in range(cn):
        g = g0 + F.topology[at + k]
        pos, nor, tan = center_fixed_terms(get3(F.PS, g, st.POSITION, l), get4(F.PS, g, st.ROTATION, l),
                                           get4(F.PM, g, bk.BIND_ROTATION, l))
        sp = v_add(sp, pos)
        sn = v_add(sn, nor)
        st_ = v_add(st_, tan)
    return center_from_sums(sp, sn, st_, cn)


@kernel(forceinline=False)
def center_and_inertia_lane(F, b, l, component, anchor, frame_delta_time, now_time_scale, skip_count, running, dt,
                            since_last_step):
    """C.2 and C.4 for lane l's team: center, anchor, teleport, smoothing, world inertia, shift.

    ``F``: the frame's arrays (``frame_call.FrameArrays``); ``component``, ``anchor``: the
    world poses of the team's component and anchor (``team_world_poses``: this frame's, or
    the build's for quality mode's build reset). The functions of this chain take the frame's
    arrays as one object and the poses as values: called for every lane of every frame, each
    array argument would cost numba a reference count it cannot prune (docs/BENCHMARKS.md,
    session 30). ``since_last_step``: team time (s) from the last step to the start of this
    frame; quality mode uses it to read the stabilisation ramp, which C.3 advances per step,
    in continuous time (the ramp at the frame's start, not at the last step before it)."""
    cpos, crot, cscl = component
    ratio = component_pose_lane(F, b, l, cpos, crot, cscl)
    center_pos, center_rot = center_pose_lane(F, b, l, cpos, crot)
    put1(F.TS, b, st.LENGTH_UNIT, l, length_unit(F.P[b, PRM_QUALITY], get3(F.TM, b, bk.INIT_SCALE, l)))
    inertia_lane(F, b, l, cpos, crot, cscl, ratio, center_pos, center_rot, anchor[0], anchor[1], frame_delta_time,
                 now_time_scale, skip_count, running, dt, since_last_step)


@kernel(forceinline=False)
def inertia_lane(F, b, l, cpos, crot, cscl, ratio, center_pos, center_rot, apos, arot, frame_delta_time,
                 now_time_scale, skip_count, running, dt, since_last_step):
    """C.4 for lane l's team once its component pose and center (C.2) are known: anchor
    (``apos``, ``arot``: its world pose, when the team has one), teleport, smoothing, world
    inertia, speed limits, the frame shift (see ``center_and_inertia_lane``)."""
    TS, TI, P = F.TS, F.TI, F.P
    # every value of P and TI read here, before the first branch, so that they are not held
    # to the end (docs/tech-notes.md §10)
    time_based = P[b, PRM_TIME_BASED_SMOOTHING] != 0.0
    anchor_inertia = P[b, PRM_ANCHOR_INERTIA]
    mode = int(P[b, PRM_TELEPORT_MODE])
    teleport_distance, teleport_rotation = P[b, PRM_TELEPORT_DISTANCE], P[b, PRM_TELEPORT_ROTATION]
    s = P[b, PRM_MOVEMENT_SMOOTHING]
    limit = P[b, PRM_MOVEMENT_SPEED_LIMIT]
    world_inertia = P[b, PRM_WORLD_INERTIA]
    rlimit = P[b, PRM_ROTATION_SPEED_LIMIT]
    stab = P[b, PRM_STABILIZATION_TIME]
    anchor = TI[b, bk.TI_ANCHOR + l]
    unit = get1(TS, b, st.LENGTH_UNIT, l)
    put3(TS, b, st.FRAME_WORLD_POS, l, center_pos)
    put4(TS, b, st.FRAME_WORLD_ROT, l, center_rot)
    put3(TS, b, st.FRAME_WORLD_SCALE, l, cscl)

    pivot = get3(TS, b, st.OLD_COMPONENT_POS, l)      # raw previous component position
    old_pos = pivot
    old_rot = get4(TS, b, st.OLD_COMPONENT_ROT, l)
    reset = get1(TS, b, st.RESET, l) != 0.0
    shift = False
    # 1. anchor
    anchor_delta = ZERO3
    anchor_rot = IDENTITY
    if anchor >= 0:
        if reset or get1(TS, b, st.ANCHOR_VALID, l) == 0.0:
            put3(TS, b, st.ANCHOR_COMPONENT_LOCAL_POS, l, q_rotate(q_inverse(arot), v_sub(cpos, apos)))
            put4(TS, b, st.OLD_ANCHOR_ROT, l, arot)
            put1(TS, b, st.ANCHOR_VALID, l, 1.0)
        anchor_center = v_add(apos, q_rotate(arot, get3(TS, b, st.ANCHOR_COMPONENT_LOCAL_POS, l)))
        anchor_delta = v_scale(v_sub(anchor_center, old_pos), 1.0 - anchor_inertia)
        anchor_rot = q_slerp(IDENTITY, q_from_to(get4(TS, b, st.OLD_ANCHOR_ROT, l), arot), 1.0 - anchor_inertia)
        old_pos = v_add(old_pos, anchor_delta)
        old_rot = q_mul(anchor_rot, old_rot)
        put4(TS, b, st.OLD_ANCHOR_ROT, l, arot)
        shift = True
    else:
        put1(TS, b, st.ANCHOR_VALID, l, 0.0)
    # 2. teleport
    keep = get1(TS, b, st.KEEP_TELEPORT, l) != 0.0
    if mode != 0 and not reset:
        delta = v_length(v_sub(cpos, old_pos))
        angle = math.degrees(q_angle(old_rot, crot))
        if delta >= teleport_distance * ratio * unit or angle >= teleport_rotation:
            if mode == TELEPORT_RESET:
                reset = True
                put1(TS, b, st.RESET, l, 1.0)
            elif mode == TELEPORT_KEEP:
                keep = True
                put1(TS, b, st.KEEP_TELEPORT, l, 1.0)
    # 3. movement smoothing
    smooth_delta = ZERO3
    if s >= 1e-6 and not reset and not keep:
        if time_based:
            felt = time_based_smoothing(TS, b, l, v_sub(cpos, old_pos), frame_delta_time, s,
                                        limit * ratio * unit if limit >= 0.0 else -1.0)
            smooth_pos = v_sub(cpos, felt)
        else:
            if math.isnan(get1(TS, b, st.SMOOTHING_VELOCITY, l)):  # quality switched off after a reset
                put3(TS, b, st.SMOOTHING_VELOCITY, l, ZERO3)
            if running:
                v = ZERO3
                if frame_delta_time > 0.0:
                    v = v_scale(v_sub(cpos, old_pos), 1.0 / frame_delta_time)
                if limit >= 0.0:
                    v = clamp_length(v, limit * ratio)
                a = smoothing_ratio(s)
                put3(TS, b, st.SMOOTHING_VELOCITY, l, v_lerp(get3(TS, b, st.SMOOTHING_VELOCITY, l), v, a))
            smooth_pos = v_sub(cpos, v_scale(get3(TS, b, st.SMOOTHING_VELOCITY, l), frame_delta_time))
        smooth_delta = v_sub(smooth_pos, old_pos)
        old_pos = smooth_pos
        shift = True
    # 4. reset: every history value becomes the current one
    if reset:
        put3(TS, b, st.OLD_FRAME_WORLD_POS, l, center_pos)
        put3(TS, b, st.NOW_WORLD_POS, l, center_pos)
        put3(TS, b, st.OLD_WORLD_POS, l, center_pos)
        put3(TS, b, st.OLD_FRAME_WORLD_SCALE, l, cscl)
        sv = math.nan if time_based else 0.0
        put3(TS, b, st.SMOOTHING_VELOCITY, l, (sv, sv, sv))
        put3(TS, b, st.FRAME_SHIFT_VECTOR, l, ZERO3)
        put4(TS, b, st.OLD_FRAME_WORLD_ROT, l, center_rot)
        put4(TS, b, st.NOW_WORLD_ROT, l, center_rot)
        put4(TS, b, st.OLD_WORLD_ROT, l, center_rot)
        put4(TS, b, st.FRAME_SHIFT_ROTATION, l, IDENTITY)
        put1(TS, b, st.INERTIA_SHIFT, l, 0.0)
        put1(TS, b, st.FRAME_MOVING_SPEED, l, 0.0)
        put3(TS, b, st.FRAME_MOVING_DIRECTION, l, ZERO3)
    else:
        # 5. world shift
        shift_vec = v_sub(cpos, old_pos)
        shift_rot = q_from_to(old_rot, crot)
        ms = 1.0 - world_inertia
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
                limit_s = limit * ratio * unit
                if speed > limit_s:
                    k = saturate((speed - limit_s) / speed)
                    ms = lerp(ms, 1.0, k)
                    work_pos = v_lerp(work_pos, cpos, k)
                    shift = True
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
        vw = get1(TS, b, st.VELOCITY_WEIGHT, l)
        if vw < 1.0:
            w = vw
            if time_based:
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
            put3(TS, b, st.FRAME_SHIFT_VECTOR, l, vec)
            put4(TS, b, st.FRAME_SHIFT_ROTATION, l, rot)
            put3(TS, b, st.OLD_FRAME_WORLD_POS, l,
                 shift_position(get3(TS, b, st.OLD_FRAME_WORLD_POS, l), pivot, vec, rot))
            put4(TS, b, st.OLD_FRAME_WORLD_ROT, l, q_mul(rot, get4(TS, b, st.OLD_FRAME_WORLD_ROT, l)))
            put3(TS, b, st.NOW_WORLD_POS, l, shift_position(get3(TS, b, st.NOW_WORLD_POS, l), pivot, vec, rot))
            put4(TS, b, st.NOW_WORLD_ROT, l, q_mul(rot, get4(TS, b, st.NOW_WORLD_ROT, l)))
            put1(TS, b, st.INERTIA_SHIFT, l, 1.0)
        # 6. wind bookkeeping
        speed = 0.0
        if frame_delta_time > 0.0 and now_time_scale > 1e-6:
            speed = v_length(v_sub(cpos, work_pos)) / frame_delta_time / now_time_scale
        put1(TS, b, st.FRAME_MOVING_SPEED, l, speed)
        moving = v_sub(cpos, work_pos)
        moving_length = v_length(moving)
        put3(TS, b, st.FRAME_MOVING_DIRECTION, l,
             v_scale(moving, 1.0 / moving_length) if moving_length > 1e-6 else ZERO3)
    # 7. reset consequences
    if reset or get1(TS, b, st.TIME_RESET, l) != 0.0:
        vw = 0.0 if stab > 1e-6 else 1.0
        put1(TS, b, st.VELOCITY_WEIGHT, l, vw)
        put1(TS, b, st.BLEND_WEIGHT, l, vw)


@kernel
def snap_lane_to_base_pose(PS, g, l):
    """C.5 Reset of lane l of particle slot g: every position history at this frame's
    animated pose, velocities, friction and collision normals zero (also used by the guards)."""
    pos = get3(PS, g, st.POSITION, l)
    rot = get4(PS, g, st.ROTATION, l)
    put3(PS, g, st.NEXT_POS, l, pos)
    put3(PS, g, st.OLD_POS, l, pos)
    put3(PS, g, st.BASE_POS, l, pos)
    put3(PS, g, st.OLD_POSITION, l, pos)
    put3(PS, g, st.VELOCITY_POS, l, pos)
    put3(PS, g, st.DISP_POS, l, pos)
    put3(PS, g, st.VELOCITY, l, ZERO3)
    put3(PS, g, st.REAL_VELOCITY, l, ZERO3)
    put3(PS, g, st.COLLISION_NORMAL, l, ZERO3)
    put4(PS, g, st.BASE_ROT, l, rot)
    put4(PS, g, st.OLD_ROTATION, l, rot)
    put1(PS, g, st.FRICTION, l, 0.0)
    put1(PS, g, st.STATIC_FRICTION, l, 0.0)
    put1(PS, g, st.DISPLAY_HISTORY, l, 0.0)   # quality display: no step state since the reset


@kernel
def shift_history(old_pos, old_position, disp_pos, old_rotation, velocity, pivot, vec, rot):
    """C.5 inertia shift of one particle's history but its real velocity: positions moved
    rigidly about the pivot, rotation and velocity turned (no branch: a loop vectorises)."""
    return (shift_position(old_pos, pivot, vec, rot), shift_position(old_position, pivot, vec, rot),
            shift_position(disp_pos, pivot, vec, rot), q_mul(rot, old_rotation), q_rotate(rot, velocity))


@kernel(forceinline=False)
def reset_or_shift_block(PS, TS, BI, b):
    """C.5 for the active lanes of block b: the lanes with an inertia shift move their
    particles' history rigidly, side by side (``shift_history``; the other lanes keep theirs,
    selected); then each lane with Reset snaps its particles to the base pose
    (``snap_lane_to_base_pose``)."""
    g0 = BI[b, bk.BI_G0]
    n = BI[b, bk.BI_N]
    w = bk.lane_width(BI, b)
    any_shift = False
    for l in range(w):
        any_shift = any_shift | (lane_shifts(TS, b, l))
    if any_shift:
        for g in range(g0, g0 + n):
            for l in range(w):
                shift = lane_shifts(TS, b, l)
                pivot = get3(TS, b, st.OLD_COMPONENT_POS, l)
                vec = get3(TS, b, st.FRAME_SHIFT_VECTOR, l)
                rot = get4(TS, b, st.FRAME_SHIFT_ROTATION, l)
                old_pos = get3(PS, g, st.OLD_POS, l)
                old_position = get3(PS, g, st.OLD_POSITION, l)
                disp_pos = get3(PS, g, st.DISP_POS, l)
                old_rotation = get4(PS, g, st.OLD_ROTATION, l)
                velocity = get3(PS, g, st.VELOCITY, l)
                real_velocity = get3(PS, g, st.REAL_VELOCITY, l)
                a, c_, d, r, u = shift_history(old_pos, old_position, disp_pos, old_rotation, velocity, pivot, vec,
                                               rot)
                rv = q_rotate(rot, real_velocity)
                put3(PS, g, st.OLD_POS, l, a if shift else old_pos)
                put3(PS, g, st.OLD_POSITION, l, c_ if shift else old_position)
                put3(PS, g, st.DISP_POS, l, d if shift else disp_pos)
                put4(PS, g, st.OLD_ROTATION, l, r if shift else old_rotation)
                put3(PS, g, st.VELOCITY, l, u if shift else velocity)
                put3(PS, g, st.REAL_VELOCITY, l, rv if shift else real_velocity)
    for l in range(w):
        if get1(TS, b, st.ACTIVE, l) != 0.0 and get1(TS, b, st.RESET, l) != 0.0:
            for g in range(g0, g0 + n):
                snap_lane_to_base_pose(PS, g, l)


@kernel
def lane_shifts(TS, b, l):
    """Does lane l shift its particles' history this frame (active, no Reset, a shift)?"""
    return (get1(TS, b, st.ACTIVE, l) != 0.0) & (get1(TS, b, st.RESET, l) == 0.0) & \
        (get1(TS, b, st.INERTIA_SHIFT, l) != 0.0)


@kernel(forceinline=False)
def distance_culling_lane(TS, TI, P, b, l, world_position):
    """H.1 distance culling of lane l's team: returns True when the team is beyond the culling
    length, and updates the fade weight ``DISTANCE_WEIGHT`` (1 inside, 0 at the limit).
    Straight-line (the decisions are ``culling_values``'), so that numba's reference-count
    pruning removes the counts of its arrays: it runs for every lane of every frame."""
    ref = TI[b, bk.TI_CULLING_REFERENCE + l]
    comp = TI[b, bk.TI_COMPONENT + l]
    at = max(ref, 0)   # no reference (-1): a row read and not used
    d = v_length((world_position[comp, 0] - world_position[at, 0], world_position[comp, 1] - world_position[at, 1],
                  world_position[comp, 2] - world_position[at, 2]))
    weight, culled = culling_values(P[b, PRM_CULLING_LENGTH], ref, d, P[b, PRM_CULLING_FADE_RATIO])
    put1(TS, b, st.DISTANCE_WEIGHT, l, weight)
    return culled


@kernel
def culling_values(length, ref, d, fade_ratio):
    """H.1 of one team: (fade weight, culled) at distance ``d`` (m) from its reference
    (``ref`` < 0: none) for a culling ``length`` (< 0: off) and fade ratio."""
    if length < 0.0 or ref < 0:
        return 1.0, False
    if d >= length:
        return 0.0, True
    fade = saturate(fade_ratio) * length
    return 1.0 - saturate(unlerp(length - fade, length, d)), False


@kernel(forceinline=False)
def end_frame_block(TS, TI, b, w, running):
    """A.7 for every active lane of block b: remember this frame's component and center (the
    center only where the team ran steps: ``running``, the team clocks' flags), clear the
    per-frame flags."""
    for l in range(w):
        t = TI[b, bk.TI_TEAM + l]
        if t < 0 or get1(TS, b, st.ACTIVE, l) == 0.0:
            continue
        put3(TS, b, st.OLD_COMPONENT_POS, l, get3(TS, b, st.COMPONENT_POS, l))
        put3(TS, b, st.OLD_COMPONENT_SCALE, l, get3(TS, b, st.COMPONENT_SCALE, l))
        put4(TS, b, st.OLD_COMPONENT_ROT, l, get4(TS, b, st.COMPONENT_ROT, l))
        if running[t]:
            put3(TS, b, st.OLD_FRAME_WORLD_POS, l, get3(TS, b, st.FRAME_WORLD_POS, l))
            put3(TS, b, st.OLD_FRAME_WORLD_SCALE, l, get3(TS, b, st.FRAME_WORLD_SCALE, l))
            put4(TS, b, st.OLD_FRAME_WORLD_ROT, l, get4(TS, b, st.FRAME_WORLD_ROT, l))
            put3(TS, b, st.EXTERNAL_FORCE, l, ZERO3)
            put1(TS, b, st.EXTERNAL_FORCE_MODE, l, 0.0)
        put1(TS, b, st.RESET, l, 0.0)
        put1(TS, b, st.TIME_RESET, l, 0.0)
        put1(TS, b, st.KEEP_TELEPORT, l, 0.0)
        put1(TS, b, st.INERTIA_SHIFT, l, 0.0)
        put1(TS, b, st.RUNNING, l, 0.0)
