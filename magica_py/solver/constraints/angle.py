"""Angle limit (docs/solver.md §D.5) and angle restoration (§D.6), one routine per baseline, 3 iterations.

Restoration pulls each edge towards its *absolute* world direction in the step basic pose
(not parent-relative, Appendix 2.2). Masses use friction only (Appendix 2.3). Both parent and
child move; the restoration pivot grows 0.1 -> 0.3 -> 0.5 over the iterations.

``angle_block`` runs one block, every baseline entry's lanes side by side, through the
per-element functions ``angle_buffer_entry`` (buffering pass), ``angle_limit_entry`` (D.5 half
of an iteration) and ``angle_restoration_entry`` (D.6 half): tuples in and out, no array
access, the reference's early returns written as selects. An iteration runs its lanes side
by side without the limit's violation path and without the opposite-vector paths of the
limit's swing and the restoration's turn (``angle_iteration_lanes`` with ``full`` False: their
acos, sincos, orthogonal axes and normalisations left out), flags the lanes that met a
violation or an opposite vector, and runs again on the full path for them when there are any:
the same bits as the full path everywhere, with the rare paths' cost only where they are taken
(the crowd's and the character's kernels ~8-10 % faster, docs/BENCHMARKS.md, session 14; the
opposite paths ~5 % of the angle stage, session 32).

The solves are written on the edge v = cp - pp rather than on world positions, and the
restoration's from-to rotation is applied as a turn in the plane of the edge and its rest
direction (``restoration_offset``) with the fma forms of acos and sincos: the reference's
results up to round-off, on a short dependency chain; docs/angle_maths.md says why each form is the same rotation, tests/test_angle_maths.py measures
the difference per call.
"""
from __future__ import annotations

import math

import numpy as np

from magica_py.build.proxy import MOVE
from magica_py.jit import kernel
from magica_py.kernels import trig
from magica_py.kernels.math3d import (
    angle_between_vectors_select, clamp_angle_select, inverse_mass_friction, lerp, opposite_unit,
    orthogonal_axis_select, q_inverse, q_mul, q_rotate, saturate, v_add, v_cross, v_dot, v_length, v_scale, v_sub,
)
from magica_py.solver import blocks as bk
from magica_py.solver import state as st
from magica_py.solver.lanes import LANES, get1, get3, get4, put1, put3, put4
from magica_py.solver.rotations import swing_select
from magica_py.solver.parameters import (
    PRM_LIMIT_STIFFNESS, PRM_RATE_MODE, PRM_RESTORATION_GRAVITY_FALLOFF, PRM_USE_ANGLE_LIMIT, PRM_USE_RESTORATION,
    clamp01, step_rate,
)

ITERATIONS = 3               # AngleLimitIteration
LIMIT_ATTENUATION = 0.9      # AngleLimitAttenuation
LIMIT_PIVOT = 0.4
ZERO3 = (0.0, 0.0, 0.0)
IDENTITY = (0.0, 0.0, 0.0, 1.0)
MIN_NORMAL = 2.2250738585072014e-308   # the smallest normal float64 (sys.float_info.min)


@kernel
def swing_rotation(a, b, full=True):
    """``rotations.swing_select(a, b)`` (unit a, b: the rotation swinging a onto b), and whether
    a and b are opposite. Returns (rotation, opposite). ``full`` False: without the opposite
    path (the rotation is then not the swing where ``opposite`` is True)."""
    return swing_select(a, b, full), opposite_unit(a, b)


