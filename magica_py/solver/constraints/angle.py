"""Angle limit (ref §D.5) and angle restoration (§D.6), one routine per baseline, 3 iterations.

Restoration pulls each edge towards its *absolute* world direction in the step basic pose
(not parent-relative, Appendix 2.2). Masses use friction only (Appendix 2.3). Both parent and
child move; the restoration pivot grows 0.1 -> 0.3 -> 0.5 over the iterations.
"""
from __future__ import annotations

import math

from magica_py.jit import kernel
from magica_py.kernels import trig
from magica_py.kernels.math3d import (
    angle_between_vectors, clamp_angle, from_to_rotation_unit, inverse_mass_friction, lerp,
    load3, load4, q_inverse, q_mul, q_rotate, saturate, store3, store4, v_add, v_dot, v_length,
    v_scale, v_sub,
)
from magica_py.solver.parameters import curve_at, curve_at_clamp01, step_rate
from magica_py.solver.rotations import full_swing

MOVE = 0x02
ITERATIONS = 3               # AngleLimitIteration
LIMIT_ATTENUATION = 0.9      # AngleLimitAttenuation
LIMIT_PIVOT = 0.4


@kernel
def solve_pivot_pair(pp, cp, v, r, pivot_ratio, wp, wc):
    """Rotate the segment p->c from ``v`` to ``r`` about the point at ``pivot_ratio`` along it.

    Returns the corrections (dp, dc) weighted by the inverse masses."""
    pivot = v_add(pp, v_scale(v, pivot_ratio))
    dp = v_scale(v_sub(v_sub(pivot, v_scale(r, pivot_ratio)), pp), wp)
    dc = v_scale(v_sub(v_add(pivot, v_scale(r, 1.0 - pivot_ratio)), cp), wc)
    return dp, dc


@kernel
def angle_team(m, ps, prm, ts, team, frequency_ratio, power_w, limit_attenuation, restoration_attenuation):
    """D.5/D.6 over every baseline of one team.

    The inverse mass (friction does not change in this routine), the restoration stiffness
    (curve, rate conversion, gravity factor) and the rest direction (length, unit vector) of
    each particle are computed once per step in the buffering pass
    rather than in each of the 3 iterations (same operations on the same values: same bits)."""
    use_limit = prm.use_angle_limit[team] != 0
    use_restoration = prm.use_restoration[team] != 0
    if not use_limit and not use_restoration:
        return
    mode = prm.rate_mode[team]
    limit_stiffness = prm.limit_stiffness[team]
    gravity_factor = lerp(1.0 - prm.restoration_gravity_falloff[team], 1.0, ts.gravity_dot[team])
    b0 = m.team_baseline_start[team]
    for b in range(b0, b0 + m.team_baseline_count[team]):
        e0 = m.baseline_start[b]
        e1 = e0 + m.baseline_count[b]
        # buffering pass
        for e in range(e0, e1):
            c = m.baseline_data[e]
            store4(ps.angle_rotation, c, load4(ps.step_basic_rot, c))
            # parents come first in a baseline (B.6), so wp below is always this step's value
            ps.angle_inverse_mass[c] = inverse_mass_friction(ps.friction[c])
            if e == e0:
                continue
            p = m.parent[c]
            length = v_length(v_sub(load3(ps.next_pos, c), load3(ps.next_pos, p)))
            bv = v_sub(load3(ps.step_basic_pos, c), load3(ps.step_basic_pos, p))
            blen = v_length(bv)
            if length < 1e-8 or blen < 1e-8:
                ps.angle_length[c] = 0.0
                store3(ps.angle_local_pos, c, (0.0, 0.0, 0.0))
                store4(ps.angle_local_rot, c, (0.0, 0.0, 0.0, 1.0))
            else:
                ps.angle_length[c] = length
                iq = q_inverse(load4(ps.step_basic_rot, p))
                store3(ps.angle_local_pos, c, q_rotate(iq, v_scale(bv, 1.0 / blen)))
                store4(ps.angle_local_rot, c, q_mul(iq, load4(ps.step_basic_rot, c)))
            store3(ps.angle_rest_vector, c, bv)
            if use_restoration:  # the rest direction does not change over the iterations
                tl = v_length(bv)
                ps.angle_rest_length[c] = tl
                if tl >= 1e-8:
                    store3(ps.angle_rest_direction, c, v_scale(bv, 1.0 / tl))
            if use_limit:
                max_angle = math.radians(curve_at(prm.limit_angle_curve, team, m.depth[c]))
                ps.angle_limit[c] = max_angle
                ps.angle_limit_cos[c] = trig.cos(max_angle)
            if use_restoration:
                kr = curve_at_clamp01(prm.restoration_stiffness_curve, team, m.depth[c])
                ps.angle_restoration_k[c] = saturate(step_rate(kr, frequency_ratio, power_w, mode)) * gravity_factor
        for k in range(ITERATIONS):
            rest_pivot = lerp(0.1, 0.5, k / 2.0)
            for e in range(e0 + 1, e1):
                c = m.baseline_data[e]
                if (m.attribute[c] & MOVE) == 0:
                    continue
                p = m.parent[c]
                c_move = True
                p_move = (m.attribute[p] & MOVE) != 0
                cp = load3(ps.next_pos, c)
                pp = load3(ps.next_pos, p)
                wc = ps.angle_inverse_mass[c]
                wp = ps.angle_inverse_mass[p]
                if use_limit:
                    cp, pp = _limit_pass(m, ps, prm, team, c, p, cp, pp, wc, wp, p_move,
                                         limit_stiffness, limit_attenuation)
                if use_restoration:
                    tl = ps.angle_rest_length[c]
                    if tl < 1e-8:
                        store3(ps.velocity_pos, c, v_add(load3(ps.velocity_pos, c), v_sub(pp, cp)))
                        store3(ps.next_pos, c, pp)
                        continue
                    v = v_sub(cp, pp)
                    vl = v_length(v)
                    if vl < 1e-8:
                        continue
                    q = from_to_rotation_unit(v_scale(v, 1.0 / vl), load3(ps.angle_rest_direction, c),
                                              ps.angle_restoration_k[c])
                    r = q_rotate(q, v)
                    dp, dc = solve_pivot_pair(pp, cp, v, r, rest_pivot, wp, wc)
                    if c_move:
                        store3(ps.next_pos, c, v_add(load3(ps.next_pos, c), dc))
                        store3(ps.velocity_pos, c, v_add(load3(ps.velocity_pos, c), v_scale(dc, restoration_attenuation)))
                    if p_move:
                        store3(ps.next_pos, p, v_add(load3(ps.next_pos, p), dp))
                        store3(ps.velocity_pos, p, v_add(load3(ps.velocity_pos, p), v_scale(dp, restoration_attenuation)))
        # clear the buffers
        for e in range(e0, e1):
            c = m.baseline_data[e]
            ps.angle_length[c] = 0.0
            store3(ps.angle_local_pos, c, (0.0, 0.0, 0.0))
            store3(ps.angle_rest_vector, c, (0.0, 0.0, 0.0))


