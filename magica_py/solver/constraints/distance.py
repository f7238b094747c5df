"""Distance (docs/solver.md §D.4): relax each moving particle towards the mass-weighted mean of its
links' corrections. Vertical links (parent/child) use the stiffness curve, horizontal and
shear links half of it; a zero-rest link *overwrites* the accumulated correction (Appendix 2.1).

``distance_team`` runs one team; ``distance_block`` runs every lane of a block
(``solver/batched``) with the same per-element functions (``distance_link``,
``distance_rest_length``, ``distance_apply``) in the same order, so both give the same bits.
"""
from __future__ import annotations

import math

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels.math3d import (
    inverse_mass_friction_depth, lerp, load3, saturate, store3, v_add, v_length, v_length_sq, v_scale, v_sub,
)
from magica_py.kernels.streams import READ, open_streams, sload, sload3, sstore, sstore3
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
    correction is computed either way and selected, so a lane loop over it vectorises.
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


@kernel(inline="always")
def _link_sum(acc, n, p_pos, q_pos, p_base, q_base, w_p, w_q, signed_rest, scale, animation_pose_ratio, stiffness,
              zero):
    """(acc, n) after one link of ``distance_team``'s loop: for a zero-rest link (``zero``,
    the same in every lane) the assignment, otherwise the correction added when the link
    counts. Both are computed and one selected, so the lane loop has no branch."""
    rest = distance_rest_length(signed_rest, scale, p_base, q_base, animation_pose_ratio)
    corr, ok = distance_link(p_pos, q_pos, rest, w_p, w_q, stiffness)
    summed = v_add(acc, corr)
    assigned = v_scale(v_sub(q_pos, p_pos), 0.5)
    return (assigned if zero else (summed if ok else acc)), (n + 1 if (zero | ok) else n)


@kernel
def _link_lanes(k0, q0, width, scale_base, lanes, lane_scale, signed_rest, animation_pose_ratio, stiffness,
                next_pos_a, base_pos_a, w, acc_a, count_a, first):
    """One link of particle rows k0 + i to rows q0 + i, every lane i, into the particle's running
    sum and count (``accum_*`` scratch); ``first``: the sums start from zero (the per-team
    stage's initial values) rather than from the scratch.

    Lane streams: the sum (1-3) and count (4) of the particle's rows, updated in place;
    positions, inverse masses and scales are only read."""
    zero = signed_rest == 0.0
    open_streams()
    for i in range(width):
        k = k0 + np.uint64(i)
        kq = q0 + np.uint64(i)
        loaded_acc, loaded_n = sload3(acc_a, k, 1), sload(count_a, k, 4)
        acc, n = _link_sum(ZERO3 if first else loaded_acc, 0 if first else loaded_n,
                           sload3(next_pos_a, k, READ), sload3(next_pos_a, kq, READ),
                           sload3(base_pos_a, k, READ), sload3(base_pos_a, kq, READ),
                           sload(w, k, READ), sload(w, kq, READ), signed_rest,
                           scale_base * sload(lane_scale, lanes + np.uint64(i), READ), animation_pose_ratio,
                           stiffness, zero)
        sstore3(acc_a, k, acc, 1)
        sstore(count_a, k, n, 4)


@kernel
def _last_link_lanes(k0, q0, width, scale_base, lanes, lane_scale, signed_rest, animation_pose_ratio, stiffness,
                     attenuation, next_pos_a, velocity_pos_a, base_pos_a, w, acc_a, count_a, first):
    """The particle's last link (``_link_lanes``) and the mean correction applied
    (``distance_apply``) in one loop; the scratch is left zero.

    Lane streams: sum 1-3, count 4, next_pos 5-7 and velocity_pos 8-10 of the particle's rows,
    each updated in place; the target's next_pos (another particle: the caller checks), base
    poses, inverse masses and scales are only read."""
    zero = signed_rest == 0.0
    open_streams()
    for i in range(width):
        k = k0 + np.uint64(i)
        kq = q0 + np.uint64(i)
        loaded_acc, loaded_n = sload3(acc_a, k, 1), sload(count_a, k, 4)
        position = sload3(next_pos_a, k, 5)
        acc, n = _link_sum(ZERO3 if first else loaded_acc, 0 if first else loaded_n,
                           position, sload3(next_pos_a, kq, READ),
                           sload3(base_pos_a, k, READ), sload3(base_pos_a, kq, READ),
                           sload(w, k, READ), sload(w, kq, READ), signed_rest,
                           scale_base * sload(lane_scale, lanes + np.uint64(i), READ), animation_pose_ratio,
                           stiffness, zero)
        next_pos, velocity_pos = distance_apply(position, sload3(velocity_pos_a, k, 8), acc, n, attenuation)
        sstore3(next_pos_a, k, next_pos, 5)
        sstore3(velocity_pos_a, k, velocity_pos, 8)
        sstore3(acc_a, k, ZERO3, 1)
        sstore(count_a, k, 0, 4)


