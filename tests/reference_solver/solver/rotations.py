"""Bone rotations from the display positions (docs/solver.md §E.2 line mode, §E.3 triangle mode).

E.2 walks each baseline parent-first: a moving bone takes the rest rotation carried by its
parent, swung so the parent->bone edge matches the simulated one, then turns by
``rotational_interpolation`` (fixed roots: ``root_rotation``) towards its children; the result
is slerped from the animated rotation by ``blend_weight``. E.3 then overrides triangle
vertices with the frame of their adjacent triangles' normals and tangents.
"""
from __future__ import annotations

import math

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels.math3d import (
    from_to_rotation, from_to_rotation_unit, load3, load4, q_inverse, q_mul, store3,
    q_rotate, q_slerp, store4, v_add, v_cross, v_dot, v_length, v_length_sq, v_lerp, v_normalize, v_scale,
    v_sub,
)

FIXED = 0x01
MOVE = 0x02
ZERO_DISTANCE = 0x20
INCLUDE_LINE = 0x01
IDENTITY = (0.0, 0.0, 0.0, 1.0)


@kernel
def normalize_or_zero(a):
    """``v_normalize`` without a branch."""
    n = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    inv = 1.0 / max(n, 1e-300)   # a zero vector: discarded below (and no 1/0 with the JIT off)
    small = n < 1e-12
    return (0.0 if small else a[0] * inv, 0.0 if small else a[1] * inv, 0.0 if small else a[2] * inv)


@kernel
def q_normalize_or_identity(q):
    """``q_normalize`` without a branch."""
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    inv = 1.0 / max(n, 1e-300)   # a zero quaternion: discarded below
    small = n < 1e-12
    return (0.0 if small else q[0] * inv, 0.0 if small else q[1] * inv,
            0.0 if small else q[2] * inv, 1.0 if small else q[3] * inv)


@kernel
def q_from_matrix_select(m00, m01, m02, m10, m11, m12, m20, m21, m22):
    """``q_from_matrix`` with its four cases computed and selected."""
    t_plus = m11 + m22
    t_minus = m11 - m22
    qa = (m21 - m12, m02 - m20, m10 - m01, 1.0 + m00 + t_plus)
    qb = (1.0 + m00 - t_plus, m01 + m10, m02 + m20, m21 - m12)
    qc = (m01 + m10, 1.0 - m00 + t_minus, m12 + m21, m02 - m20)
    qd = (m02 + m20, m12 + m21, 1.0 - m00 - t_minus, m10 - m01)
    pos00 = math.copysign(1.0, m00) >= 0.0
    first = math.copysign(1.0, t_plus) >= 0.0
    second = math.copysign(1.0, t_minus) >= 0.0
    q = (qa[0] if first else qb[0], qa[1] if first else qb[1], qa[2] if first else qb[2], qa[3] if first else qb[3])
    r = (qc[0] if second else qd[0], qc[1] if second else qd[1], qc[2] if second else qd[2], qc[3] if second else qd[3])
    q = (q[0] if pos00 else r[0], q[1] if pos00 else r[1], q[2] if pos00 else r[2], q[3] if pos00 else r[3])
    return q_normalize_or_identity(q)


@kernel
def look_rotation_select(forward, up):
    """``q_look_rotation`` (+Z = forward, +Y towards up, both unit) without branches."""
    x_axis = normalize_or_zero(v_cross(up, forward))
    y_axis = v_cross(forward, x_axis)
    return q_from_matrix_select(x_axis[0], y_axis[0], forward[0], x_axis[1], y_axis[1], forward[1],
                                x_axis[2], y_axis[2], forward[2])


@kernel
def rot_from_normal_tangent_select(normal, tangent):
    """``rot_from_normal_tangent`` (§0.2 rot_from) without branches."""
    return look_rotation_select(tangent, normal)


