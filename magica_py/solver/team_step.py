"""C.3, the team update at the start of a step (docs/solver.md §C.3), as one per-element function, and
its block form (every lane of a block at once, ``solver/batched``).

``team_step_values`` is the maths of ``step.team_step_update``; the per-team path
(``team_step_update``) and the block path (``team_step_block``) both call it, so both give
the same bits. A literal ``mode`` picks how it takes its slerps, angle and axis: SCALAR with
``kernels/math3d``'s branches (per team, the trigonometry is skipped where the rotations are
near), LANES branch-free (both paths computed, the one math3d takes selected: a lane loop over
it vectorises), LANES_NEAR the slerps' lerp path alone (a lane loop whose lanes were all found
near beforehand: the usual case). The branch-free twins below (``slerp_select``,
``q_angle_select``, ``rotation_axis_select``) give math3d's bits
(tests/test_batched_team_step.py).

``team_step_block`` runs in three parts: a scalar copy-in of each lane's team rows into the
lane arrays (``bs.lane_*``: a gather through ``lane_team`` does not vectorise), the lane loops
(streams of ``kernels/streams``, no runtime overlap checks), and a scalar copy-out of what the
team rows must keep (read by the next step, the per-team frame stages and the guards).
"""
from __future__ import annotations

import math

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels import trig
from magica_py.kernels.math3d import (
    lerp, q_angle, q_dot, q_from_to, q_normalize, q_rotate, q_slerp, q_to_angle_axis, saturate, slerp_is_near,
    slerp_near, v_dot, v_length, v_length_sq, v_lerp, v_scale, v_sub,
)
from magica_py.kernels.streams import READ, open_streams, sload, sload3, sload4, sstore, sstore3, sstore4
from magica_py.solver.batched.transfer import in3, in4, out3, out4

IDENTITY = (0.0, 0.0, 0.0, 1.0)


# How the per-element functions take their slerps, angles and axes (a literal at each call
# site, folded away once inlined): SCALAR with math3d's branches (per team: a branch skips the
# trigonometry where the rotations are near), LANES branch-free (a lane loop: both paths
# computed and selected), LANES_NEAR the slerps' lerp path alone (a lane loop whose lanes were
# all found near beforehand, ``math3d.slerp_is_near``). All three give the same bits.
SCALAR = 0
LANES = 1
LANES_NEAR = 2


# ----------------------------------------------------------------------------- branch-free twins
@kernel(inline="always")
def slerp_in_mode(q1, q2, t, mode):
    """``q_slerp(q1, q2, t)`` the way ``mode`` (SCALAR, LANES, LANES_NEAR; a literal) asks."""
    if mode == SCALAR:
        return q_slerp(q1, q2, t)
    if mode == LANES_NEAR:
        return slerp_near(q1, q2, t)
    return slerp_select(q1, q2, t)


@kernel
def slerp_select(q1, q2, t):
    """``q_slerp(q1, q2, t)`` with both its paths computed and the one it takes selected (the
    same bits; NaN takes the lerp path, as there)."""
    d = q_dot(q1, q2)
    flip = d < 0.0
    d = -d if flip else d
    b = (-q2[0], -q2[1], -q2[2], -q2[3]) if flip else q2
    angle = trig.acos(d)
    w1 = trig.sin((1.0 - t) * angle)
    w2 = trig.sin(t * angle)
    inv_s = 1.0 / trig.sin(angle)
    far = q_normalize((
        (q1[0] * w1 + b[0] * w2) * inv_s,
        (q1[1] * w1 + b[1] * w2) * inv_s,
        (q1[2] * w1 + b[2] * w2) * inv_s,
        (q1[3] * w1 + b[3] * w2) * inv_s,
    ))
    near = q_normalize((
        q1[0] + (b[0] - q1[0]) * t,
        q1[1] + (b[1] - q1[1]) * t,
        q1[2] + (b[2] - q1[2]) * t,
        q1[3] + (b[3] - q1[3]) * t,
    ))
    return far if d < 0.9995 else near


@kernel
def q_angle_select(a, b):
    """``q_angle(a, b)`` (radians), branch-free: the same bits."""
    d = q_dot(a, b)
    c = 1.0 if d > 1.0 else (-1.0 if d < -1.0 else d)
    ang = 2.0 * trig.acos(c)
    ang = 2.0 * math.pi - ang if ang > math.pi else ang
    return ang if abs(d) < 0.9999 else 0.0


@kernel
def rotation_axis_select(q):
    """The axis of ``q_to_angle_axis(q)`` (zero when degenerate), branch-free: the same bits."""
    a = trig.acos(q[3]) if abs(q[3]) < 0.9999 else 0.0
    s = trig.sin(a)
    axis = (q[0] / s, q[1] / s, q[2] / s)
    return (0.0, 0.0, 0.0) if abs(s) < 1e-6 else axis


