"""One simulation step's team update and particle stages (docs/solver.md §A.6/§C.3, §D.1, §D.2, §D.10).

``team_step_update`` runs after the runtime's ``team_time_begin_step`` (A.6: now_update_time,
frame_interpolation) and interpolates the center, derives local inertia, gravity falloff and
the stabilisation weights (C.3). ``predict_team`` is D.1, ``step_basic_pose_team`` D.2 and
``end_step_team`` D.10. Each has a block form (``predict_block``, ``step_basic_pose_block``,
``end_step_block``: every lane of a block, lanes innermost, ``solver/batched``) calling the same
branch-free per-element functions (``predict_move``, ``basic_pose_child``, ``end_step_velocity``, ...)
so that both give the same bits. Their lane loops load and store through ``kernels/streams``
(no runtime overlap checks; each loop states its streams), and where every lane of a block
takes a slerp's lerp path (``math3d.slerp_is_near``) they call ``math3d.slerp_near``, that path alone.
"""
from __future__ import annotations

import math

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels.math3d import (
    clamp_length, depth_mass, load3, load4, project_on_plane, q_dot, q_mul,
    q_normalize, q_rotate, q_slerp, saturate, slerp_is_near, slerp_near, store3, store4, v_add, v_cross,
    v_dot, v_length, v_length_sq, v_lerp, v_mul, v_normalize, v_scale, v_sub,
)
from magica_py.kernels.streams import READ, open_streams, sload, sload3, sload4, sstore, sstore3, sstore4
from magica_py.solver.batched.transfer import bload3, bload4, bstore3, bstore4
from magica_py.solver.display import record_display_state_team
from magica_py.solver.parameters import curve_at_clamp01, length_unit, step_keep, step_rate
from magica_py.solver.team_step import LANES_NEAR, SCALAR, slerp_in_mode, team_step_values

MOVE = 0x02
IDENTITY = (0.0, 0.0, 0.0, 1.0)
FRICTION_DAMPING_RATE = 0.6
STATIC_FRICTION_GAIN = 0.04
STATIC_FRICTION_LOSS = 0.05
CENTRIFUGAL_SCALE = 0.02


@kernel
def team_step_update(m, ts, prm, frame_interpolation, team, dt):
    """C.3 for one team at the start of a step (the maths: ``team_step.team_step_values``, also
    run by the block form ``team_step.team_step_block``)."""
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
        prm.stabilization_time[team], ts.velocity_weight[team], prm.blend_weight[team], ts.distance_weight[team],
        SCALAR)
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
def predict_base_pose(old_position, position, old_rotation, rotation, t, mode):
    """D.1's animated pose of a particle at frame interpolation t: (base_pos, base_rot).
    ``mode`` (a literal, ``team_step.slerp_in_mode``): SCALAR, or LANES_NEAR where
    ``slerp_is_near(old_rotation, rotation)`` (the usual case: one frame's turn of a bone)."""
    base_pos = v_lerp(old_position, position, t)
    # at the last step of a frame (t == 1) the rotation is taken as is; the slerp is
    # computed either way and selected (no branch: a lane loop over it vectorises)
    slerped = q_normalize(slerp_in_mode(old_rotation, rotation, t, mode))
    base_rot = rotation if t == 1.0 else slerped
    return base_pos, base_rot


