"""One simulation step's team update and particle stages (docs/solver.md §A.6/§C.3, §D.1, §D.2, §D.10).

``team_step_block`` runs after the runtime's ``team_time_begin_step`` (A.6: now_update_time,
frame_interpolation) and interpolates the center, derives local inertia, gravity falloff and
the stabilisation weights (C.3) of one lane's team. ``predict_block`` is D.1,
``step_basic_pose_block`` D.2 and ``end_step_block`` D.10, over one block (particles, then
lanes innermost: solver/lanes.py). The per-particle maths are separate functions (``predict_move``,
``basic_pose_child``, ``end_step_velocity``, ...), branch-free where a select is as cheap as a
branch, so that the particle loops can vectorise.
"""
from __future__ import annotations

import math

import numpy as np

from magica_py.build.proxy import MOVE
from magica_py.jit import kernel
from magica_py.kernels.math3d import (
    lerp, q_angle, q_from_to, q_to_angle_axis,
    clamp_length, depth_mass, project_on_plane, q_mul,
    q_normalize, q_normalize_select, q_rotate, q_slerp, q_slerp_along, q_slerp_path, q_slerp_select, saturate,
    v_add, v_cross, v_dot, v_length, v_length_sq, v_lerp, v_mul, v_normalize, v_scale, v_sub,
)
from magica_py.solver import blocks as bk
from magica_py.solver import state as st
from magica_py.solver.lanes import LANES, get1, get3, get4, put1, put3, put4
from magica_py.solver.parameters import (
    PRM_BLEND_WEIGHT, PRM_CENTRIFUGAL_ACCELERATION, PRM_DEPTH_INERTIA, PRM_FRICTION, PRM_GRAVITY,
    PRM_GRAVITY_DIRECTION, PRM_GRAVITY_FALLOFF, PRM_LOCAL_INERTIA, PRM_LOCAL_MOVEMENT_SPEED_LIMIT,
    PRM_LOCAL_ROTATION_SPEED_LIMIT, PRM_ANIMATION_POSE_RATIO, PRM_PARTICLE_SPEED_LIMIT, PRM_RATE_MODE,
    PRM_STABILIZATION_TIME, PRM_USE_ANGLE_LIMIT, PRM_USE_BACKSTOP, PRM_USE_MAX_DISTANCE,
    clamp01, step_keep, step_rate, step_share,
)

IDENTITY = (0.0, 0.0, 0.0, 1.0)
FRICTION_DAMPING_RATE = 0.6
STATIC_FRICTION_GAIN = 0.04
STATIC_FRICTION_LOSS = 0.05
CENTRIFUGAL_SCALE = 0.02
BASIC_POSE_KEPT = 0.99    # D.2: above this animation_pose_ratio the step keeps the animated pose
BASIC_POSE_BLEND = 1e-8   # D.2: above this ratio the rebuilt rest shape is blended to the animated pose