@kernel
def full_swing(a, b):
    """``fromto_v(a, b, 1)`` for unit a, b without trigonometry: the half-angle quaternion
    ``normalize(a x b, 1 + a.b)`` is the same rotation; the reference's degenerate cases
    (opposite: pi about the fallback axis; within 1e-6 of parallel: identity) are kept."""
    c = v_dot(a, b)
    if c > 1.0:
        c = 1.0
    elif c < -1.0:
        c = -1.0
    if abs(1.0 + c) < 1e-6 or abs(1.0 - c) < 1e-6:
        return from_to_rotation_unit(a, b, 1.0)
    x = v_cross(a, b)
    w = 1.0 + c
    inv = 1.0 / math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2] + w * w)
    return (x[0] * inv, x[1] * inv, x[2] * inv, w * inv)


@kernel(inline="always")
def line_child_pose(ibq, bp, rest_position, rest_rotation, base_pos_c, base_rot_c, a, a_zero):
    """E.2: the rest pose (position, rotation) of child c relative to its parent x, moved
    towards the animated one by ``animation_pose_ratio`` a (``a_zero``: a == 0, where the slerp
    is its first argument). ``ibq``: inverse animated rotation of x; ``bp``: animated position of x."""
    lp = v_lerp(rest_position, q_rotate(ibq, v_sub(base_pos_c, bp)), a)
    if a_zero:
        lq = rest_rotation
    else:
        lq = q_slerp(rest_rotation, q_mul(ibq, base_rot_c), a)
    return lp, lq


@kernel(inline="always")
def line_child_rotation(q, lq, tv, cur, zero):
    """E.2: rotation of a moving child: its rest rotation carried by x's rotation q, swung so
    the rest edge ``tv`` matches the simulated edge ``cur`` (not for a zero-distance child)."""
    qc = q_mul(q, lq)
    if not zero:
        qc = q_mul(full_swing(v_normalize(tv), v_normalize(cur)), qc)
    return qc


@kernel(inline="always")
def line_turn(q, ctv, cv, t):
    """E.2: x's rotation q turned by fraction t from its children's rest directions ``ctv``
    towards their simulated ones ``cv`` (left as is when either sum is (near) zero)."""
    if (v_length(ctv) >= 1e-8) & (v_length(cv) >= 1e-8):
        q = q_mul(from_to_rotation(ctv, cv, t), q)
    return q


@kernel(inline="always")
def line_blend(bq, q, bw):
    """E.2: the bone rotation blended from the animated one by ``blend_weight`` bw."""
    return q if bw == 1.0 else q_slerp(bq, q, bw)