@kernel
def predict_move(old_pos, velocity, depth, old_world_pos, inertia_vector, inertia_rotation, step_vector,
                 step_rotation, depth_inertia, velocity_weight, damping_keep, gravity, force_mode, impact,
                 scale, dt, mode):
    """D.1 for a Move particle: (velocity, velocity_pos, next_pos) after the inertia shift,
    damping (``damping_keep`` = saturate(1 - step rate of the damping curve)) and forces.
    ``mode`` (constant at each call site, ``team_step.slerp_in_mode``): SCALAR, or LANES_NEAR
    where ``slerp_is_near(inertia_rotation, step_rotation)`` holds (the usual case: both are one
    step's rotation of the team), the same bits without the slerp's acos and sines."""
    k = depth_inertia * (1.0 - depth * depth)
    # branch-free (computed both ways, then selected) so that a lane loop over it vectorises;
    # depth inertia off (k == 0): lerp/slerp at 0 are the first argument
    iv_mixed = v_lerp(inertia_vector, step_vector, k)
    iq_mixed = slerp_in_mode(inertia_rotation, step_rotation, k, mode)
    off = k == 0.0
    iv = inertia_vector if off else iv_mixed
    iq = inertia_rotation if off else iq_mixed
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
    for p in range(start, start + m.team_particle_count[team]):
        if t == 1.0:  # the last step of a frame: predict_base_pose's select, without the slerp
            base_pos = v_lerp(load3(ps.old_position, p), load3(ps.position, p), t)
            base_rot = load4(ps.rotation, p)
        else:
            base_pos, base_rot = predict_base_pose(load3(ps.old_position, p), load3(ps.position, p),
                                                   load4(ps.old_rotation, p), load4(ps.rotation, p), t, SCALAR)
        store3(ps.base_pos, p, base_pos)
        store4(ps.base_rot, p, base_rot)
        store3(ps.step_basic_pos, p, base_pos)
        store4(ps.step_basic_rot, p, base_rot)
        if (m.attribute[p] & MOVE) == 0:
            store3(ps.next_pos, p, base_pos)
            store3(ps.velocity_pos, p, base_pos)
            continue
        depth = m.depth[p]
        damping_keep = damping_keep_at(prm, team, depth, frequency_ratio, power_z)
        if depth_inertia * (1.0 - depth * depth) == 0.0:  # no depth-inertia mix: predict_move's select
            velocity, velocity_pos, next_pos = predict_move_shifted(
                load3(ps.old_pos, p), load3(ps.velocity, p), depth, old_world_pos, inertia_vector,
                inertia_rotation, velocity_weight, damping_keep, gravity, force_mode, impact, scale, dt)
        else:
            velocity, velocity_pos, next_pos = predict_move(
                load3(ps.old_pos, p), load3(ps.velocity, p), depth, old_world_pos, inertia_vector,
                inertia_rotation, step_vector, step_rotation, depth_inertia, velocity_weight,
                damping_keep, gravity, force_mode, impact, scale, dt, SCALAR)
        store3(ps.velocity, p, velocity)
        store3(ps.velocity_pos, p, velocity_pos)
        store3(ps.next_pos, p, next_pos)


# predict_block's lane streams (``kernels/streams``; every access is to row k of one particle or
# lane L, arrays distinct): base_pos 1-3, base_rot 4-7, step_basic_pos 8-10, step_basic_rot
# 11-14, next_pos 15-17, velocity_pos 18-20, velocity 21-23 (read and written in place);
# everything else is read only.


@kernel
def _base_pose_lane(old_position, position, old_rotation, rotation, base_pos_a, base_rot_a, sbp, sbr, next_pos_a,
                    velocity_pos_a, interpolation, k, L, last_step, fixed, base_near):
    """``predict_team``'s animated pose for block row k, lane L, and for a Fixed particle its
    prediction (the pose). Flags constant at each call site (they fold away): ``last_step``
    every lane is at the last step of its frame (t == 1: the base rotation is the frame's,
    predict_base_pose's select without the slerp); ``base_near`` every lane's frame rotations
    are near (``predict_base_pose``'s LANES_NEAR)."""
    t = sload(interpolation, L, READ)
    old_p = sload3(old_position, k, READ)
    new_p = sload3(position, k, READ)
    if last_step:
        base_pos = v_lerp(old_p, new_p, t)
        base_rot = sload4(rotation, k, READ)
    else:
        base_pos, base_rot = predict_base_pose(old_p, new_p, sload4(old_rotation, k, READ),
                                               sload4(rotation, k, READ), t,
                                               LANES_NEAR if base_near else SCALAR)
    sstore3(base_pos_a, k, base_pos, 1)
    sstore4(base_rot_a, k, base_rot, 4)
    sstore3(sbp, k, base_pos, 8)
    sstore4(sbr, k, base_rot, 11)
    if fixed:
        sstore3(next_pos_a, k, base_pos, 15)
        sstore3(velocity_pos_a, k, base_pos, 18)