@kernel(inline="always")
def team_step_values(old_pos, old_rot, old_frame_pos, frame_pos, old_frame_rot, frame_rot, old_frame_scale,
                     frame_scale, t, dt, local_inertia, move_limit, rotation_limit, init_scale_length,
                     gravity_direction, init_local_gravity, gravity, gravity_falloff, stabilization_time,
                     velocity_weight, blend_parameter, distance_weight):
    """C.3 of one team (docs/solver.md §C.3). Inputs: the center's pose at the previous step (old_pos,
    old_rot = TeamState now_world_pos/rot before the step), its frame poses and scales, the frame
    interpolation t, the step dt (s), the team's parameters, ``init_scale_length`` = |build
    scale|, velocity_weight before the step. Returns (now_pos, now_rot, step_vector,
    step_rotation, move_ratio, rotation_ratio, inertia_vector, inertia_rotation,
    angular_velocity (rad/s), rotation_axis, scale_ratio, gravity_dot, gravity_ratio,
    velocity_weight, blend_weight)."""
    now_pos = v_lerp(old_frame_pos, frame_pos, t)
    now_rot = q_normalize(q_slerp(old_frame_rot, frame_rot, t))
    scale = v_lerp(old_frame_scale, frame_scale, t)
    step_vector = v_sub(now_pos, old_pos)
    step_rotation = q_from_to(old_rot, now_rot)
    step_angle = q_angle(old_rot, now_rot)
    # local inertia: (1 - ratio) of the step motion is removed rigidly; over a speed limit the
    # felt speed is brought down to it
    mv = 1.0 - local_inertia
    rv = 1.0 - local_inertia
    felt = v_length(step_vector) * (1.0 - mv) / dt
    limited = lerp(1.0, mv, move_limit / felt)
    mv = limited if (move_limit >= 0.0 and felt > move_limit) else mv
    felt = math.degrees(step_angle * (1.0 - rv) / dt)
    limited = lerp(1.0, rv, rotation_limit / felt)
    rv = limited if (rotation_limit >= 0.0 and felt > rotation_limit) else rv
    inertia_vector = v_scale(step_vector, mv)
    inertia_rotation = q_slerp(IDENTITY, step_rotation, rv)
    # centrifugal helpers
    w = step_angle / dt
    axis = (0.0, 0.0, 0.0)
    if w > 1e-8:
        _angle, axis = q_to_angle_axis(step_rotation)
    ratio_of_scale = v_length(scale) / init_scale_length
    scale_ratio = max(ratio_of_scale if init_scale_length > 0.0 else 1.0, 1e-6)
    # gravity falloff
    f = q_rotate(now_rot, init_local_gravity)
    facing = saturate(v_dot(f, gravity_direction) * 0.5 + 0.5)
    gravity_dot = facing if v_length_sq(gravity_direction) > 1e-8 else 1.0
    falling = lerp(saturate(1.0 - gravity_falloff), 1.0, saturate(1.0 - gravity_dot))
    gravity_ratio = falling if (gravity > 1e-6 and gravity_falloff > 1e-6) else 1.0
    # stabilisation after a reset, then the blend weight
    rise = dt / stabilization_time if stabilization_time > 1e-6 else 1.0
    stabilising = saturate(velocity_weight + rise)
    velocity_weight = stabilising if velocity_weight < 1.0 else velocity_weight
    blend_weight = saturate(velocity_weight * blend_parameter * distance_weight)
    return (now_pos, now_rot, step_vector, step_rotation, mv, rv, inertia_vector, inertia_rotation, w, axis,
            scale_ratio, gravity_dot, gravity_ratio, velocity_weight, blend_weight)


@kernel(forceinline=False)
def team_step_block(TS, TM, P, b, w, dt):
    """C.3 for the team of each of block b's first ``w`` lanes at the start of a step (the
    maths: ``team_step_values``), at its frame interpolation of this step
    (``FRAME_INTERPOLATION``, written by the step's A.6). The lane loop is here so that numba
    counts the array arguments once a block, not once a lane."""
    for l in range(w):
        old_pos = get3(TS, b, st.NOW_WORLD_POS, l)
        old_rot = get4(TS, b, st.NOW_WORLD_ROT, l)
        put3(TS, b, st.OLD_WORLD_POS, l, old_pos)
        put4(TS, b, st.OLD_WORLD_ROT, l, old_rot)
        unit = get1(TS, b, st.LENGTH_UNIT, l)
        (now_pos, now_rot, step_vector, step_rotation, mv, rv, inertia_vector, inertia_rotation, angular_velocity, axis,
         scale_ratio, gravity_dot, gravity_ratio, velocity_weight, blend_weight) = team_step_values(
            old_pos, old_rot, get3(TS, b, st.OLD_FRAME_WORLD_POS, l), get3(TS, b, st.FRAME_WORLD_POS, l),
            get4(TS, b, st.OLD_FRAME_WORLD_ROT, l), get4(TS, b, st.FRAME_WORLD_ROT, l),
            get3(TS, b, st.OLD_FRAME_WORLD_SCALE, l), get3(TS, b, st.FRAME_WORLD_SCALE, l),
            get1(TS, b, st.FRAME_INTERPOLATION, l), dt,
            P[b, PRM_LOCAL_INERTIA], P[b, PRM_LOCAL_MOVEMENT_SPEED_LIMIT] * unit, P[b, PRM_LOCAL_ROTATION_SPEED_LIMIT],
            v_length(get3(TM, b, bk.INIT_SCALE, l)),
            (P[b, PRM_GRAVITY_DIRECTION], P[b, PRM_GRAVITY_DIRECTION + 1], P[b, PRM_GRAVITY_DIRECTION + 2]),
            get3(TM, b, bk.INIT_LOCAL_GRAVITY, l), P[b, PRM_GRAVITY], P[b, PRM_GRAVITY_FALLOFF],
            P[b, PRM_STABILIZATION_TIME], get1(TS, b, st.VELOCITY_WEIGHT, l), P[b, PRM_BLEND_WEIGHT],
            get1(TS, b, st.DISTANCE_WEIGHT, l))
        put3(TS, b, st.NOW_WORLD_POS, l, now_pos)
        put4(TS, b, st.NOW_WORLD_ROT, l, now_rot)
        put3(TS, b, st.STEP_VECTOR, l, step_vector)
        put4(TS, b, st.STEP_ROTATION, l, step_rotation)
        put1(TS, b, st.STEP_MOVE_INERTIA_RATIO, l, mv)
        put1(TS, b, st.STEP_ROTATION_INERTIA_RATIO, l, rv)
        put3(TS, b, st.INERTIA_VECTOR, l, inertia_vector)
        put4(TS, b, st.INERTIA_ROTATION, l, inertia_rotation)
        if P[b, PRM_DEPTH_INERTIA] != 0.0:   # what D.1's depth-inertia slerp needs of the lane, once a step
            slerp_to, slerp_angle, slerp_inv_sin, slerp_far = q_slerp_path(inertia_rotation, step_rotation)
            put4(TS, b, st.INERTIA_SLERP_TO, l, slerp_to)
            put1(TS, b, st.INERTIA_SLERP_ANGLE, l, slerp_angle)
            put1(TS, b, st.INERTIA_SLERP_INV_SIN, l, slerp_inv_sin)
            put1(TS, b, st.INERTIA_SLERP_FAR, l, slerp_far)
        put1(TS, b, st.ANGULAR_VELOCITY, l, angular_velocity)
        put3(TS, b, st.ROTATION_AXIS, l, axis)
        put1(TS, b, st.SCALE_RATIO, l, scale_ratio)
        put1(TS, b, st.GRAVITY_DOT, l, gravity_dot)
        put1(TS, b, st.GRAVITY_RATIO, l, gravity_ratio)
        put1(TS, b, st.VELOCITY_WEIGHT, l, velocity_weight)
        put1(TS, b, st.BLEND_WEIGHT, l, blend_weight)


