"""Collider collision (docs/solver.md §D.8): point mode (particle spheres) and edge mode (proxy edges)
against spheres, capsules with two radii and infinite planes, all as "moving planes" built
from the collider's previous-step and current-step poses (``ColliderState`` work data, G.3).

Point mode pushes ``next_pos`` directly (Gauss-Seidel); edge mode accumulates in fixed point
and averages (Jacobi). Neither touches ``velocity_pos``: the push becomes velocity in full.
Edge-mode friction is quantised to {0, 1} as MagicaCloth2's fixed-point max does (§0.2,
Appendix 2.5): we reproduce it deliberately.

``point_collision_block`` runs one block: per particle, per collider slot, the lanes side by
side through array-free per-element functions (``point_sphere``, ``point_capsule``,
``point_plane``, ``point_contact_add``), summed in scratch rows, then
``point_contact_result``. ``edge_collision_block`` runs each edge's lanes one by one (its
collider tests branch on the lane's data) through ``solve_edge_collider``.
"""
from __future__ import annotations

import math


from magica_py.build.proxy import DISABLE_COLLISION, MOVE
from magica_py.jit import kernel
from magica_py.kernels.math3d import (
    closest_segment_segment, q_rotate, saturate, v_add, v_dot, v_length, v_length_sq, v_lerp, v_normalize, v_scale,
    v_sub,
)
from magica_py.solver import blocks as bk
from magica_py.solver import state as st
from magica_py.solver.lanes import get1, get3, get4, put1, put3

from magica_py.solver.constraints.bending import FIXED_POINT

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
def particle_radius(curve, scale):
    """A particle's collision radius (m) from its radius curve value (``blocks.CURVE_RADIUS``):
    at least 0.1 mm, times ``scale`` (team scale ratio and, in quality mode, the length unit)."""
    return max(curve, 0.0001) * scale


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
def solve_point_collider(CS, k, l, shape, x, r, bmin, bmax):
    """One particle (x, radius r, bounds) against collider slot k of lane l: (distance, normal,
    pushed x); a missed bounding box gives (FAR, 0, x)."""
    z = (0.0, 0.0, 0.0)
    if shape == PLANE:
        return point_plane(x, r, get3(CS, k, st.START_NEW, l), get3(CS, k, st.PLANE_NORMAL, l))
    if not aabb_overlap(bmin, bmax, get3(CS, k, st.AABB_MIN, l), get3(CS, k, st.AABB_MAX, l)):
        return FAR, z, x
    if shape == SPHERE:
        return point_sphere(x, r, get3(CS, k, st.START_OLD, l), get3(CS, k, st.START_NEW, l),
                            get1(CS, k, st.RADIUS_START, l))
    return point_capsule(x, r, get3(CS, k, st.START_OLD, l), get3(CS, k, st.END_OLD, l), get3(CS, k, st.START_NEW, l),
                         get3(CS, k, st.END_NEW, l), get1(CS, k, st.RADIUS_START, l), get1(CS, k, st.RADIUS_END, l),
                         get4(CS, k, st.INVERSE_OLD_ROT, l), get4(CS, k, st.NOW_ROT, l))


