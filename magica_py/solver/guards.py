"""Guards (issue 4 item 5): a team whose particles become non-finite or exceed a speed bound
is reset to its base pose, and the reason is recorded in ``TeamState.guard_code`` (the system
turns it into a ``("cloth_reset", {...})`` event). Nothing non-finite reaches a transform."""
from __future__ import annotations

import math

from magica_py.jit import kernel
from magica_py.kernels.math3d import load3, load4, store3, store4
from magica_py.solver.center import snap_particles_to_base_pose

GUARD_OK = 0
GUARD_NON_FINITE = 1
GUARD_SPEED = 2
GUARD_SPEED_LIMIT = 100.0   # m/s (scaled by the team scale ratio): far above any cloth motion


@kernel
def check_team(m, ps, ts, team):
    """Return the guard code of one team after its steps (0 when healthy)."""
    limit_sq = (GUARD_SPEED_LIMIT * max(ts.scale_ratio[team], 1e-6)) ** 2
    start = m.team_particle_start[team]
    code = GUARD_OK
    for p in range(start, start + m.team_particle_count[team]):
        s = 0.0
        for c in range(3):
            x = ps.old_pos[p, c]
            v = ps.real_velocity[p, c]
            if not (math.isfinite(x) and math.isfinite(v) and math.isfinite(ps.velocity[p, c])
                    and math.isfinite(ps.disp_pos[p, c])):
                return GUARD_NON_FINITE
            s += v * v
        if s > limit_sq:
            code = GUARD_SPEED
    return code


@kernel
def reset_team_to_base(m, ps, ts, team):
    """Snap a team's particles to this frame's animated pose with zero velocity (C.5 Reset)."""
    start = m.team_particle_start[team]
    end = start + m.team_particle_count[team]
    snap_particles_to_base_pose(ps, start, end)
    for p in range(start, end):
        store3(ps.step_basic_pos, p, load3(ps.position, p))
        store4(ps.step_basic_rot, p, load4(ps.rotation, p))
    ts.velocity_weight[team] = 0.0
    ts.blend_weight[team] = 0.0