@kernel
def predict_base_pose(old_position, position, old_rotation, rotation, t):
    """D.1's animated pose of a particle at frame interpolation t: (base_pos, base_rot)."""
    base_pos = v_lerp(old_position, position, t)
    # at the last step of a frame (t == 1) the rotation is taken as is
    if t == 1.0:
        return base_pos, rotation
    return base_pos, q_normalize(q_slerp(old_rotation, rotation, t))


@kernel
def predict_move(old_pos, velocity, depth, old_world_pos, inertia_vector, inertia_rotation, step_vector,
                 step_rotation, depth_inertia, velocity_weight, damping_keep, gravity, force_mode, impact,
                 scale, dt):
    """D.1 for a Move particle: (velocity, velocity_pos, next_pos) after the inertia shift,
    damping (``damping_keep`` = saturate(1 - step rate of the damping curve)) and forces."""
    k = depth_inertia * (1.0 - depth * depth)
    # depth inertia off (k == 0): the lerp and slerp at 0 are the first argument
    iv = inertia_vector
    iq = inertia_rotation
    if k != 0.0:
        iv = v_lerp(inertia_vector, step_vector, k)
        iq = q_slerp(inertia_rotation, step_rotation, k)
    return predict_move_shifted(old_pos, velocity, depth, old_world_pos, iv, iq, velocity_weight,
                                damping_keep, gravity, force_mode, impact, scale, dt)


@kernel
def predict_move_shifted(old_pos, velocity, depth, old_world_pos, iv, iq, velocity_weight, damping_keep,
                         gravity, force_mode, impact, scale, dt):
    """``predict_move`` after the depth-inertia mix: the inertia shift (iv, iq), damping, forces."""
    w = v_add(v_add(old_world_pos, q_rotate(iq, v_sub(old_pos, old_world_pos))), iv)
    velocity_pos = w  # old_pos + (w - old_pos)
    velocity = q_rotate(iq, velocity)
    velocity = v_scale(velocity, velocity_weight)
    velocity = v_scale(velocity, damping_keep)
    # external force modes: 1 add (/ depth mass), 2 add, 3 change (/ depth mass), 4 change
    change = force_mode == 3 or force_mode == 4
    velocity = (0.0, 0.0, 0.0) if change else velocity
    with_depth = v_add(gravity, v_scale(impact, 1.0 / depth_mass(depth)))
    without_depth = v_add(gravity, impact)
    mode_force = with_depth if (force_mode == 1 or force_mode == 3) else without_depth
    force = gravity if force_mode == 0 else mode_force
    force = v_scale(force, scale)
    velocity = v_add(velocity, v_scale(force, dt))
    return velocity, velocity_pos, v_add(w, v_scale(velocity, dt))


