"""Collider collision (docs/solver.md §D.8): point mode (particle spheres) and edge mode (proxy edges)
against spheres, capsules with two radii and infinite planes, all as "moving planes" built
from the collider's previous-step and current-step poses (``ColliderState`` work data, G.3).

Point mode pushes ``next_pos`` directly (Gauss-Seidel); edge mode accumulates in fixed point
and averages (Jacobi). Neither touches ``velocity_pos``: the push becomes velocity in full.
Edge-mode friction is quantised to {0, 1} as MagicaCloth2's fixed-point max does (§0.2,
Appendix 2.5): we reproduce it deliberately.

``point_collision_team`` calls array-free per-element functions (``point_sphere``,
``point_capsule``, ``point_plane``, ``point_contact_add``, ``point_contact_result``).
"""
from __future__ import annotations

import math


from magica_py.jit import kernel
from magica_py.kernels.math3d import (
    closest_segment_segment, load3, load4, q_rotate, saturate, store3, v_add, v_dot, v_length, v_length_sq, v_lerp,
    v_normalize, v_scale, v_sub,
)
from reference_solver.solver.constraints.bending import FIXED_POINT
from reference_solver.solver.parameters import curve_at, length_unit

MOVE = 0x02
INVALID_OR_NO_COLLISION = 0x10
SPHERE = 0
CAPSULE = 1
PLANE = 2
FAR = 1e30


@kernel
def plane_push(c, n, p):
    """``IntersectPointPlaneDist``: push p onto the plane (c, n) when behind it; signed distance.
    Both answers are computed and one selected (branch-free)."""
    v = v_sub(p, c)
    d = v_dot(v, n)
    g = v_scale(n, d)
    length = v_length(g)
    pushed = v_sub(p, g)
    behind = d < 0.0
    return (-length if behind else length), (pushed if behind else p)


@kernel
def segment_parameter(c, a, b):
    """Parameter in [0, 1] of the point of segment ab closest to c (0 when a == b; branch-free)."""
    ab = v_sub(b, a)
    l2 = v_length_sq(ab)
    s = saturate(v_dot(v_sub(c, a), ab) / l2)
    return 0.0 if l2 == 0.0 else s


@kernel
def aabb_overlap(min_a, max_a, min_b, max_b):
    return (min_a[0] <= max_b[0] and max_a[0] >= min_b[0] and min_a[1] <= max_b[1]
            and max_a[1] >= min_b[1] and min_a[2] <= max_b[2] and max_a[2] >= min_b[2])


@kernel
def particle_radius(radius_curve, team, depth, scale):
    """A particle's collision radius (m): the team's radius curve at its depth, at least
    0.1 mm, times ``scale`` (team scale ratio and, in quality mode, the length unit)."""
    return max(curve_at(radius_curve, team, depth), 0.0001) * scale


# -- point mode, per element (array-free)
@kernel
def point_bounds(x, r):
    """AABB of a particle sphere grown by the contact range (cfr = r): (min, max)."""
    ext = r + r
    return (x[0] - ext, x[1] - ext, x[2] - ext), (x[0] + ext, x[1] + ext, x[2] + ext)


@kernel
def point_plane(x, r, origin, normal):
    """Particle (x, radius r) against an infinite plane: (distance, normal, pushed x)."""
    d, x2 = plane_push(v_add(origin, v_scale(normal, r)), normal, x)
    return d, normal, x2


@kernel
def point_sphere(x, r, center_old, center_new, radius):
    """Particle against a moving sphere (normal from the old center, surface at the new one)."""
    n = v_normalize(v_sub(x, center_old))
    c = v_add(center_new, v_scale(n, radius + r))
    d, x2 = plane_push(c, n, x)
    return d, n, x2


@kernel
def point_capsule(x, r, start_old, end_old, start_new, end_new, radius_start, radius_end,
                  inverse_old_rot, now_rot):
    """Particle against a moving capsule with two radii: the closest axis point of the old
    pose, its offset carried into the new pose by the collider's rotation."""
    t = segment_parameter(x, start_old, end_old)
    radius = radius_start + (radius_end - radius_start) * t
    u = q_rotate(inverse_old_rot, v_sub(x, v_lerp(start_old, end_old, t)))
    n = v_normalize(q_rotate(now_rot, u))
    c = v_add(v_lerp(start_new, end_new, t), v_scale(n, radius + r))
    d, x2 = plane_push(c, n, x)
    return d, n, x2


