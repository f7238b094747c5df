"""Display positions after the steps (ref §E.1), run every frame even with 0 steps.

The display extrapolates the last step by its real velocity to the frame time (frame
interpolation), clamps it to 1.3x the root distance of the animated pose, and blends it with
the animated pose by ``blend_weight``. Positions are updated in place in particle order: a
Move root reads its already blended display (a quirk kept on purpose, §E.1).

With ``solver.time_based_smoothing`` on (quality mode) the display is the last step's state
extrapolated by the time elapsed since that step (docs/quality-mode.md).
"""
from __future__ import annotations

from magica_py.jit import kernel
from magica_py.solver.quality import display_ftl_team
from magica_py.kernels.math3d import (
    clamp_length, load3, load4, store3, store4, v_add, v_length, v_lerp, v_scale, v_sub,
)

MOVE = 0x02
MAX_DISTANCE_RATIO = 1.3   # MaxDistanceRatioFutuerPrediction


@kernel
def display_team(m, ps, prm, ts, team, dt, time, old_time, now_update_time, running):
    blend = ts.blend_weight[team]
    interval = (now_update_time + dt) - old_time
    t = (time - old_time) / interval if interval > 0.0 else 0.0
    time_based = prm.time_based_smoothing[team] != 0
    # quality mode: the state extrapolated by the time since the last step (in [0, dt) with
    # exact timing), a function of time only; E.1's lerp from the last display is a
    # per-frame filter whose strength depends on the frame rate
    ahead = min(max(time - now_update_time, 0.0), dt)
    start = m.team_particle_start[team]
    for p in range(start, start + m.team_particle_count[team]):
        pos0 = load3(ps.position, p)
        rot0 = load4(ps.rotation, p)
        if (m.attribute[p] & MOVE) != 0:
            if time_based:
                f = v_add(load3(ps.old_pos, p), v_scale(load3(ps.real_velocity, p), ahead))
            else:
                f = v_add(load3(ps.old_pos, p), v_scale(load3(ps.real_velocity, p), dt))
                f = v_lerp(load3(ps.disp_pos, p), f, t)
            r = m.root_index[p]
            if r >= 0:
                rp = load3(ps.position, r)
                f = v_add(rp, clamp_length(v_sub(f, rp), MAX_DISTANCE_RATIO * v_length(v_sub(rp, pos0))))
            store3(ps.disp_pos, p, f)
            store3(ps.position, p, v_lerp(pos0, f, blend))
        else:
            store3(ps.disp_pos, p, pos0)
        if running:
            store3(ps.old_position, p, pos0)
            store4(ps.old_rotation, p, rot0)
        store3(ps.base_pos_buffer, p, pos0)
        store4(ps.base_rot_buffer, p, rot0)
    mode = prm.inextensibility[team]
    if time_based and (mode == 2 or mode == 3 or mode == 5):  # the FTL options
        display_ftl_team(m, ps, ts, team)
