"""One simulation step's team update and particle stages (ref §A.6/§C.3, §D.1, §D.2, §D.10).

``team_step_update`` runs after the runtime's ``team_time_begin_step`` (A.6: now_update_time,
frame_interpolation) and interpolates the center, derives local inertia, gravity falloff and
the stabilisation weights (C.3). ``predict_team`` is D.1, ``step_basic_pose_team`` D.2 and
``end_step_team`` D.10.
"""
from __future__ import annotations

import math

from magica_py.jit import kernel
from magica_py.kernels.math3d import (
    clamp_length, depth_mass, lerp, load3, load4, project_on_plane, q_angle, q_from_to, q_mul,
    q_normalize, q_rotate, q_slerp, q_to_angle_axis, saturate, store3, store4, v_add, v_cross,
    v_dot, v_length, v_length_sq, v_lerp, v_mul, v_normalize, v_scale, v_sub,
)
from magica_py.solver.parameters import curve_at_clamp01, step_keep, step_rate

MOVE = 0x02
IDENTITY = (0.0, 0.0, 0.0, 1.0)
FRICTION_DAMPING_RATE = 0.6
STATIC_FRICTION_GAIN = 0.04
STATIC_FRICTION_LOSS = 0.05
CENTRIFUGAL_SCALE = 0.02


@kernel
def team_step_update(m, ts, prm, frame_interpolation, team, dt):
    """C.3 for one team at the start of a step."""
    t = frame_interpolation
    old_pos = load3(ts.now_world_pos, team)
    old_rot = load4(ts.now_world_rot, team)
    store3(ts.old_world_pos, team, old_pos)
    store4(ts.old_world_rot, team, old_rot)
    now_pos = v_lerp(load3(ts.old_frame_world_pos, team), load3(ts.frame_world_pos, team), t)
    now_rot = q_normalize(q_slerp(load4(ts.old_frame_world_rot, team), load4(ts.frame_world_rot, team), t))
    scale = v_lerp(load3(ts.old_frame_world_scale, team), load3(ts.frame_world_scale, team), t)
    store3(ts.now_world_pos, team, now_pos)
    store4(ts.now_world_rot, team, now_rot)
    step_vector = v_sub(now_pos, old_pos)
    step_rotation = q_from_to(old_rot, now_rot)
    step_angle = q_angle(old_rot, now_rot)
    store3(ts.step_vector, team, step_vector)
    store4(ts.step_rotation, team, step_rotation)
    # local inertia: m of the step motion is removed rigidly
    li = prm.local_inertia[team]
    mv = 1.0 - li
    rv = 1.0 - li
    limit = prm.local_movement_speed_limit[team]
    felt = v_length(step_vector) * (1.0 - mv) / dt
    if limit >= 0.0 and felt > limit:
        mv = lerp(1.0, mv, limit / felt)
    limit = prm.local_rotation_speed_limit[team]
    felt = math.degrees(step_angle * (1.0 - rv) / dt)
    if limit >= 0.0 and felt > limit:
        rv = lerp(1.0, rv, limit / felt)
    ts.step_move_inertia_ratio[team] = mv
    ts.step_rotation_inertia_ratio[team] = rv
    store3(ts.inertia_vector, team, v_scale(step_vector, mv))
    store4(ts.inertia_rotation, team, q_slerp(IDENTITY, step_rotation, rv))
    # centrifugal helpers
    w = step_angle / dt
    ts.angular_velocity[team] = w
    axis = (0.0, 0.0, 0.0)
    if w > 1e-8:
        _angle, axis = q_to_angle_axis(step_rotation)
    store3(ts.rotation_axis, team, axis)
    init_scale = v_length(load3(m.team_init_scale, team))
    ts.scale_ratio[team] = max(v_length(scale) / init_scale if init_scale > 0.0 else 1.0, 1e-6)
    # gravity falloff
    g = load3(prm.gravity_direction, team)
    gravity_dot = 1.0
    if v_length_sq(g) > 1e-8:
        f = q_rotate(now_rot, load3(m.team_init_local_gravity, team))
        gravity_dot = saturate(v_dot(f, g) * 0.5 + 0.5)
    ts.gravity_dot[team] = gravity_dot
    ratio = 1.0
    falloff = prm.gravity_falloff[team]
    if prm.gravity[team] > 1e-6 and falloff > 1e-6:
        ratio = lerp(saturate(1.0 - falloff), 1.0, saturate(1.0 - gravity_dot))
    ts.gravity_ratio[team] = ratio
    # stabilisation after a reset, then the blend weight
    if ts.velocity_weight[team] < 1.0:
        stab = prm.stabilization_time[team]
        ts.velocity_weight[team] = saturate(ts.velocity_weight[team] + (dt / stab if stab > 1e-6 else 1.0))
    ts.blend_weight[team] = saturate(ts.velocity_weight[team] * prm.blend_weight[team] * ts.distance_weight[team])


