"""Triangle bending and volume (docs/solver.md §D.7), mesh connection modes only.

Corrections are accumulated per particle in MagicaCloth2's fixed point (1e-6 m units, each
contribution truncated toward zero, §0.2), averaged by count and added to the moving
particles' ``next_pos`` (Jacobi, not Gauss-Seidel). ``velocity_pos`` is untouched, so the whole
correction becomes velocity. The rest volume scales with scaleRatio, not its cube (Appendix 2.6).

``bending_block`` runs one block: each pair's lanes side by side through array-free
per-element functions (``particle_inverse_mass``, ``solve_dihedral``, ``solve_volume``,
``accumulated``), branch-free (degenerate pairs are computed through and selected away), then
``apply_accumulated_block`` (``averaged``).
"""
from __future__ import annotations

import math

import numpy as np


from magica_py.build.proxy import MOVE
from magica_py.jit import kernel
from magica_py.kernels import trig
from magica_py.kernels.math3d import (
    inverse_mass_friction_depth, saturate, v_cross, v_dot, v_length, v_length_sq, v_scale, v_sub,
)
from magica_py.solver import blocks as bk
from magica_py.solver import state as st
from magica_py.solver.lanes import LANES, get1, get3, put1, put3
from magica_py.solver.parameters import PRM_BENDING_STIFFNESS, PRM_QUALITY, PRM_RATE_MODE, constraint_stiffness

FIXED_POINT = 1e6
DONT_MOVE_INVERSE_MASS = 0.01
ZERO3 = (0.0, 0.0, 0.0)


# ----------------------------------------------------------------------------- per element
@kernel
def particle_inverse_mass(move, friction, depth):
    """Inverse mass of a bend/volume vertex: friction and depth weighted when it moves."""
    moving = inverse_mass_friction_depth(friction, depth)
    return moving if move else DONT_MOVE_INVERSE_MASS


@kernel
def accumulated(acc, count, v, ok):
    """(acc, count) after adding contribution v in fixed point (truncated toward zero, as
    InterlockUtility) when ok; unchanged otherwise. Sums of integer-valued floats are exact."""
    summed = (acc[0] + float(math.trunc(v[0] * FIXED_POINT)),
              acc[1] + float(math.trunc(v[1] * FIXED_POINT)),
              acc[2] + float(math.trunc(v[2] * FIXED_POINT)))
    return (summed if ok else acc), (count + 1 if ok else count)


@kernel
def averaged(next_pos, acc, count):
    """next_pos plus the mean of ``count`` fixed-point contributions (unchanged when none)."""
    s = 1.0 / (max(count, 1) * FIXED_POINT)
    moved = (next_pos[0] + acc[0] * s, next_pos[1] + acc[1] * s, next_pos[2] + acc[2] * s)
    return moved if count > 0 else next_pos