@kernel
def damping_keep(damping, frequency_ratio, power_z, rate_mode):
    """D.1's velocity factor of a particle whose damping curve value is ``damping``:
    saturate(1 - step rate of the clamped damping)."""
    return saturate(1.0 - step_rate(clamp01(damping), frequency_ratio, power_z, rate_mode))


@kernel(forceinline=False)
def predict_block(PS, PM, PP, TS, P, BI, topology, b, dt, frequency_ratio, power_z):
    """D.1 over block b: animated pose at this step, inertia shift, damping, forces,
    prediction (each lane at its own frame interpolation). The lane loops take the
    branch-free forms (``*_select``: the same bits); where every lane is at the frame's last
    step (t = 1) the animated rotation needs no slerp, and without depth inertia the step's
    inertia needs no mix: those loops leave that work out. A moving particle's animated
    rotation at this step is computed only where a later stage of the step reads it
    (``moving_rotation_read``); its position always is."""
    g0 = BI[b, bk.BI_G0]
    w = bk.lane_width(BI, b)
    attribute = BI[b, bk.BI_ATTRIBUTE]
    moving_rotation = moving_rotation_read(P, b)
    depth_inertia = P[b, PRM_DEPTH_INERTIA]
    g_dir = (P[b, PRM_GRAVITY_DIRECTION], P[b, PRM_GRAVITY_DIRECTION + 1], P[b, PRM_GRAVITY_DIRECTION + 2])
    g_mag = P[b, PRM_GRAVITY]
    rate_mode = int(P[b, PRM_RATE_MODE])
    last = True   # every lane at t = 1
    for l in range(w):
        last = last & (get1(TS, b, st.FRAME_INTERPOLATION, l) == 1.0)
    for j in range(BI[b, bk.BI_N]):
        g = g0 + j
        move = (topology[attribute + j] & MOVE) != 0
        if last:
            for l in range(w):
                base_pos = v_lerp(get3(PS, g, st.OLD_POSITION, l), get3(PS, g, st.POSITION, l), 1.0)
                put3(PS, g, st.BASE_POS, l, base_pos)
                put3(PS, g, st.STEP_BASIC_POS, l, base_pos)
            if moving_rotation or not move:
                for l in range(w):
                    put4(PS, g, st.BASE_ROT, l, get4(PS, g, st.ROTATION, l))
                    put4(PS, g, st.STEP_BASIC_ROT, l, get4(PS, g, st.ROTATION, l))
        elif move and not moving_rotation:
            for l in range(w):
                base_pos = v_lerp(get3(PS, g, st.OLD_POSITION, l), get3(PS, g, st.POSITION, l),
                                  get1(TS, b, st.FRAME_INTERPOLATION, l))
                put3(PS, g, st.BASE_POS, l, base_pos)
                put3(PS, g, st.STEP_BASIC_POS, l, base_pos)
        else:
            for l in range(w):
                t = get1(TS, b, st.FRAME_INTERPOLATION, l)
                rotation = get4(PS, g, st.ROTATION, l)
                base_pos = v_lerp(get3(PS, g, st.OLD_POSITION, l), get3(PS, g, st.POSITION, l), t)
                slerped = q_normalize_select(q_slerp_select(get4(PS, g, st.OLD_ROTATION, l), rotation, t))
                base_rot = rotation if t == 1.0 else slerped   # predict_base_pose's paths
                put3(PS, g, st.BASE_POS, l, base_pos)
                put4(PS, g, st.BASE_ROT, l, base_rot)
                put3(PS, g, st.STEP_BASIC_POS, l, base_pos)
                put4(PS, g, st.STEP_BASIC_ROT, l, base_rot)
        if not move:
            for l in range(w):
                base_pos = get3(PS, g, st.BASE_POS, l)
                put3(PS, g, st.NEXT_POS, l, base_pos)
                put3(PS, g, st.VELOCITY_POS, l, base_pos)
            continue
        # the damping's rate conversion needs a power only in frequency-consistent mode off
        # 90 Hz: elsewhere the ratio goes in as the constant 1.0, which takes the power (a call
        # LLVM cannot see into, that would keep the lane loop scalar) out of the compiled loop;
        # the depth-inertia mix (a slerp a lane) goes in as a constant too: a branch on the
        # block's value inside the lane loop would be computed for every lane and selected
        ratio_one = rate_mode == 0 or frequency_ratio == 1.0
        if depth_inertia != 0.0:
            if ratio_one:
                predict_move_lanes(PS, PM, PP, TS, b, g, w, np.bool_(True), depth_inertia, g_dir, g_mag, 1.0,
                                   power_z, rate_mode, dt)
            else:
                predict_move_lanes(PS, PM, PP, TS, b, g, w, np.bool_(True), depth_inertia, g_dir, g_mag,
                                   frequency_ratio, power_z, rate_mode, dt)
        elif ratio_one:
            predict_move_lanes(PS, PM, PP, TS, b, g, w, np.bool_(False), depth_inertia, g_dir, g_mag, 1.0,
                               power_z, rate_mode, dt)
        else:
            predict_move_lanes(PS, PM, PP, TS, b, g, w, np.bool_(False), depth_inertia, g_dir, g_mag,
                               frequency_ratio, power_z, rate_mode, dt)


