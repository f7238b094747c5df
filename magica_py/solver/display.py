"""Display positions after the steps (docs/solver.md §E.1), run every frame even with 0 steps.

The display extrapolates the last step by its real velocity to the frame time (frame
interpolation), clamps it to 1.3x the root distance of the animated pose, and blends it with
the animated pose by ``blend_weight``. Positions are updated in place in particle order: a
Move root reads its already blended display (a quirk kept on purpose, §E.1).

With ``solver.time_based_smoothing`` on (quality mode) the display is built from the last two
step states, each carried in its *display frame* (the particle's fixed root at that step, or
the team center for a particle without one) and shown in that frame's pose of this frame
(docs/quality-mode.md, *Display*). ``L_k(p) = root_rot_k^-1 (x_k(p) - root_pos_k)`` is
recorded at the end of step k (``record_display_state_block``), and

    shown(p, s) = root_pos + root_rot * lerp(L_{k-1}(p), L_k(p), s)

is the display at s = (time - t_k) / dt in [0, 1): the states interpolated with one step of
latency. A rotation keeps lengths and a lerp of two vectors is no longer
than the longer of them, so in the interpolated display an edge between two particles of the
same root (or of roots moving rigidly together) is never longer than in one of the two
states: it shows no stretch the state does not have, at any render rate, and it is a function
of time only. ``display_block`` writes it; ``quality_display.display_constraints_block`` then moves it out of
the colliders at this frame's pose as far as the edge bounds allow.
"""
from __future__ import annotations

from magica_py.build.proxy import MOVE
from magica_py.jit import kernel
from magica_py.kernels.math3d import clamp_length, q_inverse, q_rotate, v_add, v_length, v_lerp, v_scale, v_sub
from magica_py.solver import blocks as bk
from magica_py.solver import state as st
from magica_py.solver.lanes import get1, get3, get4, put1, put3, put4
from magica_py.solver.parameters import PRM_TIME_BASED_SMOOTHING

MAX_DISTANCE_RATIO = 1.3   # MaxDistanceRatioFutuerPrediction


@kernel
def display_fraction(dt, time, old_time, now_update_time):
    """E.1 frame interpolation: where the frame time lies between the last step's start and end."""
    interval = (now_update_time + dt) - old_time
    return (time - old_time) / interval if interval > 0.0 else 0.0


@kernel(inline="always")
def display_extrapolated(old_pos, real_velocity, disp_pos, dt, t):
    """E.1: the last step extrapolated by its real velocity, lerped from the last display."""
    return v_lerp(disp_pos, v_add(old_pos, v_scale(real_velocity, dt)), t)


@kernel(inline="always")
def display_clamped(f, root_position, position):
    """E.1: ``f`` kept within 1.3x the root distance of the animated pose ``position``."""
    return v_add(root_position, clamp_length(v_sub(f, root_position),
                                             MAX_DISTANCE_RATIO * v_length(v_sub(root_position, position))))


@kernel
def display_frame_of(topology, attribute, root_index, j):
    """The particle whose pose is particle j's display frame: its root when that is fixed,
    else -1 (the team center)."""
    r = topology[root_index + j]
    if r >= 0 and (topology[attribute + r] & MOVE) == 0:
        return r
    return -1


@kernel(forceinline=False)
def record_display_state_block(PS, TS, BI, topology, b):
    """Quality display, at the end of a step (after D.10): each particle's new state
    (``OLD_POS``) in its display frame at this step (the fixed root's step pose ``NEXT_POS`` /
    ``BASE_ROT``, or the team center ``NOW_WORLD_POS`` / ``NOW_WORLD_ROT``); the previous one
    kept as ``DISPLAY_PREV_LOCAL``."""
    g0 = BI[b, bk.BI_G0]
    w = bk.lane_width(BI, b)
    attribute, root_index = BI[b, bk.BI_ATTRIBUTE], BI[b, bk.BI_ROOT_INDEX]
    for j in range(BI[b, bk.BI_N]):
        g = g0 + j
        r = display_frame_of(topology, attribute, root_index, j)
        gr = g0 + (r if r >= 0 else j)
        for l in range(w):
            x = get3(PS, g, st.OLD_POS, l)
            if r >= 0:
                local = q_rotate(q_inverse(get4(PS, gr, st.BASE_ROT, l)), v_sub(x, get3(PS, gr, st.NEXT_POS, l)))
            else:
                local = q_rotate(q_inverse(get4(TS, b, st.NOW_WORLD_ROT, l)), v_sub(x, get3(TS, b, st.NOW_WORLD_POS, l)))
            put3(PS, g, st.DISPLAY_PREV_LOCAL, l, get3(PS, g, st.DISPLAY_LOCAL, l))
            put3(PS, g, st.DISPLAY_LOCAL, l, local)
            put1(PS, g, st.DISPLAY_HISTORY, l, min(get1(PS, g, st.DISPLAY_HISTORY, l) + 1.0, 2.0))