@kernel
def solve_dihedral(p0, p1, p2, p3, w0, w1, w2, w3, rest_angle, sign, stiffness):
    """Direction-dihedral-angle correction of the pair (v0, v1 opposite; v2-v3 the shared edge).

    Returns (ok, c0, c1, c2, c3); not ok (zero corrections) for a degenerate edge, a
    degenerate triangle or a zero denominator. Branch-free: the degenerate cases are
    computed through (inf/NaN, no exception under the numpy error model) and selected away.

    The reference's formulas with shared reciprocals (docs/distance_bending_maths.md): 1/|e| once
    instead of four divisions by |e|, 1/|n|^2 as the square of 1/|n| (the unit normals'
    factor), ``trig.acos_fma``: 4 divisions instead of 9, the same results up to round-off."""
    e = v_sub(p3, p2)
    el = v_length(e)
    inv_el = 1.0 / el
    n1 = v_cross(v_sub(p2, p0), v_sub(p3, p0))
    n2 = v_cross(v_sub(p3, p1), v_sub(p2, p1))
    l1 = v_length_sq(n1)
    l2 = v_length_sq(n2)
    r1 = 1.0 / np.sqrt(l1)   # 1 / |n1|
    r2 = 1.0 / np.sqrt(l2)
    s1 = r1 * r1               # 1 / |n1|^2
    s2 = r2 * r2
    d0 = v_scale(n1, el * s1)
    d1 = v_scale(n2, el * s2)
    a = v_dot(v_sub(p0, p3), e) * inv_el * s1
    b = v_dot(v_sub(p1, p3), e) * inv_el * s2
    d2 = (a * n1[0] + b * n2[0], a * n1[1] + b * n2[1], a * n1[2] + b * n2[2])
    a = v_dot(v_sub(p2, p0), e) * inv_el * s1
    b = v_dot(v_sub(p2, p1), e) * inv_el * s2
    d3 = (a * n1[0] + b * n2[0], a * n1[1] + b * n2[1], a * n1[2] + b * n2[2])
    n1u = v_scale(n1, r1)      # the unit normals of the reference, the same bits: acos is
    n2u = v_scale(n2, r2)      # ill-conditioned near a flat pair (1 ulp of c: 1.5e-8 rad)
    c = v_dot(n1u, n2u)
    c = -1.0 if c < -1.0 else (1.0 if c > 1.0 else c)
    phi = trig.acos_fma(c)
    phi = -phi if v_dot(v_cross(n1u, n2u), e) < 0.0 else phi
    denom = w0 * v_length_sq(d0) + w1 * v_length_sq(d1) + w2 * v_length_sq(d2) + w3 * v_length_sq(d3)
    lam = (sign * rest_angle - phi) / denom * stiffness
    # the per-team tests in their original order, negated (a NaN length passes, as it did)
    ok = (not el < 1e-8) & (not (l1 == 0.0)) & (not (l2 == 0.0)) & (not denom == 0.0)
    c0 = v_scale(d0, -w0 * lam)
    c1 = v_scale(d1, -w1 * lam)
    c2 = v_scale(d2, -w2 * lam)
    c3 = v_scale(d3, -w3 * lam)
    return (ok, c0 if ok else ZERO3, c1 if ok else ZERO3, c2 if ok else ZERO3, c3 if ok else ZERO3)


@kernel
def solve_volume(p0, p1, p2, p3, w0, w1, w2, w3, rest_volume, stiffness):
    """Tetra volume correction (volumes x1000). Returns (ok, c0, c1, c2, c3); not ok (zero
    corrections) when the denominator vanishes. Branch-free like ``solve_dihedral``."""
    volume = 1000.0 / 6.0 * v_dot(v_cross(v_sub(p1, p0), v_sub(p2, p0)), v_sub(p3, p0))
    g0 = v_cross(v_sub(p1, p2), v_sub(p3, p2))
    g1 = v_cross(v_sub(p2, p0), v_sub(p3, p0))
    g2 = v_cross(v_sub(p0, p1), v_sub(p3, p1))
    g3 = v_cross(v_sub(p1, p0), v_sub(p2, p0))
    denom = 1000.0 * (w0 * v_length_sq(g0) + w1 * v_length_sq(g1) + w2 * v_length_sq(g2) + w3 * v_length_sq(g3))
    ok = not abs(denom) < 1e-6
    lam = stiffness * (rest_volume - volume) / denom
    c0 = v_scale(g0, lam * w0)
    c1 = v_scale(g1, lam * w1)
    c2 = v_scale(g2, lam * w2)
    c3 = v_scale(g3, lam * w3)
    return (ok, c0 if ok else ZERO3, c1 if ok else ZERO3, c2 if ok else ZERO3, c3 if ok else ZERO3)


@kernel
def bending_rate(P, b, frequency_ratio, power_y):
    """Per-step stiffness of block b's bending (negative: bending off)."""
    stiffness = P[b, PRM_BENDING_STIFFNESS]
    if stiffness < 1e-6:
        return -1.0
    return saturate(constraint_stiffness(stiffness, frequency_ratio, power_y, int(P[b, PRM_RATE_MODE]),
                                         int(P[b, PRM_QUALITY])))


# ----------------------------------------------------------------------------- per block
@kernel
def accumulate_lane(PS, g, l, v, ok):
    """Add contribution v to particle slot g's accumulator in lane l when ok (``accumulated``)."""
    acc, n = accumulated(get3(PS, g, st.ACCUM_VECTOR, l), get1(PS, g, st.ACCUM_COUNT, l), v, ok)
    put3(PS, g, st.ACCUM_VECTOR, l, acc)
    put1(PS, g, st.ACCUM_COUNT, l, n)


