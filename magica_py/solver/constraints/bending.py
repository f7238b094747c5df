"""Triangle bending and volume (ref §D.7), mesh connection modes only.

Corrections are accumulated per particle in MagicaCloth2's fixed point (1e-6 m units, each
contribution truncated toward zero, ref §0.2), averaged by count and added to the moving
particles' ``next_pos`` (Jacobi, not Gauss-Seidel). ``velocity_pos`` is untouched, so the whole
correction becomes velocity. The rest volume scales with scaleRatio, not its cube (Appendix 2.6).
"""
from __future__ import annotations

import math

from magica_py.jit import kernel
from magica_py.kernels import trig
from magica_py.kernels.math3d import (
    inverse_mass_friction_depth, load3, saturate, v_cross, v_dot, v_length, v_length_sq,
    v_scale, v_sub,
)
from magica_py.solver.parameters import step_rate

MOVE = 0x02
FIXED_POINT = 1e6
DONT_MOVE_INVERSE_MASS = 0.01


@kernel
def accumulate(ps, p, v):
    """Add one contribution in fixed point (truncation toward zero, as InterlockUtility)."""
    ps.accum_vector[p, 0] += float(math.trunc(v[0] * FIXED_POINT))
    ps.accum_vector[p, 1] += float(math.trunc(v[1] * FIXED_POINT))
    ps.accum_vector[p, 2] += float(math.trunc(v[2] * FIXED_POINT))
    ps.accum_count[p] += 1


@kernel
def inverse_mass(m, ps, p):
    if (m.attribute[p] & MOVE) == 0:
        return DONT_MOVE_INVERSE_MASS
    return inverse_mass_friction_depth(ps.friction[p], m.depth[p])


@kernel
def solve_dihedral(p0, p1, p2, p3, w0, w1, w2, w3, rest_angle, sign, stiffness):
    """Direction-dihedral-angle correction of the pair (v0, v1 opposite; v2-v3 the shared edge).

    Returns (ok, c0, c1, c2, c3)."""
    z = (0.0, 0.0, 0.0)
    e = v_sub(p3, p2)
    el = v_length(e)
    if el < 1e-8:
        return False, z, z, z, z
    n1 = v_cross(v_sub(p2, p0), v_sub(p3, p0))
    n2 = v_cross(v_sub(p3, p1), v_sub(p2, p1))
    l1 = v_length_sq(n1)
    l2 = v_length_sq(n2)
    if l1 == 0.0 or l2 == 0.0:
        return False, z, z, z, z
    n1u = v_scale(n1, 1.0 / math.sqrt(l1))
    n2u = v_scale(n2, 1.0 / math.sqrt(l2))
    n1 = v_scale(n1, 1.0 / l1)
    n2 = v_scale(n2, 1.0 / l2)
    d0 = v_scale(n1, el)
    d1 = v_scale(n2, el)
    a = v_dot(v_sub(p0, p3), e) / el
    b = v_dot(v_sub(p1, p3), e) / el
    d2 = (a * n1[0] + b * n2[0], a * n1[1] + b * n2[1], a * n1[2] + b * n2[2])
    a = v_dot(v_sub(p2, p0), e) / el
    b = v_dot(v_sub(p2, p1), e) / el
    d3 = (a * n1[0] + b * n2[0], a * n1[1] + b * n2[1], a * n1[2] + b * n2[2])
    c = v_dot(n1u, n2u)
    c = -1.0 if c < -1.0 else (1.0 if c > 1.0 else c)
    phi = trig.acos(c)
    if v_dot(v_cross(n1u, n2u), e) < 0.0:
        phi = -phi
    denom = w0 * v_length_sq(d0) + w1 * v_length_sq(d1) + w2 * v_length_sq(d2) + w3 * v_length_sq(d3)
    if denom == 0.0:
        return False, z, z, z, z
    lam = (sign * rest_angle - phi) / denom * stiffness
    return (True, v_scale(d0, -w0 * lam), v_scale(d1, -w1 * lam), v_scale(d2, -w2 * lam),
            v_scale(d3, -w3 * lam))