@kernel
def _move_lane(next_pos_a, velocity_pos_a, velocity_a, old_pos_a, lane_old_world_pos, lane_iv, lane_iq, lane_sv,
               lane_sq, lane_vw, lane_gr, lane_fm, lane_f, lane_scale, k, L, depth, depth_inertia, damping_keep,
               gravity_direction, gravity, dt, mixed, near):
    """``predict_team``'s Move-particle prediction for block row k, lane L. Flags constant at each
    call site: ``mixed`` the depth-inertia mix is on for this particle (predict_move's k != 0),
    ``near`` every lane's inertia and step rotations are near (``predict_move``'s LANES_NEAR)."""
    gravity_vector = v_scale(gravity_direction, gravity * sload(lane_gr, L, READ))
    if mixed:
        velocity, velocity_pos, next_pos = predict_move(
            sload3(old_pos_a, k, READ), sload3(velocity_a, k, 21), depth, sload3(lane_old_world_pos, L, READ),
            sload3(lane_iv, L, READ), sload4(lane_iq, L, READ), sload3(lane_sv, L, READ),
            sload4(lane_sq, L, READ), depth_inertia, sload(lane_vw, L, READ), damping_keep, gravity_vector,
            sload(lane_fm, L, READ), sload3(lane_f, L, READ), sload(lane_scale, L, READ), dt,
            LANES_NEAR if near else SCALAR)
    else:
        velocity, velocity_pos, next_pos = predict_move_shifted(
            sload3(old_pos_a, k, READ), sload3(velocity_a, k, 21), depth, sload3(lane_old_world_pos, L, READ),
            sload3(lane_iv, L, READ), sload4(lane_iq, L, READ), sload(lane_vw, L, READ), damping_keep,
            gravity_vector, sload(lane_fm, L, READ), sload3(lane_f, L, READ), sload(lane_scale, L, READ), dt)
    sstore3(velocity_a, k, velocity, 21)
    sstore3(velocity_pos_a, k, velocity_pos, 18)
    sstore3(next_pos_a, k, next_pos, 15)


@kernel
def predict_block(m, bs, prm, blk, b, dt, frequency_ratio, power_z):
    """D.1 for every lane of block b (``solver/batched``): ``predict_team``'s maths, lanes innermost."""
    ex = blk.block_exemplar[b]
    width = blk.block_width[b]
    lanes = np.uint64(blk.block_lane_base[b])
    p0 = m.team_particle_start[ex]
    depth_inertia = prm.depth_inertia[ex]
    gravity_direction = load3(prm.gravity_direction, ex)
    gravity = prm.gravity[ex]
    # arrays as locals: read through the table inside the loop, their pointers would be
    # reloaded after every store and the lane loop would not vectorise
    old_position, position, old_rotation, rotation = bs.old_position, bs.position, bs.old_rotation, bs.rotation
    base_pos_a, base_rot_a, sbp, sbr = bs.base_pos, bs.base_rot, bs.step_basic_pos, bs.step_basic_rot
    next_pos_a, velocity_pos_a, velocity_a, old_pos_a = bs.next_pos, bs.velocity_pos, bs.velocity, bs.old_pos
    interpolation, lane_old_world_pos = bs.lane_frame_interpolation, bs.lane_old_world_pos
    lane_iv, lane_iq, lane_sv, lane_sq = (bs.lane_inertia_vector, bs.lane_inertia_rotation,
                                          bs.lane_step_vector, bs.lane_step_rotation)
    lane_vw, lane_gr, lane_fm, lane_f, lane_scale = (bs.lane_velocity_weight, bs.lane_gravity_ratio,
                                                     bs.lane_external_force_mode, bs.lane_external_force,
                                                     bs.lane_scale_ratio)
    # block-uniform shortcuts (same bits: they take the value the per-element select takes):
    # at the last step of a frame in every lane the base rotation is the frame's rotation;
    # the depth-inertia slerp of every lane on its lerp path (inertia and step rotation are
    # one step's rotation of the team: the usual case), its acos and sines are not computed
    last_step = True
    near = True
    for i in range(width):
        L = lanes + np.uint64(i)
        if interpolation[L] != 1.0:
            last_step = False
        if not slerp_is_near(bload4(lane_iq, L), bload4(lane_sq, L)):
            near = False
    # the block's arrays, in _predict_lanes' order
    pa = (old_position, position, old_rotation, rotation, base_pos_a, base_rot_a, sbp, sbr, next_pos_a,
          velocity_pos_a, velocity_a, old_pos_a)
    la = (interpolation, lane_old_world_pos, lane_iv, lane_iq, lane_sv, lane_sq, lane_vw, lane_gr, lane_fm, lane_f,
          lane_scale)
    for p in range(blk.block_particle_count[b]):
        # unsigned row indices: numba wraps negative signed indices (a select per access that
        # hides the affine address from LLVM's vectoriser)
        k0 = np.uint64(blk.block_row_base[b] + p * width)
        depth = m.depth[p0 + p]
        move = (m.attribute[p0 + p] & MOVE) != 0
        mixed = depth_inertia * (1.0 - depth * depth) != 0.0
        damping_keep = damping_keep_at(prm, ex, depth, frequency_ratio, power_z) if move else 1.0
        c = (k0, lanes, width, depth, depth_inertia, damping_keep, gravity_direction, gravity, dt)
        # flags literal at each call, so that the lane bodies are branch-free
        if last_step:
            _predict_particle(pa, la, c, move, mixed, near, True, False)
        elif _frame_rotations_near(old_rotation, rotation, k0, width):
            _predict_particle(pa, la, c, move, mixed, near, False, True)
        else:
            _predict_particle(pa, la, c, move, mixed, near, False, False)