@kernel(inline="always")
def restoration_offset(a, v, vl, b, t, full=True):
    """``r - v`` for ``r = from_to_rotation_unit(a, b, t) · v`` (a = v / vl unit, b unit): the
    same rotation written for a short dependency chain. v turns by t times the angle theta = acos(a·b) in the plane of a and b:
    ``r = v cos(t theta) + vl sin(t theta) w / |w|``, w = b - (a·b) a the in-plane
    direction towards b (``(axis x a) |a x b|`` for the reference's axis = normalize(a x b),
    so the rotation about that axis of a vector orthogonal to it). No quaternion, no cross
    product, one sincos of the full angle; acos and sincos in their fma forms
    (``trig.acos_fma``, ``trig.sincos_fma``). Paths as the reference's: parallel (1 - c <
    1e-6) gives 0, opposite (1 + c < 1e-6) turns t pi about ``orthogonal_axis(a)`` (w =
    axis x a). ``full`` False (a constant at the call site) leaves the opposite path out: the
    offset is then not the turn where ``opposite`` is True, which the caller redoes.

    Returns (r - v, opposite)."""
    c = v_dot(a, b)
    c = 1.0 if c > 1.0 else c
    c = -1.0 if c < -1.0 else c
    opposite = abs(1.0 + c) < 1e-6
    parallel = abs(1.0 - c) < 1e-6
    w = v_sub(b, v_scale(a, c))
    theta = trig.acos_fma(c)
    if full:
        w = v_cross(orthogonal_axis_select(a), a) if opposite else w
        theta = math.pi if opposite else theta
    # off the chain: ready before the sincos. |w| is 0 only on the parallel path, whose result
    # is discarded (|w| >= ~1e-3 on the kept ones): the floor keeps the discarded division
    # finite, which the JIT-off run needs (a Python float division by 0 raises)
    k = vl / max(v_length(w), MIN_NORMAL)
    s, co = trig.sincos_fma(theta * t)
    d = v_sub(v_scale(w, s * k), v_scale(v, 1.0 - co))
    return (ZERO3 if (not opposite) & parallel else d), opposite


# ----------------------------------------------------------------------------- per element
@kernel
def restoration_rate(curve, frequency_ratio, power_w, rate_mode):
    """D.6 restoration stiffness of this step of a particle whose stiffness curve value is
    ``curve``, before the team's gravity factor."""
    return saturate(step_rate(clamp01(curve), frequency_ratio, power_w, rate_mode))


@kernel
def restoration_gravity_factor(falloff, gravity_dot):
    """D.6 stiffness factor: 1 with gravity along the rest pose's, 1 - falloff against it."""
    return lerp(1.0 - falloff, 1.0, gravity_dot)


@kernel(inline="always")
def angle_buffer_entry(cp, pp, c_basic_pos, p_basic_pos, c_basic_rot, p_basic_rot, old_rest_direction):
    """Buffering pass of a non-root entry (child c of parent p).

    Returns (angle_length, angle_local_pos, angle_local_rot, angle_rest_length,
    angle_rest_direction); a degenerate segment or rest edge (< 1e-8 m)
    gives length 0, a zero local direction and the identity rotation, and a degenerate rest
    edge keeps ``old_rest_direction`` (the restoration snaps that child and never reads it)."""
    length = v_length(v_sub(cp, pp))
    bv = v_sub(c_basic_pos, p_basic_pos)
    blen = v_length(bv)
    iq = q_inverse(p_basic_rot)
    direction = v_scale(bv, 1.0 / blen)
    local_pos = q_rotate(iq, direction)
    local_rot = q_mul(iq, c_basic_rot)
    degenerate = (length < 1e-8) | (blen < 1e-8)
    length = 0.0 if degenerate else length
    local_pos = ZERO3 if degenerate else local_pos
    local_rot = IDENTITY if degenerate else local_rot
    rest_direction = direction if blen >= 1e-8 else old_rest_direction
    return length, local_pos, local_rot, blen, rest_direction


@kernel(inline="always")
def edge_of(cp, pp):
    """(v, |v|, v / |v|) of the edge cp - pp: what the restoration turns when no limit pass
    ran before it (``angle_limit_entry`` returns the same triple of the edge it leaves)."""
    v = v_sub(cp, pp)
    vl = v_length(v)
    return v, vl, v_scale(v, 1.0 / vl)