@kernel
def _limit_pass(m, ps, prm, team, c, p, cp, pp, wc, wp, p_move, limit_stiffness, attenuation):
    """The angle-limit half of one iteration for child c; returns the (cp, pp) restoration sees."""
    v = v_sub(cp, pp)
    vl = v_length(v)
    if vl < 1e-8:
        return cp, pp
    tv = q_rotate(load4(ps.angle_rotation, p), load3(ps.angle_local_pos, c))
    tl = v_length(tv)
    if tl < 1e-8:  # degenerate rest: snap onto the parent; the local cp stays as it was (quirk)
        store3(ps.velocity_pos, c, v_add(load3(ps.velocity_pos, c), v_sub(pp, cp)))
        store3(ps.next_pos, c, pp)
        store4(ps.angle_rotation, c, q_mul(load4(ps.angle_rotation, p), load4(ps.angle_local_rot, c)))
        return cp, pp
    vn = v_scale(v, 1.0 / vl)
    tn = v_scale(tv, 1.0 / tl)
    lb = ps.angle_length[c]
    lc = (vl + lb) * 0.5
    if lb < 1e-8 or lc < 1e-8:
        return cp, pp
    v = v_scale(vn, lc)
    r = v
    # alpha > max angle  <=>  cos(alpha) < cos(max angle): acos only for a violation
    if v_dot(vn, tn) < ps.angle_limit_cos[c]:
        alpha = angle_between_vectors(v, tn)
        max_angle = ps.angle_limit[c]
        if alpha > max_angle:
            r = clamp_angle(v, tn, lerp(alpha, max_angle, limit_stiffness))
    dp, dc = solve_pivot_pair(pp, cp, v, r, LIMIT_PIVOT, wp, wc)
    cp = v_add(cp, dc)
    store3(ps.next_pos, c, cp)
    store3(ps.velocity_pos, c, v_add(load3(ps.velocity_pos, c), v_scale(dc, attenuation)))
    if p_move:
        pp = v_add(pp, dp)
        store3(ps.next_pos, p, pp)
        store3(ps.velocity_pos, p, v_add(load3(ps.velocity_pos, p), v_scale(dp, attenuation)))
    u = v_sub(cp, pp)
    ul = v_length(u)
    if ul < 1e-8:
        return cp, pp
    rot = q_mul(full_swing(tn, v_scale(u, 1.0 / ul)),
                q_mul(load4(ps.angle_rotation, p), load4(ps.angle_local_rot, c)))
    store4(ps.angle_rotation, c, rot)
    return cp, pp