@kernel
def _frame_rotations_near(old_rotation, rotation, k0, width):
    """True when every lane of rows k0 .. k0 + width - 1 has its frame rotations (old, new) near:
    ``predict_base_pose``'s slerp then takes its lerp path in every lane (read-only pre-pass)."""
    near = True
    for i in range(width):
        k = k0 + np.uint64(i)
        if not slerp_is_near(bload4(old_rotation, k), bload4(rotation, k)):
            near = False
    return near


@kernel(inline="always")
def _predict_particle(pa, la, c, move, mixed, near, last_step, base_near):
    """One particle's lane loops: the variant of ``_predict_lanes`` its flags select
    (``last_step`` and ``base_near`` literal here, the others chosen at run time)."""
    if not move:
        _predict_lanes(pa, la, c, last_step, True, False, False, base_near)
    elif not mixed:
        _predict_lanes(pa, la, c, last_step, False, False, False, base_near)
    elif near:
        _predict_lanes(pa, la, c, last_step, False, True, True, base_near)
    else:
        _predict_lanes(pa, la, c, last_step, False, True, False, base_near)


@kernel
def _predict_lanes(pa, la, c, last_step, fixed, mixed, near, base_near):
    """predict_block's lane loops of one particle (rows k0 .. k0 + width - 1). Flags constant at
    each call: ``last_step`` / ``base_near`` (``_base_pose_lane``), ``fixed`` a Fixed particle
    (its prediction is the pose), ``mixed`` / ``near`` (``_move_lane``)."""
    (old_position, position, old_rotation, rotation, base_pos_a, base_rot_a, sbp, sbr, next_pos_a, velocity_pos_a,
     velocity_a, old_pos_a) = pa
    (interpolation, lane_old_world_pos, lane_iv, lane_iq, lane_sv, lane_sq, lane_vw, lane_gr, lane_fm, lane_f,
     lane_scale) = la
    k0, lanes, width, depth, depth_inertia, damping_keep, gravity_direction, gravity, dt = c
    if fixed:
        open_streams()
        for i in range(width):
            _base_pose_lane(old_position, position, old_rotation, rotation, base_pos_a, base_rot_a, sbp, sbr,
                            next_pos_a, velocity_pos_a, interpolation, k0 + np.uint64(i), lanes + np.uint64(i),
                            last_step, True, base_near)
        return
    if last_step:
        # without the slerp the pose is cheap: pose and prediction in one loop (with it, the
        # merged loop does not vectorise: 42 -> 102 ns/particle; with the slerp's lerp path
        # alone, base_near, merged and split measured the same)
        open_streams()
        for i in range(width):
            k, L = k0 + np.uint64(i), lanes + np.uint64(i)
            _base_pose_lane(old_position, position, old_rotation, rotation, base_pos_a, base_rot_a, sbp, sbr,
                            next_pos_a, velocity_pos_a, interpolation, k, L, True, False, False)
            _move_lane(next_pos_a, velocity_pos_a, velocity_a, old_pos_a, lane_old_world_pos, lane_iv, lane_iq,
                       lane_sv, lane_sq, lane_vw, lane_gr, lane_fm, lane_f, lane_scale, k, L, depth, depth_inertia,
                       damping_keep, gravity_direction, gravity, dt, mixed, near)
        return
    open_streams()
    for i in range(width):
        _base_pose_lane(old_position, position, old_rotation, rotation, base_pos_a, base_rot_a, sbp, sbr,
                        next_pos_a, velocity_pos_a, interpolation, k0 + np.uint64(i), lanes + np.uint64(i),
                        False, False, base_near)
    open_streams()
    for i in range(width):
        _move_lane(next_pos_a, velocity_pos_a, velocity_a, old_pos_a, lane_old_world_pos, lane_iv, lane_iq, lane_sv,
                   lane_sq, lane_vw, lane_gr, lane_fm, lane_f, lane_scale, k0 + np.uint64(i), lanes + np.uint64(i),
                   depth, depth_inertia, damping_keep, gravity_direction, gravity, dt, mixed, near)