@kernel(inline="always")
def angle_limit_entry(cp, pp, vel_c, vel_p, rot_c, rot_p, local_pos, local_rot, length, max_angle,
                      max_angle_cos, wc, wp, p_move, stiffness, attenuation, full=True):
    """The angle-limit half of one iteration for child c (positions cp, pp read at its start).

    ``vel_*`` velocity_pos, ``rot_*`` angle_rotation, ``local_*`` / ``length`` the buffered
    angle_local_pos / angle_local_rot / angle_length of c. Returns (cp, pp, next_c, vel_c,
    vel_p, rot_c, edge): the positions the restoration sees, then c's next_pos, both
    velocity_pos and c's angle_rotation after the pass (p's next_pos is the returned pp), and
    the edge the restoration turns, (cp - pp, its length, its direction) of the returned
    positions, computed on the edge (``edge_of`` of them up to round-off). Paths, in the
    reference's order: segment shorter than 1e-8 m: nothing; degenerate rest direction: c
    snaps onto p but the returned cp stays as it was (quirk); degenerate rest length:
    nothing; otherwise the limit is solved about the pivot at 0.4 and c's rotation swung
    (kept when the new segment is degenerate).

    Also returns ``rare``: the solve path met a limit violation or an opposite swing.
    ``full`` False leaves the violation's path out (passed as a constant, LLVM removes its
    maths): the results are then exact wherever ``rare`` is False (``angle_iteration_lanes``)."""
    v = v_sub(cp, pp)
    vl = v_length(v)
    tv = q_rotate(rot_p, local_pos)
    tl = v_length(tv)
    rest_rot = q_mul(rot_p, local_rot)
    inv_vl = 1.0 / vl
    vn = v_scale(v, inv_vl)
    tn = v_scale(tv, 1.0 / tl)
    lc = (vl + length) * 0.5
    # alpha > max angle <=> cos(alpha) < cos(max angle): acos only for a violation
    violated = v_dot(vn, tn) < max_angle_cos
    # solve_pivot_pair(pp, cp, vn lc, r, 0.4, wp, wc) with cp - pp = v, written on the edge:
    # r = vn lc (no violation) leaves p in place and moves c along v by (lc / vl - 1) v, so the
    # new edge is v (1 + s), s = (length - vl) / (2 vl) wc: same direction vn, no sqrt
    stretch = (length - vl) * 0.5 * inv_vl   # lc / vl - 1
    s = stretch * wc
    dc = v_scale(v, s)
    dp = ZERO3
    edge = v_scale(v, 1.0 + s)
    edge_length = vl * (1.0 + s)
    edge_unit = vn
    # the violation's path, computed either way and selected (branch-free: the lane loop
    # vectorises; the same bits as the reference's branches)
    rescaled = v_scale(vn, lc)
    alpha = angle_between_vectors_select(rescaled, tn)
    turn = v_sub(clamp_angle_select(rescaled, tn, lerp(alpha, max_angle, stiffness)), rescaled)
    limited_dp = v_scale(turn, -LIMIT_PIVOT * wp)
    limited_dc = v_scale(v_add(v_scale(v, stretch), v_scale(turn, 1.0 - LIMIT_PIVOT)), wc)
    limited_edge = v_add(v, v_sub(limited_dc, limited_dp) if p_move else limited_dc)
    limited_length = v_length(limited_edge)
    limited_unit = v_scale(limited_edge, 1.0 / limited_length)
    limited = violated & (alpha > max_angle) & full
    dp = limited_dp if limited else dp
    dc = limited_dc if limited else dc
    edge = limited_edge if limited else edge
    edge_length = limited_length if limited else edge_length
    edge_unit = limited_unit if limited else edge_unit
    solved_c = v_add(cp, dc)
    solved_vel_c = v_add(vel_c, v_scale(dc, attenuation))
    solved_p = v_add(pp, dp) if p_move else pp
    solved_vel_p = v_add(vel_p, v_scale(dp, attenuation)) if p_move else vel_p
    swing, opposite = swing_rotation(tn, edge_unit, full)
    swung = q_mul(swing, rest_rot)
    solved_rot = rot_c if edge_length < 1e-8 else swung
    # path selection (a NaN compares false everywhere, as the reference's early returns do)
    skip = vl < 1e-8
    snap = (not skip) & (tl < 1e-8)
    solve = (not skip) & (not (tl < 1e-8)) & (not ((length < 1e-8) | (lc < 1e-8)))
    snapped_vel_c = v_add(vel_c, v_sub(pp, cp))
    next_c = solved_c if solve else (pp if snap else cp)
    vel_c = solved_vel_c if solve else (snapped_vel_c if snap else vel_c)
    vel_p = solved_vel_p if solve else vel_p
    rot_c = solved_rot if solve else (rest_rot if snap else rot_c)
    cp = solved_c if solve else cp
    pp = solved_p if solve else pp
    edge = edge if solve else v
    edge_length = edge_length if solve else vl
    edge_unit = edge_unit if solve else vn
    rare = solve & (violated | ((not (edge_length < 1e-8)) & opposite))
    return cp, pp, next_c, vel_c, vel_p, rot_c, (edge, edge_length, edge_unit), rare