@kernel
def display_interpolated(PS, TS, b, g, gr, l, rooted, alpha):
    """Quality display of a Move particle (slot g, display frame slot gr when ``rooted``, else
    the team center): its state interpolated between the last two steps at ``alpha`` (in
    [0, 1): one step of latency) in its display frame at this frame's pose; its last state as
    is when no step ran since a reset."""
    history = get1(PS, g, st.DISPLAY_HISTORY, l)
    if history == 0.0:
        return get3(PS, g, st.OLD_POS, l)
    local = get3(PS, g, st.DISPLAY_LOCAL, l)
    if history >= 2.0:
        local = v_lerp(get3(PS, g, st.DISPLAY_PREV_LOCAL, l), local, alpha)
    if rooted:
        return v_add(get3(PS, gr, st.POSITION, l), q_rotate(get4(PS, gr, st.ROTATION, l), local))
    return v_add(get3(TS, b, st.FRAME_WORLD_POS, l), q_rotate(get4(TS, b, st.FRAME_WORLD_ROT, l), local))


@kernel(forceinline=False)
def display_block(PS, TS, P, BI, topology, b, dt, quality):
    """E.1 for block b (module docstring); quality mode's collider and edge pass follows in
    ``quality_display.display_constraints_block``. Each lane's clock is in ``TS``
    (``DISPLAY_T``, ``DISPLAY_ALPHA``: written by the frame before the end stages).
    ``quality``: the frame's quality stage switch (None: no team of the scene uses quality
    mode, its interpolation is not compiled)."""
    g0 = BI[b, bk.BI_G0]
    w = bk.lane_width(BI, b)
    n = BI[b, bk.BI_N]
    attribute, root_index = BI[b, bk.BI_ATTRIBUTE], BI[b, bk.BI_ROOT_INDEX]
    time_based = P[b, PRM_TIME_BASED_SMOOTHING] != 0.0
    if quality is not None:
        if time_based:
            # the roots' poses are read below: compute every Move display first (a Move root
            # is not a display frame, so the order does not matter here)
            for j in range(n):
                if (topology[attribute + j] & MOVE) == 0:
                    continue
                g = g0 + j
                r = display_frame_of(topology, attribute, root_index, j)
                gr = g0 + (r if r >= 0 else j)
                for l in range(w):
                    put3(PS, g, st.DISP_POS, l, display_interpolated(PS, TS, b, g, gr, l, r >= 0,
                                                                     get1(TS, b, st.DISPLAY_ALPHA, l)))
    # one pass in particle order (a Move particle reads its root's position as written so far:
    # a Move root's display, the quirk of §E.1), the root's position gathered next to it first
    for j in range(n):
        g = g0 + j
        move = (topology[attribute + j] & MOVE) != 0
        r = topology[root_index + j]
        clamp = move and (not time_based) and r >= 0
        if clamp:
            gr = g0 + r
            for l in range(w):
                put3(PS, g, st.PARTNER_POS, l, get3(PS, gr, st.POSITION, l))
        for l in range(w):   # the animated pose kept (E.2 reads it); stores selected, not branched
            pos0 = get3(PS, g, st.POSITION, l)
            rot0 = get4(PS, g, st.ROTATION, l)
            running = get1(TS, b, st.RUNNING, l) != 0.0
            old_position = get3(PS, g, st.OLD_POSITION, l)
            old_rotation = get4(PS, g, st.OLD_ROTATION, l)
            put3(PS, g, st.OLD_POSITION, l, pos0 if running else old_position)
            put4(PS, g, st.OLD_ROTATION, l, rot0 if running else old_rotation)
            put3(PS, g, st.BASE_POS_BUFFER, l, pos0)
            put4(PS, g, st.BASE_ROT_BUFFER, l, rot0)
        if not move:
            for l in range(w):
                put3(PS, g, st.DISP_POS, l, get3(PS, g, st.POSITION, l))
        elif time_based:   # no E.1 clamp: the interpolation is bounded by the states
            for l in range(w):
                put3(PS, g, st.POSITION, l, v_lerp(get3(PS, g, st.POSITION, l), get3(PS, g, st.DISP_POS, l),
                                                   get1(TS, b, st.BLEND_WEIGHT, l)))
        else:
            for l in range(w):
                pos0 = get3(PS, g, st.POSITION, l)
                f = display_extrapolated(get3(PS, g, st.OLD_POS, l), get3(PS, g, st.REAL_VELOCITY, l),
                                         get3(PS, g, st.DISP_POS, l), dt, get1(TS, b, st.DISPLAY_T, l))
                clamped = display_clamped(f, get3(PS, g, st.PARTNER_POS, l), pos0)
                f = clamped if clamp else f
                put3(PS, g, st.DISP_POS, l, f)
                put3(PS, g, st.POSITION, l, v_lerp(pos0, f, get1(TS, b, st.BLEND_WEIGHT, l)))