@kernel(inline="always")
def moving_rotation_read(P, b):
    """Does a stage of this step read a moving particle's animated rotation as D.1 leaves it
    (``BASE_ROT``, ``STEP_BASIC_ROT``)? D.2 rebuilds each moving baseline entry's
    ``STEP_BASIC_ROT`` from the fixed start's (reading no moving particle's D.1 rotation), then,
    with the animation pose ratio above 1e-8, slerps it towards ``BASE_ROT`` (above 0.99 it
    keeps D.1's instead). Of the stages after it only the angle limit (D.5) reads
    ``STEP_BASIC_ROT``, and only the motion constraint (D.9) reads ``BASE_ROT``. So the moving
    particles' rotations are needed for the angle limit with the ratio above 1e-8 and for the
    motion constraint; elsewhere their slerp is left out. A fixed particle's rotation is always
    computed (D.2 starts each baseline from it, E.1 reads it as a display frame)."""
    limit = (P[b, PRM_USE_ANGLE_LIMIT] != 0.0) & (P[b, PRM_ANIMATION_POSE_RATIO] > BASIC_POSE_BLEND)
    motion = (P[b, PRM_USE_MAX_DISTANCE] != 0.0) | (P[b, PRM_USE_BACKSTOP] != 0.0)
    return limit | motion


@kernel
def predict_move_lanes(PS, PM, PP, TS, b, g, w, mix, depth_inertia, g_dir, g_mag, frequency_ratio, power_z,
                       rate_mode, dt):
    """D.1's inertia shift, damping, forces and prediction of the moving particle in slot g,
    every lane of block b. ``mix``: the block's depth inertia is not 0 (a constant at each call
    site, so that without it the mix's slerp is not compiled into the loop)."""
    for l in range(min(w, LANES)):
        depth = get1(PM, g, bk.DEPTH, l)
        gravity = v_scale(g_dir, g_mag * get1(TS, b, st.GRAVITY_RATIO, l))
        scale = get1(TS, b, st.SCALE_RATIO, l) * get1(TS, b, st.LENGTH_UNIT, l)   # forces follow the scale
        iv = get3(TS, b, st.INERTIA_VECTOR, l)
        iq = get4(TS, b, st.INERTIA_ROTATION, l)
        if mix:   # predict_move's depth-inertia mix, where k != 0
            k = depth_inertia * (1.0 - depth * depth)
            mixed_v = v_lerp(iv, get3(TS, b, st.STEP_VECTOR, l), k)
            mixed_q = q_slerp_along(iq, get4(TS, b, st.INERTIA_SLERP_TO, l), get1(TS, b, st.INERTIA_SLERP_ANGLE, l),
                                    get1(TS, b, st.INERTIA_SLERP_INV_SIN, l), get1(TS, b, st.INERTIA_SLERP_FAR, l), k)
            iv = mixed_v if k != 0.0 else iv
            iq = mixed_q if k != 0.0 else iq
        velocity, velocity_pos, next_pos = predict_move_shifted(
            get3(PS, g, st.OLD_POS, l), get3(PS, g, st.VELOCITY, l), depth, get3(TS, b, st.OLD_WORLD_POS, l),
            iv, iq, get1(TS, b, st.VELOCITY_WEIGHT, l),
            damping_keep(get1(PP, g, bk.CURVE_DAMPING, l), frequency_ratio, power_z, rate_mode), gravity,
            int(get1(TS, b, st.EXTERNAL_FORCE_MODE, l)), get3(TS, b, st.EXTERNAL_FORCE, l), scale, dt)
        put3(PS, g, st.VELOCITY, l, velocity)
        put3(PS, g, st.VELOCITY_POS, l, velocity_pos)
        put3(PS, g, st.NEXT_POS, l, next_pos)


