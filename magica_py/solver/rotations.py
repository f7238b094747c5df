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

from magica_py.build.proxy import BASELINE_INCLUDE_LINE, FIXED, MOVE, ZERO_DISTANCE
from magica_py.jit import kernel
from magica_py.kernels.math3d import (
    from_to_rotation_unit_select, opposite_unit, orthogonal_axis_select, q_axis_angle, q_inverse, q_mul,
    q_normalize_select, q_rotate, q_slerp, q_slerp_select, v_add, v_cross, v_dot, v_length, v_length_sq, v_lerp,
    v_normalize_select, v_scale, v_sub,
)
from magica_py.solver import blocks as bk
from magica_py.solver import state as st
from magica_py.solver.lanes import LANES, get1, get3, get4, put3, put4
from magica_py.solver.parameters import PRM_ANIMATION_POSE_RATIO, PRM_ROOT_ROTATION, PRM_ROTATIONAL_INTERPOLATION

IDENTITY = (0.0, 0.0, 0.0, 1.0)


@kernel(inline="always")
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
    return q_normalize_select(q)


@kernel
def look_rotation_select(forward, up):
    """``q_look_rotation`` (+Z = forward, +Y towards up, both unit) without branches."""
    x_axis = v_normalize_select(v_cross(up, forward))
    y_axis = v_cross(forward, x_axis)
    return q_from_matrix_select(x_axis[0], y_axis[0], forward[0], x_axis[1], y_axis[1], forward[1],
                                x_axis[2], y_axis[2], forward[2])


@kernel(inline="always")
def rot_from_normal_tangent_select(normal, tangent):
    """``rot_from_normal_tangent`` (§0.2 rot_from) without branches."""
    return look_rotation_select(tangent, normal)


@kernel
def swing_select(a, b, with_opposite=True):
    """``fromto_v(a, b, 1)`` for unit a and b (docs/solver.md §0.2) without trigonometry or a
    branch: the half-angle quaternion ``normalize(a x b, 1 + a.b)`` is the same rotation; a and
    b opposite (``|1 + a.b| < 1e-6``): pi about ``orthogonal_axis(a)``; within 1e-6 of
    parallel: the identity. Every path is computed and the answer selected; the reference
    solver's branching ``full_swing`` (tests/reference_solver) gives the same bits. Used by E.2
    and the angle limit (D.5). ``with_opposite`` False (a constant at the call site) leaves
    the opposite path out: the result is then not the swing where a and b are opposite, which
    the caller must detect and redo (the angle stage's lean pass, ``angle_iteration_lanes``)."""
    c = v_dot(a, b)
    c = 1.0 if c > 1.0 else c
    c = -1.0 if c < -1.0 else c
    x = v_cross(a, b)
    w = 1.0 + c
    inv = 1.0 / np.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2] + w * w)
    half_angle = (x[0] * inv, x[1] * inv, x[2] * inv, w * inv)
    kept = IDENTITY if abs(1.0 - c) < 1e-6 else half_angle
    if not with_opposite:
        return kept
    opposite = abs(1.0 + c) < 1e-6
    flip = q_axis_angle(orthogonal_axis_select(a), math.pi * 1.0)
    return flip if opposite else kept


@kernel(inline="always")
def line_child_pose(ibq, bp, rest_position, rest_rotation, base_pos_c, base_rot_c, a):
    """E.2: the rest pose (position, rotation) of child c relative to its parent x, moved
    towards the animated one by ``animation_pose_ratio`` a (> 0: ``line_child_lanes`` takes the
    rest pose as it is for a = 0). ``ibq``: inverse animated rotation of x; ``bp``: animated
    position of x."""
    lp = v_lerp(rest_position, q_rotate(ibq, v_sub(base_pos_c, bp)), a)
    lq = q_slerp(rest_rotation, q_mul(ibq, base_rot_c), a)
    return lp, lq


