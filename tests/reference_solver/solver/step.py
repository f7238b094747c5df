"""One simulation step's team update and particle stages (docs/solver.md §A.6/§C.3, §D.1, §D.2, §D.10).

``team_step_update`` runs after the runtime's ``team_time_begin_step`` (A.6: now_update_time,
frame_interpolation) and interpolates the center, derives local inertia, gravity falloff and
the stabilisation weights (C.3). ``predict_team`` is D.1, ``step_basic_pose_team`` D.2 and
``end_step_team`` D.10. The per-particle maths are separate functions (``predict_move``,
``basic_pose_child``, ``end_step_velocity``, ...), branch-free where a select is as cheap as a
branch, so that the particle loops can vectorise.
"""
from __future__ import annotations

import math


from magica_py.jit import kernel
from magica_py.kernels.math3d import (
    lerp, q_angle, q_from_to, q_to_angle_axis,
    clamp_length, depth_mass, load3, load4, project_on_plane, q_mul,
    q_normalize, q_rotate, q_slerp, saturate, store3, store4, v_add, v_cross,
    v_dot, v_length, v_length_sq, v_lerp, v_mul, v_normalize, v_scale, v_sub,
)
from reference_solver.solver.parameters import curve_at_clamp01, length_unit, step_keep, step_rate, step_share

MOVE = 0x02
IDENTITY = (0.0, 0.0, 0.0, 1.0)
FRICTION_DAMPING_RATE = 0.6
STATIC_FRICTION_GAIN = 0.04
STATIC_FRICTION_LOSS = 0.05
CENTRIFUGAL_SCALE = 0.02


@kernel
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


@kernel
def team_step_update(m, ts, prm, frame_interpolation, team, dt):
    """C.3 for one team at the start of a step (the maths: ``team_step_values``)."""
    old_pos = load3(ts.now_world_pos, team)
    old_rot = load4(ts.now_world_rot, team)
    store3(ts.old_world_pos, team, old_pos)
    store4(ts.old_world_rot, team, old_rot)
    (now_pos, now_rot, step_vector, step_rotation, mv, rv, inertia_vector, inertia_rotation, w, axis,
     scale_ratio, gravity_dot, gravity_ratio, velocity_weight, blend_weight) = team_step_values(
        old_pos, old_rot, load3(ts.old_frame_world_pos, team), load3(ts.frame_world_pos, team),
        load4(ts.old_frame_world_rot, team), load4(ts.frame_world_rot, team),
        load3(ts.old_frame_world_scale, team), load3(ts.frame_world_scale, team), frame_interpolation, dt,
        prm.local_inertia[team], prm.local_movement_speed_limit[team] * length_unit(m, prm, team),
        prm.local_rotation_speed_limit[team],
        v_length(load3(m.team_init_scale, team)), load3(prm.gravity_direction, team),
        load3(m.team_init_local_gravity, team), prm.gravity[team], prm.gravity_falloff[team],
        prm.stabilization_time[team], ts.velocity_weight[team], prm.blend_weight[team], ts.distance_weight[team])
    store3(ts.now_world_pos, team, now_pos)
    store4(ts.now_world_rot, team, now_rot)
    store3(ts.step_vector, team, step_vector)
    store4(ts.step_rotation, team, step_rotation)
    ts.step_move_inertia_ratio[team] = mv
    ts.step_rotation_inertia_ratio[team] = rv
    store3(ts.inertia_vector, team, inertia_vector)
    store4(ts.inertia_rotation, team, inertia_rotation)
    ts.angular_velocity[team] = w
    store3(ts.rotation_axis, team, axis)
    ts.scale_ratio[team] = scale_ratio
    ts.gravity_dot[team] = gravity_dot
    ts.gravity_ratio[team] = gravity_ratio
    ts.velocity_weight[team] = velocity_weight
    ts.blend_weight[team] = blend_weight


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
def damping_keep_at(prm, team, depth, frequency_ratio, power_z):
    """D.1's velocity factor at a depth: saturate(1 - step rate of the damping curve)."""
    damp = curve_at_clamp01(prm.damping_curve, team, depth)
    return saturate(1.0 - step_rate(damp, frequency_ratio, power_z, prm.rate_mode[team]))