@kernel
def basic_pose_child(parent_pos, parent_rot, local_position, local_rotation, scale):
    """D.2: a baseline child's rest pose placed on its parent's (scale = build scale x scale ratio)."""
    pos = v_add(q_rotate(parent_rot, v_mul(local_position, scale)), parent_pos)
    return pos, q_mul(parent_rot, local_rotation)


@kernel
def basic_pose_blend(pos, rot, base_pos, base_rot, ratio, mode):
    """D.2: the rest shape blended towards the animated pose by animation_pose_ratio (``mode`` as
    in ``predict_move``: LANES_NEAR where ``slerp_is_near(rot, base_rot)``)."""
    return v_lerp(pos, base_pos, ratio), slerp_in_mode(rot, base_rot, ratio, mode)


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
            pos, rot = basic_pose_child(load3(ps.step_basic_pos, p), load4(ps.step_basic_rot, p),
                                        load3(m.baseline_local_position, v), load4(m.baseline_local_rotation, v), s)
            store3(ps.step_basic_pos, v, pos)
            store4(ps.step_basic_rot, v, rot)
        if a > 1e-8:
            for e in range(e0, e1):
                v = m.baseline_data[e]
                pos, rot = basic_pose_blend(load3(ps.step_basic_pos, v), load4(ps.step_basic_rot, v),
                                            load3(ps.base_pos, v), load4(ps.base_rot, v), a, SCALAR)
                store3(ps.step_basic_pos, v, pos)
                store4(ps.step_basic_rot, v, rot)


@kernel
def step_basic_pose_block(m, bs, prm, blk, b):
    """D.2 for every lane of block b (``solver/batched``): ``step_basic_pose_team``'s maths,
    baseline entries in the per-team order, lanes innermost."""
    ex = blk.block_exemplar[b]
    a = prm.animation_pose_ratio[ex]
    if a > 0.99:
        return
    width = blk.block_width[b]
    lanes = np.uint64(blk.block_lane_base[b])
    row_base = blk.block_row_base[b]
    p0 = m.team_particle_start[ex]
    init_scale = load3(m.team_init_scale, ex)
    sbp, sbr, base_pos, base_rot = bs.step_basic_pos, bs.step_basic_rot, bs.base_pos, bs.base_rot
    scale = bs.lane_scale_ratio
    b0 = m.team_baseline_start[ex]
    for bl in range(b0, b0 + m.team_baseline_count[ex]):
        e0 = m.baseline_start[bl]
        e1 = e0 + m.baseline_count[bl]
        for e in range(e0 + 1, e1):
            v = m.baseline_data[e]
            kv = np.uint64(row_base + (v - p0) * width)
            kp = np.uint64(row_base + (m.parent[v] - p0) * width)
            local_position = load3(m.baseline_local_position, v)
            local_rotation = load4(m.baseline_local_rotation, v)
            if kp != kv:
                # streams: the child's rows (step_basic_pos 1-3, step_basic_rot 4-7) are
                # written; the parent's rows, a multiple of width >= width away, are only read
                open_streams()
                for i in range(width):
                    s = v_scale(init_scale, sload(scale, lanes + np.uint64(i), READ))
                    pos, rot = basic_pose_child(sload3(sbp, kp + np.uint64(i), READ),
                                                sload4(sbr, kp + np.uint64(i), READ),
                                                local_position, local_rotation, s)
                    sstore3(sbp, kv + np.uint64(i), pos, 1)
                    sstore4(sbr, kv + np.uint64(i), rot, 4)
                continue
            # a vertex its own parent (never built: the parent links come from the bone tree);
            # plain loads and stores, LLVM keeps the order
            for i in range(width):
                s = v_scale(init_scale, scale[lanes + np.uint64(i)])
                pos, rot = basic_pose_child(bload3(sbp, kp + np.uint64(i)), bload4(sbr, kp + np.uint64(i)),
                                            local_position, local_rotation, s)
                bstore3(sbp, kv + np.uint64(i), pos)
                bstore4(sbr, kv + np.uint64(i), rot)
        if a > 1e-8:
            for e in range(e0, e1):
                kv = np.uint64(row_base + (m.baseline_data[e] - p0) * width)
                # the rest shape near the animated pose in every lane (the usual case): the
                # blend's slerp on its lerp path, without its acos and sines (same bits)
                far = 0
                for i in range(width):  # read only: no stores to order
                    k = kv + np.uint64(i)
                    far += 0 if slerp_is_near(sload4(sbr, k, READ), sload4(base_rot, k, READ)) else 1
                # streams: step_basic_pos 1-3 and step_basic_rot 4-7 updated in place
                open_streams()
                if far == 0:
                    for i in range(width):
                        k = kv + np.uint64(i)
                        pos, rot = basic_pose_blend(sload3(sbp, k, 1), sload4(sbr, k, 4), sload3(base_pos, k, READ),
                                                    sload4(base_rot, k, READ), a, LANES_NEAR)
                        sstore3(sbp, k, pos, 1)
                        sstore4(sbr, k, rot, 4)
                    continue
                for i in range(width):
                    k = kv + np.uint64(i)
                    pos, rot = basic_pose_blend(sload3(sbp, k, 1), sload4(sbr, k, 4), sload3(base_pos, k, READ),
                                                sload4(base_rot, k, READ), a, SCALAR)
                    sstore3(sbp, k, pos, 1)
                    sstore4(sbr, k, rot, 4)


