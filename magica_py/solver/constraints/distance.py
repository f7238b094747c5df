"""Distance (docs/solver.md §D.4): relax each moving particle towards the mass-weighted mean of its
links' corrections. Vertical links (parent/child) use the stiffness curve, horizontal and
shear links half of it; a zero-rest link *overwrites* the accumulated correction (Appendix 2.1).

``distance_block`` runs one block: a first pass writes every particle's inverse mass and
stiffness of this pass (``distance_particle_terms``), then the particles in order
(Gauss-Seidel, §D.0), each link gathered (``PARTNER_*`` rows) and solved across the lanes
(``distance_link_lanes``: ``distance_rest_length``, ``distance_link``), the mean applied
(``distance_apply``). With an animation pose ratio of 0 (every preset's) the rest length is the
build's at the team's scale, and the animated distance is neither gathered nor computed.
"""
from __future__ import annotations

import numpy as np

from magica_py.build.proxy import MOVE
from magica_py.jit import kernel
from magica_py.kernels.math3d import (
    inverse_mass_friction_depth, lerp, saturate, v_add, v_length, v_scale, v_sub,
)
from magica_py.solver import blocks as bk
from magica_py.solver import state as st
from magica_py.solver.lanes import LANES, get1, get3, put1, put3
from magica_py.solver.parameters import (
    PRM_ANIMATION_POSE_RATIO, PRM_QUALITY, PRM_RATE_MODE, clamp01, constraint_stiffness,
)

VELOCITY_ATTENUATION = 0.3   # DistanceVelocityAttenuation
FIX_MASS = 50.0              # inverse mass of a fixed partner is 1/50
ZERO3 = (0.0, 0.0, 0.0)


@kernel(inline="always")
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


@kernel(inline="always")
def distance_rest_length(signed_rest, scale, p_base, q_base, animation_pose_ratio):
    """The link's rest length this step: the build rest length at the team's scale blended
    towards the animated pose's distance, ``lerp(|rest| scale, |p_base - q_base|, ratio)``.
    ``distance_link_lanes`` calls it only for a ratio other than 0 (``a_zero``)."""
    return lerp(abs(signed_rest) * scale, v_length(v_sub(p_base, q_base)), animation_pose_ratio)


@kernel(inline="always")
def distance_apply(position, velocity_pos, acc, n, attenuation):
    """(next_pos, velocity_pos) after the mean correction ``acc / n`` (unchanged when n == 0)."""
    delta = v_scale(acc, 1.0 / max(n, 1))   # no link: discarded below (and no 1/0 with the JIT off)
    moved = v_add(position, delta)
    dragged = v_add(velocity_pos, v_scale(delta, attenuation))
    some = n > 0
    return (moved if some else position), (dragged if some else velocity_pos)


@kernel(inline="always")
def distance_stiffness(curve, frequency_ratio, power_y, mode, quality):
    """(vertical, horizontal) per-step stiffness of a particle whose stiffness curve value is
    ``curve``."""
    k = clamp01(curve)
    return (saturate(constraint_stiffness(k, frequency_ratio, power_y, mode, quality)),
            saturate(constraint_stiffness(k * 0.5, frequency_ratio, power_y, mode, quality)))


@kernel(inline="always")
def distance_particle_terms(PS, PM, PP, P, BI, topology, b, frequency_ratio, power_y):
    """Every particle's inverse mass of this pass (1/50 when fixed) and its link stiffnesses,
    written to ``INVERSE_MASS``, ``K_VERTICAL``, ``K_HORIZONTAL``."""
    g0 = BI[b, bk.BI_G0]
    w = bk.lane_width(BI, b)
    attribute = BI[b, bk.BI_ATTRIBUTE]
    mode = int(P[b, PRM_RATE_MODE])
    quality = int(P[b, PRM_QUALITY])
    for j in range(BI[b, bk.BI_N]):
        g = g0 + j
        if (topology[attribute + j] & MOVE) == 0:
            for l in range(w):
                put1(PS, g, st.INVERSE_MASS, l, 1.0 / FIX_MASS)
            continue
        # the stiffness's rate conversion (a pow, an opaque call that keeps a loop scalar) is
        # left out of the compiled loop by constant arguments where it cannot apply (plain
        # int64 values, which LLVM folds after inlining: docs/tech-notes.md §7)
        if mode == 0:
            distance_terms_lanes(PS, PM, PP, g, w, frequency_ratio, power_y, np.int64(0), quality)
        elif quality == 0 or frequency_ratio == 1.0:
            distance_terms_lanes(PS, PM, PP, g, w, 1.0, power_y, mode, quality)
        else:
            distance_terms_lanes(PS, PM, PP, g, w, frequency_ratio, power_y, mode, quality)