@kernel
def predict_team(m, ps, prm, ts, team, frame_interpolation, dt, frequency_ratio, power_z):
    """D.1: animated pose at this step, inertia shift, damping, forces, prediction."""
    t = frame_interpolation
    mode = prm.rate_mode[team]
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
    scale = ts.scale_ratio[team]
    start = m.team_particle_start[team]
    for p in range(start, start + m.team_particle_count[team]):
        base_pos = v_lerp(load3(ps.old_position, p), load3(ps.position, p), t)
        if t == 1.0:  # the last step of a frame: slerp(a, b, 1) == b
            base_rot = load4(ps.rotation, p)
        else:
            base_rot = q_normalize(q_slerp(load4(ps.old_rotation, p), load4(ps.rotation, p), t))
        store3(ps.base_pos, p, base_pos)
        store4(ps.base_rot, p, base_rot)
        store3(ps.step_basic_pos, p, base_pos)
        store4(ps.step_basic_rot, p, base_rot)
        if (m.attribute[p] & MOVE) == 0:
            store3(ps.next_pos, p, base_pos)
            store3(ps.velocity_pos, p, base_pos)
            continue
        old_pos = load3(ps.old_pos, p)
        depth = m.depth[p]
        k = depth_inertia * (1.0 - depth * depth)
        if k == 0.0:  # depth inertia off: lerp/slerp at 0 are the first argument
            iv = inertia_vector
            iq = inertia_rotation
        else:
            iv = v_lerp(inertia_vector, step_vector, k)
            iq = q_slerp(inertia_rotation, step_rotation, k)
        w = v_add(v_add(old_world_pos, q_rotate(iq, v_sub(old_pos, old_world_pos))), iv)
        velocity_pos = w  # old_pos + (w - old_pos)
        velocity = q_rotate(iq, load3(ps.velocity, p))
        velocity = v_scale(velocity, velocity_weight)
        damp = curve_at_clamp01(prm.damping_curve, team, depth)
        velocity = v_scale(velocity, saturate(1.0 - step_rate(damp, frequency_ratio, power_z, mode)))
        force = gravity
        if force_mode != 0:
            if force_mode == 3 or force_mode == 4:
                velocity = (0.0, 0.0, 0.0)
            if force_mode == 1 or force_mode == 3:
                force = v_add(force, v_scale(impact, 1.0 / depth_mass(depth)))
            else:
                force = v_add(force, impact)
        force = v_scale(force, scale)
        velocity = v_add(velocity, v_scale(force, dt))
        store3(ps.velocity, p, velocity)
        store3(ps.velocity_pos, p, velocity_pos)
        store3(ps.next_pos, p, v_add(w, v_scale(velocity, dt)))


@kernel
def step_basic_pose_team(m, ps, prm, ts, team):
    """D.2: rebuild the rest shape along each baseline and blend it to the animated pose."""
    a = prm.animation_pose_ratio[team]
    if a > 0.99:
        return
    s = v_scale(load3(m.team_init_scale, team), ts.scale_ratio[team])
    b0 = m.team_baseline_start[team]
    for b in range(b0, b0 + m.team_baseline_count[team]):
        e0 = m.baseline_start[b]
        e1 = e0 + m.baseline_count[b]
        for e in range(e0 + 1, e1):
            v = m.baseline_data[e]
            p = m.parent[v]
            prot = load4(ps.step_basic_rot, p)
            store3(ps.step_basic_pos, v, v_add(q_rotate(prot, v_mul(load3(m.baseline_local_position, v), s)),
                                               load3(ps.step_basic_pos, p)))
            store4(ps.step_basic_rot, v, q_mul(prot, load4(m.baseline_local_rotation, v)))
        if a > 1e-8:
            for e in range(e0, e1):
                v = m.baseline_data[e]
                store3(ps.step_basic_pos, v, v_lerp(load3(ps.step_basic_pos, v), load3(ps.base_pos, v), a))
                store4(ps.step_basic_rot, v, q_slerp(load4(ps.step_basic_rot, v), load4(ps.base_rot, v), a))


