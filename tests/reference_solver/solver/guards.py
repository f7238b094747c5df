"""Guards (docs/solver.md §E.5): a team whose particles become non-finite or exceed a speed bound
is reset to its base pose, and the reason is recorded in ``TeamState.guard_code`` (the system
turns it into a ``("cloth_reset", {...})`` event). Nothing non-finite reaches a transform."""
from __future__ import annotations

import math


from magica_py.jit import kernel
from magica_py.kernels.math3d import load3, load4, store3, store4
from reference_solver.solver.center import snap_particles_to_base_pose

GUARD_OK = 0
GUARD_NON_FINITE = 1
GUARD_SPEED = 2
GUARD_SPEED_LIMIT = 100.0   # m/s (scaled by the team scale ratio): far above any cloth motion


@kernel
def speed_limit_sq(scale_ratio):
    """Squared speed bound (m/s)^2 of a team with scale ratio ``scale_ratio``."""
    return (GUARD_SPEED_LIMIT * max(scale_ratio, 1e-6)) ** 2


@kernel(inline="always")
def particle_verdict(old_pos, real_velocity, velocity, disp_pos, limit_sq):
    """(non-finite, too fast) of one particle after the steps (branch-free)."""
    finite = True
    s = 0.0
    for c in range(3):
        v = real_velocity[c]
        finite = finite & math.isfinite(old_pos[c]) & math.isfinite(v) & math.isfinite(velocity[c]) \
            & math.isfinite(disp_pos[c])
        s += v * v
    return (not finite), s > limit_sq


@kernel
def check_team(m, ps, ts, team):
    """Return the guard code of one team after its steps (0 when healthy).

    One read-only pass with the verdicts OR-ed (no early exit: the loop vectorises); any
    non-finite value wins over a speed excess, as with the early return it replaces."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_team_particle_count = m.team_particle_count
    # quality mode: the bound follows the cloth's length unit too (1.0 in faithful mode)
    limit_sq = speed_limit_sq(ts.scale_ratio[team] * ts.length_unit[team])
    old_pos, real_velocity, velocity, disp_pos = ps.old_pos, ps.real_velocity, ps.velocity, ps.disp_pos
    start = m.team_particle_start[team]
    non_finite = False
    too_fast = False
    for p in range(start, start + m_team_particle_count[team]):
        bad, fast = particle_verdict(load3(old_pos, p), load3(real_velocity, p), load3(velocity, p),
                                     load3(disp_pos, p), limit_sq)
        non_finite = non_finite | bad
        too_fast = too_fast | fast
    return guard_code(non_finite, too_fast)


@kernel
def guard_code(non_finite, too_fast):
    if non_finite:
        return GUARD_NON_FINITE
    return GUARD_SPEED if too_fast else GUARD_OK


@kernel
def reset_team_to_base(m, ps, ts, team):
    """Snap a team's particles to this frame's animated pose with zero velocity (docs/solver.md §C.5 Reset)."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    ps_position, ps_rotation, ps_step_basic_pos = ps.position, ps.rotation, ps.step_basic_pos
    ps_step_basic_rot = ps.step_basic_rot
    start = m.team_particle_start[team]
    end = start + m.team_particle_count[team]
    snap_particles_to_base_pose(ps, start, end)
    for p in range(start, end):
        store3(ps_step_basic_pos, p, load3(ps_position, p))
        store4(ps_step_basic_rot, p, load4(ps_rotation, p))
    ts.velocity_weight[team] = 0.0
    ts.blend_weight[team] = 0.0
