"""Quality mode's display (``docs/quality-mode.md``, *Display*): after E.1 (``display.py``) the
interpolated display is moved towards a target that is out of the colliders at this frame's
pose, never showing an edge longer than the step states it interpolates allow
(``display_constraints_block``, every lane of a block side by side). The step passes are in
``quality.py``.
"""
from __future__ import annotations

import numpy as np

from magica_py.build.proxy import DISABLE_COLLISION, MOVE
from magica_py.jit import kernel
from magica_py.kernels.math3d import q_rotate, v_add, v_dot, v_length, v_length_sq, v_lerp, v_scale, v_sub
from magica_py.solver import blocks as bk
from magica_py.solver import state as st
from magica_py.solver.colliders import capsule_ends
from magica_py.solver.constraints.collision import (
    PLANE, SPHERE, particle_radius, segment_parameter,
)
from magica_py.solver.lanes import get1, get3, get4, put1, put3
from magica_py.solver.parameters import PRM_COLLISION_LAST, PRM_COLLISION_MODE
from magica_py.solver.quality import clamp_to_sphere, push_out_of_ball

DISPLAY_PASSES = 2        # collider push + edge clamp passes of the quality display
DISPLAY_EDGE_PASSES = 2    # edge passes of the quality display's target after its collider push
DISPLAY_MOVE_PASSES = 3    # bounded moves of the quality display towards its target


@kernel(forceinline=False)
def display_colliders_block(CS, BI, topology, b, w):
    """Block b's collider slots at this frame's pose (G.2: ``FRAME_POS`` / ``FRAME_ROT`` /
    ``FRAME_SCALE``), lanes ``0 .. w - 1``, into the ``DISPLAY_*`` rows the display's pushes read:
    a sphere's centre and scaled radius, a capsule's ends and radii (``capsule_ends``), a plane's
    point and normal. Once per frame and slot instead of once per particle and pass."""
    c0 = BI[b, bk.BI_COLLIDER0]
    shapes, directions = BI[b, bk.BI_COLLIDER_SHAPE], BI[b, bk.BI_COLLIDER_DIRECTION]
    reverses, aligns = BI[b, bk.BI_COLLIDER_REVERSE], BI[b, bk.BI_COLLIDER_ALIGNED]
    for c in range(BI[b, bk.BI_COLLIDERS]):
        k = c0 + c
        shape, direction = topology[shapes + c], topology[directions + c]
        reverse, aligned = topology[reverses + c] != 0, topology[aligns + c] != 0
        for l in range(w):
            pos = get3(CS, k, st.FRAME_POS, l)
            rot = get4(CS, k, st.FRAME_ROT, l)
            scale = get3(CS, k, st.FRAME_SCALE, l)
            if shape == PLANE:
                put3(CS, k, st.DISPLAY_START, l, pos)
                put3(CS, k, st.DISPLAY_NORMAL, l, q_rotate(rot, (0.0, -1.0 if scale[1] < 0.0 else 1.0, 0.0)))
            elif shape == SPHERE:
                radius = get3(CS, k, st.SIZE, l)[0] * abs(scale[0])
                put3(CS, k, st.DISPLAY_START, l, pos)
                put3(CS, k, st.DISPLAY_END, l, pos)
                put1(CS, k, st.DISPLAY_RADIUS_START, l, radius)
                put1(CS, k, st.DISPLAY_RADIUS_END, l, radius)
            else:
                s = scale[0] if direction == 0 else (scale[1] if direction == 1 else scale[2])
                a, e, ra, re = capsule_ends(pos, rot, direction, reverse, aligned, get3(CS, k, st.SIZE, l), s)
                put3(CS, k, st.DISPLAY_START, l, a)
                put3(CS, k, st.DISPLAY_END, l, e)
                put1(CS, k, st.DISPLAY_RADIUS_START, l, ra)
                put1(CS, k, st.DISPLAY_RADIUS_END, l, re)