@kernel
def end_step_team(m, ps, prm, ts, team, dt, frequency_ratio):
    """D.10: velocity from positions, static and dynamic friction, speed limit, centrifugal term."""
    mode = prm.rate_mode[team]
    scale = ts.scale_ratio[team]
    static_threshold = prm.friction[team] * scale
    dynamic = prm.friction[team]
    speed_limit = prm.particle_speed_limit[team]
    angular_velocity = ts.angular_velocity[team]
    centrifugal = prm.centrifugal_acceleration[team]
    axis = load3(ts.rotation_axis, team)
    center = load3(ts.now_world_pos, team)
    velocity_weight = ts.velocity_weight[team]
    friction_keep = step_keep(FRICTION_DAMPING_RATE, frequency_ratio, mode)
    gain = step_rate(STATIC_FRICTION_GAIN, frequency_ratio, 1.0, mode)
    start = m.team_particle_start[team]
    for p in range(start, start + m.team_particle_count[team]):
        next_pos = load3(ps.next_pos, p)
        old_pos = load3(ps.old_pos, p)
        if (m.attribute[p] & MOVE) != 0:
            cn = load3(ps.collision_normal, p)
            f = ps.friction[p]
            contact = v_length_sq(cn) > 1e-8 and f > 1e-8
            sf = ps.static_friction[p]
            velocity_pos = load3(ps.velocity_pos, p)
            if contact and static_threshold > 0.0:
                d = v_sub(next_pos, old_pos)
                tv = v_sub(d, v_scale(cn, v_dot(d, cn)))
                speed = v_length(tv) / dt
                if speed < static_threshold:
                    sf = saturate(sf + gain)
                else:
                    sf = saturate(sf - max((speed - static_threshold) / 0.2, STATIC_FRICTION_LOSS))
                next_pos = v_sub(next_pos, v_scale(tv, sf))
                velocity_pos = v_sub(velocity_pos, v_scale(tv, sf))
                store3(ps.next_pos, p, next_pos)
            else:
                sf = saturate(sf - STATIC_FRICTION_LOSS)
            ps.static_friction[p] = sf
            vel = v_scale(v_sub(next_pos, velocity_pos), 1.0 / dt)
            speed_sq = v_length_sq(vel)
            direction = (0.0, 0.0, 0.0)
            if speed_sq >= 1e-8:
                direction = v_scale(vel, 1.0 / math.sqrt(speed_sq))
                if contact and dynamic > 0.0:
                    dd = 0.5 + 0.5 * v_dot(cn, direction)
                    dd = 1.0 - dd * dd
                    vel = v_sub(vel, v_scale(vel, dd * saturate(f * dynamic)))
            ps.friction[p] = f * friction_keep
            if speed_limit >= 0.0:
                vel = clamp_length(vel, speed_limit * scale)
            if angular_velocity > 1e-8 and centrifugal > 1e-8 and speed_sq >= 1e-8:
                lv = project_on_plane(v_sub(next_pos, center), axis)
                radius = v_length(lv)
                if radius > 1e-8:
                    n = v_scale(lv, 1.0 / radius)
                    mass = 1.0 + (1.0 - m.depth[p])
                    force = mass * angular_velocity * angular_velocity * radius
                    u = v_normalize(v_cross(axis, n))
                    force *= saturate(v_dot(direction, u))
                    vel = v_add(vel, v_scale(n, force * centrifugal * CENTRIFUGAL_SCALE))
            store3(ps.velocity, p, v_scale(vel, velocity_weight))
        store3(ps.real_velocity, p, v_scale(v_sub(next_pos, old_pos), 1.0 / dt))
        store3(ps.old_pos, p, next_pos)