@kernel
def _link_pair_lanes(k0, qa0, qb0, width, scale_base, lanes, lane_scale, rest_a, rest_b, animation_pose_ratio,
                     stiffness_a, stiffness_b, next_pos_a, base_pos_a, w, acc_a, count_a, first):
    """Two consecutive links of the particle (targets at rows qa0 + i, then qb0 + i) in one
    loop (``_link_lanes`` twice, the sums kept in registers between them)."""
    zero_a = rest_a == 0.0
    zero_b = rest_b == 0.0
    open_streams()
    for i in range(width):
        k = k0 + np.uint64(i)
        ka = qa0 + np.uint64(i)
        kb = qb0 + np.uint64(i)
        loaded_acc, loaded_n = sload3(acc_a, k, 1), sload(count_a, k, 4)
        position, base, w_p = sload3(next_pos_a, k, READ), sload3(base_pos_a, k, READ), sload(w, k, READ)
        scale = scale_base * sload(lane_scale, lanes + np.uint64(i), READ)
        acc, n = _link_sum(ZERO3 if first else loaded_acc, 0 if first else loaded_n, position,
                           sload3(next_pos_a, ka, READ), base, sload3(base_pos_a, ka, READ), w_p, sload(w, ka, READ),
                           rest_a, scale, animation_pose_ratio, stiffness_a, zero_a)
        acc, n = _link_sum(acc, n, position, sload3(next_pos_a, kb, READ), base, sload3(base_pos_a, kb, READ),
                           w_p, sload(w, kb, READ), rest_b, scale, animation_pose_ratio, stiffness_b, zero_b)
        sstore3(acc_a, k, acc, 1)
        sstore(count_a, k, n, 4)


@kernel
def _last_link_pair_lanes(k0, qa0, qb0, width, scale_base, lanes, lane_scale, rest_a, rest_b, animation_pose_ratio,
                          stiffness_a, stiffness_b, attenuation, next_pos_a, velocity_pos_a, base_pos_a, w, acc_a,
                          count_a, first):
    """The particle's last two links (``_link_pair_lanes``) and the mean correction applied
    (``_last_link_lanes``: the same streams; neither target is the particle, the caller checks)."""
    zero_a = rest_a == 0.0
    zero_b = rest_b == 0.0
    open_streams()
    for i in range(width):
        k = k0 + np.uint64(i)
        ka = qa0 + np.uint64(i)
        kb = qb0 + np.uint64(i)
        loaded_acc, loaded_n = sload3(acc_a, k, 1), sload(count_a, k, 4)
        position, base, w_p = sload3(next_pos_a, k, 5), sload3(base_pos_a, k, READ), sload(w, k, READ)
        scale = scale_base * sload(lane_scale, lanes + np.uint64(i), READ)
        acc, n = _link_sum(ZERO3 if first else loaded_acc, 0 if first else loaded_n, position,
                           sload3(next_pos_a, ka, READ), base, sload3(base_pos_a, ka, READ), w_p, sload(w, ka, READ),
                           rest_a, scale, animation_pose_ratio, stiffness_a, zero_a)
        acc, n = _link_sum(acc, n, position, sload3(next_pos_a, kb, READ), base, sload3(base_pos_a, kb, READ),
                           w_p, sload(w, kb, READ), rest_b, scale, animation_pose_ratio, stiffness_b, zero_b)
        next_pos, velocity_pos = distance_apply(position, sload3(velocity_pos_a, k, 8), acc, n, attenuation)
        sstore3(next_pos_a, k, next_pos, 5)
        sstore3(velocity_pos_a, k, velocity_pos, 8)
        sstore3(acc_a, k, ZERO3, 1)
        sstore(count_a, k, 0, 4)


@kernel
def _apply_lanes(k0, width, attenuation, next_pos_a, velocity_pos_a, acc_a, count_a):
    """``distance_apply`` from the scratch sums, which are left zero. Lane streams: next_pos
    1-3, velocity_pos 4-6, sum 7-9, count 10 of the particle's rows, each updated in place."""
    open_streams()
    for i in range(width):
        k = k0 + np.uint64(i)
        next_pos, velocity_pos = distance_apply(sload3(next_pos_a, k, 1), sload3(velocity_pos_a, k, 4),
                                                sload3(acc_a, k, 7), sload(count_a, k, 10), attenuation)
        sstore3(next_pos_a, k, next_pos, 1)
        sstore3(velocity_pos_a, k, velocity_pos, 4)
        sstore3(acc_a, k, ZERO3, 7)
        sstore(count_a, k, 0, 10)


