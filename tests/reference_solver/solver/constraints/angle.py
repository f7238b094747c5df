"""Angle limit (docs/solver.md §D.5) and angle restoration (§D.6), one routine per baseline, 3 iterations.

Restoration pulls each edge towards its *absolute* world direction in the step basic pose
(not parent-relative, Appendix 2.2). Masses use friction only (Appendix 2.3). Both parent and
child move; the restoration pivot grows 0.1 -> 0.3 -> 0.5 over the iterations.

``angle_team`` runs one team through the per-element functions ``angle_buffer_entry``
(buffering pass), ``angle_limit_entry`` (D.5 half of an iteration) and
``angle_restoration_entry`` (D.6 half): tuples in and out, no array access, the reference's
early returns written as selects.

The solves are written on the edge v = cp - pp rather than on world positions, and the
restoration's from-to rotation is applied as a turn in the plane of the edge and its rest
direction (``restoration_offset``) with the fma forms of acos and sincos: the reference's
results up to round-off, on a short dependency chain; docs/angle_maths.md says why each form is the same rotation, tests/test_angle_maths.py measures
the difference per call.
"""
from __future__ import annotations

import math


from magica_py.jit import kernel
from magica_py.kernels import trig
from magica_py.kernels.math3d import (
    inverse_mass_friction, lerp, load3, load4, orthogonal_axis,
    q_axis_angle, q_inverse, q_mul, q_rotate, saturate, store3, store4, v_add, v_cross, v_dot, v_length,
    v_scale, v_sub,
)
from reference_solver.solver.maths import angle_between_vectors, clamp_angle
from reference_solver.solver.parameters import curve_at, curve_at_clamp01, step_rate

MOVE = 0x02
ITERATIONS = 3               # AngleLimitIteration
LIMIT_ATTENUATION = 0.9      # AngleLimitAttenuation
LIMIT_PIVOT = 0.4
ZERO3 = (0.0, 0.0, 0.0)
IDENTITY = (0.0, 0.0, 0.0, 1.0)


@kernel(inline="always")
def swing_rotation(a, b):
    """``rotations.full_swing(a, b)`` (unit a, b), the same bits on every path, without the
    branch full_swing can never take: its degenerate cases call ``from_to_rotation_unit``
    whose general (acos, sincos) branch is excluded by the very tests that led there.
    Returns (rotation, opposite)."""
    c = v_dot(a, b)
    c = 1.0 if c > 1.0 else c
    c = -1.0 if c < -1.0 else c
    x = v_cross(a, b)
    w = 1.0 + c
    inv = 1.0 / math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2] + w * w)
    half_angle = (x[0] * inv, x[1] * inv, x[2] * inv, w * inv)
    opposite = abs(1.0 + c) < 1e-6
    flip = q_axis_angle(orthogonal_axis(a), math.pi * 1.0)
    return (flip if opposite else (IDENTITY if abs(1.0 - c) < 1e-6 else half_angle)), opposite


@kernel(inline="always")
def restoration_offset(a, v, vl, b, t):
    """``r - v`` for ``r = from_to_rotation_unit(a, b, t) · v`` (a = v / vl unit, b unit): the
    same rotation written for a short dependency chain. v turns by t times the angle theta = acos(a·b) in the plane of a and b:
    ``r = v cos(t theta) + vl sin(t theta) w / |w|``, w = b - (a·b) a the in-plane
    direction towards b (``(axis x a) |a x b|`` for the reference's axis = normalize(a x b),
    so the rotation about that axis of a vector orthogonal to it). No quaternion, no cross
    product, one sincos of the full angle; acos and sincos in their fma forms
    (``trig.acos_fma``, ``trig.sincos_fma``). Paths as the reference's: parallel (1 - c <
    1e-6) gives 0, opposite (1 + c < 1e-6) turns t pi about ``orthogonal_axis(a)`` (w =
    axis x a).

    Returns (r - v, opposite)."""
    c = v_dot(a, b)
    c = 1.0 if c > 1.0 else c
    c = -1.0 if c < -1.0 else c
    opposite = abs(1.0 + c) < 1e-6
    parallel = abs(1.0 - c) < 1e-6
    w = v_sub(b, v_scale(a, c))
    theta = trig.acos_fma(c)
    w = v_cross(orthogonal_axis(a), a) if opposite else w
    theta = math.pi if opposite else theta
    k = vl / v_length(w)   # off the chain: ready before the sincos
    s, co = trig.sincos_fma(theta * t)
    d = v_sub(v_scale(w, s * k), v_scale(v, 1.0 - co))
    return (ZERO3 if (not opposite) & parallel else d), opposite