@kernel(inline="always")
def line_child_rotation(q, lq, tv, cur, zero, full):
    """E.2: rotation of a moving child: its rest rotation carried by x's rotation q, swung so
    the rest edge ``tv`` matches the simulated edge ``cur`` (not for a zero-distance child).
    Branch-free (``swing_select``). Returns (rotation, opposite): ``opposite``, the swing met
    edges in opposite directions, whose path ``full`` False leaves out (the rotation is then
    not the reference's and the caller redoes the lane with ``full`` True)."""
    qc = q_mul(q, lq)
    a = v_normalize_select(tv)
    b = v_normalize_select(cur)
    opposite = False
    if not zero:
        qc = q_mul(swing_select(a, b, full), qc)
        opposite = opposite_unit(a, b)
    return qc, opposite


@kernel(inline="always")
def line_turn(q, ctv, cv, t, full):
    """E.2: x's rotation q turned by fraction t from its children's rest directions ``ctv``
    towards their simulated ones ``cv`` (left as is when either sum is (near) zero).
    Branch-free. Returns (rotation, opposite): ``opposite``, the turn met sums in opposite
    directions, whose path ``full`` False leaves out (see ``line_child_rotation``)."""
    a = v_normalize_select(ctv)
    b = v_normalize_select(cv)
    turned = q_mul(from_to_rotation_unit_select(a, b, t, full), q)
    turns = (v_length(ctv) >= 1e-8) & (v_length(cv) >= 1e-8)
    return (turned if turns else q), turns & opposite_unit(a, b)