# ----------------------------------------------------------------------------- per element
@kernel(inline="always")  # numba-level: too big for LLVM's inliner, and a call stops vectorisation
def team_step_values(old_pos, old_rot, old_frame_pos, frame_pos, old_frame_rot, frame_rot, old_frame_scale,
                     frame_scale, t, dt, local_inertia, move_limit, rotation_limit, init_scale_length,
                     gravity_direction, init_local_gravity, gravity, gravity_falloff, stabilization_time,
                     velocity_weight, blend_parameter, distance_weight, mode):
    """C.3 of one team; branch-free but for ``mode`` SCALAR (see above: the same bits in every
    mode; LANES_NEAR where both slerps, of the frame rotations and of the inertia rotation,
    are near). Inputs: the center's pose at the previous step (old_pos,
    old_rot = TeamState now_world_pos/rot before the step), its frame poses and scales, the frame
    interpolation t, the step dt (s), the team's parameters, ``init_scale_length`` = |build
    scale|, velocity_weight before the step. Returns (now_pos, now_rot, step_vector,
    step_rotation, move_ratio, rotation_ratio, inertia_vector, inertia_rotation,
    angular_velocity (rad/s), rotation_axis, scale_ratio, gravity_dot, gravity_ratio,
    velocity_weight, blend_weight)."""
    now_pos = v_lerp(old_frame_pos, frame_pos, t)
    now_rot = q_normalize(slerp_in_mode(old_frame_rot, frame_rot, t, mode))
    scale = v_lerp(old_frame_scale, frame_scale, t)
    step_vector = v_sub(now_pos, old_pos)
    step_rotation = q_from_to(old_rot, now_rot)
    if mode == SCALAR:
        step_angle = q_angle(old_rot, now_rot)
    else:
        step_angle = q_angle_select(old_rot, now_rot)
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
    inertia_rotation = slerp_in_mode(IDENTITY, step_rotation, rv, mode)
    # centrifugal helpers
    w = step_angle / dt
    if mode == SCALAR:
        axis = (0.0, 0.0, 0.0)
        if w > 1e-8:
            _angle, axis = q_to_angle_axis(step_rotation)
    else:
        turning_axis = rotation_axis_select(step_rotation)
        axis = turning_axis if w > 1e-8 else (0.0, 0.0, 0.0)
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


# ----------------------------------------------------------------------------- block form
@kernel
def team_step_copy_in(ts, tt, blk, bs, b):
    """Each lane's team rows into its lane arrays (the lane loop's inputs), and the previous
    step's pose into old_world_pos/rot (C.3's first stores, copies)."""
    lanes = blk.block_lane_base[b]
    for i in range(blk.block_width[b]):
        L = lanes + i
        t = blk.lane_team[L]
        for c in range(3):
            ts.old_world_pos[t, c] = ts.now_world_pos[t, c]
        for c in range(4):
            ts.old_world_rot[t, c] = ts.now_world_rot[t, c]
        bs.lane_frame_interpolation[L] = tt.frame_interpolation[t]
        in3(bs.lane_old_world_pos, L, ts.now_world_pos, t)
        in4(bs.lane_now_world_rot, L, ts.now_world_rot, t)
        in3(bs.lane_old_frame_world_pos, L, ts.old_frame_world_pos, t)
        in3(bs.lane_frame_world_pos, L, ts.frame_world_pos, t)
        in4(bs.lane_old_frame_world_rot, L, ts.old_frame_world_rot, t)
        in4(bs.lane_frame_world_rot, L, ts.frame_world_rot, t)
        in3(bs.lane_old_frame_world_scale, L, ts.old_frame_world_scale, t)
        in3(bs.lane_frame_world_scale, L, ts.frame_world_scale, t)
        bs.lane_velocity_weight[L] = ts.velocity_weight[t]
        bs.lane_distance_weight[L] = ts.distance_weight[t]
        bs.lane_external_force_mode[L] = ts.external_force_mode[t]
        in3(bs.lane_external_force, L, ts.external_force, t)


