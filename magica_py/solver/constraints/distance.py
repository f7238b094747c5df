"""Distance (ref §D.4): relax each moving particle towards the mass-weighted mean of its
links' corrections. Vertical links (parent/child) use the stiffness curve, horizontal and
shear links half of it; a zero-rest link *overwrites* the accumulated correction (Appendix 2.1).

``distance_team`` runs one team; ``distance_block`` runs every lane of a block
(``solver/batched``) with the same per-element functions (``distance_link``,
``distance_rest_length``, ``distance_apply``) in the same order, so both give the same bits.
"""
from __future__ import annotations

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels.math3d import (
    inverse_mass_friction_depth, lerp, load3, saturate, store3, v_add, v_length, v_scale, v_sub,
)
from magica_py.solver.batched.transfer import bload3, bstore3
from magica_py.solver.parameters import curve_at_clamp01, step_rate

MOVE = 0x02
FIXED = 0x01
VELOCITY_ATTENUATION = 0.3   # DistanceVelocityAttenuation
FIX_MASS = 50.0              # inverse mass of a fixed partner is 1/50
ZERO3 = (0.0, 0.0, 0.0)


@kernel
def distance_link(p_pos, q_pos, rest, w_p, w_q, stiffness):
    """One link's correction of p, ``(L - L0) k (v/L) w_p/(w_p + w_q)``, and whether it counts
    (False, with a zero correction, when the link is degenerate: L < 1e-8). Branch-free: the
    correction is computed either way and selected, so a lane loop over it vectorises."""
    v = v_sub(q_pos, p_pos)
    length = v_length(v)
    ok = not (length < 1e-8)
    corr = v_scale(v, (length - rest) * stiffness / length * w_p / (w_p + w_q))
    return (corr if ok else ZERO3), ok


@kernel
def distance_rest_length(signed_rest, scale, p_base, q_base, animation_pose_ratio):
    """The link's rest length this step: the build rest length at the team's scale blended
    towards the animated pose's distance."""
    return lerp(abs(signed_rest) * scale, v_length(v_sub(p_base, q_base)), animation_pose_ratio)


@kernel
def distance_apply(position, velocity_pos, acc, n, attenuation):
    """(next_pos, velocity_pos) after the mean correction ``acc / n`` (unchanged when n == 0)."""
    delta = v_scale(acc, 1.0 / n)
    moved = v_add(position, delta)
    dragged = v_add(velocity_pos, v_scale(delta, attenuation))
    some = n > 0
    return (moved if some else position), (dragged if some else velocity_pos)


@kernel
def distance_stiffness(prm, team, depth, frequency_ratio, power_y):
    """(vertical, horizontal) per-step stiffness of a particle at ``depth``."""
    k = curve_at_clamp01(prm.distance_stiffness_curve, team, depth)
    mode = prm.rate_mode[team]
    return (saturate(step_rate(k, frequency_ratio, power_y, mode)),
            saturate(step_rate(k * 0.5, frequency_ratio, power_y, mode)))


@kernel
def distance_team(m, ps, prm, ts, team, frequency_ratio, power_y, attenuation):
    """D.4 over one team (Gauss-Seidel in particle order)."""
    start = m.team_particle_start[team]
    a = prm.animation_pose_ratio[team]
    s = m.team_init_scale[team, 0] * ts.scale_ratio[team]
    for p in range(start, start + m.team_particle_count[team]):
        if (m.attribute[p] & MOVE) == 0:
            continue
        depth = m.depth[p]
        w_p = inverse_mass_friction_depth(ps.friction[p], depth)
        k_vertical, k_horizontal = distance_stiffness(prm, team, depth, frequency_ratio, power_y)
        pp = load3(ps.next_pos, p)
        bp = load3(ps.base_pos, p)
        acc = ZERO3
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
            rest = distance_rest_length(r, s, bp, load3(ps.base_pos, q), a)
            corr, ok = distance_link(pp, qp, rest, w_p, w_q, k_vertical if r > 0.0 else k_horizontal)
            if ok:
                acc = v_add(acc, corr)
                n += 1
        next_pos, velocity_pos = distance_apply(pp, load3(ps.velocity_pos, p), acc, n, attenuation)
        store3(ps.next_pos, p, next_pos)
        store3(ps.velocity_pos, p, velocity_pos)