@kernel
def static_friction_step(next_pos, old_pos, velocity_pos, normal, static_friction, dt, static_threshold, gain):
    """D.10 static friction of a particle in contact: its tangential move this step is cancelled
    by the static friction factor, which grows while the particle holds (tangential speed below
    the threshold) and drops as it slips. Returns (next_pos, velocity_pos, static_friction)."""
    d = v_sub(next_pos, old_pos)
    tv = v_sub(d, v_scale(normal, v_dot(d, normal)))
    speed = v_length(tv) / dt
    held = saturate(static_friction + gain)
    slipping = saturate(static_friction - max((speed - static_threshold) / 0.2, STATIC_FRICTION_LOSS))
    sf = held if speed < static_threshold else slipping
    return v_sub(next_pos, v_scale(tv, sf)), v_sub(velocity_pos, v_scale(tv, sf)), sf


@kernel
def end_step_velocity(next_pos, velocity_pos, dt):
    """D.10 velocity of a Move particle from its positions: (velocity, unit direction (0 when
    not moving), moving). Branch-free."""
    vel = v_scale(v_sub(next_pos, velocity_pos), 1.0 / dt)
    speed_sq = v_length_sq(vel)
    moving = speed_sq >= 1e-8
    unit = v_scale(vel, 1.0 / math.sqrt(speed_sq))
    return vel, (unit if moving else (0.0, 0.0, 0.0)), moving


@kernel
def dynamic_friction_brake(vel, direction, normal, friction, dynamic_friction):
    """D.10 dynamic friction of a moving particle in contact: brakes motion along the surface,
    not away from it."""
    dd = 0.5 + 0.5 * v_dot(normal, direction)
    dd = 1.0 - dd * dd
    return v_sub(vel, v_scale(vel, dd * saturate(friction * dynamic_friction)))


@kernel
def centrifugal_velocity(vel, next_pos, direction, moving, depth, angular_velocity, centrifugal, axis, center):
    """D.10 centrifugal term: outwards from the team's rotation axis through its center, scaled
    by how much the particle moves along the rotation (none when not rotating, not moving or on
    the axis). Branch-free."""
    lv = project_on_plane(v_sub(next_pos, center), axis)
    radius = v_length(lv)
    n = v_scale(lv, 1.0 / radius)
    mass = 1.0 + (1.0 - depth)
    force = mass * angular_velocity * angular_velocity * radius
    u = v_normalize(v_cross(axis, n))
    force *= saturate(v_dot(direction, u))
    flung = v_add(vel, v_scale(n, force * centrifugal * CENTRIFUGAL_SCALE))
    return flung if (angular_velocity > 1e-8 and centrifugal > 1e-8 and moving and radius > 1e-8) else vel