@kernel
def solve_volume(p0, p1, p2, p3, w0, w1, w2, w3, rest_volume, stiffness):
    """Tetra volume correction (volumes x1000). Returns (ok, c0, c1, c2, c3)."""
    z = (0.0, 0.0, 0.0)
    volume = 1000.0 / 6.0 * v_dot(v_cross(v_sub(p1, p0), v_sub(p2, p0)), v_sub(p3, p0))
    g0 = v_cross(v_sub(p1, p2), v_sub(p3, p2))
    g1 = v_cross(v_sub(p2, p0), v_sub(p3, p0))
    g2 = v_cross(v_sub(p0, p1), v_sub(p3, p1))
    g3 = v_cross(v_sub(p1, p0), v_sub(p2, p0))
    denom = 1000.0 * (w0 * v_length_sq(g0) + w1 * v_length_sq(g1) + w2 * v_length_sq(g2) + w3 * v_length_sq(g3))
    if abs(denom) < 1e-6:
        return False, z, z, z, z
    lam = stiffness * (rest_volume - volume) / denom
    return (True, v_scale(g0, lam * w0), v_scale(g1, lam * w1), v_scale(g2, lam * w2),
            v_scale(g3, lam * w3))


@kernel
def bending_team(m, ps, prm, ts, team, frequency_ratio, power_y):
    """Accumulate the dihedral and volume corrections of one team (applied by ``apply_accumulated``).

    The inverse mass of each particle is computed once per call into ``ps.bend_inverse_mass``
    (friction and depth do not change during the routine): a mesh vertex belongs to several
    bend pairs, so per-pair evaluation repeated the same division ~8 times per vertex."""
    stiffness = prm.bending_stiffness[team]
    if stiffness < 1e-6:
        return
    k = saturate(step_rate(stiffness, frequency_ratio, power_y, prm.rate_mode[team]))
    start = m.team_particle_start[team]
    for p in range(start, start + m.team_particle_count[team]):
        ps.bend_inverse_mass[p] = inverse_mass(m, ps, p)
    w = ps.bend_inverse_mass
    b0 = m.team_bend_start[team]
    for b in range(b0, b0 + m.team_bend_count[team]):
        v0 = m.bend_vertices[b, 0]
        v1 = m.bend_vertices[b, 1]
        v2 = m.bend_vertices[b, 2]
        v3 = m.bend_vertices[b, 3]
        ok, c0, c1, c2, c3 = solve_dihedral(
            load3(ps.next_pos, v0), load3(ps.next_pos, v1), load3(ps.next_pos, v2), load3(ps.next_pos, v3),
            w[v0], w[v1], w[v2], w[v3], m.bend_rest_angle[b], m.bend_sign[b], k)
        if ok:
            accumulate(ps, v0, c0)
            accumulate(ps, v1, c1)
            accumulate(ps, v2, c2)
            accumulate(ps, v3, c3)
    scale = ts.scale_ratio[team]
    b0 = m.team_volume_start[team]
    for b in range(b0, b0 + m.team_volume_count[team]):
        v0 = m.volume_vertices[b, 0]
        v1 = m.volume_vertices[b, 1]
        v2 = m.volume_vertices[b, 2]
        v3 = m.volume_vertices[b, 3]
        ok, c0, c1, c2, c3 = solve_volume(
            load3(ps.next_pos, v0), load3(ps.next_pos, v1), load3(ps.next_pos, v2), load3(ps.next_pos, v3),
            w[v0], w[v1], w[v2], w[v3], m.volume_rest[b] * scale, k)
        if ok:
            accumulate(ps, v0, c0)
            accumulate(ps, v1, c1)
            accumulate(ps, v2, c2)
            accumulate(ps, v3, c3)


@kernel
def apply_accumulated(m, ps, team, move_only):
    """Add the averaged accumulator to next_pos (moving particles only when ``move_only``) and clear it."""
    start = m.team_particle_start[team]
    for p in range(start, start + m.team_particle_count[team]):
        n = ps.accum_count[p]
        if n > 0 and (not move_only or (m.attribute[p] & MOVE) != 0):
            s = 1.0 / (n * FIXED_POINT)
            ps.next_pos[p, 0] += ps.accum_vector[p, 0] * s
            ps.next_pos[p, 1] += ps.accum_vector[p, 1] * s
            ps.next_pos[p, 2] += ps.accum_vector[p, 2] * s
        ps.accum_vector[p, 0] = 0.0
        ps.accum_vector[p, 1] = 0.0
        ps.accum_vector[p, 2] = 0.0
        ps.accum_count[p] = 0