# ----------------------------------------------------------------------------- per element
@kernel
def limit_angle_at(prm, team, depth):
    """D.5 limit angle (rad) of a particle at ``depth``."""
    return math.radians(curve_at(prm.limit_angle_curve, team, depth))


@kernel
def restoration_rate_at(prm, team, depth, frequency_ratio, power_w):
    """D.6 restoration stiffness of this step at ``depth``, before the team's gravity factor."""
    kr = curve_at_clamp01(prm.restoration_stiffness_curve, team, depth)
    return saturate(step_rate(kr, frequency_ratio, power_w, prm.rate_mode[team]))


@kernel
def restoration_gravity_factor(falloff, gravity_dot):
    """D.6 stiffness factor: 1 with gravity along the rest pose's, 1 - falloff against it."""
    return lerp(1.0 - falloff, 1.0, gravity_dot)


@kernel(inline="always")
def angle_buffer_entry(cp, pp, c_basic_pos, p_basic_pos, c_basic_rot, p_basic_rot, old_rest_direction):
    """Buffering pass of a non-root entry (child c of parent p).

    Returns (angle_length, angle_local_pos, angle_local_rot, angle_rest_vector,
    angle_rest_length, angle_rest_direction); a degenerate segment or rest edge (< 1e-8 m)
    gives length 0, a zero local direction and the identity rotation, and a degenerate rest
    edge keeps ``old_rest_direction`` (the restoration snaps that child and never reads it)."""
    length = v_length(v_sub(cp, pp))
    bv = v_sub(c_basic_pos, p_basic_pos)
    blen = v_length(bv)
    iq = q_inverse(p_basic_rot)
    direction = v_scale(bv, 1.0 / blen)
    local_pos = q_rotate(iq, direction)
    local_rot = q_mul(iq, c_basic_rot)
    degenerate = (length < 1e-8) | (blen < 1e-8)
    length = 0.0 if degenerate else length
    local_pos = ZERO3 if degenerate else local_pos
    local_rot = IDENTITY if degenerate else local_rot
    rest_direction = direction if blen >= 1e-8 else old_rest_direction
    return length, local_pos, local_rot, bv, blen, rest_direction


@kernel(inline="always")
def edge_of(cp, pp):
    """(v, |v|, v / |v|) of the edge cp - pp: what the restoration turns when no limit pass
    ran before it (``angle_limit_entry`` returns the same triple of the edge it leaves)."""
    v = v_sub(cp, pp)
    vl = v_length(v)
    return v, vl, v_scale(v, 1.0 / vl)


