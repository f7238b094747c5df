"""Triangle bending and volume (docs/solver.md §D.7), mesh connection modes only.

Corrections are accumulated per particle in MagicaCloth2's fixed point (1e-6 m units, each
contribution truncated toward zero, §0.2), averaged by count and added to the moving
particles' ``next_pos`` (Jacobi, not Gauss-Seidel). ``velocity_pos`` is untouched, so the whole
correction becomes velocity. The rest volume scales with scaleRatio, not its cube (Appendix 2.6).

``bending_team`` / ``apply_accumulated`` run one team through array-free per-element
functions (``particle_inverse_mass``, ``solve_dihedral``, ``solve_volume``, ``accumulated``,
``averaged``), branch-free (degenerate pairs are computed through and selected away).
"""
from __future__ import annotations

import math


from magica_py.jit import kernel
from magica_py.kernels import trig
from magica_py.kernels.math3d import (
    inverse_mass_friction_depth, load3, saturate, store3, v_cross, v_dot, v_length, v_length_sq,
    v_scale, v_sub,
)
from reference_solver.solver.parameters import constraint_stiffness

MOVE = 0x02
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
    r1 = 1.0 / math.sqrt(l1)   # 1 / |n1|
    r2 = 1.0 / math.sqrt(l2)
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
def bending_rate(prm, team, frequency_ratio, power_y):
    """Per-step stiffness of the team's bending (negative: bending off)."""
    stiffness = prm.bending_stiffness[team]
    if stiffness < 1e-6:
        return -1.0
    return saturate(constraint_stiffness(stiffness, frequency_ratio, power_y, prm.rate_mode[team], prm.quality[team]))


# ----------------------------------------------------------------------------- per team
@kernel
def accumulate(ps, p, v):
    """Add one contribution to particle p's accumulator (``accumulated``)."""
    acc, n = accumulated(load3(ps.accum_vector, p), ps.accum_count[p], v, True)
    store3(ps.accum_vector, p, acc)
    ps.accum_count[p] = n


@kernel
def inverse_mass(m, ps, p):
    return particle_inverse_mass((m.attribute[p] & MOVE) != 0, ps.friction[p], m.depth[p])


@kernel
def bending_team(m, ps, prm, ts, team, frequency_ratio, power_y):
    """Accumulate the dihedral and volume corrections of one team (applied by ``apply_accumulated``).

    The inverse mass of each particle is computed once per call into ``ps.bend_inverse_mass``
    (friction and depth do not change during the routine): a mesh vertex belongs to several
    bend pairs, so per-pair evaluation repeated the same division ~8 times per vertex."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_bend_rest_angle, m_bend_sign, m_bend_vertices = m.bend_rest_angle, m.bend_sign, m.bend_vertices
    m_team_bend_count, m_team_particle_count = m.team_bend_count, m.team_particle_count
    m_team_volume_count, m_volume_rest = m.team_volume_count, m.volume_rest
    m_volume_vertices, ps_bend_inverse_mass, ps_next_pos = m.volume_vertices, ps.bend_inverse_mass, ps.next_pos
    k = bending_rate(prm, team, frequency_ratio, power_y)
    if k < 0.0:
        return
    start = m.team_particle_start[team]
    for p in range(start, start + m_team_particle_count[team]):
        ps_bend_inverse_mass[p] = inverse_mass(m, ps, p)
    w = ps_bend_inverse_mass
    b0 = m.team_bend_start[team]
    for b in range(b0, b0 + m_team_bend_count[team]):
        v0 = m_bend_vertices[b, 0]
        v1 = m_bend_vertices[b, 1]
        v2 = m_bend_vertices[b, 2]
        v3 = m_bend_vertices[b, 3]
        ok, c0, c1, c2, c3 = solve_dihedral(
            load3(ps_next_pos, v0), load3(ps_next_pos, v1), load3(ps_next_pos, v2), load3(ps_next_pos, v3),
            w[v0], w[v1], w[v2], w[v3], m_bend_rest_angle[b], m_bend_sign[b], k)
        if ok:
            accumulate(ps, v0, c0)
            accumulate(ps, v1, c1)
            accumulate(ps, v2, c2)
            accumulate(ps, v3, c3)
    scale = ts.scale_ratio[team]
    b0 = m.team_volume_start[team]
    for b in range(b0, b0 + m_team_volume_count[team]):
        v0 = m_volume_vertices[b, 0]
        v1 = m_volume_vertices[b, 1]
        v2 = m_volume_vertices[b, 2]
        v3 = m_volume_vertices[b, 3]
        ok, c0, c1, c2, c3 = solve_volume(
            load3(ps_next_pos, v0), load3(ps_next_pos, v1), load3(ps_next_pos, v2), load3(ps_next_pos, v3),
            w[v0], w[v1], w[v2], w[v3], m_volume_rest[b] * scale, k)
        if ok:
            accumulate(ps, v0, c0)
            accumulate(ps, v1, c1)
            accumulate(ps, v2, c2)
            accumulate(ps, v3, c3)


@kernel
def apply_accumulated(m, ps, team, move_only):
    """Add the averaged accumulator to next_pos (moving particles only when ``move_only``) and clear it."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_attribute, m_team_particle_count, ps_accum_count = m.attribute, m.team_particle_count, ps.accum_count
    ps_accum_vector, ps_next_pos = ps.accum_vector, ps.next_pos
    start = m.team_particle_start[team]
    for p in range(start, start + m_team_particle_count[team]):
        if not move_only or (m_attribute[p] & MOVE) != 0:
            store3(ps_next_pos, p, averaged(load3(ps_next_pos, p), load3(ps_accum_vector, p), ps_accum_count[p]))
        store3(ps_accum_vector, p, ZERO3)
        ps_accum_count[p] = 0