@kernel
def distance_block(m, bs, prm, blk, b, frequency_ratio, power_y, attenuation):
    """D.4 for every lane of block b: ``distance_team``'s maths, lanes innermost.

    Each lane visits particles and links in the per-team order (Gauss-Seidel). A particle's
    running sum and count live in the ``accum_vector`` / ``accum_count`` scratch rows of that
    particle (zero between stages, left zero here) so that the lane loop is innermost for
    every link; what depends on topology or parameters only (zero-rest link, fixed partner,
    stiffness) is decided outside the lane loop."""
    ex = blk.block_exemplar[b]
    width = blk.block_width[b]
    lanes = np.uint64(blk.block_lane_base[b])
    row_base = blk.block_row_base[b]
    p0 = m.team_particle_start[ex]
    a = prm.animation_pose_ratio[ex]
    init_scale = m.team_init_scale[ex, 0]
    next_pos_a, velocity_pos_a, base_pos_a, friction = bs.next_pos, bs.velocity_pos, bs.base_pos, bs.friction
    acc_a, count_a, lane_scale = bs.accum_vector, bs.accum_count, bs.lane_scale_ratio
    for p in range(blk.block_particle_count[b]):
        if (m.attribute[p0 + p] & MOVE) == 0:
            continue
        depth = m.depth[p0 + p]
        k_vertical, k_horizontal = distance_stiffness(prm, ex, depth, frequency_ratio, power_y)
        k0 = np.uint64(row_base + p * width)
        for link in range(m.distance_start[p0 + p], m.distance_start[p0 + p] + m.distance_count[p0 + p]):
            q = m.distance_target[link] - p0
            r = m.distance_rest[link]
            q0 = np.uint64(row_base + q * width)
            if r == 0.0:
                for i in range(width):
                    k = k0 + np.uint64(i)
                    bstore3(acc_a, k, v_scale(v_sub(bload3(next_pos_a, q0 + np.uint64(i)), bload3(next_pos_a, k)), 0.5))
                    count_a[k] += 1
                continue
            stiffness = k_vertical if r > 0.0 else k_horizontal
            if (m.attribute[p0 + q] & MOVE) == 0:
                for i in range(width):
                    k = k0 + np.uint64(i)
                    kq = q0 + np.uint64(i)
                    rest = distance_rest_length(r, init_scale * lane_scale[lanes + np.uint64(i)],
                                                bload3(base_pos_a, k), bload3(base_pos_a, kq), a)
                    corr, ok = distance_link(bload3(next_pos_a, k), bload3(next_pos_a, kq), rest,
                                             inverse_mass_friction_depth(friction[k], depth), 1.0 / FIX_MASS,
                                             stiffness)
                    acc = bload3(acc_a, k)
                    bstore3(acc_a, k, v_add(acc, corr) if ok else acc)
                    count_a[k] += 1 if ok else 0
            else:
                depth_q = m.depth[p0 + q]
                for i in range(width):
                    k = k0 + np.uint64(i)
                    kq = q0 + np.uint64(i)
                    rest = distance_rest_length(r, init_scale * lane_scale[lanes + np.uint64(i)],
                                                bload3(base_pos_a, k), bload3(base_pos_a, kq), a)
                    corr, ok = distance_link(bload3(next_pos_a, k), bload3(next_pos_a, kq), rest,
                                             inverse_mass_friction_depth(friction[k], depth),
                                             inverse_mass_friction_depth(friction[kq], depth_q), stiffness)
                    acc = bload3(acc_a, k)
                    bstore3(acc_a, k, v_add(acc, corr) if ok else acc)
                    count_a[k] += 1 if ok else 0
        for i in range(width):
            k = k0 + np.uint64(i)
            next_pos, velocity_pos = distance_apply(bload3(next_pos_a, k), bload3(velocity_pos_a, k),
                                                    bload3(acc_a, k), count_a[k], attenuation)
            bstore3(next_pos_a, k, next_pos)
            bstore3(velocity_pos_a, k, velocity_pos)
            bstore3(acc_a, k, ZERO3)
            count_a[k] = 0