@kernel
def bending_inverse_masses(PS, PM, BI, topology, b):
    """Every particle's inverse mass of this bending pass into ``BEND_INVERSE_MASS``, once per
    particle: friction and depth do not change during the routine, and a mesh vertex belongs
    to up to ~8 bend pairs."""
    g0 = BI[b, bk.BI_G0]
    w = bk.lane_width(BI, b)
    attribute = BI[b, bk.BI_ATTRIBUTE]
    for j in range(BI[b, bk.BI_N]):
        g = g0 + j
        move = (topology[attribute + j] & MOVE) != 0
        for l in range(w):
            put1(PS, g, st.BEND_INVERSE_MASS, l,
                 particle_inverse_mass(move, get1(PS, g, st.FRICTION, l), get1(PM, g, bk.DEPTH, l)))


@kernel
def gather_pair(PS, topology, first, g0, w):
    """The pair whose four block-local vertices start at ``topology[first]``: vertices 1-3's
    next_pos and inverse mass into vertex 0's slot (``BEND_PARTNER_POS``, ``BEND_PARTNER_W``), so
    that the solving loop reads one item. Returns the four slots."""
    g = g0 + topology[first]
    g_1 = g0 + topology[first + 1]
    g_2 = g0 + topology[first + 2]
    g_3 = g0 + topology[first + 3]
    for l in range(min(w, LANES)):
        put3(PS, g, st.BEND_PARTNER_POS, l, get3(PS, g_1, st.NEXT_POS, l))
        put1(PS, g, st.BEND_PARTNER_W, l, get1(PS, g_1, st.BEND_INVERSE_MASS, l))
    for l in range(min(w, LANES)):
        put3(PS, g, st.BEND_PARTNER_POS + 3 * LANES, l, get3(PS, g_2, st.NEXT_POS, l))
        put1(PS, g, st.BEND_PARTNER_W + LANES, l, get1(PS, g_2, st.BEND_INVERSE_MASS, l))
    for l in range(min(w, LANES)):
        put3(PS, g, st.BEND_PARTNER_POS + 6 * LANES, l, get3(PS, g_3, st.NEXT_POS, l))
        put1(PS, g, st.BEND_PARTNER_W + 2 * LANES, l, get1(PS, g_3, st.BEND_INVERSE_MASS, l))
    return g, g_1, g_2, g_3


@kernel
def solve_pair_lanes(PS, g, w, volume, k):
    """One dihedral pair (``volume`` False) or volume pair (True), every lane, on vertex 0's
    slot g alone: vertex 0's correction into its accumulator, vertices 1-3's over their gathered
    positions, ``BEND_OK`` where they apply (``scatter_pair``)."""
    for l in range(min(w, LANES)):
        p0 = get3(PS, g, st.NEXT_POS, l)
        p1 = get3(PS, g, st.BEND_PARTNER_POS, l)
        p2 = get3(PS, g, st.BEND_PARTNER_POS + 3 * LANES, l)
        p3 = get3(PS, g, st.BEND_PARTNER_POS + 6 * LANES, l)
        w0 = get1(PS, g, st.BEND_INVERSE_MASS, l)
        w1 = get1(PS, g, st.BEND_PARTNER_W, l)
        w2 = get1(PS, g, st.BEND_PARTNER_W + LANES, l)
        w3 = get1(PS, g, st.BEND_PARTNER_W + 2 * LANES, l)
        if volume:
            ok, c0, c1, c2, c3 = solve_volume(p0, p1, p2, p3, w0, w1, w2, w3, get1(PS, g, st.BEND_REST, l), k)
        else:
            ok, c0, c1, c2, c3 = solve_dihedral(p0, p1, p2, p3, w0, w1, w2, w3, get1(PS, g, st.BEND_REST, l),
                                                get1(PS, g, st.BEND_SIGN, l), k)
        accumulate_lane(PS, g, l, c0, ok)
        put3(PS, g, st.BEND_PARTNER_POS, l, c1)
        put3(PS, g, st.BEND_PARTNER_POS + 3 * LANES, l, c2)
        put3(PS, g, st.BEND_PARTNER_POS + 6 * LANES, l, c3)
        put1(PS, g, st.BEND_OK, l, 1.0 if ok else 0.0)


