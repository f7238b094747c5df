"""Distance (ref §D.4): relax each moving particle towards the mass-weighted mean of its
links' corrections. Vertical links (parent/child) use the stiffness curve, horizontal and
shear links half of it; a zero-rest link *overwrites* the accumulated correction (Appendix 2.1)."""
from __future__ import annotations

from magica_py.jit import kernel
from magica_py.kernels.math3d import (
    inverse_mass_friction_depth, lerp, load3, saturate, store3, v_add, v_length, v_scale, v_sub,
)
from magica_py.solver.parameters import curve_at_clamp01, step_rate

MOVE = 0x02
FIXED = 0x01
VELOCITY_ATTENUATION = 0.3   # DistanceVelocityAttenuation
FIX_MASS = 50.0              # inverse mass of a fixed partner is 1/50


@kernel
def solve_distance_link(p_pos, q_pos, rest, w_p, w_q, stiffness):
    """One link's correction of p (zero when degenerate): ``(L - L0) k (v/L) w_p/(w_p + w_q)``."""
    v = v_sub(q_pos, p_pos)
    length = v_length(v)
    if length < 1e-8:
        return (0.0, 0.0, 0.0), False
    return v_scale(v, (length - rest) * stiffness / length * w_p / (w_p + w_q)), True


@kernel
def distance_team(m, ps, prm, ts, team, frequency_ratio, power_y, attenuation):
    """D.4 over one team (Gauss-Seidel in particle order)."""
    start = m.team_particle_start[team]
    a = prm.animation_pose_ratio[team]
    s = m.team_init_scale[team, 0] * ts.scale_ratio[team]
    mode = prm.rate_mode[team]
    for p in range(start, start + m.team_particle_count[team]):
        attr = m.attribute[p]
        if (attr & MOVE) == 0:
            continue
        depth = m.depth[p]
        w_p = inverse_mass_friction_depth(ps.friction[p], depth)
        k = curve_at_clamp01(prm.distance_stiffness_curve, team, depth)
        k_vertical = saturate(step_rate(k, frequency_ratio, power_y, mode))
        k_horizontal = saturate(step_rate(k * 0.5, frequency_ratio, power_y, mode))
        pp = load3(ps.next_pos, p)
        bp = load3(ps.base_pos, p)
        acc = (0.0, 0.0, 0.0)
        n = 0
        for link in range(m.distance_start[p], m.distance_start[p] + m.distance_count[p]):
            q = m.distance_target[link]
            r = m.distance_rest[link]
            qp = load3(ps.next_pos, q)
            if r == 0.0:  # zero-distance link: assignment, not accumulation (quirk)
                acc = v_scale(v_sub(qp, pp), 0.5)
                n += 1
                continue
            if (m.attribute[q] & MOVE) == 0:
                w_q = 1.0 / FIX_MASS
            else:
                w_q = inverse_mass_friction_depth(ps.friction[q], m.depth[q])
            rest = lerp(abs(r) * s, v_length(v_sub(bp, load3(ps.base_pos, q))), a)
            corr, ok = solve_distance_link(pp, qp, rest, w_p, w_q, k_vertical if r > 0.0 else k_horizontal)
            if ok:
                acc = v_add(acc, corr)
                n += 1
        if n > 0:
            delta = v_scale(acc, 1.0 / n)
            store3(ps.next_pos, p, v_add(pp, delta))
            store3(ps.velocity_pos, p, v_add(load3(ps.velocity_pos, p), v_scale(delta, attenuation)))