@kernel
def line_rotations_team(m, ps, prm, ts, team):
    """E.2 over the IncludeLine baselines of one team."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_baseline_count, m_baseline_data, m_baseline_flags = m.baseline_count, m.baseline_data, m.baseline_flags
    m_baseline_start, m_team_baseline_count = m.baseline_start, m.team_baseline_count
    if m.team_has_lines[team] == 0:
        return
    ri = prm.rotational_interpolation[team]
    rr = prm.root_rotation[team]
    a = prm.animation_pose_ratio[team]
    a_zero = a == 0.0
    bw = ts.blend_weight[team]
    # arrays as locals, flat rows, unsigned indices (through the tables the array pointers
    # are reloaded after every store); the walk and the maths are unchanged
    attribute, child_start, child_count, child_data = m.attribute, m.child_start, m.child_count, m.child_data
    rest_position, rest_rotation = m.baseline_local_position, m.baseline_local_rotation
    position, rotation = ps.position, ps.rotation
    base_pos_buffer, base_rot_buffer = ps.base_pos_buffer, ps.base_rot_buffer
    b0 = m.team_baseline_start[team]
    for b in range(b0, b0 + m_team_baseline_count[team]):
        if (m_baseline_flags[b] & INCLUDE_LINE) == 0:
            continue
        e0 = m_baseline_start[b]
        for e in range(e0, e0 + m_baseline_count[b]):
            x = np.uint64(m_baseline_data[e])
            attr = attribute[x]
            pos = load3(position, x)
            q = load4(rotation, x)
            bp = load3(base_pos_buffer, x)
            bq = load4(base_rot_buffer, x)
            cn = child_count[x]
            if cn > 0 and (attr & (FIXED | MOVE)) != 0:
                ibq = q_inverse(bq)
                ctv = (0.0, 0.0, 0.0)
                cv = (0.0, 0.0, 0.0)
                c0 = child_start[x]
                for k in range(c0, c0 + cn):
                    c = np.uint64(child_data[k])
                    if a_zero:
                        lp, lq = line_child_pose(ibq, bp, load3(rest_position, c), load4(rest_rotation, c),
                                                 load3(base_pos_buffer, c), load4(base_rot_buffer, c), a, True)
                    else:
                        lp, lq = line_child_pose(ibq, bp, load3(rest_position, c), load4(rest_rotation, c),
                                                 load3(base_pos_buffer, c), load4(base_rot_buffer, c), a, False)
                    zero = (attribute[c] & ZERO_DISTANCE) != 0
                    tv = (0.0, 0.0, 0.0) if zero else q_rotate(q, lp)
                    ctv = v_add(ctv, tv)
                    if (attribute[c] & MOVE) != 0:
                        cur = v_sub(load3(position, c), pos)
                        cv = v_add(cv, cur)
                        qc = line_child_rotation(q, lq, tv, cur, zero)
                        store4(rotation, c, qc)
                    else:
                        cv = v_add(cv, tv)
                t = ri if (attr & MOVE) != 0 else rr
                q = line_turn(q, ctv, cv, t)
            store4(rotation, x, line_blend(bq, q, bw))


TRIANGLES_PER_VERTEX = 6   # E.3's vectorised pass sums up to this many triangles per vertex


@kernel
def triangle_frame_from(p0, p1, p2, uv0, uv1, uv2):
    """Normal and uv tangent of a triangle at the display positions p0..p2 with corner uvs
    uv0..uv2 (normal 0 when degenerate). Branch-free (the per-triangle loop vectorises)."""
    e1 = v_sub(p1, p0)
    e2 = v_sub(p2, p0)
    n = v_cross(e1, e2)
    unit = normalize_or_zero(n)
    flat_triangle = not (v_length_sq(n) > 1e-16)
    normal = (0.0 if flat_triangle else unit[0], 0.0 if flat_triangle else unit[1], 0.0 if flat_triangle else unit[2])
    du1 = uv1[0] - uv0[0]
    dv1 = uv1[1] - uv0[1]
    du2 = uv2[0] - uv0[0]
    dv2 = uv2[1] - uv0[1]
    area = du1 * dv2 - du2 * dv1
    inv_area = 1.0 / area
    r = inv_area if area != 0.0 else 1.0
    # standard uv tangent, negated for Unity's left-handed convention (B.4)
    tangent = v_scale(v_sub(v_scale(e1, dv2), v_scale(e2, dv1)), -r)
    return normal, normalize_or_zero(tangent)


@kernel(inline="always")
def add_flipped(acc, v, flip):
    """E.3 sum of a vertex's triangle normals (tangents): ``acc + v``, v negated where the
    triangle's winding is flipped for this vertex."""
    return v_add(acc, v_scale(v, -1.0 if flip else 1.0))


@kernel
def vertex_frame_rotation(ns, ts_):
    """E.3's rotation of a vertex from its summed triangle normals ``ns`` and tangents ``ts_``:
    (valid, rotation); not valid when a sum is (near) zero or the two are parallel."""
    nn = normalize_or_zero(ns)
    tn = normalize_or_zero(ts_)
    d = v_dot(nn, tn)
    binormal = normalize_or_zero(v_cross(nn, tn))
    valid = (v_length(ns) > 1e-6) & (v_length(ts_) > 1e-6) & (abs(d) < 1.0 - 1e-9)
    return valid, look_rotation_select(binormal, nn)