@kernel
def point_contact_add(sum_push, sum_n, n_acc, count, min_dist, x, r, d, n, x2):
    """One collider's answer (d, n, x2) added to a particle's sums: push and normal of the
    colliders it penetrates (d <= 0), normal and closest distance of those within the
    contact range (d <= cfr = r). Returns the five sums (branch-free)."""
    pushed = d <= 0.0
    near = d <= r
    push_added = v_add(sum_push, v_sub(x2, x))
    n_added = v_add(sum_n, n)
    near_added = v_add(n_acc, n)
    closest = min(min_dist, d)
    return ((push_added if pushed else sum_push), (n_added if pushed else sum_n),
            (near_added if near else n_acc), (count + 1 if pushed else count),
            (closest if near else min_dist))


@kernel
def point_contact_result(x, sum_push, sum_n, count, n_acc, min_dist, r, friction):
    """A particle's collision outcome from its sums: (next_pos, friction, collision normal).
    The push is the mean push scaled by the length of the mean normal (opposed colliders cancel);
    friction grows with the closeness of the nearest collider within the contact range
    (``min_dist <= r`` exactly when one was: min_dist starts at FAR). Branch-free."""
    n = max(count, 1)   # no contact: the select below keeps x (and no 1/0 with the JIT off)
    mag = v_length(v_scale(sum_n, 1.0 / n))
    pushed = v_add(x, v_scale(sum_push, min(mag, 1.0) / n))
    new_x = pushed if (count > 0 and mag >= 1e-8) else x
    contact = min_dist <= r and v_length_sq(n_acc) > 1e-6
    rubbed = max(friction, 1.0 - saturate(min_dist / r))
    unit = v_normalize(n_acc)
    return new_x, (rubbed if contact else friction), (unit if contact else n_acc)


@kernel
def solve_point_collider(cs, k, x, r, bmin, bmax):
    """One particle (x, radius r, bounds) against collider slot k: (distance, normal, pushed x)."""
    z = (0.0, 0.0, 0.0)
    shape = cs.shape[k]
    if shape == PLANE:
        return point_plane(x, r, load3(cs.start_new, k), load3(cs.plane_normal, k))
    if not aabb_overlap(bmin, bmax, load3(cs.aabb_min, k), load3(cs.aabb_max, k)):
        return FAR, z, x
    if shape == SPHERE:
        return point_sphere(x, r, load3(cs.start_old, k), load3(cs.start_new, k), cs.radius_start[k])
    return point_capsule(x, r, load3(cs.start_old, k), load3(cs.end_old, k), load3(cs.start_new, k),
                         load3(cs.end_new, k), cs.radius_start[k], cs.radius_end[k],
                         load4(cs.inverse_old_rot, k), load4(cs.now_rot, k))