@kernel
def display_collider_push(CS, k, l, shape, x, r):
    """``x`` (a sphere of radius r) moved onto the surface of collider slot k of lane l at this
    frame's pose (``display_colliders_block``) when it lies inside it, along the shortest way
    out; unchanged otherwise (or when its centre is on the capsule's axis)."""
    if shape == PLANE:
        n = get3(CS, k, st.DISPLAY_NORMAL, l)
        d = v_dot(v_sub(x, get3(CS, k, st.DISPLAY_START, l)), n) - r
        return v_sub(x, v_scale(n, d)) if d < 0.0 else x
    a = get3(CS, k, st.DISPLAY_START, l)
    e = get3(CS, k, st.DISPLAY_END, l)
    ra = get1(CS, k, st.DISPLAY_RADIUS_START, l)
    t = segment_parameter(x, a, e)
    reach = ra + (get1(CS, k, st.DISPLAY_RADIUS_END, l) - ra) * t + r
    return push_out_of_ball(x, v_lerp(a, e, t), reach)


@kernel
def display_collider_push_bounded(CS, k, l, shape, x, r, parent, bound):
    """``display_collider_push`` of x, kept within ``bound`` of ``parent`` when it can be: a
    pushed point farther than ``bound`` from ``parent`` is moved to the nearest point of the
    circle where the pushed-to surface (the sphere, or a capsule's sphere at the pushed
    point's axis parameter) meets the sphere of radius ``bound`` around ``parent``; exact for a
    sphere, where alternating the push with the parent clamp only converges slowly. Where that
    circle does not exist (the parent deeper than ``bound``, or a plane) the pushed point is
    returned and the caller's clamp wins."""
    y = display_collider_push(CS, k, l, shape, x, r)
    if shape == PLANE or (y[0] == x[0] and y[1] == x[1] and y[2] == x[2]):
        return y
    if v_length_sq(v_sub(y, parent)) <= bound * bound:
        return y
    a = get3(CS, k, st.DISPLAY_START, l)
    ra = get1(CS, k, st.DISPLAY_RADIUS_START, l)
    if shape == SPHERE:
        c = a
        reach = ra + r
    else:
        e = get3(CS, k, st.DISPLAY_END, l)
        t = segment_parameter(x, a, e)
        c = v_lerp(a, e, t)
        reach = ra + (get1(CS, k, st.DISPLAY_RADIUS_END, l) - ra) * t + r
    n = v_sub(parent, c)
    dist = v_length(n)
    if dist < 1e-12:
        return y
    n = v_scale(n, 1.0 / dist)
    along = (reach * reach - bound * bound + dist * dist) / (2.0 * dist)   # circle plane, from c along n
    h2 = reach * reach - along * along
    if h2 <= 0.0:
        return y
    w = v_sub(y, c)
    w = v_sub(w, v_scale(n, v_dot(w, n)))
    wl = v_length(w)
    if wl < 1e-12:
        return y
    return v_add(v_add(c, v_scale(n, along)), v_scale(w, np.sqrt(h2) / wl))


@kernel
def display_edge_bound(PS, ga, gb, l, dt):
    """The longest the displayed edge (particle slots ga, gb; lane l) may be: the larger of its
    step-basic rest length and its length in the two step states the display interpolates, the
    last one (``OLD_POS``) and the one before (``OLD_POS - REAL_VELOCITY dt``, D.10's definition
    of the real velocity; the C.5 shift moves and turns both together)."""
    old_a = get3(PS, ga, st.OLD_POS, l)
    old_b = get3(PS, gb, st.OLD_POS, l)
    before = v_sub(v_sub(old_a, v_scale(get3(PS, ga, st.REAL_VELOCITY, l), dt)),
                   v_sub(old_b, v_scale(get3(PS, gb, st.REAL_VELOCITY, l), dt)))
    rest = v_length(v_sub(get3(PS, ga, st.STEP_BASIC_POS, l), get3(PS, gb, st.STEP_BASIC_POS, l)))
    return max(rest, max(v_length(v_sub(old_a, old_b)), v_length(before)))


@kernel
def safe_fraction(e0, de, bound):
    """The largest s in [0, 1] with |e0 + s de| <= max(bound, |e0|) (|.| is convex in s, so
    every s below it keeps the edge within the bound too)."""
    limit = max(bound, v_length(e0))
    end = v_add(e0, de)
    if v_dot(end, end) <= limit * limit:
        return 1.0
    a = v_dot(de, de)
    half_b = v_dot(e0, de)
    c = v_dot(e0, e0) - limit * limit
    disc = half_b * half_b - a * c
    if a <= 0.0 or disc <= 0.0:
        return 0.0
    return min(max((-half_b + np.sqrt(disc)) / a, 0.0), 1.0)