@kernel
def end_step_team(m, ps, prm, ts, team, dt, frequency_ratio):
    """D.10: velocity from positions, static and dynamic friction, speed limit, centrifugal term."""
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
            velocity_pos = load3(ps.velocity_pos, p)
            # the branches skip work whose result the block stage computes and discards
            if contact and static_threshold > 0.0:
                next_pos, velocity_pos, sf = static_friction_step(next_pos, old_pos, velocity_pos, cn,
                                                                  ps.static_friction[p], dt, static_threshold, gain)
                store3(ps.next_pos, p, next_pos)
            else:
                sf = saturate(ps.static_friction[p] - STATIC_FRICTION_LOSS)
            ps.static_friction[p] = sf
            vel, direction, moving = end_step_velocity(next_pos, velocity_pos, dt)
            if moving and contact and dynamic > 0.0:
                vel = dynamic_friction_brake(vel, direction, cn, f, dynamic)
            ps.friction[p] = f * friction_keep
            if speed_limit >= 0.0:
                vel = clamp_length(vel, speed_limit * scale)
            if spinning:
                vel = centrifugal_velocity(vel, next_pos, direction, moving, m.depth[p], angular_velocity,
                                           centrifugal, axis, center)
            store3(ps.velocity, p, v_scale(vel, velocity_weight))
        store3(ps.real_velocity, p, v_scale(v_sub(next_pos, old_pos), 1.0 / dt))
        store3(ps.old_pos, p, next_pos)
    if prm.time_based_smoothing[team] != 0:   # quality display: keep this state (display.py)
        record_display_state_team(m, ps, ts, team)


@kernel
def _end_step_lane(next_pos_a, old_pos_a, velocity_pos_a, velocity_a, real_velocity_a, normal_a, friction_a,
                   static_friction_a, k, depth, dt, dynamic, gain, friction_keep, speed_limit, centrifugal, spin,
                   touch, scale, angular_velocity, axis, center, velocity_weight):
    """end_step_team's Move-particle body on block row k, branch-free. Flags, constant at each
    call site so that they fold away: ``spin`` the block's centrifugal acceleration is on;
    ``touch`` some lane of this particle is in contact (else the friction work is skipped: its
    results would be discarded in every lane).

    Streams (``kernels/streams``; every access is to row k, arrays distinct): next_pos 1-3,
    old_pos 4-6, velocity 7-9, real_velocity 10-12, friction 13, static_friction 14 (the
    in-place updates load in the stream they store to); velocity_pos and the collision
    normal are read only."""
    old_pos = sload3(old_pos_a, k, 4)
    next_pos = sload3(next_pos_a, k, 1)
    velocity_pos = sload3(velocity_pos_a, k, READ)
    cn = sload3(normal_a, k, READ)
    f = sload(friction_a, k, 13)
    sf = sload(static_friction_a, k, 14)
    static_threshold = dynamic * scale
    contact = v_length_sq(cn) > 1e-8 and f > 1e-8
    released = saturate(sf - STATIC_FRICTION_LOSS)
    if touch:
        stuck_pos, stuck_velocity_pos, stuck_sf = static_friction_step(next_pos, old_pos, velocity_pos, cn, sf, dt,
                                                                       static_threshold, gain)
        sticking = contact and static_threshold > 0.0
        next_pos = stuck_pos if sticking else next_pos
        velocity_pos = stuck_velocity_pos if sticking else velocity_pos
        released = stuck_sf if sticking else released
    sstore(static_friction_a, k, released, 14)
    vel, direction, moving = end_step_velocity(next_pos, velocity_pos, dt)
    if touch:
        braked = dynamic_friction_brake(vel, direction, cn, f, dynamic)
        vel = braked if (moving and contact and dynamic > 0.0) else vel
    sstore(friction_a, k, f * friction_keep, 13)
    limited = clamp_length(vel, speed_limit * scale)
    vel = limited if speed_limit >= 0.0 else vel
    if spin:
        vel = centrifugal_velocity(vel, next_pos, direction, moving, depth, angular_velocity, centrifugal, axis, center)
    sstore3(next_pos_a, k, next_pos, 1)
    sstore3(velocity_a, k, v_scale(vel, velocity_weight), 7)
    sstore3(real_velocity_a, k, v_scale(v_sub(next_pos, old_pos), 1.0 / dt), 10)
    sstore3(old_pos_a, k, next_pos, 4)