@kernel(inline="always")
def angle_limit_entry(cp, pp, vel_c, vel_p, rot_c, rot_p, local_pos, local_rot, length, max_angle,
                      max_angle_cos, wc, wp, p_move, stiffness, attenuation):
    """The angle-limit half of one iteration for child c (positions cp, pp read at its start).

    ``vel_*`` velocity_pos, ``rot_*`` angle_rotation, ``local_*`` / ``length`` the buffered
    angle_local_pos / angle_local_rot / angle_length of c. Returns (cp, pp, next_c, vel_c,
    vel_p, rot_c, edge): the positions the restoration sees, then c's next_pos, both
    velocity_pos and c's angle_rotation after the pass (p's next_pos is the returned pp), and
    the edge the restoration turns, (cp - pp, its length, its direction) of the returned
    positions, computed on the edge (``edge_of`` of them up to round-off). Paths, in the
    reference's order: segment shorter than 1e-8 m: nothing; degenerate rest direction: c
    snaps onto p but the returned cp stays as it was (quirk); degenerate rest length:
    nothing; otherwise the limit is solved about the pivot at 0.4 and c's rotation swung
    (kept when the new segment is degenerate).

    Also returns ``rare``: the solve path met a limit violation or an opposite swing."""
    v = v_sub(cp, pp)
    vl = v_length(v)
    tv = q_rotate(rot_p, local_pos)
    tl = v_length(tv)
    rest_rot = q_mul(rot_p, local_rot)
    inv_vl = 1.0 / vl
    vn = v_scale(v, inv_vl)
    tn = v_scale(tv, 1.0 / tl)
    lc = (vl + length) * 0.5
    # alpha > max angle <=> cos(alpha) < cos(max angle): acos only for a violation
    violated = v_dot(vn, tn) < max_angle_cos
    # solve_pivot_pair(pp, cp, vn lc, r, 0.4, wp, wc) with cp - pp = v, written on the edge:
    # r = vn lc (no violation) leaves p in place and moves c along v by (lc / vl - 1) v, so the
    # new edge is v (1 + s), s = (length - vl) / (2 vl) wc: same direction vn, no sqrt
    stretch = (length - vl) * 0.5 * inv_vl   # lc / vl - 1
    s = stretch * wc
    dc = v_scale(v, s)
    dp = ZERO3
    edge = v_scale(v, 1.0 + s)
    edge_length = vl * (1.0 + s)
    edge_unit = vn
    if violated:
        rescaled = v_scale(vn, lc)
        alpha = angle_between_vectors(rescaled, tn)
        if alpha > max_angle:
            turn = v_sub(clamp_angle(rescaled, tn, lerp(alpha, max_angle, stiffness)), rescaled)
            dp = v_scale(turn, -LIMIT_PIVOT * wp)
            dc = v_scale(v_add(v_scale(v, stretch), v_scale(turn, 1.0 - LIMIT_PIVOT)), wc)
            edge = v_add(v, v_sub(dc, dp) if p_move else dc)
            edge_length = v_length(edge)
            edge_unit = v_scale(edge, 1.0 / edge_length)
    solved_c = v_add(cp, dc)
    solved_vel_c = v_add(vel_c, v_scale(dc, attenuation))
    solved_p = v_add(pp, dp) if p_move else pp
    solved_vel_p = v_add(vel_p, v_scale(dp, attenuation)) if p_move else vel_p
    swing, opposite = swing_rotation(tn, edge_unit)
    swung = q_mul(swing, rest_rot)
    solved_rot = rot_c if edge_length < 1e-8 else swung
    # path selection (a NaN compares false everywhere, as the reference's early returns do)
    skip = vl < 1e-8
    snap = (not skip) & (tl < 1e-8)
    solve = (not skip) & (not (tl < 1e-8)) & (not ((length < 1e-8) | (lc < 1e-8)))
    snapped_vel_c = v_add(vel_c, v_sub(pp, cp))
    next_c = solved_c if solve else (pp if snap else cp)
    vel_c = solved_vel_c if solve else (snapped_vel_c if snap else vel_c)
    vel_p = solved_vel_p if solve else vel_p
    rot_c = solved_rot if solve else (rest_rot if snap else rot_c)
    cp = solved_c if solve else cp
    pp = solved_p if solve else pp
    edge = edge if solve else v
    edge_length = edge_length if solve else vl
    edge_unit = edge_unit if solve else vn
    rare = solve & (violated | ((not (edge_length < 1e-8)) & opposite))
    return cp, pp, next_c, vel_c, vel_p, rot_c, (edge, edge_length, edge_unit), rare


