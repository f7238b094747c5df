"""Bone rotations from the display positions (ref §E.2 line mode, §E.3 triangle mode).

E.2 walks each baseline parent-first: a moving bone takes the rest rotation carried by its
parent, swung so the parent->bone edge matches the simulated one, then turns by
``rotational_interpolation`` (fixed roots: ``root_rotation``) towards its children; the result
is slerped from the animated rotation by ``blend_weight``. E.3 then overrides triangle
vertices with the frame of their adjacent triangles' normals and tangents.
"""
from __future__ import annotations

from magica_py.jit import kernel
import math

from magica_py.kernels.math3d import (
    from_to_rotation, from_to_rotation_unit, load3, load4, q_inverse, q_look_rotation, q_mul,
    q_rotate, q_slerp, store3, store4, v_add, v_cross, v_dot, v_length, v_length_sq, v_lerp,
    v_normalize, v_scale, v_sub,
)

FIXED = 0x01
MOVE = 0x02
ZERO_DISTANCE = 0x20
INCLUDE_LINE = 0x01


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


@kernel
def line_rotations_team(m, ps, prm, ts, team):
    """E.2 over the IncludeLine baselines of one team."""
    if m.team_has_lines[team] == 0:
        return
    ri = prm.rotational_interpolation[team]
    rr = prm.root_rotation[team]
    a = prm.animation_pose_ratio[team]
    bw = ts.blend_weight[team]
    b0 = m.team_baseline_start[team]
    for b in range(b0, b0 + m.team_baseline_count[team]):
        if (m.baseline_flags[b] & INCLUDE_LINE) == 0:
            continue
        e0 = m.baseline_start[b]
        for e in range(e0, e0 + m.baseline_count[b]):
            x = m.baseline_data[e]
            attr = m.attribute[x]
            pos = load3(ps.position, x)
            q = load4(ps.rotation, x)
            bp = load3(ps.base_pos_buffer, x)
            bq = load4(ps.base_rot_buffer, x)
            cn = m.child_count[x]
            if cn > 0 and (attr & (FIXED | MOVE)) != 0:
                ibq = q_inverse(bq)
                ctv = (0.0, 0.0, 0.0)
                cv = (0.0, 0.0, 0.0)
                c0 = m.child_start[x]
                for k in range(c0, c0 + cn):
                    c = m.child_data[k]
                    lp = v_lerp(load3(m.baseline_local_position, c),
                                q_rotate(ibq, v_sub(load3(ps.base_pos_buffer, c), bp)), a)
                    if a == 0.0:  # slerp at 0 is its first argument
                        lq = load4(m.baseline_local_rotation, c)
                    else:
                        lq = q_slerp(load4(m.baseline_local_rotation, c),
                                     q_mul(ibq, load4(ps.base_rot_buffer, c)), a)
                    zero = (m.attribute[c] & ZERO_DISTANCE) != 0
                    tv = (0.0, 0.0, 0.0) if zero else q_rotate(q, lp)
                    ctv = v_add(ctv, tv)
                    if (m.attribute[c] & MOVE) != 0:
                        cur = v_sub(load3(ps.position, c), pos)
                        cv = v_add(cv, cur)
                        qc = q_mul(q, lq)
                        if not zero:
                            qc = q_mul(full_swing(v_normalize(tv), v_normalize(cur)), qc)
                        store4(ps.rotation, c, qc)
                    else:
                        cv = v_add(cv, tv)
                t = ri if (attr & MOVE) != 0 else rr
                if v_length(ctv) >= 1e-8 and v_length(cv) >= 1e-8:
                    q = q_mul(from_to_rotation(ctv, cv, t), q)
            store4(ps.rotation, x, q if bw == 1.0 else q_slerp(bq, q, bw))


@kernel
def triangle_rotations_team(m, ps, team):
    """E.3: rotation of triangle vertices from their triangles' display normals and uv tangents.

    Each triangle's frame is computed once (into ``ps.triangle_normal/tangent``) and then
    summed per vertex: a vertex of a strip mesh touches up to 6 triangles, so computing the
    frame per (vertex, triangle) pair did the same work ~3 times. Positions do not change in
    E.3, so the frames and sums are bit-identical either way."""
    t0 = m.team_triangle_start[team]
    tn_count = m.team_triangle_count[team]
    if tn_count == 0:
        return
    for tri in range(t0, t0 + tn_count):
        tn, tt = triangle_frame(m, ps, tri)
        store3(ps.triangle_normal, tri, tn)
        store3(ps.triangle_tangent, tri, tt)
    start = m.team_particle_start[team]
    for p in range(start, start + m.team_particle_count[team]):
        n = m.vertex_triangle_count[p]
        if n == 0:
            continue
        ns = (0.0, 0.0, 0.0)
        ts_ = (0.0, 0.0, 0.0)
        k0 = m.vertex_triangle_start[p]
        for k in range(k0, k0 + n):
            tri = m.vertex_triangle_data[k]
            flip = m.vertex_triangle_flip[k]
            ns = v_add(ns, v_scale(load3(ps.triangle_normal, tri), -1.0 if (flip & 1) != 0 else 1.0))
            ts_ = v_add(ts_, v_scale(load3(ps.triangle_tangent, tri), -1.0 if (flip & 2) != 0 else 1.0))
        if v_length(ns) > 1e-6 and v_length(ts_) > 1e-6:
            nn = v_normalize(ns)
            tn = v_normalize(ts_)
            d = v_dot(nn, tn)
            if abs(d) < 1.0 - 1e-9:
                binormal = v_normalize(v_cross(nn, tn))
                store4(ps.rotation, p, q_look_rotation(binormal, nn))


@kernel
def triangle_frame(m, ps, tri):
    """Normal and uv tangent of triangle ``tri`` at the display positions (0 when degenerate)."""
    i0 = m.triangles[tri, 0]
    i1 = m.triangles[tri, 1]
    i2 = m.triangles[tri, 2]
    p0 = load3(ps.position, i0)
    e1 = v_sub(load3(ps.position, i1), p0)
    e2 = v_sub(load3(ps.position, i2), p0)
    n = v_cross(e1, e2)
    normal = v_normalize(n) if v_length_sq(n) > 1e-16 else (0.0, 0.0, 0.0)
    du1 = m.triangle_uv[tri, 1, 0] - m.triangle_uv[tri, 0, 0]
    dv1 = m.triangle_uv[tri, 1, 1] - m.triangle_uv[tri, 0, 1]
    du2 = m.triangle_uv[tri, 2, 0] - m.triangle_uv[tri, 0, 0]
    dv2 = m.triangle_uv[tri, 2, 1] - m.triangle_uv[tri, 0, 1]
    area = du1 * dv2 - du2 * dv1
    r = 1.0 / area if area != 0.0 else 1.0
    # standard uv tangent, negated for Unity's left-handed convention (B.4)
    tangent = v_scale(v_sub(v_scale(e1, dv2), v_scale(e2, dv1)), -r)
    return normal, v_normalize(tangent)