@kernel
def distance_terms_lanes(PS, PM, PP, g, w, frequency_ratio, power_y, mode, quality):
    """``distance_particle_terms`` of the Move particle in slot g, lanes 0..w."""
    for l in range(w):
        depth = get1(PM, g, bk.DEPTH, l)
        put1(PS, g, st.INVERSE_MASS, l, inverse_mass_friction_depth(get1(PS, g, st.FRICTION, l), depth))
        k_vertical, k_horizontal = distance_stiffness(get1(PP, g, bk.CURVE_DISTANCE_STIFFNESS, l), frequency_ratio,
                                                      power_y, mode, quality)
        put1(PS, g, st.K_VERTICAL, l, k_vertical)
        put1(PS, g, st.K_HORIZONTAL, l, k_horizontal)


@kernel
def distance_link_lanes(PS, TS, TM, LM, g, b, lk, w, a, a_zero):
    """One link (slot ``lk``) of the Move particle in slot g, lanes 0..w, its partner's rows
    gathered next to it: the correction added to ``ACCUM3`` / ``ACCUM_N``. ``a_zero``: the
    animation pose ratio a is 0 (a constant at each call site), where the rest length is the
    build's at the team's scale, ``lerp(x, d, 0)``, and the animated distance d is not read
    (the same bits for every finite d; ``PARTNER_BASE`` is not gathered)."""
    for l in range(min(w, LANES)):
        r = get1(LM, lk, bk.DISTANCE_REST, l)
        pp = get3(PS, g, st.NEXT_POS, l)
        qp = get3(PS, g, st.PARTNER_POS, l)
        s = get1(TM, b, bk.INIT_SCALE, l) * get1(TS, b, st.SCALE_RATIO, l)
        if a_zero:
            rest = abs(r) * s
        else:
            rest = distance_rest_length(r, s, get3(PS, g, st.BASE_POS, l), get3(PS, g, st.PARTNER_BASE, l), a)
        k_vertical = get1(PS, g, st.K_VERTICAL, l)
        k_horizontal = get1(PS, g, st.K_HORIZONTAL, l)
        corr, ok = distance_link(pp, qp, rest, get1(PS, g, st.INVERSE_MASS, l), get1(PS, g, st.PARTNER_W, l),
                                 k_vertical if r > 0.0 else k_horizontal)
        acc = get3(PS, g, st.ACCUM3, l)
        n = get1(PS, g, st.ACCUM_N, l)
        zero = r == 0.0   # zero-distance link: assignment, not accumulation (quirk)
        half = v_scale(v_sub(qp, pp), 0.5)
        summed = v_add(acc, corr)
        acc = half if zero else (summed if ok else acc)
        put3(PS, g, st.ACCUM3, l, acc)
        put1(PS, g, st.ACCUM_N, l, n + (1.0 if (zero or ok) else 0.0))


@kernel(forceinline=False)
def distance_block(PS, PM, PP, TS, TM, LM, P, BI, topology, b, frequency_ratio, power_y, attenuation):
    """D.4 over block b (Gauss-Seidel in particle order, every lane side by side)."""
    distance_particle_terms(PS, PM, PP, P, BI, topology, b, frequency_ratio, power_y)
    g0 = BI[b, bk.BI_G0]
    w = bk.lane_width(BI, b)
    attribute = BI[b, bk.BI_ATTRIBUTE]
    link_start, link_count, link_target = (BI[b, bk.BI_DISTANCE_START], BI[b, bk.BI_DISTANCE_COUNT],
                                           BI[b, bk.BI_DISTANCE_TARGET])
    link0 = BI[b, bk.BI_LINK0]
    a = P[b, PRM_ANIMATION_POSE_RATIO]
    a_zero = a == 0.0
    for j in range(BI[b, bk.BI_N]):
        if (topology[attribute + j] & MOVE) == 0:
            continue
        g = g0 + j
        for l in range(w):
            put3(PS, g, st.ACCUM3, l, ZERO3)
            put1(PS, g, st.ACCUM_N, l, 0.0)
        k0 = topology[link_start + j]
        for k in range(k0, k0 + topology[link_count + j]):
            gq = g0 + topology[link_target + k]
            for l in range(w):   # the partner's values next to p's (solving then reads item g only)
                put3(PS, g, st.PARTNER_POS, l, get3(PS, gq, st.NEXT_POS, l))
                put1(PS, g, st.PARTNER_W, l, get1(PS, gq, st.INVERSE_MASS, l))
            if not a_zero:
                for l in range(w):
                    put3(PS, g, st.PARTNER_BASE, l, get3(PS, gq, st.BASE_POS, l))
            # a ratio of 0 goes in as a constant: the animated distance is then not read at all
            if a_zero:
                distance_link_lanes(PS, TS, TM, LM, g, b, link0 + k, w, a, np.bool_(True))
            else:
                distance_link_lanes(PS, TS, TM, LM, g, b, link0 + k, w, a, np.bool_(False))
        for l in range(w):
            next_pos, velocity_pos = distance_apply(get3(PS, g, st.NEXT_POS, l), get3(PS, g, st.VELOCITY_POS, l),
                                                    get3(PS, g, st.ACCUM3, l), get1(PS, g, st.ACCUM_N, l), attenuation)
            put3(PS, g, st.NEXT_POS, l, next_pos)
            put3(PS, g, st.VELOCITY_POS, l, velocity_pos)