@kernel(inline="always")
def angle_restoration_entry(cp, pp, edge, next_c, vel_c, next_p, vel_p, rest_length, rest_direction, stiffness,
                            pivot, wc, wp, p_move, attenuation, full=True):
    """The restoration half of one iteration for child c: the edge cp - pp (as the limit
    pass returned it; ``edge`` = (v, |v|, v / |v|) of it, from ``angle_limit_entry`` or
    ``edge_of``) turned towards ``rest_direction`` by ``stiffness`` about the point at
    ``pivot``, the corrections added to the current next_pos / velocity_pos of c and p.
    A degenerate rest edge snaps c onto pp; a degenerate edge does nothing.
    Returns (next_c, vel_c, next_p, vel_p, rare): ``rare``, the solve path met an opposite
    edge (``full`` False: its results are then not the reference's, and the caller redoes
    the lane on the full path)."""
    v, vl, a = edge
    d, opposite = restoration_offset(a, v, vl, rest_direction, stiffness, full)
    # solve_pivot_pair(pp, cp, v, v + d, pivot, wp, wc) with cp - pp = v: the pivot cancels
    dp = v_scale(d, -pivot * wp)
    dc = v_scale(d, (1.0 - pivot) * wc)
    snap = rest_length < 1e-8
    solve = (not snap) & (not (vl < 1e-8))
    move_p = solve & p_move
    snapped_vel_c = v_add(vel_c, v_sub(pp, cp))
    solved_next_c = v_add(next_c, dc)
    solved_vel_c = v_add(vel_c, v_scale(dc, attenuation))
    solved_next_p = v_add(next_p, dp)
    solved_vel_p = v_add(vel_p, v_scale(dp, attenuation))
    next_c_out = solved_next_c if solve else (pp if snap else next_c)
    vel_c_out = solved_vel_c if solve else (snapped_vel_c if snap else vel_c)
    next_p = solved_next_p if move_p else next_p
    vel_p = solved_vel_p if move_p else vel_p
    return next_c_out, vel_c_out, next_p, vel_p, solve & opposite


@kernel
def angle_iteration_lanes(PS, gc, w, p_move, rest_pivot, use_limit, use_restoration, limit_stiffness,
                          limit_attenuation, restoration_attenuation, full):
    """One iteration of D.5 then D.6 for child slot gc, every lane, from its rows (the
    parent's gathered next to them). ``full`` False: without the limit's violation path and
    the opposite-vector paths of the limit's swing and of the restoration's turn, the lanes
    where one was needed (the entries' ``rare``) flagged in ``ANGLE_RARE`` and their rows left
    as they were; ``full`` True: the flagged lanes solved on the full path (every lane
    computed, the others' results discarded: a vector loop needs no branch)."""
    for l in range(min(w, LANES)):
        cp = get3(PS, gc, st.NEXT_POS, l)
        pp = get3(PS, gc, st.PARTNER_POS, l)
        vel_c = get3(PS, gc, st.VELOCITY_POS, l)
        vel_p = get3(PS, gc, st.PARTNER_VELOCITY_POS, l)
        kept_c, kept_p, kept_vel_c, kept_vel_p = cp, pp, vel_c, vel_p
        next_c = cp
        wc = get1(PS, gc, st.ANGLE_INVERSE_MASS, l)
        wp = get1(PS, gc, st.PARTNER_W, l)
        rare = False
        kept_rot = rot_c = IDENTITY   # the limit's working rotation: read and written with the limit only
        if use_limit:
            kept_rot = get4(PS, gc, st.ANGLE_ROTATION, l)
            cp, pp, next_c, vel_c, vel_p, rot_c, edge, rare = angle_limit_entry(
                cp, pp, vel_c, vel_p, kept_rot, get4(PS, gc, st.PARTNER_ROTATION, l),
                get3(PS, gc, st.ANGLE_LOCAL_POS, l), get4(PS, gc, st.ANGLE_LOCAL_ROT, l),
                get1(PS, gc, st.ANGLE_LENGTH, l), get1(PS, gc, st.ANGLE_LIMIT, l), get1(PS, gc, st.ANGLE_LIMIT_COS, l),
                wc, wp, p_move, limit_stiffness, limit_attenuation, full)
        else:
            edge = edge_of(cp, pp)
        next_p = pp
        if use_restoration:
            next_c, vel_c, next_p, vel_p, opposite = angle_restoration_entry(
                cp, pp, edge, next_c, vel_c, next_p, vel_p, get1(PS, gc, st.ANGLE_REST_LENGTH, l),
                get3(PS, gc, st.ANGLE_REST_DIRECTION, l), get1(PS, gc, st.ANGLE_RESTORATION_K, l),
                rest_pivot, wc, wp, p_move, restoration_attenuation, full)
            rare = rare | opposite
        flagged = get1(PS, gc, st.ANGLE_RARE, l) != 0.0
        keep = (not flagged) if full else rare
        put3(PS, gc, st.NEXT_POS, l, kept_c if keep else next_c)
        put3(PS, gc, st.VELOCITY_POS, l, kept_vel_c if keep else vel_c)
        put3(PS, gc, st.PARTNER_POS, l, kept_p if keep else next_p)
        put3(PS, gc, st.PARTNER_VELOCITY_POS, l, kept_vel_p if keep else vel_p)
        if use_limit:
            put4(PS, gc, st.ANGLE_ROTATION, l, kept_rot if keep else rot_c)
        put1(PS, gc, st.ANGLE_RARE, l, 1.0 if (flagged if full else rare) else 0.0)