@kernel
def predict_team(m, ps, prm, ts, team, frame_interpolation, dt, frequency_ratio, power_z):
    """D.1: animated pose at this step, inertia shift, damping, forces, prediction."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_attribute, m_depth, m_team_particle_count = m.attribute, m.depth, m.team_particle_count
    ps_base_pos, ps_base_rot, ps_next_pos, ps_old_pos = ps.base_pos, ps.base_rot, ps.next_pos, ps.old_pos
    ps_old_position, ps_old_rotation, ps_position = ps.old_position, ps.old_rotation, ps.position
    ps_rotation, ps_step_basic_pos, ps_step_basic_rot = ps.rotation, ps.step_basic_pos, ps.step_basic_rot
    ps_velocity, ps_velocity_pos = ps.velocity, ps.velocity_pos
    t = frame_interpolation
    old_world_pos = load3(ts.old_world_pos, team)
    inertia_vector = load3(ts.inertia_vector, team)
    inertia_rotation = load4(ts.inertia_rotation, team)
    step_vector = load3(ts.step_vector, team)
    step_rotation = load4(ts.step_rotation, team)
    depth_inertia = prm.depth_inertia[team]
    velocity_weight = ts.velocity_weight[team]
    gravity = v_scale(load3(prm.gravity_direction, team), prm.gravity[team] * ts.gravity_ratio[team])
    force_mode = ts.external_force_mode[team]
    impact = load3(ts.external_force, team)
    scale = ts.scale_ratio[team] * length_unit(m, prm, team)   # forces follow the cloth's scale
    start = m.team_particle_start[team]
    for p in range(start, start + m_team_particle_count[team]):
        if t == 1.0:  # the last step of a frame: predict_base_pose's select, without the slerp
            base_pos = v_lerp(load3(ps_old_position, p), load3(ps_position, p), t)
            base_rot = load4(ps_rotation, p)
        else:
            base_pos, base_rot = predict_base_pose(load3(ps_old_position, p), load3(ps_position, p),
                                                   load4(ps_old_rotation, p), load4(ps_rotation, p), t)
        store3(ps_base_pos, p, base_pos)
        store4(ps_base_rot, p, base_rot)
        store3(ps_step_basic_pos, p, base_pos)
        store4(ps_step_basic_rot, p, base_rot)
        if (m_attribute[p] & MOVE) == 0:
            store3(ps_next_pos, p, base_pos)
            store3(ps_velocity_pos, p, base_pos)
            continue
        depth = m_depth[p]
        damping_keep = damping_keep_at(prm, team, depth, frequency_ratio, power_z)
        if depth_inertia * (1.0 - depth * depth) == 0.0:  # no depth-inertia mix: predict_move's select
            velocity, velocity_pos, next_pos = predict_move_shifted(
                load3(ps_old_pos, p), load3(ps_velocity, p), depth, old_world_pos, inertia_vector,
                inertia_rotation, velocity_weight, damping_keep, gravity, force_mode, impact, scale, dt)
        else:
            velocity, velocity_pos, next_pos = predict_move(
                load3(ps_old_pos, p), load3(ps_velocity, p), depth, old_world_pos, inertia_vector,
                inertia_rotation, step_vector, step_rotation, depth_inertia, velocity_weight,
                damping_keep, gravity, force_mode, impact, scale, dt)
        store3(ps_velocity, p, velocity)
        store3(ps_velocity_pos, p, velocity_pos)
        store3(ps_next_pos, p, next_pos)



@kernel
def basic_pose_child(parent_pos, parent_rot, local_position, local_rotation, scale):
    """D.2: a baseline child's rest pose placed on its parent's (scale = build scale x scale ratio)."""
    pos = v_add(q_rotate(parent_rot, v_mul(local_position, scale)), parent_pos)
    return pos, q_mul(parent_rot, local_rotation)


@kernel
def basic_pose_blend(pos, rot, base_pos, base_rot, ratio):
    """D.2: the rest shape blended towards the animated pose by animation_pose_ratio."""
    return v_lerp(pos, base_pos, ratio), q_slerp(rot, base_rot, ratio)


@kernel
def step_basic_pose_team(m, ps, prm, ts, team):
    """D.2: rebuild the rest shape along each baseline and blend it to the animated pose."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_baseline_count, m_baseline_data = m.baseline_count, m.baseline_data
    m_baseline_local_position, m_baseline_local_rotation = m.baseline_local_position, m.baseline_local_rotation
    m_baseline_start, m_parent, m_team_baseline_count = m.baseline_start, m.parent, m.team_baseline_count
    ps_base_pos, ps_base_rot, ps_step_basic_pos = ps.base_pos, ps.base_rot, ps.step_basic_pos
    ps_step_basic_rot = ps.step_basic_rot
    a = prm.animation_pose_ratio[team]
    if a > 0.99:
        return
    s = v_scale(load3(m.team_init_scale, team), ts.scale_ratio[team])
    b0 = m.team_baseline_start[team]
    for b in range(b0, b0 + m_team_baseline_count[team]):
        e0 = m_baseline_start[b]
        e1 = e0 + m_baseline_count[b]
        for e in range(e0 + 1, e1):
            v = m_baseline_data[e]
            p = m_parent[v]
            pos, rot = basic_pose_child(load3(ps_step_basic_pos, p), load4(ps_step_basic_rot, p),
                                        load3(m_baseline_local_position, v), load4(m_baseline_local_rotation, v), s)
            store3(ps_step_basic_pos, v, pos)
            store4(ps_step_basic_rot, v, rot)
        if a > 1e-8:
            for e in range(e0, e1):
                v = m_baseline_data[e]
                pos, rot = basic_pose_blend(load3(ps_step_basic_pos, v), load4(ps_step_basic_rot, v),
                                            load3(ps_base_pos, v), load4(ps_base_rot, v), a)
                store3(ps_step_basic_pos, v, pos)
                store4(ps_step_basic_rot, v, rot)


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
    unit = v_scale(vel, 1.0 / math.sqrt(max(speed_sq, 1e-300)))   # at rest: discarded by the select
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
    return v_scale(vel, step_keep(keep, frequency_ratio, 1))


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