@kernel(inline="always")
def angle_restoration_entry(cp, pp, edge, next_c, vel_c, next_p, vel_p, rest_length, rest_direction, stiffness,
                            pivot, wc, wp, p_move, attenuation):
    """The restoration half of one iteration for child c: the edge cp - pp (as the limit
    pass returned it; ``edge`` = (v, |v|, v / |v|) of it, from ``angle_limit_entry`` or
    ``edge_of``) turned towards ``rest_direction`` by ``stiffness`` about the point at
    ``pivot``, the corrections added to the current next_pos / velocity_pos of c and p.
    A degenerate rest edge snaps c onto pp; a degenerate edge does nothing.
    Returns (next_c, vel_c, next_p, vel_p, rare): ``rare``, the solve path met an opposite
    edge."""
    v, vl, a = edge
    d, opposite = restoration_offset(a, v, vl, rest_direction, stiffness)
    # solve_pivot_pair(pp, cp, v, v + d, pivot, wp, wc) with cp - pp = v: the pivot cancels
    dp = v_scale(d, -pivot * wp)
    dc = v_scale(d, (1.0 - pivot) * wc)
    snap = rest_length < 1e-8
    solve = (not snap) & (not (vl < 1e-8))
    move_p = solve & p_move
    snapped_vel_c = v_add(vel_c, v_sub(pp, cp))
    solved_next_c = v_add(next_c, dc)
    solved_vel_c = v_add(vel_c, v_scale(dc, attenuation))
    solved_next_p = v_add(next_p, dp)
    solved_vel_p = v_add(vel_p, v_scale(dp, attenuation))
    next_c_out = solved_next_c if solve else (pp if snap else next_c)
    vel_c_out = solved_vel_c if solve else (snapped_vel_c if snap else vel_c)
    next_p = solved_next_p if move_p else next_p
    vel_p = solved_vel_p if move_p else vel_p
    return next_c_out, vel_c_out, next_p, vel_p, solve & opposite