# ----------------------------------------------------------------------------- per block
@kernel(forceinline=False)
def angle_block(PS, PP, TS, P, BI, topology, b, frequency_ratio, power_w, limit_attenuation, restoration_attenuation):
    """D.5/D.6 over every baseline of block b, each entry's lanes side by side.

    The inverse mass (friction does not change in this routine), the restoration stiffness
    (curve, rate conversion, gravity factor) and the rest direction (length, unit vector) of
    each particle are computed once per step in the buffering pass
    rather than in each of the 3 iterations (same operations on the same values: same bits).
    The limit's rows (``ANGLE_ROTATION``, ``ANGLE_LENGTH``, ``ANGLE_LOCAL_POS`` / ``_ROT``, the
    parent's ``PARTNER_ROTATION``) are buffered and carried only when the block uses the limit:
    the restoration reads none of them. Every buffer row is written in the buffering pass
    before the iterations read it, so nothing is cleared afterwards."""
    use_limit = P[b, PRM_USE_ANGLE_LIMIT] != 0.0
    use_restoration = P[b, PRM_USE_RESTORATION] != 0.0
    limit_stiffness = P[b, PRM_LIMIT_STIFFNESS]
    falloff = P[b, PRM_RESTORATION_GRAVITY_FALLOFF]
    rate_mode = int(P[b, PRM_RATE_MODE])
    g0 = BI[b, bk.BI_G0]
    w = bk.lane_width(BI, b)
    attribute, parent = BI[b, bk.BI_ATTRIBUTE], BI[b, bk.BI_PARENT]
    bl_start, bl_count, bl_data = BI[b, bk.BI_BASELINE_START], BI[b, bk.BI_BASELINE_COUNT], BI[b, bk.BI_BASELINE_DATA]
    lines = BI[b, bk.BI_BASELINES]
    if not use_limit and not use_restoration:   # no early return (docs/tech-notes.md §10)
        lines = 0
    for line in range(lines):
        e0 = topology[bl_start + line]
        e1 = e0 + topology[bl_count + line]
        # buffering pass
        for e in range(e0, e1):
            c = topology[bl_data + e]
            gc = g0 + c
            for l in range(w):
                # parents come first in a baseline (B.6), so wp below is always this step's value
                put1(PS, gc, st.ANGLE_INVERSE_MASS, l, inverse_mass_friction(get1(PS, gc, st.FRICTION, l)))
            if use_limit:
                for l in range(w):
                    put4(PS, gc, st.ANGLE_ROTATION, l, get4(PS, gc, st.STEP_BASIC_ROT, l))
            if e == e0:
                continue
            gp = g0 + topology[parent + c]
            for l in range(w):   # the parent's rows next to the child: the loop below reads one item
                put3(PS, gc, st.PARTNER_POS, l, get3(PS, gp, st.NEXT_POS, l))
                put3(PS, gc, st.PARTNER_BASE, l, get3(PS, gp, st.STEP_BASIC_POS, l))
            if use_limit:
                for l in range(w):
                    put4(PS, gc, st.PARTNER_ROTATION, l, get4(PS, gp, st.STEP_BASIC_ROT, l))
            for l in range(w):
                length, local_pos, local_rot, rest_length, rest_direction = angle_buffer_entry(
                    get3(PS, gc, st.NEXT_POS, l), get3(PS, gc, st.PARTNER_POS, l), get3(PS, gc, st.STEP_BASIC_POS, l),
                    get3(PS, gc, st.PARTNER_BASE, l), get4(PS, gc, st.STEP_BASIC_ROT, l),
                    get4(PS, gc, st.PARTNER_ROTATION, l), get3(PS, gc, st.ANGLE_REST_DIRECTION, l))
                if use_limit:
                    put1(PS, gc, st.ANGLE_LENGTH, l, length)
                    put3(PS, gc, st.ANGLE_LOCAL_POS, l, local_pos)
                    put4(PS, gc, st.ANGLE_LOCAL_ROT, l, local_rot)
                if use_restoration:  # the rest direction does not change over the iterations
                    put1(PS, gc, st.ANGLE_REST_LENGTH, l, rest_length)
                    put3(PS, gc, st.ANGLE_REST_DIRECTION, l, rest_direction)
                    gravity_factor = restoration_gravity_factor(falloff, get1(TS, b, st.GRAVITY_DOT, l))
                    put1(PS, gc, st.ANGLE_RESTORATION_K, l,
                         restoration_rate(get1(PP, gc, bk.CURVE_RESTORATION_STIFFNESS, l), frequency_ratio, power_w,
                                          rate_mode) * gravity_factor)
                if use_limit:
                    max_angle = math.radians(get1(PP, gc, bk.CURVE_LIMIT_ANGLE, l))
                    put1(PS, gc, st.ANGLE_LIMIT, l, max_angle)
                    put1(PS, gc, st.ANGLE_LIMIT_COS, l, trig.cos(max_angle))
        for k in range(ITERATIONS):
            rest_pivot = lerp(0.1, 0.5, k / 2.0)
            for e in range(e0 + 1, e1):
                c = topology[bl_data + e]
                if (topology[attribute + c] & MOVE) == 0:
                    continue
                p = topology[parent + c]
                p_move = (topology[attribute + p] & MOVE) != 0
                gc = g0 + c
                gp = g0 + p
                # gather, solve, scatter: the solving loop reads and writes one item (the
                # child's rows and the parent's copied next to them), so it vectorises across
                # the lanes; the parent's results go back before the next entry reads them
                for l in range(w):
                    put3(PS, gc, st.PARTNER_POS, l, get3(PS, gp, st.NEXT_POS, l))
                    put3(PS, gc, st.PARTNER_VELOCITY_POS, l, get3(PS, gp, st.VELOCITY_POS, l))
                    put1(PS, gc, st.PARTNER_W, l, get1(PS, gp, st.ANGLE_INVERSE_MASS, l))
                    if use_limit:
                        put4(PS, gc, st.PARTNER_ROTATION, l, get4(PS, gp, st.ANGLE_ROTATION, l))
                # the lanes side by side without the limit's violation path (its acos, sincos
                # and normalisations for every lane); where a lane met a violation or an
                # opposite swing (rare), the iteration runs again on the full path for it (the
                # path switch a plain bool that LLVM folds: one compile, docs/tech-notes.md §7)
                angle_iteration_lanes(PS, gc, w, p_move, rest_pivot, use_limit, use_restoration, limit_stiffness,
                                      limit_attenuation, restoration_attenuation, np.bool_(False))
                rare = False
                for l in range(w):
                    rare = rare or get1(PS, gc, st.ANGLE_RARE, l) != 0.0
                if rare:
                    angle_iteration_lanes(PS, gc, w, p_move, rest_pivot, use_limit, use_restoration, limit_stiffness,
                                          limit_attenuation, restoration_attenuation, np.bool_(True))
                for l in range(w):
                    put3(PS, gp, st.NEXT_POS, l, get3(PS, gc, st.PARTNER_POS, l))
                    put3(PS, gp, st.VELOCITY_POS, l, get3(PS, gc, st.PARTNER_VELOCITY_POS, l))