@kernel
def triangle_rotations_team(m, ps, team):
    """E.3: rotation of triangle vertices from their triangles' display normals and uv tangents.

    Each triangle's frame is computed once (into ``ps.triangle_normal/tangent``) and then
    summed per vertex: a vertex of a strip mesh touches up to 6 triangles, so computing the
    frame per (vertex, triangle) pair did the same work ~3 times. Positions do not change in
    E.3, so the frames and sums are bit-identical either way.

    The per-vertex sums run over ``TRIANGLES_PER_VERTEX`` slots, the unused ones selected away
    (same additions in the same order); a vertex with more triangles is left to a scalar pass."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_vertex_triangle_count = m.vertex_triangle_count
    t0 = m.team_triangle_start[team]
    tn_count = m.team_triangle_count[team]
    if tn_count == 0:
        return
    triangles, triangle_uv = m.triangles, m.triangle_uv
    position = ps.position
    triangle_normal, triangle_tangent = ps.triangle_normal, ps.triangle_tangent
    for tri in range(t0, t0 + tn_count):
        tn, tt = triangle_frame_from(
            load3(position, triangles[tri, 0]), load3(position, triangles[tri, 1]), load3(position, triangles[tri, 2]),
            (triangle_uv[tri, 0, 0], triangle_uv[tri, 0, 1]),
            (triangle_uv[tri, 1, 0], triangle_uv[tri, 1, 1]),
            (triangle_uv[tri, 2, 0], triangle_uv[tri, 2, 1]))
        store3(triangle_normal, tri, tn)
        store3(triangle_tangent, tri, tt)
    start = m.team_particle_start[team]
    count = m.team_particle_count[team]
    vt_start, vt_count, vt_data, vt_flip = (m.vertex_triangle_start, m_vertex_triangle_count,
                                            m.vertex_triangle_data, m.vertex_triangle_flip)
    rotation = ps.rotation
    crowded = 0
    first = np.uint64(start)
    for j in range(count):
        p = first + np.uint64(j)
        n = vt_count[p]
        k0 = vt_start[p]
        ns = (0.0, 0.0, 0.0)
        ts_ = (0.0, 0.0, 0.0)
        for k in range(TRIANGLES_PER_VERTEX):
            used = k < n
            # an unused slot reads entry 0 (always valid) and is selected away
            e = np.uint64(k0 + k) if used else np.uint64(0)
            tri = vt_data[e]
            flip = vt_flip[e]
            ns_k = add_flipped(ns, load3(triangle_normal, tri), (flip & 1) != 0)
            ts_k = add_flipped(ts_, load3(triangle_tangent, tri), (flip & 2) != 0)
            ns = (ns_k[0] if used else ns[0], ns_k[1] if used else ns[1], ns_k[2] if used else ns[2])
            ts_ = (ts_k[0] if used else ts_[0], ts_k[1] if used else ts_[1], ts_k[2] if used else ts_[2])
        valid, q = vertex_frame_rotation(ns, ts_)
        few = n <= TRIANGLES_PER_VERTEX
        crowded += 0 if few else 1
        if valid & few:
            store4(rotation, p, q)
    if crowded > 0:
        for p in range(start, start + count):
            if m_vertex_triangle_count[p] > TRIANGLES_PER_VERTEX:
                crowded_vertex_rotation(m, ps, p)


@kernel
def crowded_vertex_rotation(m, ps, p):
    """E.3 for a vertex with more than ``TRIANGLES_PER_VERTEX`` triangles (scalar)."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_vertex_triangle_count, m_vertex_triangle_data = m.vertex_triangle_count, m.vertex_triangle_data
    m_vertex_triangle_flip, ps_triangle_normal = m.vertex_triangle_flip, ps.triangle_normal
    ps_triangle_tangent = ps.triangle_tangent
    ns = (0.0, 0.0, 0.0)
    ts_ = (0.0, 0.0, 0.0)
    k0 = m.vertex_triangle_start[p]
    for k in range(k0, k0 + m_vertex_triangle_count[p]):
        tri = m_vertex_triangle_data[k]
        flip = m_vertex_triangle_flip[k]
        ns = add_flipped(ns, load3(ps_triangle_normal, tri), (flip & 1) != 0)
        ts_ = add_flipped(ts_, load3(ps_triangle_tangent, tri), (flip & 2) != 0)
    valid, q = vertex_frame_rotation(ns, ts_)
    if valid:
        store4(ps.rotation, p, q)