@kernel(inline="always")
def basic_pose_child(parent_pos, parent_rot, local_position, local_rotation, scale):
    """D.2: a baseline child's rest pose placed on its parent's (scale = build scale x scale ratio)."""
    pos = v_add(q_rotate(parent_rot, v_mul(local_position, scale)), parent_pos)
    return pos, q_mul(parent_rot, local_rotation)


@kernel(inline="always")
def basic_pose_blend(pos, rot, base_pos, base_rot, ratio):
    """D.2: the rest shape blended towards the animated pose by animation_pose_ratio."""
    return v_lerp(pos, base_pos, ratio), q_slerp(rot, base_rot, ratio)


@kernel(forceinline=False)
def step_basic_pose_block(PS, PM, TS, TM, P, BI, topology, b):
    """D.2 over block b: rebuild the rest shape along each baseline and blend it to the
    animated pose."""
    a = P[b, PRM_ANIMATION_POSE_RATIO]
    g0 = BI[b, bk.BI_G0]
    w = bk.lane_width(BI, b)
    parent = BI[b, bk.BI_PARENT]
    bl_start, bl_count, bl_data = BI[b, bk.BI_BASELINE_START], BI[b, bk.BI_BASELINE_COUNT], BI[b, bk.BI_BASELINE_DATA]
    lines = BI[b, bk.BI_BASELINES]
    if a > BASIC_POSE_KEPT:   # the step keeps the animated pose (no early return: docs/tech-notes.md §10)
        lines = 0
    for line in range(lines):
        e0 = topology[bl_start + line]
        e1 = e0 + topology[bl_count + line]
        for e in range(e0 + 1, e1):
            v = topology[bl_data + e]
            gv = g0 + v
            gp = g0 + topology[parent + v]
            for l in range(w):
                s = v_scale(get3(TM, b, bk.INIT_SCALE, l), get1(TS, b, st.SCALE_RATIO, l))
                pos, rot = basic_pose_child(get3(PS, gp, st.STEP_BASIC_POS, l), get4(PS, gp, st.STEP_BASIC_ROT, l),
                                            get3(PM, gv, bk.BASELINE_LOCAL_POSITION, l),
                                            get4(PM, gv, bk.BASELINE_LOCAL_ROTATION, l), s)
                put3(PS, gv, st.STEP_BASIC_POS, l, pos)
                put4(PS, gv, st.STEP_BASIC_ROT, l, rot)
        if a > BASIC_POSE_BLEND:
            for e in range(e0, e1):
                gv = g0 + topology[bl_data + e]
                for l in range(w):
                    pos, rot = basic_pose_blend(get3(PS, gv, st.STEP_BASIC_POS, l), get4(PS, gv, st.STEP_BASIC_ROT, l),
                                                get3(PS, gv, st.BASE_POS, l), get4(PS, gv, st.BASE_ROT, l), a)
                    put3(PS, gv, st.STEP_BASIC_POS, l, pos)
                    put4(PS, gv, st.STEP_BASIC_ROT, l, rot)


@kernel
def static_friction_step(next_pos, old_pos, velocity_pos, normal, static_friction, dt, static_threshold, gain,
                         loss_scale):
    """D.10 static friction of a particle in contact: its tangential move this step is cancelled
    by the static friction factor, which grows while the particle holds (tangential speed below
    the threshold) and drops as it slips (by ``max((speed - threshold) / 0.2, 0.05)`` per step
    at 90 Hz, times ``loss_scale``: 1 in MagicaCloth2 mode, 90/f in frequency-consistent
    mode). Returns (next_pos, velocity_pos, static_friction)."""
    d = v_sub(next_pos, old_pos)
    tv = v_sub(d, v_scale(normal, v_dot(d, normal)))
    speed = v_length(tv) / dt
    held = saturate(static_friction + gain)
    slipping = saturate(static_friction - max((speed - static_threshold) / 0.2, STATIC_FRICTION_LOSS) * loss_scale)
    sf = held if speed < static_threshold else slipping
    return v_sub(next_pos, v_scale(tv, sf)), v_sub(velocity_pos, v_scale(tv, sf)), sf


@kernel
def end_step_velocity(next_pos, velocity_pos, dt):
    """D.10 velocity of a Move particle from its positions: (velocity, unit direction (0 when
    not moving), moving). Branch-free."""
    vel = v_scale(v_sub(next_pos, velocity_pos), 1.0 / dt)
    speed_sq = v_length_sq(vel)
    moving = speed_sq >= 1e-8
    unit = v_scale(vel, 1.0 / np.sqrt(max(speed_sq, 1e-300)))   # at rest: discarded by the select
    return vel, (unit if moving else (0.0, 0.0, 0.0)), moving