@kernel(inline="always")
def line_turn_pairs(PS, gx, t):
    """The lean pass of ``line_turn`` for bone slot gx of a full block (``LANES`` lanes), two
    lanes an iteration: lane h and lane h + LANES / 2. The turn's acos, sincos and
    normalisations are one long dependency chain per lane, and LLVM's vector loop runs one
    vector of lanes at a time; two independent vectors side by side keep the core's pipelines
    busy (E.2 about 11 % faster on the light scene, docs/BENCHMARKS.md, session 33). The half is a
    constant, so the two groups are known not to overlap and the loop still vectorises.
    Returns whether a lane's sums were opposite (its rotation is then kept, for the full pass)."""
    rare = False
    for h in range(LANES // 2):
        la = h
        lb = h + LANES // 2
        q0a = get4(PS, gx, st.ROTATION, la)
        q0b = get4(PS, gx, st.ROTATION, lb)
        qa, oa = line_turn(q0a, get3(PS, gx, st.CHILD_REST_SUM, la), get3(PS, gx, st.CHILD_EDGE_SUM, la), t,
                           np.bool_(False))
        qb, ob = line_turn(q0b, get3(PS, gx, st.CHILD_REST_SUM, lb), get3(PS, gx, st.CHILD_EDGE_SUM, lb), t,
                           np.bool_(False))
        put4(PS, gx, st.ROTATION, la, q0a if oa else qa)
        put4(PS, gx, st.ROTATION, lb, q0b if ob else qb)
        rare = rare | oa | ob
    return rare


@kernel(inline="always")
def line_blend(bq, q, bw):
    """E.2: the bone rotation blended from the animated one by ``blend_weight`` bw. Branch-free."""
    blended = q_slerp_select(bq, q, bw)
    return q if bw == 1.0 else blended


@kernel
def line_child_lanes(PS, PM, gc, w, zero, move, a, a_zero, full):
    """E.2 of child slot gc (its parent's pose gathered next to it), lanes 0..w: its rest and
    simulated edges (``CHILD_REST_EDGE``, ``CHILD_EDGE``) and, when it moves, its rotation.
    ``a_zero``: the animation pose ratio a is 0 (a constant at each call site), where the rest
    pose is the build's and the animated poses are not read: ``lerp(p, x, 0)`` is p for every
    finite x but for the sign of a zero component of p (docs/solver.md §E.2), and the slerp
    at 0 is its first argument. ``full`` False: without the swing's opposite-edge path;
    returns whether a moving lane needed it, and then the caller runs every lane again with
    ``full`` True (the pass reads none of the rows it writes, so running it twice is the same
    as running it once)."""
    z = (0.0, 0.0, 0.0)
    rare = False
    for l in range(min(w, LANES)):
        q = get4(PS, gc, st.PARENT_ROTATION, l)
        if a_zero:
            lp = get3(PM, gc, bk.BASELINE_LOCAL_POSITION, l)
            lq = get4(PM, gc, bk.BASELINE_LOCAL_ROTATION, l)
        else:
            lp, lq = line_child_pose(q_inverse(get4(PS, gc, st.PARENT_BASE_ROT, l)),
                                     get3(PS, gc, st.PARENT_BASE_POS, l), get3(PM, gc, bk.BASELINE_LOCAL_POSITION, l),
                                     get4(PM, gc, bk.BASELINE_LOCAL_ROTATION, l), get3(PS, gc, st.BASE_POS_BUFFER, l),
                                     get4(PS, gc, st.BASE_ROT_BUFFER, l), a)
        tv = z if zero else q_rotate(q, lp)
        cur = v_sub(get3(PS, gc, st.POSITION, l), get3(PS, gc, st.PARENT_POSITION, l))
        put3(PS, gc, st.CHILD_REST_EDGE, l, tv)
        put3(PS, gc, st.CHILD_EDGE, l, cur if move else tv)
        if move:
            rotation, opposite = line_child_rotation(q, lq, tv, cur, zero, full)
            put4(PS, gc, st.ROTATION, l, rotation)
            rare = rare | opposite
    return rare


@kernel(forceinline=False)
def line_rotations_block(PS, PM, TS, P, BI, topology, b):
    """E.2 over the IncludeLine baselines of block b, every lane side by side. For each bone
    x with children, in baseline order: its pose is copied next to each child (``PARENT_*``),
    each child's rotation and its rest and simulated edges are solved across the lanes
    (``CHILD_REST_EDGE`` / ``CHILD_EDGE``), the edges are summed at x in child order, and x
    turns and blends. Each loop touches one or two items, so the lane loops vectorise."""
    ri = P[b, PRM_ROTATIONAL_INTERPOLATION]
    rr = P[b, PRM_ROOT_ROTATION]
    a = P[b, PRM_ANIMATION_POSE_RATIO]
    a_zero = a == 0.0
    g0 = BI[b, bk.BI_G0]
    w = bk.lane_width(BI, b)
    attribute = BI[b, bk.BI_ATTRIBUTE]
    child_start, child_count, child_data = BI[b, bk.BI_CHILD_START], BI[b, bk.BI_CHILD_COUNT], BI[b, bk.BI_CHILD_DATA]
    bl_flags, bl_start, bl_count, bl_data = (BI[b, bk.BI_BASELINE_FLAGS], BI[b, bk.BI_BASELINE_START],
                                             BI[b, bk.BI_BASELINE_COUNT], BI[b, bk.BI_BASELINE_DATA])
    lines = BI[b, bk.BI_BASELINES]
    if BI[b, bk.BI_HAS_LINES] == 0:   # no early return (docs/tech-notes.md §10)
        lines = 0
    z = (0.0, 0.0, 0.0)
    blend = False   # a lane whose blend weight is not 1 (line_blend is the identity at 1: its slerp left out)
    for l in range(w):
        blend = blend | (get1(TS, b, st.BLEND_WEIGHT, l) != 1.0)
    for line in range(lines):
        if (topology[bl_flags + line] & BASELINE_INCLUDE_LINE) == 0:
            continue
        e0 = topology[bl_start + line]
        for e in range(e0, e0 + topology[bl_count + line]):
            x = topology[bl_data + e]
            gx = g0 + x
            attr = topology[attribute + x]
            cn = topology[child_count + x]
            c0 = topology[child_start + x]
            if cn > 0 and (attr & (FIXED | MOVE)) != 0:
                for k in range(c0, c0 + cn):
                    gc = g0 + topology[child_data + k]
                    for l in range(w):   # x's pose next to the child
                        put4(PS, gc, st.PARENT_ROTATION, l, get4(PS, gx, st.ROTATION, l))
                        put3(PS, gc, st.PARENT_POSITION, l, get3(PS, gx, st.POSITION, l))
                    if not a_zero:   # x's animated pose: read only to move the rest pose towards it
                        for l in range(w):
                            put4(PS, gc, st.PARENT_BASE_ROT, l, get4(PS, gx, st.BASE_ROT_BUFFER, l))
                            put3(PS, gc, st.PARENT_BASE_POS, l, get3(PS, gx, st.BASE_POS_BUFFER, l))
                for k in range(c0, c0 + cn):
                    c = topology[child_data + k]
                    gc = g0 + c
                    zero = (topology[attribute + c] & ZERO_DISTANCE) != 0
                    move = (topology[attribute + c] & MOVE) != 0
                    # a == 0 goes in as a constant: tested in the lane loop, the rest rotation's
                    # slerp towards the animated one would be computed for every lane and dropped;
                    # the lean pass leaves the opposite-edge swing out, redone where it is needed
                    if a_zero:
                        rare = line_child_lanes(PS, PM, gc, w, zero, move, a, np.bool_(True), np.bool_(False))
                    else:
                        rare = line_child_lanes(PS, PM, gc, w, zero, move, a, np.bool_(False), np.bool_(False))
                    if rare:
                        line_child_lanes(PS, PM, gc, w, zero, move, a, a_zero, np.bool_(True))
                for l in range(w):
                    put3(PS, gx, st.CHILD_REST_SUM, l, z)
                    put3(PS, gx, st.CHILD_EDGE_SUM, l, z)
                for k in range(c0, c0 + cn):   # the sums in child order
                    gc = g0 + topology[child_data + k]
                    for l in range(w):
                        put3(PS, gx, st.CHILD_REST_SUM, l,
                             v_add(get3(PS, gx, st.CHILD_REST_SUM, l), get3(PS, gc, st.CHILD_REST_EDGE, l)))
                        put3(PS, gx, st.CHILD_EDGE_SUM, l,
                             v_add(get3(PS, gx, st.CHILD_EDGE_SUM, l), get3(PS, gc, st.CHILD_EDGE, l)))
                t = ri if (attr & MOVE) != 0 else rr
                # the lean turn: lanes whose sums are opposite keep their rotation
                if w == LANES:
                    rare = line_turn_pairs(PS, gx, t)
                else:
                    rare = False
                    for l in range(w):
                        q0 = get4(PS, gx, st.ROTATION, l)
                        q, opposite = line_turn(q0, get3(PS, gx, st.CHILD_REST_SUM, l),
                                                get3(PS, gx, st.CHILD_EDGE_SUM, l), t, np.bool_(False))
                        put4(PS, gx, st.ROTATION, l, q0 if opposite else q)
                        rare = rare | opposite
                if rare:       # and turn on the full path
                    for l in range(w):
                        q0 = get4(PS, gx, st.ROTATION, l)
                        q, opposite = line_turn(q0, get3(PS, gx, st.CHILD_REST_SUM, l),
                                                get3(PS, gx, st.CHILD_EDGE_SUM, l), t, np.bool_(True))
                        put4(PS, gx, st.ROTATION, l, q if opposite else q0)
            if blend:
                for l in range(w):
                    put4(PS, gx, st.ROTATION, l, line_blend(get4(PS, gx, st.BASE_ROT_BUFFER, l),
                                                            get4(PS, gx, st.ROTATION, l),
                                                            get1(TS, b, st.BLEND_WEIGHT, l)))


@kernel
def triangle_frame_from(p0, p1, p2, uv0, uv1, uv2):
    """Normal and uv tangent of a triangle at the display positions p0..p2 with corner uvs
    uv0..uv2 (normal 0 when degenerate). Branch-free (the per-triangle loop vectorises)."""
    e1 = v_sub(p1, p0)
    e2 = v_sub(p2, p0)
    n = v_cross(e1, e2)
    unit = v_normalize_select(n)
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
    return normal, v_normalize_select(tangent)


@kernel(inline="always")
def add_flipped(acc, v, flip):
    """E.3 sum of a vertex's triangle normals (tangents): ``acc + v``, v negated where the
    triangle's winding is flipped for this vertex."""
    return v_add(acc, v_scale(v, -1.0 if flip else 1.0))


@kernel
def vertex_frame_rotation(ns, ts_):
    """E.3's rotation of a vertex from its summed triangle normals ``ns`` and tangents ``ts_``:
    (valid, rotation); not valid when a sum is (near) zero or the two are parallel."""
    nn = v_normalize_select(ns)
    tn = v_normalize_select(ts_)
    d = v_dot(nn, tn)
    binormal = v_normalize_select(v_cross(nn, tn))
    valid = (v_length(ns) > 1e-6) & (v_length(ts_) > 1e-6) & (abs(d) < 1.0 - 1e-9)
    return valid, look_rotation_select(binormal, nn)


@kernel(forceinline=False)
def triangle_rotations_block(PS, TRS, TRM, BI, topology, b):
    """E.3 over block b: rotation of triangle vertices from their triangles' display normals
    and uv tangents.

    Each triangle's frame is computed once (into ``TRIANGLE_NORMAL/TANGENT``) and then summed
    per vertex: a vertex of a strip mesh touches up to 6 triangles, so computing the frame
    per (vertex, triangle) pair did the same work ~3 times. Positions do not change in E.3,
    so the frames and sums are the same bits either way."""
    tn_count = BI[b, bk.BI_TRIANGLES]
    if tn_count == 0:
        return
    g0 = BI[b, bk.BI_G0]
    w = bk.lane_width(BI, b)
    t0 = BI[b, bk.BI_TRIANGLE0]
    corners = BI[b, bk.BI_TRIANGLE_CORNERS]
    for tri in range(tn_count):
        ga = g0 + topology[corners + 3 * tri]
        gb = g0 + topology[corners + 3 * tri + 1]
        gc = g0 + topology[corners + 3 * tri + 2]
        it = t0 + tri
        for l in range(w):
            tn, tt = triangle_frame_from(
                get3(PS, ga, st.POSITION, l), get3(PS, gb, st.POSITION, l), get3(PS, gc, st.POSITION, l),
                (TRM[it, bk.TRIANGLE_UV + l], TRM[it, bk.TRIANGLE_UV + LANES + l]),
                (TRM[it, bk.TRIANGLE_UV + 2 * LANES + l], TRM[it, bk.TRIANGLE_UV + 3 * LANES + l]),
                (TRM[it, bk.TRIANGLE_UV + 4 * LANES + l], TRM[it, bk.TRIANGLE_UV + 5 * LANES + l]))
            put3(TRS, it, st.TRIANGLE_NORMAL, l, tn)
            put3(TRS, it, st.TRIANGLE_TANGENT, l, tt)
    vt_start, vt_count = BI[b, bk.BI_VERTEX_TRIANGLE_START], BI[b, bk.BI_VERTEX_TRIANGLE_COUNT]
    vt_data, vt_flip = BI[b, bk.BI_VERTEX_TRIANGLE_DATA], BI[b, bk.BI_VERTEX_TRIANGLE_FLIP]
    z = (0.0, 0.0, 0.0)
    for j in range(BI[b, bk.BI_N]):
        n = topology[vt_count + j]
        if n == 0:
            continue
        g = g0 + j
        k0 = topology[vt_start + j]
        for l in range(w):
            put3(PS, g, st.CHILD_REST_SUM, l, z)
            put3(PS, g, st.CHILD_EDGE_SUM, l, z)
        for k in range(k0, k0 + n):
            it = t0 + topology[vt_data + k]
            flip = topology[vt_flip + k]
            for l in range(w):
                put3(PS, g, st.CHILD_REST_SUM, l, add_flipped(get3(PS, g, st.CHILD_REST_SUM, l),
                                                              get3(TRS, it, st.TRIANGLE_NORMAL, l), (flip & 1) != 0))
                put3(PS, g, st.CHILD_EDGE_SUM, l, add_flipped(get3(PS, g, st.CHILD_EDGE_SUM, l),
                                                              get3(TRS, it, st.TRIANGLE_TANGENT, l), (flip & 2) != 0))
        for l in range(w):
            valid, q = vertex_frame_rotation(get3(PS, g, st.CHILD_REST_SUM, l), get3(PS, g, st.CHILD_EDGE_SUM, l))
            if valid:
                put4(PS, g, st.ROTATION, l, q)