# ----------------------------------------------------------------------------- per team
@kernel
def angle_team(m, ps, prm, ts, team, frequency_ratio, power_w, limit_attenuation, restoration_attenuation):
    """D.5/D.6 over every baseline of one team.

    The inverse mass (friction does not change in this routine), the restoration stiffness
    (curve, rate conversion, gravity factor) and the rest direction (length, unit vector) of
    each particle are computed once per step in the buffering pass
    rather than in each of the 3 iterations (same operations on the same values: same bits)."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_attribute, m_baseline_count, m_baseline_data = m.attribute, m.baseline_count, m.baseline_data
    m_baseline_start, m_depth, m_parent = m.baseline_start, m.depth, m.parent
    m_team_baseline_count, ps_angle_inverse_mass = m.team_baseline_count, ps.angle_inverse_mass
    ps_angle_length, ps_angle_limit, ps_angle_limit_cos = ps.angle_length, ps.angle_limit, ps.angle_limit_cos
    ps_angle_local_pos, ps_angle_local_rot = ps.angle_local_pos, ps.angle_local_rot
    ps_angle_rest_direction, ps_angle_rest_length = ps.angle_rest_direction, ps.angle_rest_length
    ps_angle_rest_vector, ps_angle_restoration_k = ps.angle_rest_vector, ps.angle_restoration_k
    ps_angle_rotation, ps_friction, ps_next_pos = ps.angle_rotation, ps.friction, ps.next_pos
    ps_step_basic_pos, ps_step_basic_rot = ps.step_basic_pos, ps.step_basic_rot
    ps_velocity_pos = ps.velocity_pos
    use_limit = prm.use_angle_limit[team] != 0
    use_restoration = prm.use_restoration[team] != 0
    if not use_limit and not use_restoration:
        return
    limit_stiffness = prm.limit_stiffness[team]
    gravity_factor = restoration_gravity_factor(prm.restoration_gravity_falloff[team], ts.gravity_dot[team])
    b0 = m.team_baseline_start[team]
    for b in range(b0, b0 + m_team_baseline_count[team]):
        e0 = m_baseline_start[b]
        e1 = e0 + m_baseline_count[b]
        # buffering pass
        for e in range(e0, e1):
            c = m_baseline_data[e]
            store4(ps_angle_rotation, c, load4(ps_step_basic_rot, c))
            # parents come first in a baseline (B.6), so wp below is always this step's value
            ps_angle_inverse_mass[c] = inverse_mass_friction(ps_friction[c])
            if e == e0:
                continue
            p = m_parent[c]
            length, local_pos, local_rot, rest_vector, rest_length, rest_direction = angle_buffer_entry(
                load3(ps_next_pos, c), load3(ps_next_pos, p), load3(ps_step_basic_pos, c),
                load3(ps_step_basic_pos, p), load4(ps_step_basic_rot, c), load4(ps_step_basic_rot, p),
                load3(ps_angle_rest_direction, c))
            ps_angle_length[c] = length
            store3(ps_angle_local_pos, c, local_pos)
            store4(ps_angle_local_rot, c, local_rot)
            store3(ps_angle_rest_vector, c, rest_vector)
            if use_restoration:  # the rest direction does not change over the iterations
                ps_angle_rest_length[c] = rest_length
                store3(ps_angle_rest_direction, c, rest_direction)
                ps_angle_restoration_k[c] = restoration_rate_at(prm, team, m_depth[c], frequency_ratio,
                                                                power_w) * gravity_factor
            if use_limit:
                max_angle = limit_angle_at(prm, team, m_depth[c])
                ps_angle_limit[c] = max_angle
                ps_angle_limit_cos[c] = trig.cos(max_angle)
        for k in range(ITERATIONS):
            rest_pivot = lerp(0.1, 0.5, k / 2.0)
            for e in range(e0 + 1, e1):
                c = m_baseline_data[e]
                if (m_attribute[c] & MOVE) == 0:
                    continue
                p = m_parent[c]
                p_move = (m_attribute[p] & MOVE) != 0
                cp = load3(ps_next_pos, c)
                pp = load3(ps_next_pos, p)
                next_c = cp
                vel_c = load3(ps_velocity_pos, c)
                vel_p = load3(ps_velocity_pos, p)
                wc = ps_angle_inverse_mass[c]
                wp = ps_angle_inverse_mass[p]
                if use_limit:
                    cp, pp, next_c, vel_c, vel_p, rot_c, edge, _rare = angle_limit_entry(
                        cp, pp, vel_c, vel_p, load4(ps_angle_rotation, c), load4(ps_angle_rotation, p),
                        load3(ps_angle_local_pos, c), load4(ps_angle_local_rot, c), ps_angle_length[c],
                        ps_angle_limit[c], ps_angle_limit_cos[c], wc, wp, p_move, limit_stiffness,
                        limit_attenuation)
                    store4(ps_angle_rotation, c, rot_c)
                else:
                    edge = edge_of(cp, pp)
                next_p = pp
                if use_restoration:
                    next_c, vel_c, next_p, vel_p, _rare = angle_restoration_entry(
                        cp, pp, edge, next_c, vel_c, next_p, vel_p, ps_angle_rest_length[c],
                        load3(ps_angle_rest_direction, c), ps_angle_restoration_k[c], rest_pivot, wc, wp,
                        p_move, restoration_attenuation)
                store3(ps_next_pos, c, next_c)
                store3(ps_velocity_pos, c, vel_c)
                store3(ps_next_pos, p, next_p)
                store3(ps_velocity_pos, p, vel_p)
        # clear the buffers
        for e in range(e0, e1):
            c = m_baseline_data[e]
            ps_angle_length[c] = 0.0
            store3(ps_angle_local_pos, c, ZERO3)
            store3(ps_angle_rest_vector, c, ZERO3)