@kernel(forceinline=False)
def point_collision_block(PS, PP, TS, CS, BI, topology, b):
    """D.8 point mode over block b's moving particles: per particle and collider slot, the
    lanes side by side; the sums of ``point_contact_add`` in scratch rows (``ACCUM3`` push,
    ``CONTACT_*``), then each particle's result."""
    g0 = BI[b, bk.BI_G0]
    w = bk.lane_width(BI, b)
    attribute = BI[b, bk.BI_ATTRIBUTE]
    c0 = BI[b, bk.BI_COLLIDER0]
    shapes = BI[b, bk.BI_COLLIDER_SHAPE]
    z = (0.0, 0.0, 0.0)
    for j in range(BI[b, bk.BI_N]):
        attr = topology[attribute + j]
        if (attr & MOVE) == 0 or (attr & DISABLE_COLLISION) != 0:
            continue
        g = g0 + j
        for l in range(w):
            put3(PS, g, st.ACCUM3, l, z)
            put3(PS, g, st.CONTACT_NORMAL_SUM, l, z)
            put3(PS, g, st.CONTACT_NEAR_SUM, l, z)
            put1(PS, g, st.ACCUM_N, l, 0.0)
            put1(PS, g, st.CONTACT_MIN_DIST, l, FAR)
        for c in range(BI[b, bk.BI_COLLIDERS]):
            k = c0 + c
            shape = topology[shapes + c]
            for l in range(w):
                scale = get1(TS, b, st.SCALE_RATIO, l) * get1(TS, b, st.LENGTH_UNIT, l)
                r = particle_radius(get1(PP, g, bk.CURVE_RADIUS, l), scale)
                x = get3(PS, g, st.NEXT_POS, l)
                bmin, bmax = point_bounds(x, r)
                d, n, x2 = solve_point_collider(CS, k, l, shape, x, r, bmin, bmax)
                # out of range, missed or suspended: the sums stay as they are
                hit = d <= r and get1(CS, k, st.SCALE_SUSPEND, l) == 0.0
                sum_push, sum_n, n_acc, count, min_dist = point_contact_add(
                    get3(PS, g, st.ACCUM3, l), get3(PS, g, st.CONTACT_NORMAL_SUM, l),
                    get3(PS, g, st.CONTACT_NEAR_SUM, l), get1(PS, g, st.ACCUM_N, l),
                    get1(PS, g, st.CONTACT_MIN_DIST, l), x, r, d, n, x2)
                if hit:
                    put3(PS, g, st.ACCUM3, l, sum_push)
                    put3(PS, g, st.CONTACT_NORMAL_SUM, l, sum_n)
                    put3(PS, g, st.CONTACT_NEAR_SUM, l, n_acc)
                    put1(PS, g, st.ACCUM_N, l, count)
                    put1(PS, g, st.CONTACT_MIN_DIST, l, min_dist)
        for l in range(w):
            scale = get1(TS, b, st.SCALE_RATIO, l) * get1(TS, b, st.LENGTH_UNIT, l)
            r = particle_radius(get1(PP, g, bk.CURVE_RADIUS, l), scale)
            x = get3(PS, g, st.NEXT_POS, l)
            count = get1(PS, g, st.ACCUM_N, l)
            min_dist = get1(PS, g, st.CONTACT_MIN_DIST, l)
            n_acc = get3(PS, g, st.CONTACT_NEAR_SUM, l)
            # otherwise the result is (x, friction, n_acc): nothing else changes
            if count > 0.0 or min_dist <= r:
                new_x, friction, n_acc = point_contact_result(x, get3(PS, g, st.ACCUM3, l),
                                                              get3(PS, g, st.CONTACT_NORMAL_SUM, l), count, n_acc,
                                                              min_dist, r, get1(PS, g, st.FRICTION, l))
                put3(PS, g, st.NEXT_POS, l, new_x)
                put1(PS, g, st.FRICTION, l, friction)
            put3(PS, g, st.COLLISION_NORMAL, l, n_acc)