@kernel
def scatter_pair(PS, g, g_1, g_2, g_3, w):
    """Vertices 1-3's corrections (``solve_pair_lanes``, in vertex 0's slot g) into their
    accumulators where the pair applies. The fixed-point sums are exact, so the order of the
    additions does not matter."""
    for l in range(min(w, LANES)):
        accumulate_lane(PS, g_1, l, get3(PS, g, st.BEND_PARTNER_POS, l), get1(PS, g, st.BEND_OK, l) != 0.0)
    for l in range(min(w, LANES)):
        accumulate_lane(PS, g_2, l, get3(PS, g, st.BEND_PARTNER_POS + 3 * LANES, l), get1(PS, g, st.BEND_OK, l) != 0.0)
    for l in range(min(w, LANES)):
        accumulate_lane(PS, g_3, l, get3(PS, g, st.BEND_PARTNER_POS + 6 * LANES, l), get1(PS, g, st.BEND_OK, l) != 0.0)


@kernel(forceinline=False)
def bending_block(PS, PM, TS, BM, VM, P, BI, topology, b, frequency_ratio, power_y):
    """D.7 over block b: the dihedral and volume corrections of every pair accumulated in fixed
    point (pairs in order, every lane side by side), then the averages added to the moving
    particles' ``next_pos`` and the accumulators cleared (Jacobi: every pair sees the positions
    the pass started from). Each pair is gathered into its vertex 0's slot, solved there and
    scattered back (``gather_pair``, ``solve_pair_lanes``, ``scatter_pair``): a loop that reads
    and writes rows of four slots at run-time distances stays scalar (docs/architecture.md,
    *Lane form*)."""
    g0 = BI[b, bk.BI_G0]
    w = bk.lane_width(BI, b)
    k = bending_rate(P, b, frequency_ratio, power_y)
    if k >= 0.0:
        bending_inverse_masses(PS, PM, BI, topology, b)
        bend0 = BI[b, bk.BI_BEND0]
        vertices = BI[b, bk.BI_BEND_VERTICES]
        for e in range(BI[b, bk.BI_BENDS]):
            g, g_1, g_2, g_3 = gather_pair(PS, topology, vertices + 4 * e, g0, w)
            for l in range(w):
                put1(PS, g, st.BEND_REST, l, get1(BM, bend0 + e, bk.BEND_REST_ANGLE, l))
                put1(PS, g, st.BEND_SIGN, l, get1(BM, bend0 + e, bk.BEND_SIGN, l))
            # a literal switch (one compile per value, docs/tech-notes.md §7): numba prunes the
            # other pair kind before LLVM sees the loop, ~9 % faster than the folded plain bool
            solve_pair_lanes(PS, g, w, False, k)
            scatter_pair(PS, g, g_1, g_2, g_3, w)
        volume0 = BI[b, bk.BI_VOLUME0]
        vertices = BI[b, bk.BI_VOLUME_VERTICES]
        for e in range(BI[b, bk.BI_VOLUMES]):
            g, g_1, g_2, g_3 = gather_pair(PS, topology, vertices + 4 * e, g0, w)
            for l in range(w):
                put1(PS, g, st.BEND_REST, l, get1(VM, volume0 + e, bk.VOLUME_REST, l) * get1(TS, b, st.SCALE_RATIO, l))
            solve_pair_lanes(PS, g, w, True, k)
            scatter_pair(PS, g, g_1, g_2, g_3, w)
    apply_accumulated_block(PS, BI, topology, b)


@kernel(forceinline=False)
def apply_accumulated_block(PS, BI, topology, b):
    """Add the averaged accumulator to the moving particles' next_pos (``averaged``) and clear it."""
    g0 = BI[b, bk.BI_G0]
    w = bk.lane_width(BI, b)
    attribute = BI[b, bk.BI_ATTRIBUTE]
    for j in range(BI[b, bk.BI_N]):
        g = g0 + j
        if (topology[attribute + j] & MOVE) != 0:
            for l in range(w):
                put3(PS, g, st.NEXT_POS, l, averaged(get3(PS, g, st.NEXT_POS, l), get3(PS, g, st.ACCUM_VECTOR, l),
                                                     get1(PS, g, st.ACCUM_COUNT, l)))
        for l in range(w):
            put3(PS, g, st.ACCUM_VECTOR, l, ZERO3)
            put1(PS, g, st.ACCUM_COUNT, l, 0.0)
