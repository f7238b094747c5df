"""Display positions after the steps (docs/solver.md §E.1), run every frame even with 0 steps.

The display extrapolates the last step by its real velocity to the frame time (frame
interpolation), clamps it to 1.3x the root distance of the animated pose, and blends it with
the animated pose by ``blend_weight``. Positions are updated in place in particle order: a
Move root reads its already blended display (a quirk kept on purpose, §E.1).

With ``solver.time_based_smoothing`` on (quality mode) the display is the last step's state
extrapolated by the time elapsed since that step (docs/quality-mode.md).
"""
from __future__ import annotations

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels.math3d import load3, load4, store3, store4, clamp_length, v_add, v_length, v_lerp, v_scale, v_sub
from magica_py.solver.quality import display_ftl_team

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
def display_team(m, ps, prm, ts, team, dt, time, old_time, now_update_time, running):
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_team_particle_count = m.team_particle_count
    blend = ts.blend_weight[team]
    t = display_fraction(dt, time, old_time, now_update_time)
    time_based = prm.time_based_smoothing[team] != 0
    # quality mode: the state extrapolated by the time since the last step (in [0, dt) with
    # exact timing), a function of time only; E.1's lerp from the last display is a
    # per-frame filter whose strength depends on the frame rate
    ahead = min(max(time - now_update_time, 0.0), dt)
    # arrays as locals, flat rows, unsigned indices: through the tables the array pointers
    # are reloaded after every store. One pass in particle order (the root read below)
    attribute, root_index = m.attribute, m.root_index
    position, rotation, disp_pos = ps.position, ps.rotation, ps.disp_pos
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
                f = v_add(load3(old_pos, p), v_scale(load3(real_velocity, p), ahead))
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
    mode = prm.inextensibility[team]
    if time_based and (mode == 2 or mode == 3 or mode == 5):  # the FTL options
        display_ftl_team(m, ps, ts, team)