@kernel
def end_step_block(m, bs, prm, blk, b, dt, frequency_ratio):
    """D.10 for every lane of block b (``solver/batched``): ``end_step_team``'s maths, lanes innermost."""
    ex = blk.block_exemplar[b]
    width = blk.block_width[b]
    lanes = np.uint64(blk.block_lane_base[b])
    p0 = m.team_particle_start[ex]
    mode = prm.rate_mode[ex]
    dynamic = prm.friction[ex]
    speed_limit = prm.particle_speed_limit[ex]
    centrifugal = prm.centrifugal_acceleration[ex]
    friction_keep = step_keep(FRICTION_DAMPING_RATE, frequency_ratio, mode)
    gain = step_rate(STATIC_FRICTION_GAIN, frequency_ratio, 1.0, mode)
    next_pos_a, old_pos_a, velocity_pos_a, velocity_a, real_velocity_a = (bs.next_pos, bs.old_pos, bs.velocity_pos,
                                                                          bs.velocity, bs.real_velocity)
    normal_a, friction_a, static_friction_a = bs.collision_normal, bs.friction, bs.static_friction
    lane_scale, lane_av, lane_axis, lane_center, lane_vw = (bs.lane_scale_ratio, bs.lane_angular_velocity,
                                                            bs.lane_rotation_axis, bs.lane_now_world_pos,
                                                            bs.lane_velocity_weight)
    for p in range(blk.block_particle_count[b]):
        k0 = np.uint64(blk.block_row_base[b] + p * width)
        if (m.attribute[p0 + p] & MOVE) == 0:
            # streams: real_velocity 1-3, old_pos 4-6 (in place); next_pos read only
            open_streams()
            for i in range(width):
                k = k0 + np.uint64(i)
                next_pos = sload3(next_pos_a, k, READ)
                sstore3(real_velocity_a, k, v_scale(v_sub(next_pos, sload3(old_pos_a, k, 4)), 1.0 / dt), 1)
                sstore3(old_pos_a, k, next_pos, 4)
            continue
        depth = m.depth[p0 + p]
        touching = 0
        for i in range(width):  # read only: no stores to order
            k = k0 + np.uint64(i)
            in_contact = v_length_sq(sload3(normal_a, k, READ)) > 1e-8 and sload(friction_a, k, READ) > 1e-8
            touching += 1 if in_contact else 0
        # four variants of one lane loop (flags constant in each): centrifugal on, contact in some lane;
        # the streams of each are _end_step_lane's
        open_streams()
        if centrifugal > 1e-8 and touching > 0:
            for i in range(width):
                L = lanes + np.uint64(i)
                _end_step_lane(next_pos_a, old_pos_a, velocity_pos_a, velocity_a, real_velocity_a, normal_a,
                               friction_a, static_friction_a, k0 + np.uint64(i), depth, dt, dynamic, gain,
                               friction_keep, speed_limit, centrifugal, True, True, sload(lane_scale, L, READ),
                               sload(lane_av, L, READ), sload3(lane_axis, L, READ), sload3(lane_center, L, READ),
                               sload(lane_vw, L, READ))
        elif centrifugal > 1e-8:
            for i in range(width):
                L = lanes + np.uint64(i)
                _end_step_lane(next_pos_a, old_pos_a, velocity_pos_a, velocity_a, real_velocity_a, normal_a,
                               friction_a, static_friction_a, k0 + np.uint64(i), depth, dt, dynamic, gain,
                               friction_keep, speed_limit, centrifugal, True, False, sload(lane_scale, L, READ),
                               sload(lane_av, L, READ), sload3(lane_axis, L, READ), sload3(lane_center, L, READ),
                               sload(lane_vw, L, READ))
        elif touching > 0:
            for i in range(width):
                L = lanes + np.uint64(i)
                _end_step_lane(next_pos_a, old_pos_a, velocity_pos_a, velocity_a, real_velocity_a, normal_a,
                               friction_a, static_friction_a, k0 + np.uint64(i), depth, dt, dynamic, gain,
                               friction_keep, speed_limit, centrifugal, False, True, sload(lane_scale, L, READ),
                               0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), sload(lane_vw, L, READ))
        else:
            for i in range(width):
                L = lanes + np.uint64(i)
                _end_step_lane(next_pos_a, old_pos_a, velocity_pos_a, velocity_a, real_velocity_a, normal_a,
                               friction_a, static_friction_a, k0 + np.uint64(i), depth, dt, dynamic, gain,
                               friction_keep, speed_limit, centrifugal, False, False, sload(lane_scale, L, READ),
                               0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), sload(lane_vw, L, READ))