@kernel
def end_step_team(m, ps, prm, ts, team, dt, frequency_ratio):
    """D.10: velocity from positions, static and dynamic friction, speed limit, centrifugal term."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_attribute, m_depth, m_team_particle_count = m.attribute, m.depth, m.team_particle_count
    ps_collision_normal, ps_friction, ps_next_pos = ps.collision_normal, ps.friction, ps.next_pos
    ps_old_pos, ps_real_velocity, ps_static_friction = ps.old_pos, ps.real_velocity, ps.static_friction
    ps_velocity, ps_velocity_pos = ps.velocity, ps.velocity_pos
    mode = prm.rate_mode[team]
    scale = ts.scale_ratio[team] * length_unit(m, prm, team)
    static_threshold = prm.friction[team] * scale
    dynamic = prm.friction[team]
    speed_limit = prm.particle_speed_limit[team]
    angular_velocity = ts.angular_velocity[team]
    centrifugal = prm.centrifugal_acceleration[team]
    spinning = angular_velocity > 1e-8 and centrifugal > 1e-8
    axis = load3(ts.rotation_axis, team)
    center = load3(ts.now_world_pos, team)
    velocity_weight = ts.velocity_weight[team]
    # frequency-consistent and quality modes convert the per-step amounts of D.10 by the step:
    # the centrifugal velocity increment and the static-friction loss scale with 90/f, the
    # dynamic-friction brake's kept share becomes a retention keep^(90/f) (per step, the brake
    # would grow per second with f and the motion would not converge as the step shrinks,
    # docs/quality-mode.md *Convergence*); MagicaCloth2 mode and 90 Hz keep the bits
    consistent = mode != 0 and frequency_ratio != 1.0
    loss_scale = frequency_ratio if consistent else 1.0
    if consistent:
        centrifugal = step_share(centrifugal, frequency_ratio, mode)
    friction_keep = step_keep(FRICTION_DAMPING_RATE, frequency_ratio, mode)
    gain = step_rate(STATIC_FRICTION_GAIN, frequency_ratio, 1.0, mode)
    start = m.team_particle_start[team]
    for p in range(start, start + m_team_particle_count[team]):
        next_pos = load3(ps_next_pos, p)
        old_pos = load3(ps_old_pos, p)
        if (m_attribute[p] & MOVE) != 0:
            cn = load3(ps_collision_normal, p)
            f = ps_friction[p]
            contact = v_length_sq(cn) > 1e-8 and f > 1e-8
            velocity_pos = load3(ps_velocity_pos, p)
            if contact and static_threshold > 0.0:
                next_pos, velocity_pos, sf = static_friction_step(next_pos, old_pos, velocity_pos, cn,
                                                                  ps_static_friction[p], dt, static_threshold, gain,
                                                                  loss_scale)
                store3(ps_next_pos, p, next_pos)
            else:
                sf = saturate(ps_static_friction[p] - STATIC_FRICTION_LOSS * loss_scale)
            ps_static_friction[p] = sf
            vel, direction, moving = end_step_velocity(next_pos, velocity_pos, dt)
            if moving and contact and dynamic > 0.0:
                if consistent:
                    vel = dynamic_friction_keep(vel, direction, cn, f, dynamic, frequency_ratio)
                else:
                    vel = dynamic_friction_brake(vel, direction, cn, f, dynamic)
            ps_friction[p] = f * friction_keep
            if speed_limit >= 0.0:
                vel = clamp_length(vel, speed_limit * scale)
            if spinning:
                vel = centrifugal_velocity(vel, next_pos, direction, moving, m_depth[p], angular_velocity,
                                           centrifugal, axis, center)
            store3(ps_velocity, p, v_scale(vel, velocity_weight))
        store3(ps_real_velocity, p, v_scale(v_sub(next_pos, old_pos), 1.0 / dt))
        store3(ps_old_pos, p, next_pos)