@kernel
def dynamic_friction_share(direction, normal, friction, dynamic_friction):
    """D.10: the share of a moving particle's velocity dynamic friction removes in a step at
    90 Hz: none moving straight away from the surface, ``friction x dynamic_friction`` along it."""
    dd = 0.5 + 0.5 * v_dot(normal, direction)
    dd = 1.0 - dd * dd
    return dd * saturate(friction * dynamic_friction)


@kernel
def dynamic_friction_brake(vel, direction, normal, friction, dynamic_friction):
    """D.10 dynamic friction of a moving particle in contact: brakes motion along the surface,
    not away from it."""
    return v_sub(vel, v_scale(vel, dynamic_friction_share(direction, normal, friction, dynamic_friction)))


@kernel
def dynamic_friction_keep(vel, direction, normal, friction, dynamic_friction, frequency_ratio):
    """``dynamic_friction_brake`` in frequency-consistent mode: the share of the velocity the
    brake keeps in a step, ``1 - share`` at 90 Hz, is a per-step retention, converted as
    ``keep^(90/f)`` (``step_keep``)."""
    keep = 1.0 - dynamic_friction_share(direction, normal, friction, dynamic_friction)
    return v_scale(vel, step_keep(keep, frequency_ratio, np.int64(1)))


@kernel
def centrifugal_velocity(vel, next_pos, direction, moving, depth, angular_velocity, centrifugal, axis, center):
    """D.10 centrifugal term: outwards from the team's rotation axis through its center, scaled
    by how much the particle moves along the rotation (none when not rotating, not moving or on
    the axis). Branch-free."""
    lv = project_on_plane(v_sub(next_pos, center), axis)
    radius = v_length(lv)
    n = v_scale(lv, 1.0 / max(radius, 1e-300))   # on the axis: discarded by the select
    mass = 1.0 + (1.0 - depth)
    force = mass * angular_velocity * angular_velocity * radius
    u = v_normalize(v_cross(axis, n))
    force *= saturate(v_dot(direction, u))
    flung = v_add(vel, v_scale(n, force * centrifugal * CENTRIFUGAL_SCALE))
    return flung if (angular_velocity > 1e-8 and centrifugal > 1e-8 and moving and radius > 1e-8) else vel


@kernel(forceinline=False)
def end_step_block(PS, PM, TS, P, BI, topology, b, dt, frequency_ratio):
    """D.10 over block b: velocity from positions, static and dynamic friction, speed limit,
    centrifugal term."""
    g0 = BI[b, bk.BI_G0]
    w = bk.lane_width(BI, b)
    attribute = BI[b, bk.BI_ATTRIBUTE]
    mode = int(P[b, PRM_RATE_MODE])
    dynamic = P[b, PRM_FRICTION]
    speed_limit = P[b, PRM_PARTICLE_SPEED_LIMIT]
    centrifugal_parameter = P[b, PRM_CENTRIFUGAL_ACCELERATION]
    # frequency-consistent and quality modes convert the per-step amounts of D.10 by the step:
    # the centrifugal velocity increment and the static-friction loss scale with 90/f, the
    # dynamic-friction brake's kept share becomes a retention keep^(90/f) (per step, the brake
    # would grow per second with f and the motion would not converge as the step shrinks,
    # docs/quality-mode.md *Convergence*); MagicaCloth2 mode and 90 Hz keep the bits
    consistent = mode != 0 and frequency_ratio != 1.0
    loss_scale = frequency_ratio if consistent else 1.0
    centrifugal = step_share(centrifugal_parameter, frequency_ratio, mode) if consistent else centrifugal_parameter
    friction_keep = step_keep(FRICTION_DAMPING_RATE, frequency_ratio, mode)
    gain = step_rate(STATIC_FRICTION_GAIN, frequency_ratio, 1.0, mode)
    # friction (static and dynamic), the particle speed limit and the centrifugal term act only
    # with their parameter set; without any of them the lane loop leaves their paths out
    extras = dynamic > 0.0 or speed_limit >= 0.0 or centrifugal > 1e-8
    for j in range(BI[b, bk.BI_N]):
        g = g0 + j
        if (topology[attribute + j] & MOVE) == 0:
            for l in range(w):
                next_pos = get3(PS, g, st.NEXT_POS, l)
                put3(PS, g, st.REAL_VELOCITY, l, v_scale(v_sub(next_pos, get3(PS, g, st.OLD_POS, l)), 1.0 / dt))
                put3(PS, g, st.OLD_POS, l, next_pos)
            continue
        # the consistent brake's pow (an opaque call that keeps a loop scalar) is left out of
        # the compiled loop by a constant argument where it cannot apply (a plain bool, which
        # LLVM folds after inlining: one compile for both, docs/tech-notes.md §7); so are the
        # extras' paths where the block has none (tested in the lane loop, a branch on a block's
        # value is computed for every lane and its result selected)
        if consistent:
            if extras:
                end_step_lanes(PS, PM, TS, g, b, w, dt, frequency_ratio, np.bool_(True), np.bool_(True), dynamic,
                               speed_limit, centrifugal, friction_keep, gain, loss_scale)
            else:
                end_step_lanes(PS, PM, TS, g, b, w, dt, frequency_ratio, np.bool_(True), np.bool_(False), dynamic,
                               speed_limit, centrifugal, friction_keep, gain, loss_scale)
        elif extras:
            end_step_lanes(PS, PM, TS, g, b, w, dt, 1.0, np.bool_(False), np.bool_(True), dynamic, speed_limit,
                           centrifugal, friction_keep, gain, loss_scale)
        else:
            end_step_lanes(PS, PM, TS, g, b, w, dt, 1.0, np.bool_(False), np.bool_(False), dynamic, speed_limit,
                           centrifugal, friction_keep, gain, loss_scale)