@kernel
def distance_block(m, bs, prm, blk, b, frequency_ratio, power_y, attenuation):
    """D.4 for every lane of block b: ``distance_team``'s maths, lanes innermost.

    Each lane visits particles and links in the per-team order (Gauss-Seidel). The lane loop
    is the innermost loop for every link; between a particle's links its running sum and count
    live in the ``accum_vector`` / ``accum_count`` scratch rows of that particle (zero between
    stages, left zero here). Links run two per lane loop (the sums in registers between the
    two); the first link starts from zero, the last loop also applies the mean correction, so
    a particle with one or two links never touches the scratch; a particle without
    links is left as it is (``distance_apply`` with n == 0 returns its inputs). What depends on
    topology or parameters only (zero-rest link, stiffness) is decided outside the lane loop.
    The inverse masses (friction does not change during the pass) are computed once per
    particle and lane into the block scratch ``distance_inverse_mass``, instead of twice per link.

    Lane streams (``kernels/streams``): each loop writes only the particle's own rows. The last
    loop also writes next_pos there while reading its targets': if one of them were the
    particle itself (never in a built model: links join distinct vertices, but the test is one
    compare) its links run as any others and the correction is applied in a loop of its own."""
    ex = blk.block_exemplar[b]
    width = blk.block_width[b]
    lanes = np.uint64(blk.block_lane_base[b])
    row_base = blk.block_row_base[b]
    count = blk.block_particle_count[b]
    p0 = m.team_particle_start[ex]
    a = prm.animation_pose_ratio[ex]
    init_scale = m.team_init_scale[ex, 0]
    next_pos_a, velocity_pos_a, base_pos_a, friction = bs.next_pos, bs.velocity_pos, bs.base_pos, bs.friction
    acc_a, count_a, lane_scale, w = bs.accum_vector, bs.accum_count, bs.lane_scale_ratio, bs.distance_inverse_mass
    for p in range(count):
        k0 = np.uint64(row_base + p * width)
        open_streams()
        if (m.attribute[p0 + p] & MOVE) == 0:
            for i in range(width):
                sstore(w, k0 + np.uint64(i), 1.0 / FIX_MASS, 1)
        else:
            depth = m.depth[p0 + p]
            for i in range(width):
                k = k0 + np.uint64(i)
                sstore(w, k, inverse_mass_friction_depth(sload(friction, k, READ), depth), 1)
    for p in range(count):
        links = m.distance_count[p0 + p]
        if (m.attribute[p0 + p] & MOVE) == 0 or links == 0:
            continue
        k_vertical, k_horizontal = distance_stiffness(prm, ex, m.depth[p0 + p], frequency_ratio, power_y)
        k0 = np.uint64(row_base + p * width)
        first_link = m.distance_start[p0 + p]
        end_link = first_link + links
        link = first_link
        while link < end_link:  # two links per lane loop, the sums in registers between them
            first = link == first_link
            r = m.distance_rest[link]
            q0 = np.uint64(row_base + (m.distance_target[link] - p0) * width)
            stiffness = k_vertical if r > 0.0 else k_horizontal
            if link + 1 < end_link:
                r_b = m.distance_rest[link + 1]
                qb0 = np.uint64(row_base + (m.distance_target[link + 1] - p0) * width)
                stiffness_b = k_vertical if r_b > 0.0 else k_horizontal
                last = link + 2 == end_link
                if last and q0 != k0 and qb0 != k0:
                    _last_link_pair_lanes(k0, q0, qb0, width, init_scale, lanes, lane_scale, r, r_b, a, stiffness,
                                          stiffness_b, attenuation, next_pos_a, velocity_pos_a, base_pos_a, w, acc_a,
                                          count_a, first)
                else:
                    _link_pair_lanes(k0, q0, qb0, width, init_scale, lanes, lane_scale, r, r_b, a, stiffness,
                                     stiffness_b, next_pos_a, base_pos_a, w, acc_a, count_a, first)
                    if last:
                        _apply_lanes(k0, width, attenuation, next_pos_a, velocity_pos_a, acc_a, count_a)
                link += 2
                continue
            if q0 != k0:
                _last_link_lanes(k0, q0, width, init_scale, lanes, lane_scale, r, a, stiffness, attenuation,
                                 next_pos_a, velocity_pos_a, base_pos_a, w, acc_a, count_a, first)
            else:
                _link_lanes(k0, q0, width, init_scale, lanes, lane_scale, r, a, stiffness,
                            next_pos_a, base_pos_a, w, acc_a, count_a, first)
                _apply_lanes(k0, width, attenuation, next_pos_a, velocity_pos_a, acc_a, count_a)
            link += 1
