"""Distance (docs/solver.md §D.4): relax each moving particle towards the mass-weighted mean of its
links' corrections. Vertical links (parent/child) use the stiffness curve, horizontal and
shear links half of it; a zero-rest link *overwrites* the accumulated correction (Appendix 2.1).

``distance_team`` runs one team through the per-element functions ``distance_link``,
``distance_rest_length`` and ``distance_apply``.
"""
from __future__ import annotations

import math


from magica_py.jit import kernel
from magica_py.kernels.math3d import (
    inverse_mass_friction_depth, lerp, load3, saturate, store3, v_add, v_length, v_length_sq, v_scale, v_sub,
)
from reference_solver.solver.parameters import constraint_stiffness, curve_at_clamp01

MOVE = 0x02
FIXED = 0x01
VELOCITY_ATTENUATION = 0.3   # DistanceVelocityAttenuation
FIX_MASS = 50.0              # inverse mass of a fixed partner is 1/50
ZERO3 = (0.0, 0.0, 0.0)


@kernel
def distance_link(p_pos, q_pos, rest, w_p, w_q, stiffness):
    """One link's correction of p, ``(L - L0) k (v/L) w_p/(w_p + w_q)``, and whether it counts
    (False, with a zero correction, when the link is degenerate: L < 1e-8). Branch-free: the
    correction is computed either way and selected.
    One division, by ``L (w_p + w_q)``, for the reference's two (docs/distance_bending_maths.md)."""
    v = v_sub(q_pos, p_pos)
    length = v_length(v)
    ok = not (length < 1e-8)
    corr = v_scale(v, (length - rest) * stiffness * w_p / (length * (w_p + w_q)))
    return (corr if ok else ZERO3), ok


@kernel
def distance_rest_length(signed_rest, scale, p_base, q_base, animation_pose_ratio):
    """The link's rest length this step: the build rest length at the team's scale blended
    towards the animated pose's distance, ``lerp(|rest| scale, |p_base - q_base|, ratio)``.

    With a ratio of 0 the lerp is ``x + (d - x) * 0``: x when d is finite, NaN when it is not,
    and the squared distance is finite exactly when the distance is, so it stands in for the
    distance with the same bits and without the square root."""
    d2 = v_length_sq(v_sub(p_base, q_base))
    pose = math.sqrt(d2) if animation_pose_ratio != 0.0 else d2
    return lerp(abs(signed_rest) * scale, pose, animation_pose_ratio)


@kernel
def distance_apply(position, velocity_pos, acc, n, attenuation):
    """(next_pos, velocity_pos) after the mean correction ``acc / n`` (unchanged when n == 0)."""
    delta = v_scale(acc, 1.0 / max(n, 1))   # no link: discarded below (and no 1/0 with the JIT off)
    moved = v_add(position, delta)
    dragged = v_add(velocity_pos, v_scale(delta, attenuation))
    some = n > 0
    return (moved if some else position), (dragged if some else velocity_pos)


@kernel
def distance_stiffness(prm, team, depth, frequency_ratio, power_y):
    """(vertical, horizontal) per-step stiffness of a particle at ``depth``."""
    k = curve_at_clamp01(prm.distance_stiffness_curve, team, depth)
    mode = prm.rate_mode[team]
    quality = prm.quality[team]
    return (saturate(constraint_stiffness(k, frequency_ratio, power_y, mode, quality)),
            saturate(constraint_stiffness(k * 0.5, frequency_ratio, power_y, mode, quality)))


@kernel
def distance_team(m, ps, prm, ts, team, frequency_ratio, power_y, attenuation):
    """D.4 over one team (Gauss-Seidel in particle order). The tables' arrays are read into
    locals once (a table field read in the loop would take and release a reference each time)."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_team_particle_count = m.team_particle_count
    start = m.team_particle_start[team]
    a = prm.animation_pose_ratio[team]
    s = m.team_init_scale[team, 0] * ts.scale_ratio[team]
    attribute, depth_of, friction = m.attribute, m.depth, ps.friction
    distance_start, distance_count, distance_target, distance_rest = (
        m.distance_start, m.distance_count, m.distance_target, m.distance_rest)
    next_pos_a, base_pos_a, velocity_pos_a = ps.next_pos, ps.base_pos, ps.velocity_pos
    for p in range(start, start + m_team_particle_count[team]):
        if (attribute[p] & MOVE) == 0:
            continue
        depth = depth_of[p]
        w_p = inverse_mass_friction_depth(friction[p], depth)
        k_vertical, k_horizontal = distance_stiffness(prm, team, depth, frequency_ratio, power_y)
        pp = load3(next_pos_a, p)
        bp = load3(base_pos_a, p)
        acc = ZERO3
        n = 0
        for link in range(distance_start[p], distance_start[p] + distance_count[p]):
            q = distance_target[link]
            r = distance_rest[link]
            qp = load3(next_pos_a, q)
            if r == 0.0:  # zero-distance link: assignment, not accumulation (quirk)
                acc = v_scale(v_sub(qp, pp), 0.5)
                n += 1
                continue
            if (attribute[q] & MOVE) == 0:
                w_q = 1.0 / FIX_MASS
            else:
                w_q = inverse_mass_friction_depth(friction[q], depth_of[q])
            rest = distance_rest_length(r, s, bp, load3(base_pos_a, q), a)
            corr, ok = distance_link(pp, qp, rest, w_p, w_q, k_vertical if r > 0.0 else k_horizontal)
            if ok:
                acc = v_add(acc, corr)
                n += 1
        next_pos, velocity_pos = distance_apply(pp, load3(velocity_pos_a, p), acc, n, attenuation)
        store3(next_pos_a, p, next_pos)
        store3(velocity_pos_a, p, velocity_pos)