@kernel
def end_step_lanes(PS, PM, TS, g, b, w, dt, frequency_ratio, consistent, extras, dynamic, speed_limit, centrifugal,
                   friction_keep, gain, loss_scale):
    """``end_step_block`` of the Move particle in slot g of block b, lanes 0..w. ``extras``
    (a constant at each call site): the block has friction, a particle speed limit or a
    centrifugal acceleration; without, their paths are not compiled into the loop."""
    for l in range(w):
        scale = get1(TS, b, st.SCALE_RATIO, l) * get1(TS, b, st.LENGTH_UNIT, l)
        static_threshold = dynamic * scale
        angular_velocity = get1(TS, b, st.ANGULAR_VELOCITY, l)
        next_pos = get3(PS, g, st.NEXT_POS, l)
        old_pos = get3(PS, g, st.OLD_POS, l)
        cn = get3(PS, g, st.COLLISION_NORMAL, l)
        f = get1(PS, g, st.FRICTION, l)
        contact = v_length_sq(cn) > 1e-8 and f > 1e-8
        velocity_pos = get3(PS, g, st.VELOCITY_POS, l)
        static_friction = get1(PS, g, st.STATIC_FRICTION, l)
        if extras and contact and static_threshold > 0.0:
            next_pos, velocity_pos, sf = static_friction_step(next_pos, old_pos, velocity_pos, cn,
                                                              static_friction, dt, static_threshold, gain,
                                                              loss_scale)
        else:
            sf = saturate(static_friction - STATIC_FRICTION_LOSS * loss_scale)
        put1(PS, g, st.STATIC_FRICTION, l, sf)
        vel, direction, moving = end_step_velocity(next_pos, velocity_pos, dt)
        if extras and moving and contact and dynamic > 0.0:
            if consistent:
                vel = dynamic_friction_keep(vel, direction, cn, f, dynamic, frequency_ratio)
            else:
                vel = dynamic_friction_brake(vel, direction, cn, f, dynamic)
        put1(PS, g, st.FRICTION, l, f * friction_keep)
        if extras and speed_limit >= 0.0:
            vel = clamp_length(vel, speed_limit * scale)
        if extras and angular_velocity > 1e-8 and centrifugal > 1e-8:
            vel = centrifugal_velocity(vel, next_pos, direction, moving, get1(PM, g, bk.DEPTH, l),
                                       angular_velocity, centrifugal, get3(TS, b, st.ROTATION_AXIS, l),
                                       get3(TS, b, st.NOW_WORLD_POS, l))
        put3(PS, g, st.VELOCITY, l, v_scale(vel, get1(TS, b, st.VELOCITY_WEIGHT, l)))
        put3(PS, g, st.REAL_VELOCITY, l, v_scale(v_sub(next_pos, old_pos), 1.0 / dt))
        put3(PS, g, st.OLD_POS, l, next_pos)
        put3(PS, g, st.NEXT_POS, l, next_pos)
