"""A Python driver of the team-time kernels (``magica_py/runtime/team_time.py``) for the tests:
one call per phase of docs/solver.md §A.4 / §A.6 / §A.7 on a ``TeamTimeState``, the way the
frame kernel (``solver/frame.py``) calls them inside its numba function::

    frame_update(state, settings, unity_time)        # §A.4: update_count, skip_count, time...
    for k in range(state.max_update_count()):
        begin_step(state, settings, k)               # §A.6: now_update_time += dt, interpolation
        ... a step for teams with state.step_running ...
    end_frame(state, settings)                       # §A.7: clear flags, 7200 s wrap
"""
from __future__ import annotations

from magica_py.runtime.team_time import (
    SimulationTimeSettings, TeamTimeState, team_time_begin_step, team_time_end_frame, team_time_frame_update,
)


def frame_update(state: TeamTimeState, settings: SimulationTimeSettings, unity_time,
                 fixed_update_count: int | None = None) -> None:
    """§A.4 for all teams. ``unity_time`` is a ``clock.UnityTime`` (or anything with its
    fields); ``fixed_update_count`` overrides ``unity_time.fixed_update_count`` (the player's
    live counter, ``ctx.counters.fixed_update_count``)."""
    fixed_count = unity_time.fixed_update_count if fixed_update_count is None else fixed_update_count
    team_time_frame_update(
        state.active, state.suspended, state.update_mode, state.team_time_scale,
        state.time, state.old_time, state.now_update_time, state.old_update_time,
        state.frame_update_time, state.frame_old_time,
        state.update_count, state.skip_count, state.frame_delta_time, state.now_time_scale,
        state.frame_add, state.running,
        float(unity_time.delta_time), float(unity_time.unscaled_delta_time),
        float(unity_time.fixed_delta_time), int(fixed_count),
        float(settings.global_time_scale), float(settings.simulation_delta_time),
        int(settings.max_steps_per_frame), int(settings.timing_code))


def begin_step(state: TeamTimeState, settings: SimulationTimeSettings, step: int) -> None:
    """§A.6 for all teams at the start of step ``step``; sets ``state.step_running``."""
    team_time_begin_step(int(step), state.active, state.update_count, state.time,
                         state.now_update_time, state.frame_old_time, state.frame_interpolation,
                         state.step_running, float(settings.simulation_delta_time),
                         int(settings.timing_code))


def end_frame(state: TeamTimeState, settings: SimulationTimeSettings) -> None:
    """§A.7 timing part for all teams."""
    team_time_end_frame(state.active, state.running, state.step_running, state.skip_count,
                        state.time, state.old_time, state.now_update_time, state.old_update_time,
                        state.frame_update_time, state.frame_old_time, int(settings.timing_code))