# DISPLAY_LANE: a lane's progress through the display (lanes leave it at different points)
LANE_DONE = 0.0       # nothing (more) to do: not shown, or its target is its interpolated display
LANE_SHOWN = 1.0      # shown: its target is being built
LANE_MOVING = 2.0     # its target differs from its display: moving towards it
LANE_PASSES = 3.0     # short of its target after the common move: in the move passes


@kernel(forceinline=False)
def display_constraints_block(PS, PP, TS, CS, EDS, P, BI, topology, b, dt):
    """Quality display of every lane of block b after E.1 (``display.display_block``): the
    interpolated display in ``POSITION`` (every edge within its bound,
    ``display_edge_bound``) moved towards a target that is out of the colliders at this
    frame's pose, never past the bounds.

    1. The target, in ``POSITION``: along every baseline, parents first, each Move
       particle is pushed out of the team's colliders at this frame's pose, onto the
       nearest point that is also within its parent link's bound when there is one
       (``display_collider_push_bounded``; only when the cloth collides: ``collision_mode`` not
       none and ``collision_last`` on), and kept within that bound (follow-the-leader),
       ``DISPLAY_PASSES`` times; then ``DISPLAY_EDGE_PASSES`` Gauss-Seidel passes shorten the
       other edges (a skirt's rings) longer than their bound, both ends moving.
    2. The display, in ``DISP_POS``: starting from the interpolated display, the whole
       team moves towards its target by one common fraction, the largest that keeps every
       link (D.4's partners, every proxy edge) within its bound (each link moves linearly in
       the fraction and its length is convex, ``safe_fraction``): a target within every
       bound (a line cloth's) is reached exactly. Then each Move particle in turn moves
       towards its target by the largest fraction that keeps each of its links within its
       bound with its neighbours' current display, ``DISPLAY_MOVE_PASSES`` times. Every move
       keeps the display within the bounds, so none is ever shown longer than the state
       allows; where a push would need more stretch than the state has, the particle is
       shown partly inside the collider. Then copied to ``POSITION``.

    Every lane side by side: the loops run over the block's topology with the lanes inside,
    each lane's progress in ``DISPLAY_LANE`` (a lane with nothing left to do is skipped), its
    common fraction in ``DISPLAY_COMMON``."""
    g0 = BI[b, bk.BI_G0]
    n = BI[b, bk.BI_N]
    w = bk.lane_width(BI, b)
    attribute, parent = BI[b, bk.BI_ATTRIBUTE], BI[b, bk.BI_PARENT]
    bl_start, bl_count, bl_data = BI[b, bk.BI_BASELINE_START], BI[b, bk.BI_BASELINE_COUNT], BI[b, bk.BI_BASELINE_DATA]
    link_start, link_count, link_target = (BI[b, bk.BI_DISTANCE_START], BI[b, bk.BI_DISTANCE_COUNT],
                                           BI[b, bk.BI_DISTANCE_TARGET])
    pairs = BI[b, bk.BI_EDGE_PAIRS]
    c0 = BI[b, bk.BI_COLLIDER0]
    colliders = BI[b, bk.BI_COLLIDERS]
    shapes = BI[b, bk.BI_COLLIDER_SHAPE]
    for j in range(n):   # the interpolated display, blended (E.1)
        for l in range(w):
            put3(PS, g0 + j, st.DISP_POS, l, get3(PS, g0 + j, st.POSITION, l))
    shown = False
    for l in range(w):
        lane_shown = get1(TS, b, st.BLEND_WEIGHT, l) > 0.0
        put1(TS, b, st.DISPLAY_LANE, l, LANE_SHOWN if lane_shown else LANE_DONE)
        put1(TS, b, st.DISPLAY_COMMON, l, 1.0)
        shown = shown or lane_shown
    if not shown:
        return
    collide = P[b, PRM_COLLISION_MODE] != 0.0 and P[b, PRM_COLLISION_LAST] != 0.0 and colliders > 0
    if collide:
        display_colliders_block(CS, BI, topology, b, w)
    # 1. the target
    for line in range(BI[b, bk.BI_BASELINES]):
        e0 = topology[bl_start + line]
        for e in range(e0 + 1, e0 + topology[bl_count + line]):
            v = topology[bl_data + e]
            p = topology[parent + v]
            attr = topology[attribute + v]
            if (attr & MOVE) == 0 or p < 0:
                continue
            gv = g0 + v
            gp = g0 + p
            hits = collide and (attr & DISABLE_COLLISION) == 0
            for l in range(w):
                if get1(TS, b, st.DISPLAY_LANE, l) == LANE_DONE:
                    continue
                bound = display_edge_bound(PS, gv, gp, l, dt)
                parent_pos = get3(PS, gp, st.POSITION, l)
                x = get3(PS, gv, st.POSITION, l)
                r = particle_radius(get1(PP, gv, bk.CURVE_RADIUS, l),
                                    get1(TS, b, st.SCALE_RATIO, l) * get1(TS, b, st.LENGTH_UNIT, l))
                for _ in range(DISPLAY_PASSES):
                    if hits:
                        for c in range(colliders):
                            k = c0 + c
                            if get1(CS, k, st.SCALE_SUSPEND, l) == 0.0:
                                x = display_collider_push_bounded(CS, k, l, topology[shapes + c], x, r, parent_pos,
                                                                  bound)
                    x, _move = clamp_to_sphere(x, parent_pos, bound)
                put3(PS, gv, st.POSITION, l, x)
    edges = BI[b, bk.BI_EDGES]
    s0 = BI[b, bk.BI_EDGE0]
    if DISPLAY_EDGE_PASSES > 0:
        for f in range(edges):   # each edge's bound, once (the passes below do not change it)
            ga = g0 + topology[pairs + 2 * f]
            gb = g0 + topology[pairs + 2 * f + 1]
            for l in range(w):
                put1(EDS, s0 + f, st.EDGE_DISPLAY_BOUND, l, display_edge_bound(PS, ga, gb, l, dt))
    for _ in range(DISPLAY_EDGE_PASSES):
        for f in range(edges):
            ia = topology[pairs + 2 * f]
            ib = topology[pairs + 2 * f + 1]
            wa = 1.0 if (topology[attribute + ia] & MOVE) != 0 else 0.0
            wb = 1.0 if (topology[attribute + ib] & MOVE) != 0 else 0.0
            if wa + wb <= 0.0:
                continue
            ga = g0 + ia
            gb = g0 + ib
            for l in range(w):   # the second end's position next to the first's
                put3(PS, ga, st.PARTNER_POS, l, get3(PS, gb, st.POSITION, l))
            for l in range(w):   # an edge within its bound (or a lane done) writes its ends back unchanged
                pa = get3(PS, ga, st.POSITION, l)
                pb = get3(PS, ga, st.PARTNER_POS, l)
                d = v_sub(pb, pa)
                length = v_length(d)
                bound = get1(EDS, s0 + f, st.EDGE_DISPLAY_BOUND, l)
                keep = get1(TS, b, st.DISPLAY_LANE, l) == LANE_DONE or length <= bound or length < 1e-12
                c = v_scale(d, (length - bound) / (length * (wa + wb)))   # discarded when kept
                put3(PS, ga, st.POSITION, l, pa if keep else v_add(pa, v_scale(c, wa)))
                put3(PS, ga, st.ACCUM3, l, pb if keep else v_sub(pb, v_scale(c, wb)))
            for l in range(w):
                put3(PS, gb, st.POSITION, l, get3(PS, ga, st.ACCUM3, l))
    # 2. the whole team towards its target by one fraction: each edge moves linearly in it (an
    # edge is seen from its moving ends, as in the passes below; one whose ends keep still keeps
    # its length)
    for v in range(n):
        if (topology[attribute + v] & MOVE) == 0:
            continue
        gv = g0 + v
        for l in range(w):
            if get1(TS, b, st.DISPLAY_LANE, l) != LANE_DONE:
                move_v = v_sub(get3(PS, gv, st.POSITION, l), get3(PS, gv, st.DISP_POS, l))
                if v_dot(move_v, move_v) != 0.0:
                    put1(TS, b, st.DISPLAY_LANE, l, LANE_MOVING)
        k0 = topology[link_start + v]
        for link in range(k0, k0 + topology[link_count + v]):
            gu = g0 + topology[link_target + link]
            for l in range(w):
                if get1(TS, b, st.DISPLAY_LANE, l) == LANE_DONE:
                    continue
                shown_v = get3(PS, gv, st.DISP_POS, l)
                target = get3(PS, gv, st.POSITION, l)
                move_v = v_sub(target, shown_v)
                if v_dot(move_v, move_v) == 0.0:
                    continue
                e0 = v_sub(shown_v, get3(PS, gu, st.DISP_POS, l))
                e1 = v_sub(target, get3(PS, gu, st.POSITION, l))
                if v_dot(e1, e1) > v_dot(e0, e0):   # otherwise the edge never gets longer than now
                    put1(TS, b, st.DISPLAY_COMMON, l,
                         min(get1(TS, b, st.DISPLAY_COMMON, l),
                             safe_fraction(e0, v_sub(e1, e0), display_edge_bound(PS, gv, gu, l, dt))))
    passes = False
    for l in range(w):
        if get1(TS, b, st.DISPLAY_LANE, l) == LANE_SHOWN:   # the target is the interpolated display
            put1(TS, b, st.DISPLAY_LANE, l, LANE_DONE)
        elif get1(TS, b, st.DISPLAY_LANE, l) == LANE_MOVING and get1(TS, b, st.DISPLAY_COMMON, l) < 1.0:
            put1(TS, b, st.DISPLAY_LANE, l, LANE_PASSES)   # short of its target after the common move
            passes = True
    for v in range(n):
        if (topology[attribute + v] & MOVE) == 0:
            continue
        gv = g0 + v
        for l in range(w):
            common = get1(TS, b, st.DISPLAY_COMMON, l)
            if get1(TS, b, st.DISPLAY_LANE, l) != LANE_DONE and common > 0.0:
                shown_v = get3(PS, gv, st.DISP_POS, l)
                put3(PS, gv, st.DISP_POS, l, v_add(shown_v, v_scale(v_sub(get3(PS, gv, st.POSITION, l), shown_v),
                                                                    common)))
    for _ in range(DISPLAY_MOVE_PASSES if passes else 0):
        for v in range(n):
            if (topology[attribute + v] & MOVE) == 0:
                continue
            gv = g0 + v
            for l in range(w):
                put1(PS, gv, st.DISPLAY_FRACTION, l, 1.0)
            k0 = topology[link_start + v]
            for link in range(k0, k0 + topology[link_count + v]):
                gu = g0 + topology[link_target + link]
                for l in range(w):
                    if get1(TS, b, st.DISPLAY_LANE, l) != LANE_PASSES:
                        continue
                    shown_v = get3(PS, gv, st.DISP_POS, l)
                    move = v_sub(get3(PS, gv, st.POSITION, l), shown_v)
                    if v_dot(move, move) == 0.0:
                        continue
                    put1(PS, gv, st.DISPLAY_FRACTION, l,
                         min(get1(PS, gv, st.DISPLAY_FRACTION, l),
                             safe_fraction(v_sub(shown_v, get3(PS, gu, st.DISP_POS, l)), move,
                                           display_edge_bound(PS, gv, gu, l, dt))))
            for l in range(w):
                if get1(TS, b, st.DISPLAY_LANE, l) != LANE_PASSES:
                    continue
                shown_v = get3(PS, gv, st.DISP_POS, l)
                move = v_sub(get3(PS, gv, st.POSITION, l), shown_v)
                if v_dot(move, move) != 0.0:
                    put3(PS, gv, st.DISP_POS, l, v_add(shown_v, v_scale(move, get1(PS, gv, st.DISPLAY_FRACTION, l))))
    for j in range(n):
        for l in range(w):
            if get1(TS, b, st.DISPLAY_LANE, l) != LANE_DONE:
                put3(PS, g0 + j, st.POSITION, l, get3(PS, g0 + j, st.DISP_POS, l))