@kernel
def team_step_copy_out(ts, blk, bs, b):
    """What the team rows keep of the lane loop's results (read by the next step, the
    per-team frame stages and the guards)."""
    lanes = blk.block_lane_base[b]
    for i in range(blk.block_width[b]):
        L = lanes + i
        t = blk.lane_team[L]
        out3(ts.now_world_pos, t, bs.lane_now_world_pos, L)
        out4(ts.now_world_rot, t, bs.lane_now_world_rot, L)
        out3(ts.step_vector, t, bs.lane_step_vector, L)
        out4(ts.step_rotation, t, bs.lane_step_rotation, L)
        ts.step_move_inertia_ratio[t] = bs.lane_step_move_inertia_ratio[L]
        ts.step_rotation_inertia_ratio[t] = bs.lane_step_rotation_inertia_ratio[L]
        out3(ts.inertia_vector, t, bs.lane_inertia_vector, L)
        out4(ts.inertia_rotation, t, bs.lane_inertia_rotation, L)
        ts.angular_velocity[t] = bs.lane_angular_velocity[L]
        out3(ts.rotation_axis, t, bs.lane_rotation_axis, L)
        ts.scale_ratio[t] = bs.lane_scale_ratio[L]
        ts.gravity_dot[t] = bs.lane_gravity_dot[L]
        ts.gravity_ratio[t] = bs.lane_gravity_ratio[L]
        ts.velocity_weight[t] = bs.lane_velocity_weight[L]
        ts.blend_weight[t] = bs.lane_blend_weight[L]


@kernel
def team_step_lanes(m, prm, blk, bs, b, dt):
    """C.3 of every lane of block b on the lane arrays (after ``team_step_copy_in``); the
    parameters and build references are the exemplar's (equal in every lane by formation).

    Streams (``kernels/streams``; every access is to lane L of one lane array, arrays
    distinct): now_world_pos 1-3, now_world_rot 4-7 (read and written in place: the previous
    step's rotation in, this step's out; the previous position comes in old_world_pos), step_vector 8-10, step_rotation 11-14, move ratio
    15, rotation ratio 16, inertia_vector 17-19, inertia_rotation 20-23, angular_velocity 24,
    rotation_axis 25-27, scale_ratio 28, gravity_dot 29, gravity_ratio 30, velocity_weight 31
    (in place), blend_weight 32; the rest is read only."""
    ex = blk.block_exemplar[b]
    lanes = np.uint64(blk.block_lane_base[b])
    local_inertia = prm.local_inertia[ex]
    move_limit = prm.local_movement_speed_limit[ex]
    rotation_limit = prm.local_rotation_speed_limit[ex]
    init_scale_length = v_length((m.team_init_scale[ex, 0], m.team_init_scale[ex, 1], m.team_init_scale[ex, 2]))
    gravity_direction = (prm.gravity_direction[ex, 0], prm.gravity_direction[ex, 1], prm.gravity_direction[ex, 2])
    init_local_gravity = (m.team_init_local_gravity[ex, 0], m.team_init_local_gravity[ex, 1],
                          m.team_init_local_gravity[ex, 2])
    gravity = prm.gravity[ex]
    falloff = prm.gravity_falloff[ex]
    stabilization_time = prm.stabilization_time[ex]
    blend_parameter = prm.blend_weight[ex]
    # the block's arrays as locals (through the table their pointers are reloaded after each store)
    interpolation, old_world_pos, now_world_pos, now_world_rot = (
        bs.lane_frame_interpolation, bs.lane_old_world_pos, bs.lane_now_world_pos, bs.lane_now_world_rot)
    old_frame_pos, frame_pos, old_frame_rot, frame_rot, old_frame_scale, frame_scale = (
        bs.lane_old_frame_world_pos, bs.lane_frame_world_pos, bs.lane_old_frame_world_rot, bs.lane_frame_world_rot,
        bs.lane_old_frame_world_scale, bs.lane_frame_world_scale)
    step_vector_a, step_rotation_a, move_ratio_a, rotation_ratio_a = (
        bs.lane_step_vector, bs.lane_step_rotation, bs.lane_step_move_inertia_ratio,
        bs.lane_step_rotation_inertia_ratio)
    inertia_vector_a, inertia_rotation_a, angular_velocity_a, axis_a = (
        bs.lane_inertia_vector, bs.lane_inertia_rotation, bs.lane_angular_velocity, bs.lane_rotation_axis)
    scale_ratio_a, gravity_dot_a, gravity_ratio_a, velocity_weight_a, blend_weight_a, distance_weight_a = (
        bs.lane_scale_ratio, bs.lane_gravity_dot, bs.lane_gravity_ratio, bs.lane_velocity_weight,
        bs.lane_blend_weight, bs.lane_distance_weight)
    width = blk.block_width[b]
    # every lane's slerps near (the usual case: a step's rotations are small): their lerp path
    # alone; the inertia slerp's rotation needs the frame slerp's result (read only, no stores)
    far = 0
    for i in range(width):
        L = lanes + np.uint64(i)
        far += 0 if slerp_is_near(sload4(old_frame_rot, L, READ), sload4(frame_rot, L, READ)) else 1
    if far == 0:
        for i in range(width):
            L = lanes + np.uint64(i)
            now_rot = q_normalize(slerp_near(sload4(old_frame_rot, L, READ), sload4(frame_rot, L, READ),
                                                  sload(interpolation, L, READ)))
            far += 0 if slerp_is_near(IDENTITY, q_from_to(sload4(now_world_rot, L, READ), now_rot)) else 1
    # one lane loop per mode (a literal in each call, folded away once inlined)
    inputs = (old_world_pos, old_frame_pos, frame_pos, old_frame_rot, frame_rot, old_frame_scale, frame_scale,
              interpolation, distance_weight_a)
    outputs = (now_world_pos, now_world_rot, step_vector_a, step_rotation_a, move_ratio_a, rotation_ratio_a,
               inertia_vector_a, inertia_rotation_a, angular_velocity_a, axis_a, scale_ratio_a, gravity_dot_a,
               gravity_ratio_a, velocity_weight_a, blend_weight_a)
    params = (local_inertia, move_limit, rotation_limit, init_scale_length, gravity_direction, init_local_gravity,
              gravity, falloff, stabilization_time, blend_parameter)
    open_streams()
    if far == 0:
        for i in range(width):
            _team_step_lane(lanes + np.uint64(i), inputs, outputs, params, dt, LANES_NEAR)
    else:
        for i in range(width):
            _team_step_lane(lanes + np.uint64(i), inputs, outputs, params, dt, LANES)