@kernel
def solve_edge_collider(CS, k, l, shape, a, b, ra, rb, cfr, bmin, bmax):
    """Edge (a, b) against collider slot k of lane l: (distance, normal, pushed a, pushed b);
    a missed bounding box or a collider out of range gives (FAR, 0, a, b)."""
    z = (0.0, 0.0, 0.0)
    if shape == PLANE:
        n = get3(CS, k, st.PLANE_NORMAL, l)
        o = get3(CS, k, st.START_NEW, l)
        da, a2 = plane_push(v_add(o, v_scale(n, ra)), n, a)
        db, b2 = plane_push(v_add(o, v_scale(n, rb)), n, b)
        return min(da, db), n, a2, b2
    if not aabb_overlap(bmin, bmax, get3(CS, k, st.AABB_MIN, l), get3(CS, k, st.AABB_MAX, l)):
        return FAR, z, a, b
    if shape == SPHERE:
        o_old = get3(CS, k, st.START_OLD, l)
        o_new = get3(CS, k, st.START_NEW, l)
        s = segment_parameter(o_old, a, b)
        c = v_lerp(a, b, s)
        v = v_sub(c, o_old)
        vl = v_length(v)
        if vl < 1e-9:
            return FAR, z, a, b
        n = v_scale(v, 1.0 / vl)
        gap = vl - v_dot(n, v_sub(o_new, o_old))
        th = ra + (rb - ra) * s + get1(CS, k, st.RADIUS_START, l)
        if gap > th + cfr:
            return FAR, z, a, b
        l2 = v_dot(n, v_sub(c, o_new))
    else:
        so = get3(CS, k, st.START_OLD, l)
        eo = get3(CS, k, st.END_OLD, l)
        rs = get1(CS, k, st.RADIUS_START, l)
        re = get1(CS, k, st.RADIUS_END, l)
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
        sn = get3(CS, k, st.START_NEW, l)
        en = get3(CS, k, st.END_NEW, l)
        ds = v_sub(sn, so)
        de = v_sub(en, eo)
        gap = vl - v_dot(n, v_lerp(ds, de, t))
        th = ra + (rb - ra) * s + rs + (re - rs) * t
        if gap > th + cfr:
            return FAR, z, a, b
        d = v_lerp(sn, en, t)
        l2 = v_dot(n, v_sub(ca, d))
    if l2 > th:
        return l2 - th, n, a, b
    depth = th - l2
    b0 = 1.0 - s
    b1 = s
    sc = depth / (b0 * b0 + b1 * b1)
    return -depth, n, v_add(a, v_scale(n, b0 * sc)), v_add(b, v_scale(n, b1 * sc))


@kernel
def accumulate_push(PS, g, l, v):
    """Add push v to particle slot g's fixed-point accumulator in lane l (truncated toward zero)."""
    acc = get3(PS, g, st.ACCUM_VECTOR, l)
    put3(PS, g, st.ACCUM_VECTOR, l, (acc[0] + float(math.trunc(v[0] * FIXED_POINT)),
                                     acc[1] + float(math.trunc(v[1] * FIXED_POINT)),
                                     acc[2] + float(math.trunc(v[2] * FIXED_POINT))))
    put1(PS, g, st.ACCUM_COUNT, l, get1(PS, g, st.ACCUM_COUNT, l) + 1.0)


