"""Display positions after the steps (docs/solver.md §E.1), run every frame even with 0 steps.

The display extrapolates the last step by its real velocity to the frame time (frame
interpolation), clamps it to 1.3x the root distance of the animated pose, and blends it with
the animated pose by ``blend_weight``. Positions are updated in place in particle order: a
Move root reads its already blended display (a quirk kept on purpose, §E.1).

With ``solver.time_based_smoothing`` on (quality mode) the display is built from the last two
step states, each carried in its *display frame* (the particle's fixed root at that step, or
the team center for a particle without one) and shown in that frame's pose of this frame
(docs/quality-mode.md, *Display*). ``L_k(p) = root_rot_k^-1 (x_k(p) - root_pos_k)`` is
recorded at the end of step k (``record_display_state_team``), and

    shown(p, s) = root_pos + root_rot * lerp(L_{k-1}(p), L_k(p), s)

is the display at s = (time - t_k) / dt in [0, 1): the states interpolated with one step of
latency. A rotation keeps lengths and a lerp of two vectors is no longer
than the longer of them, so in the interpolated display an edge between two particles of the
same root (or of roots moving rigidly together) is never longer than in one of the two
states: it shows no stretch the state does not have, at any render rate, and it is a function
of time only. ``display_team`` writes it; ``quality_display.display_constraints_team`` then moves it out of
the colliders at this frame's pose as far as the edge bounds allow.
"""
from __future__ import annotations

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels.math3d import (
    clamp_length, load3, load4, q_inverse, q_rotate, store3, store4, v_add, v_length, v_lerp, v_scale, v_sub,
)

MOVE = 0x02
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
def display_frame_index(m, p):
    """The particle whose pose is p's display frame: its root when that is fixed, else -1
    (the team center)."""
    r = m.root_index[p]
    if r >= 0 and (m.attribute[r] & MOVE) == 0:
        return r
    return -1


@kernel
def record_display_state_team(m, ps, ts, team):
    """Quality display, at the end of a step (after D.10): each particle's new state
    (``old_pos``) in its display frame at this step (the fixed root's step pose ``next_pos`` /
    ``base_rot``, or the team center ``now_world_pos`` / ``now_world_rot``); the previous one
    kept as ``display_prev_local``."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_team_particle_count, ps_base_rot = m.team_particle_count, ps.base_rot
    ps_display_history, ps_display_local = ps.display_history, ps.display_local
    ps_display_prev_local, ps_next_pos, ps_old_pos = ps.display_prev_local, ps.next_pos, ps.old_pos
    center_pos = load3(ts.now_world_pos, team)
    center_inv = q_inverse(load4(ts.now_world_rot, team))
    start = m.team_particle_start[team]
    for p in range(start, start + m_team_particle_count[team]):
        r = display_frame_index(m, p)
        if r >= 0:
            local = q_rotate(q_inverse(load4(ps_base_rot, r)), v_sub(load3(ps_old_pos, p), load3(ps_next_pos, r)))
        else:
            local = q_rotate(center_inv, v_sub(load3(ps_old_pos, p), center_pos))
        store3(ps_display_prev_local, p, load3(ps_display_local, p))
        store3(ps_display_local, p, local)
        ps_display_history[p] = min(ps_display_history[p] + 1, 2)


@kernel
def display_interpolated(m, ps, ts, team, p, alpha):
    """Quality display of Move particle p: its state interpolated between the last two steps
    at ``alpha`` (in [0, 1): one step of latency) in its display frame at this frame's pose;
    its last state as is when no step ran since a reset."""
    history = ps.display_history[p]
    if history == 0:
        return load3(ps.old_pos, p)
    local = load3(ps.display_local, p)
    if history >= 2:
        local = v_lerp(load3(ps.display_prev_local, p), local, alpha)
    r = display_frame_index(m, p)
    if r >= 0:
        return v_add(load3(ps.position, r), q_rotate(load4(ps.rotation, r), local))
    return v_add(load3(ts.frame_world_pos, team), q_rotate(load4(ts.frame_world_rot, team), local))


@kernel
def display_team(m, ps, prm, ts, team, dt, time, old_time, now_update_time, running, quality):
    """E.1 for one team (module docstring); quality mode's collider and edge pass follows in
    ``quality_display.display_constraints_team``. ``quality``: the frame's quality stage switch (None:
    no team of the scene uses quality mode, its interpolation is not compiled)."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_attribute, m_team_particle_count, ps_disp_pos = m.attribute, m.team_particle_count, ps.disp_pos
    blend = ts.blend_weight[team]
    t = display_fraction(dt, time, old_time, now_update_time)
    time_based = prm.time_based_smoothing[team] != 0
    # quality mode: the last two states interpolated with one step of latency, at the time
    # since the last step (in [0, dt) with exact timing): a function of time only (E.1's lerp
    # from the last display is a per-frame filter whose strength depends on the frame rate),
    # within the states' edge lengths (extrapolating along each particle's velocity is not)
    alpha = min(max(time - now_update_time, 0.0), dt) / dt if dt > 0.0 else 0.0
    if quality is not None:
        if time_based:
            # the roots' poses are read below: compute every Move display first (a Move root
            # is not a display frame, so the order does not matter here)
            start = m.team_particle_start[team]
            for p in range(start, start + m_team_particle_count[team]):
                if (m_attribute[p] & MOVE) != 0:
                    store3(ps_disp_pos, p, display_interpolated(m, ps, ts, team, p, alpha))
    # one pass in particle order (the root read below)
    attribute, root_index = m_attribute, m.root_index
    position, rotation, disp_pos = ps.position, ps.rotation, ps_disp_pos
    old_pos, real_velocity = ps.old_pos, ps.real_velocity
    old_position, old_rotation = ps.old_position, ps.old_rotation
    base_pos_buffer, base_rot_buffer = ps.base_pos_buffer, ps.base_rot_buffer
    first = np.uint64(m.team_particle_start[team])
    for j in range(m_team_particle_count[team]):
        p = first + np.uint64(j)
        pos0 = load3(position, p)
        rot0 = load4(rotation, p)
        if (attribute[p] & MOVE) != 0:
            if time_based:
                f = load3(disp_pos, p)   # no E.1 clamp: the interpolation is bounded by the states
            else:
                f = display_extrapolated(load3(old_pos, p), load3(real_velocity, p), load3(disp_pos, p), dt, t)
                r = root_index[p]
                if r >= 0:
                    f = display_clamped(f, load3(position, np.uint64(r)), pos0)
            store3(disp_pos, p, f)
            store3(position, p, v_lerp(pos0, f, blend))
        else:
            store3(disp_pos, p, pos0)
        if running:
            store3(old_position, p, pos0)
            store4(old_rotation, p, rot0)
        store3(base_pos_buffer, p, pos0)
        store4(base_rot_buffer, p, rot0)