@kernel(inline="always")
def _team_step_lane(L, inputs, outputs, params, dt, mode):
    """C.3 of lane L (``team_step_lanes``' loop body; its streams)."""
    (old_world_pos, old_frame_pos, frame_pos, old_frame_rot, frame_rot, old_frame_scale, frame_scale,
     interpolation, distance_weight_a) = inputs
    (now_world_pos, now_world_rot, step_vector_a, step_rotation_a, move_ratio_a, rotation_ratio_a,
     inertia_vector_a, inertia_rotation_a, angular_velocity_a, axis_a, scale_ratio_a, gravity_dot_a,
     gravity_ratio_a, velocity_weight_a, blend_weight_a) = outputs
    (local_inertia, move_limit, rotation_limit, init_scale_length, gravity_direction, init_local_gravity,
     gravity, falloff, stabilization_time, blend_parameter) = params
    (now_pos, now_rot, step_vector, step_rotation, mv, rv, inertia_vector, inertia_rotation, w, axis,
     scale_ratio, gravity_dot, gravity_ratio, velocity_weight, blend_weight) = team_step_values(
        sload3(old_world_pos, L, READ), sload4(now_world_rot, L, 4), sload3(old_frame_pos, L, READ),
        sload3(frame_pos, L, READ), sload4(old_frame_rot, L, READ), sload4(frame_rot, L, READ),
        sload3(old_frame_scale, L, READ), sload3(frame_scale, L, READ), sload(interpolation, L, READ), dt,
        local_inertia, move_limit, rotation_limit, init_scale_length, gravity_direction, init_local_gravity,
        gravity, falloff, stabilization_time, sload(velocity_weight_a, L, 31), blend_parameter,
        sload(distance_weight_a, L, READ), mode)
    sstore3(now_world_pos, L, now_pos, 1)
    sstore4(now_world_rot, L, now_rot, 4)
    sstore3(step_vector_a, L, step_vector, 8)
    sstore4(step_rotation_a, L, step_rotation, 11)
    sstore(move_ratio_a, L, mv, 15)
    sstore(rotation_ratio_a, L, rv, 16)
    sstore3(inertia_vector_a, L, inertia_vector, 17)
    sstore4(inertia_rotation_a, L, inertia_rotation, 20)
    sstore(angular_velocity_a, L, w, 24)
    sstore3(axis_a, L, axis, 25)
    sstore(scale_ratio_a, L, scale_ratio, 28)
    sstore(gravity_dot_a, L, gravity_dot, 29)
    sstore(gravity_ratio_a, L, gravity_ratio, 30)
    sstore(velocity_weight_a, L, velocity_weight, 31)
    sstore(blend_weight_a, L, blend_weight, 32)


@kernel
def team_step_block(m, prm, ts, tt, blk, bs, b, dt):
    """C.3 of every lane of block b (``step.team_step_update`` for each lane's team, the same
    bits): team rows written as there, and this step's lane values (``bs.lane_*``) filled."""
    team_step_copy_in(ts, tt, blk, bs, b)
    team_step_lanes(m, prm, blk, bs, b, dt)
    team_step_copy_out(ts, blk, bs, b)