@kernel
def point_collision_team(m, ps, prm, ts, cs, team):
    """D.8 point mode over one team's moving particles."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    cs_scale_suspend, m_attribute, m_depth = cs.scale_suspend, m.attribute, m.depth
    m_team_particle_count, prm_radius_curve = m.team_particle_count, prm.radius_curve
    ps_collision_normal, ps_friction, ps_next_pos = ps.collision_normal, ps.friction, ps.next_pos
    start = m.team_particle_start[team]
    scale = ts.scale_ratio[team] * length_unit(m, prm, team)
    c0 = ts.collider_start[team]
    c1 = c0 + ts.collider_count[team]
    z = (0.0, 0.0, 0.0)
    for p in range(start, start + m_team_particle_count[team]):
        attr = m_attribute[p]
        if (attr & MOVE) == 0 or (attr & INVALID_OR_NO_COLLISION) != 0:
            continue
        r = particle_radius(prm_radius_curve, team, m_depth[p], scale)
        x = load3(ps_next_pos, p)
        bmin, bmax = point_bounds(x, r)
        sum_push, sum_n, n_acc, count, min_dist = z, z, z, 0, FAR
        for k in range(c0, c1):
            if cs_scale_suspend[k] != 0:
                continue
            d, n, x2 = solve_point_collider(cs, k, x, r, bmin, bmax)
            if d <= r:  # otherwise (out of range, or missed) the sums stay as they are: skip the work
                sum_push, sum_n, n_acc, count, min_dist = point_contact_add(sum_push, sum_n, n_acc, count, min_dist,
                                                                            x, r, d, n, x2)
        if count > 0 or min_dist <= r:  # otherwise the result is (x, friction, n_acc): skip the work
            new_x, friction, n_acc = point_contact_result(x, sum_push, sum_n, count, n_acc, min_dist, r,
                                                          ps_friction[p])
            store3(ps_next_pos, p, new_x)
            ps_friction[p] = friction
        store3(ps_collision_normal, p, n_acc)


@kernel
def solve_edge_collider(cs, k, a, b, ra, rb, cfr, bmin, bmax):
    """Edge (a, b) against collider slot k: (distance, normal, pushed a, pushed b)."""
    z = (0.0, 0.0, 0.0)
    shape = cs.shape[k]
    if shape == PLANE:
        n = load3(cs.plane_normal, k)
        o = load3(cs.start_new, k)
        da, a2 = plane_push(v_add(o, v_scale(n, ra)), n, a)
        db, b2 = plane_push(v_add(o, v_scale(n, rb)), n, b)
        return min(da, db), n, a2, b2
    if not aabb_overlap(bmin, bmax, load3(cs.aabb_min, k), load3(cs.aabb_max, k)):
        return FAR, z, a, b
    if shape == SPHERE:
        o_old = load3(cs.start_old, k)
        o_new = load3(cs.start_new, k)
        s = segment_parameter(o_old, a, b)
        c = v_lerp(a, b, s)
        v = v_sub(c, o_old)
        vl = v_length(v)
        if vl < 1e-9:
            return FAR, z, a, b
        n = v_scale(v, 1.0 / vl)
        l = vl - v_dot(n, v_sub(o_new, o_old))
        th = ra + (rb - ra) * s + cs.radius_start[k]
        if l > th + cfr:
            return FAR, z, a, b
        l2 = v_dot(n, v_sub(c, o_new))
    else:
        so = load3(cs.start_old, k)
        eo = load3(cs.end_old, k)
        rs = cs.radius_start[k]
        re = cs.radius_end[k]
        s, t, ca, cb = closest_segment_segment(a, b, so, eo)
        v = v_sub(ca, cb)
        vl = v_length(v)
        if vl < 1e-9:
            return FAR, z, a, b
        n = v_scale(v, 1.0 / vl)
        if rs != re:  # tapered: closest points against the axis shifted onto the surface
            s, t, _ca, _cb = closest_segment_segment(a, b, v_add(so, v_scale(n, rs)), v_add(eo, v_scale(n, re)))
            ca = v_lerp(a, b, s)
            cb = v_lerp(so, eo, t)
            v = v_sub(ca, cb)
            vl = v_length(v)
            if vl < 1e-9:
                return FAR, z, a, b
            n = v_scale(v, 1.0 / vl)
        ds = v_sub(load3(cs.start_new, k), so)
        de = v_sub(load3(cs.end_new, k), eo)
        l = vl - v_dot(n, v_lerp(ds, de, t))
        th = ra + (rb - ra) * s + rs + (re - rs) * t
        if l > th + cfr:
            return FAR, z, a, b
        d = v_lerp(load3(cs.start_new, k), load3(cs.end_new, k), t)
        l2 = v_dot(n, v_sub(ca, d))
    if l2 > th:
        return l2 - th, n, a, b
    depth = th - l2
    b0 = 1.0 - s
    b1 = s
    sc = depth / (b0 * b0 + b1 * b1)
    return -depth, n, v_add(a, v_scale(n, b0 * sc)), v_add(b, v_scale(n, b1 * sc))


@kernel
def edge_collision_team(m, ps, prm, ts, cs, team):
    """D.8 edge mode over one team's edges (accumulate), then the sum step."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    cs_scale_suspend, m_attribute, m_depth, m_edges = cs.scale_suspend, m.attribute, m.depth, m.edges
    m_team_edge_count, m_team_particle_count = m.team_edge_count, m.team_particle_count
    prm_radius_curve, ps_accum_count, ps_accum_friction = prm.radius_curve, ps.accum_count, ps.accum_friction
    ps_accum_normal, ps_accum_vector = ps.accum_normal, ps.accum_vector
    ps_collision_normal, ps_friction, ps_next_pos = ps.collision_normal, ps.friction, ps.next_pos
    scale = ts.scale_ratio[team] * length_unit(m, prm, team)
    c0 = ts.collider_start[team]
    c1 = c0 + ts.collider_count[team]
    e0 = m.team_edge_start[team]
    for e in range(e0, e0 + m_team_edge_count[team]):
        ia = m_edges[e, 0]
        ib = m_edges[e, 1]
        a_move = (m_attribute[ia] & MOVE) != 0
        b_move = (m_attribute[ib] & MOVE) != 0
        if not a_move and not b_move:
            continue
        ra = curve_at(prm_radius_curve, team, m_depth[ia]) * scale
        rb = curve_at(prm_radius_curve, team, m_depth[ib]) * scale
        cfr = (ra + rb) * 0.5
        a = load3(ps_next_pos, ia)
        b = load3(ps_next_pos, ib)
        bmin = (min(a[0] - ra, b[0] - rb) - cfr, min(a[1] - ra, b[1] - rb) - cfr, min(a[2] - ra, b[2] - rb) - cfr)
        bmax = (max(a[0] + ra, b[0] + rb) + cfr, max(a[1] + ra, b[1] + rb) + cfr, max(a[2] + ra, b[2] + rb) + cfr)
        push_a = (0.0, 0.0, 0.0)
        push_b = (0.0, 0.0, 0.0)
        sum_n = (0.0, 0.0, 0.0)
        n_acc = (0.0, 0.0, 0.0)
        cnt = 0
        min_dist = FAR
        touched = False
        for k in range(c0, c1):
            if cs_scale_suspend[k] != 0:
                continue
            d, n, a2, b2 = solve_edge_collider(cs, k, a, b, ra, rb, cfr, bmin, bmax)
            if d <= 0.0:
                push_a = v_add(push_a, v_sub(a2, a))
                push_b = v_add(push_b, v_sub(b2, b))
                sum_n = v_add(sum_n, n)
                cnt += 1
            if d <= cfr:
                touched = True
                n_acc = v_add(n_acc, n)
                min_dist = min(min_dist, d)
        if cnt > 0:
            mag = v_length(v_scale(sum_n, 1.0 / cnt))
            if mag >= 1e-8:
                f = min(mag, 1.0) / cnt
                _accumulate(ps, ia, v_scale(push_a, f))
                _accumulate(ps, ib, v_scale(push_b, f))
        if touched:
            # fixed-point max: the value is cast to an integer before scaling (quirk, §0.2)
            recorded = float(math.trunc(1.0 - saturate(min_dist / cfr)))
            if a_move:
                ps_accum_friction[ia] = max(ps_accum_friction[ia], recorded)
                store3(ps_accum_normal, ia, v_add(load3(ps_accum_normal, ia), n_acc))
            if b_move:
                ps_accum_friction[ib] = max(ps_accum_friction[ib], recorded)
                store3(ps_accum_normal, ib, v_add(load3(ps_accum_normal, ib), n_acc))
    # sum step
    start = m.team_particle_start[team]
    for p in range(start, start + m_team_particle_count[team]):
        n = ps_accum_count[p]
        if n > 0:
            s = 1.0 / (n * FIXED_POINT)
            ps_next_pos[p, 0] += ps_accum_vector[p, 0] * s
            ps_next_pos[p, 1] += ps_accum_vector[p, 1] * s
            ps_next_pos[p, 2] += ps_accum_vector[p, 2] * s
        if ps_accum_friction[p] > 0.0:
            ps_friction[p] = max(ps_friction[p], ps_accum_friction[p])
        nsum = load3(ps_accum_normal, p)
        if v_length_sq(nsum) > 0.0:
            store3(ps_collision_normal, p, v_normalize(nsum))
        ps_accum_vector[p, 0] = 0.0
        ps_accum_vector[p, 1] = 0.0
        ps_accum_vector[p, 2] = 0.0
        ps_accum_count[p] = 0
        ps_accum_friction[p] = 0.0
        store3(ps_accum_normal, p, (0.0, 0.0, 0.0))


@kernel
def _accumulate(ps, p, v):
    ps.accum_vector[p, 0] += float(math.trunc(v[0] * FIXED_POINT))
    ps.accum_vector[p, 1] += float(math.trunc(v[1] * FIXED_POINT))
    ps.accum_vector[p, 2] += float(math.trunc(v[2] * FIXED_POINT))
    ps.accum_count[p] += 1