@kernel(forceinline=False)
def edge_collision_block(PS, PP, TS, CS, BI, topology, b):
    """D.8 edge mode over block b: per edge (in order) and lane, the edge against every
    collider slot of the lane, its pushes accumulated in fixed point at both ends and its
    contact recorded (friction as a fixed-point max, normals summed); then the sum step.
    The collider tests branch on the lane's data: the lanes run one after another per edge."""
    g0 = BI[b, bk.BI_G0]
    w = bk.lane_width(BI, b)
    attribute = BI[b, bk.BI_ATTRIBUTE]
    pairs = BI[b, bk.BI_EDGE_PAIRS]
    c0 = BI[b, bk.BI_COLLIDER0]
    colliders = BI[b, bk.BI_COLLIDERS]
    shapes = BI[b, bk.BI_COLLIDER_SHAPE]
    z = (0.0, 0.0, 0.0)
    for e in range(BI[b, bk.BI_EDGES]):
        ja = topology[pairs + 2 * e]
        jb = topology[pairs + 2 * e + 1]
        a_move = (topology[attribute + ja] & MOVE) != 0
        b_move = (topology[attribute + jb] & MOVE) != 0
        if not a_move and not b_move:
            continue
        ga = g0 + ja
        gb = g0 + jb
        for l in range(w):
            scale = get1(TS, b, st.SCALE_RATIO, l) * get1(TS, b, st.LENGTH_UNIT, l)
            ra = get1(PP, ga, bk.CURVE_RADIUS, l) * scale
            rb = get1(PP, gb, bk.CURVE_RADIUS, l) * scale
            cfr = (ra + rb) * 0.5
            pa = get3(PS, ga, st.NEXT_POS, l)
            pb = get3(PS, gb, st.NEXT_POS, l)
            bmin = (min(pa[0] - ra, pb[0] - rb) - cfr, min(pa[1] - ra, pb[1] - rb) - cfr,
                    min(pa[2] - ra, pb[2] - rb) - cfr)
            bmax = (max(pa[0] + ra, pb[0] + rb) + cfr, max(pa[1] + ra, pb[1] + rb) + cfr,
                    max(pa[2] + ra, pb[2] + rb) + cfr)
            push_a = z
            push_b = z
            sum_n = z
            n_acc = z
            cnt = 0
            min_dist = FAR
            touched = False
            for c in range(colliders):
                k = c0 + c
                if get1(CS, k, st.SCALE_SUSPEND, l) != 0.0:
                    continue
                d, n, a2, b2 = solve_edge_collider(CS, k, l, topology[shapes + c], pa, pb, ra, rb, cfr, bmin, bmax)
                if d <= 0.0:
                    push_a = v_add(push_a, v_sub(a2, pa))
                    push_b = v_add(push_b, v_sub(b2, pb))
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
                    accumulate_push(PS, ga, l, v_scale(push_a, f))
                    accumulate_push(PS, gb, l, v_scale(push_b, f))
            if touched:
                # fixed-point max: the value is cast to an integer before scaling (quirk, §0.2)
                recorded = float(math.trunc(1.0 - saturate(min_dist / cfr)))
                if a_move:
                    put1(PS, ga, st.ACCUM_FRICTION, l, max(get1(PS, ga, st.ACCUM_FRICTION, l), recorded))
                    put3(PS, ga, st.ACCUM_NORMAL, l, v_add(get3(PS, ga, st.ACCUM_NORMAL, l), n_acc))
                if b_move:
                    put1(PS, gb, st.ACCUM_FRICTION, l, max(get1(PS, gb, st.ACCUM_FRICTION, l), recorded))
                    put3(PS, gb, st.ACCUM_NORMAL, l, v_add(get3(PS, gb, st.ACCUM_NORMAL, l), n_acc))
    # sum step: every particle with contributions (Jacobi), then the accumulators cleared
    for j in range(BI[b, bk.BI_N]):
        g = g0 + j
        for l in range(w):
            n = get1(PS, g, st.ACCUM_COUNT, l)
            if n > 0.0:
                s = 1.0 / (n * FIXED_POINT)
                acc = get3(PS, g, st.ACCUM_VECTOR, l)
                x = get3(PS, g, st.NEXT_POS, l)
                put3(PS, g, st.NEXT_POS, l, (x[0] + acc[0] * s, x[1] + acc[1] * s, x[2] + acc[2] * s))
            accf = get1(PS, g, st.ACCUM_FRICTION, l)
            if accf > 0.0:
                put1(PS, g, st.FRICTION, l, max(get1(PS, g, st.FRICTION, l), accf))
            nsum = get3(PS, g, st.ACCUM_NORMAL, l)
            if v_length_sq(nsum) > 0.0:
                put3(PS, g, st.COLLISION_NORMAL, l, v_normalize(nsum))
            put3(PS, g, st.ACCUM_VECTOR, l, z)
            put1(PS, g, st.ACCUM_COUNT, l, 0.0)
            put1(PS, g, st.ACCUM_FRICTION, l, 0.0)
            put3(PS, g, st.ACCUM_NORMAL, l, z)
