"""MagicaCloth2 per-team simulation timing (docs/solver.md §A.3 TimeManager.FrameUpdate, §A.4, §A.6, §A.7).

Every cloth component is a *team*. Each team keeps its own clock, fed by the frame delta
of its update mode, and decides once per frame how many fixed-size simulation steps of
``dt = 1/frequency`` to run (at most ``max_steps_per_frame``; time beyond that is dropped,
not queued). During the steps ``frame_interpolation`` says where between "the last frame
that simulated" and "this frame" each step sits.

Calling sequence (LATE_UPDATE, all teams, inside the frame kernel ``solver/frame.py``;
``tests/team_time_driver.py`` drives the same kernels from Python)::

    team_time_frame_update(...)                      # §A.4: update_count, skip_count, time...
    for k in range(most steps of any team):
        team_time_begin_step(k, ...)                 # §A.6: now_update_time += dt, interpolation
        ... solver step for teams with step_running ...
    team_time_end_frame(...)                         # §A.7: clear flags, 7200 s wrap

``TeamTimeState`` fields (capacity ``n`` teams; slots with ``active == False`` are ignored;
"written by" frame_update / begin_step / end_frame means ``team_time_frame_update`` /
``team_time_begin_step(_team)`` / ``team_time_end_frame``):

=====================  ==========  =====  ====================================================
field                  dtype       units  meaning / written by
=====================  ==========  =====  ====================================================
active                 bool        -      slot in use (team registry: ``activate``/``deactivate``)
suspended              bool        -      skip this frame's timing (culled, disabled, scale < 1e-6):
                                          time does not advance, no step (solver, before
                                          ``frame_update``)
update_mode            int8        -      UPDATE_NORMAL / UPDATE_UNITY_PHYSICS / UPDATE_UNSCALED
team_time_scale        float64     1      team time scale, [0,1] (API; ``set_time_scale``)
time, old_time         float64     s      team clock after / before this frame (frame_update)
now_update_time        float64     s      time of the last executed step (begin_step)
old_update_time        float64     s      now_update_time at the start of the last frame with
                                          steps (frame_update)
frame_update_time      float64     s      ``time`` of the last frame with steps (frame_update)
frame_old_time         float64     s      ``time`` of the frame with steps before that
update_count           int32       -      steps to run this frame (frame_update)
skip_count             int32       -      planned steps dropped this frame (frame_update; 0 after
                                          end_frame on frames that ran)
frame_delta_time       float64     s      unscaled frame delta of the update mode (frame_update)
now_time_scale         float64     1      team scale * global scale (1 for unscaled) (frame_update)
frame_add              float64     s      frame_delta_time * now_time_scale (frame_update)
frame_interpolation    float64     1      [0,1], position of the current step (begin_step)
running                bool        -      update_count > 0 this frame (frame_update; cleared by
                                          end_frame)
step_running           bool        -      the team runs step k (begin_step; cleared by end_frame)
=====================  ==========  =====  ====================================================

Timing modes (``SimulationTimeSettings.timing``):

* ``"exact"`` (default, a documented deviation, Appendix 3.1): float64 counters, and the
  planned step count is ``trunc((T - now_update_time)/dt + STEP_EPSILON)`` with
  ``STEP_EPSILON = 1e-6`` of a step (11 ns at 90 Hz). Frame rates commensurate with the
  frequency (30, 45, 90, 180 fps at 90 Hz) then give exact step counts (30 fps: 3 every
  frame, 90 fps: 1 every frame) instead of rounding-dependent 0/2 patterns. Accumulated
  float64 error stays ~1e-12 s (the 7200 s wrap bounds the magnitudes), far below the
  epsilon; a frame landing within 11 ns before a step boundary runs that step early, which
  only saturates its frame_interpolation at 1.
* ``"faithful"``: the formulas of §A.4 in float64 without the epsilon (90 fps gives
  1,1,0,2,... patterns; exactly 30 fps sometimes plans 4 and drops a step).
* ``"faithful32"``: like faithful, but every operation rounded to float32 as in the C#
  source (``time``, ``add``, ``dt``... are ``float``), for bit-level comparisons with Unity.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels.math3d import saturate
from magica_py.kernels import portable

# update modes (§A.4; AnimatorLinkage resolves to one of these, NORMAL without an animator)
UPDATE_NORMAL = 0
UPDATE_UNITY_PHYSICS = 1
UPDATE_UNSCALED = 2
UPDATE_MODES = {"normal": UPDATE_NORMAL, "unity_physics": UPDATE_UNITY_PHYSICS,
                "unscaled": UPDATE_UNSCALED}

TIMING_EXACT = 0
TIMING_FAITHFUL = 1
TIMING_FAITHFUL32 = 2
TIMING_MODES = {"exact": TIMING_EXACT, "faithful": TIMING_FAITHFUL, "faithful32": TIMING_FAITHFUL32}

STEP_EPSILON = 1e-6         # fraction of a step added before truncation in exact mode
DRIFT_GUARD_OFFSET = 0.0001  # s, §A.4 float-drift guard: nowUpdateTime = T - dt + 0.0001
TIME_WRAP_LIMIT = 7200.0     # s, §A.7: past this, all six counters go back by TIME_WRAP_SHIFT
TIME_WRAP_SHIFT = 3600.0

DEFAULT_FREQUENCY = 90
FREQUENCY_RANGE = (30, 150)
DEFAULT_MAX_STEPS = 3
MAX_STEPS_RANGE = (1, 5)
# quality mode and converged references (docs/quality-mode.md): frequencies and step
# counts beyond MagicaCloth2's caps, opted into with ``extended_range``
EXTENDED_FREQUENCY_RANGE = (30, 2880)
EXTENDED_MAX_STEPS_RANGE = (1, 64)


def update_mode_code(name) -> int:
    """``"normal" | "unity_physics" | "unscaled"`` (or the int code) -> int code."""
    if isinstance(name, (int, np.integer)) and int(name) in UPDATE_MODES.values():
        return int(name)
    key = str(name).lower().replace("-", "_")
    if key == "animator_linkage":  # no Animator in this runtime: falls back to Normal (§A.4)
        key = "normal"
    if key not in UPDATE_MODES:
        raise ValueError(f"update_mode: expected one of {sorted(UPDATE_MODES)}, got {name!r}")
    return UPDATE_MODES[key]


def timing_code(name) -> int:
    if isinstance(name, (int, np.integer)) and int(name) in TIMING_MODES.values():
        return int(name)
    if str(name) not in TIMING_MODES:
        raise ValueError(f"timing: expected one of {sorted(TIMING_MODES)}, got {name!r}")
    return TIMING_MODES[str(name)]


# ----------------------------------------------------------------------------- global settings
@dataclass
class SimulationTimeSettings:
    """MagicaCloth2's global timing (``TimeManager.FrameUpdate``, §A.3).

    Out-of-range values are clamped as MagicaCloth2 does (the scene loader reports them as
    errors before they get here); ``timing`` is validated.
    """

    frequency: int = DEFAULT_FREQUENCY
    max_steps_per_frame: int = DEFAULT_MAX_STEPS
    global_time_scale: float = 1.0
    timing: str = "exact"
    extended_range: bool = False   # quality mode / references: allow up to 2880 Hz and 64 steps

    def __post_init__(self):
        f_range = EXTENDED_FREQUENCY_RANGE if self.extended_range else FREQUENCY_RANGE
        s_range = EXTENDED_MAX_STEPS_RANGE if self.extended_range else MAX_STEPS_RANGE
        f = float(self.frequency)
        if not math.isfinite(f) or f != int(f):
            raise ValueError(f"simulation_frequency: expected an integer in Hz, got {self.frequency!r}")
        self.frequency = int(min(max(int(f), f_range[0]), f_range[1]))
        m = float(self.max_steps_per_frame)
        if not math.isfinite(m) or m != int(m):
            raise ValueError(f"max_steps_per_frame: expected an integer, got {self.max_steps_per_frame!r}")
        self.max_steps_per_frame = int(min(max(int(m), s_range[0]), s_range[1]))
        g = float(self.global_time_scale)
        if math.isnan(g):
            raise ValueError("global_time_scale: expected a number in [0, 1], got nan")
        self.global_time_scale = min(max(g, 0.0), 1.0)
        self.timing_code = timing_code(self.timing)

    @property
    def simulation_delta_time(self) -> float:
        """``dt = 1/frequency`` (float32-rounded in faithful32 mode, as in the source)."""
        dt = 1.0 / self.frequency
        return float(np.float32(dt)) if self.timing_code == TIMING_FAITHFUL32 else dt

    @property
    def max_delta_time(self) -> float:
        """``dt * max_steps`` (computed by the source but unused by it)."""
        return self.simulation_delta_time * self.max_steps_per_frame

    @property
    def simulation_power(self) -> tuple[float, float, float, float]:
        """``SimulationPower`` (x, y, z, w) with ``r = 90/frequency`` (§A.3).

        y scales distance and bending stiffness, z damping, w angle restoration; x is unused.
        All four are 1 at 90 Hz.
        """
        r = 90.0 / self.frequency
        return (r, math.sqrt(r) if r > 1.0 else r, portable.pow(r, 0.3) if r > 1.0 else r,
                portable.pow(r, 1.8))

    @classmethod
    def from_scene_settings(cls, settings) -> "SimulationTimeSettings":
        """Read ``simulation_frequency``, ``max_steps_per_frame``, ``timing`` and
        ``global_time_scale`` by attribute (or key) from any settings object."""
        def get(name, default):
            v = settings.get(name) if isinstance(settings, dict) else getattr(settings, name, None)
            return default if v is None else v

        return cls(frequency=get("simulation_frequency", DEFAULT_FREQUENCY),
                   max_steps_per_frame=get("max_steps_per_frame", DEFAULT_MAX_STEPS),
                   global_time_scale=get("global_time_scale", 1.0),
                   timing=get("timing", "exact"),
                   extended_range=bool(get("extended_range", False)))


# ----------------------------------------------------------------------------- kernels
@kernel
def _r(x, single):
    """Round to float32 when emulating the C# float arithmetic."""
    if single:
        return np.float64(np.float32(x))
    return x


@kernel
def team_time_frame_update(active, suspended, update_mode, team_time_scale,
                           time, old_time, now_update_time, old_update_time,
                           frame_update_time, frame_old_time,
                           update_count, skip_count, frame_delta_time, now_time_scale,
                           frame_add, running,
                           delta_time, unscaled_delta_time, fixed_delta_time, fixed_update_count,
                           global_time_scale, dt, max_steps, timing):
    """§A.4 for every active team: frame delta, time scale, step count, dropped time, counters."""
    single = timing == TIMING_FAITHFUL32
    for t in range(active.shape[0]):
        if not active[t]:
            continue
        if suspended[t]:  # culled / disabled: the team's time does not advance
            update_count[t] = 0
            skip_count[t] = 0
            running[t] = False
            frame_delta_time[t] = 0.0
            frame_add[t] = 0.0
            continue
        mode = update_mode[t]
        if mode == UPDATE_UNITY_PHYSICS:
            fdt = _r(fixed_update_count * _r(fixed_delta_time, single), single)
        elif mode == UPDATE_UNSCALED:
            fdt = _r(unscaled_delta_time, single)
        else:
            fdt = _r(delta_time, single)
        scale = team_time_scale[t]
        if mode != UPDATE_UNSCALED:
            scale = _r(scale * global_time_scale, single)
        add = _r(fdt * scale, single)
        T = _r(time[t] + add, single)
        planned = _r(_r(T - now_update_time[t], single) / dt, single)
        if timing == TIMING_EXACT:
            planned += STEP_EPSILON
        n = int(planned)  # truncation toward zero, not floor (§A.4)
        count = n if n < max_steps else max_steps
        skip = n - count
        if skip > 0:  # dropped time is forgotten, not queued
            T = _r(T - _r(dt * skip, single), single)
        if count > 0 and add == 0.0:  # float-drift guard
            count = 0
            skip = 0
            now_update_time[t] = _r(_r(T - dt, single) + DRIFT_GUARD_OFFSET, single)
        if count > 0:
            frame_old_time[t] = frame_update_time[t]
            frame_update_time[t] = T
            old_update_time[t] = now_update_time[t]
        old_time[t] = time[t]
        time[t] = T
        update_count[t] = count
        skip_count[t] = skip
        frame_delta_time[t] = fdt
        now_time_scale[t] = scale
        frame_add[t] = add
        running[t] = count > 0


@kernel
def team_time_begin_step(step, active, update_count, time, now_update_time, frame_old_time,
                         frame_interpolation, step_running, dt, timing):
    """§A.6 at the start of step ``step`` (0-based): teams with ``step < update_count`` advance."""
    for t in range(active.shape[0]):
        team_time_begin_step_team(step, t, active, update_count, time, now_update_time, frame_old_time,
                                  frame_interpolation, step_running, dt, timing)


@kernel
def team_time_begin_step_team(step, t, active, update_count, time, now_update_time, frame_old_time,
                              frame_interpolation, step_running, dt, timing):
    """``team_time_begin_step`` for team t alone (teams are independent: the parallel frame
    kernel runs each team's steps on the thread that owns it). Straight-line: the decisions are
    in ``begin_step_values``, which takes no array, so that numba's reference-count pruning
    removes this function's counts of its arrays (a branch between them keeps them: the frame
    calls this for every lane at every step)."""
    running, now, interpolation = begin_step_values(step, active[t], update_count[t], time[t], now_update_time[t],
                                                    frame_old_time[t], frame_interpolation[t], dt, timing)
    step_running[t] = running
    now_update_time[t] = now
    frame_interpolation[t] = interpolation


@kernel
def begin_step_values(step, active, update_count, time, now_update_time, frame_old_time, frame_interpolation, dt,
                      timing):
    """§A.6 of one team at the start of step ``step``: (step running, now_update_time, frame
    interpolation) from the team's clock values; a team that does not run this step keeps its
    clock and interpolation."""
    single = timing == TIMING_FAITHFUL32
    if not active or step >= update_count:
        return False, now_update_time, frame_interpolation
    now = _r(now_update_time + dt, single)
    span = _r(time - frame_old_time, single)
    if span > 0.0:
        return True, now, saturate(_r(_r(now - frame_old_time, single) / span, single))
    return True, now, 1.0


@kernel
def team_time_end_frame(active, running, step_running, skip_count,
                        time, old_time, now_update_time, old_update_time,
                        frame_update_time, frame_old_time, timing):
    """§A.7 (the timing part): clear flags, and shift all clocks back 3600 s past 7200 s."""
    single = timing == TIMING_FAITHFUL32
    for t in range(active.shape[0]):
        if not active[t]:
            continue
        if running[t]:
            skip_count[t] = 0
        running[t] = False
        step_running[t] = False
        if time[t] > TIME_WRAP_LIMIT:
            time[t] = _r(time[t] - TIME_WRAP_SHIFT, single)
            old_time[t] = _r(old_time[t] - TIME_WRAP_SHIFT, single)
            now_update_time[t] = _r(now_update_time[t] - TIME_WRAP_SHIFT, single)
            old_update_time[t] = _r(old_update_time[t] - TIME_WRAP_SHIFT, single)
            frame_update_time[t] = _r(frame_update_time[t] - TIME_WRAP_SHIFT, single)
            frame_old_time[t] = _r(frame_old_time[t] - TIME_WRAP_SHIFT, single)


@kernel
def team_time_reset(teams, time, old_time, now_update_time, old_update_time,
                    frame_update_time, frame_old_time, update_count, skip_count,
                    frame_interpolation, running, step_running):
    """"Time reset" (build, ResetCloth): zero the six counters of the listed teams (§A.4)."""
    for k in range(teams.shape[0]):
        t = teams[k]
        time[t] = 0.0
        old_time[t] = 0.0
        now_update_time[t] = 0.0
        old_update_time[t] = 0.0
        frame_update_time[t] = 0.0
        frame_old_time[t] = 0.0
        update_count[t] = 0
        skip_count[t] = 0
        frame_interpolation[t] = 1.0
        running[t] = False
        step_running[t] = False


# ----------------------------------------------------------------------------- state SoA
_FIELDS = (
    ("active", np.bool_, False), ("suspended", np.bool_, False),
    ("update_mode", np.int8, UPDATE_NORMAL), ("team_time_scale", np.float64, 1.0),
    ("time", np.float64, 0.0), ("old_time", np.float64, 0.0),
    ("now_update_time", np.float64, 0.0), ("old_update_time", np.float64, 0.0),
    ("frame_update_time", np.float64, 0.0), ("frame_old_time", np.float64, 0.0),
    ("update_count", np.int32, 0), ("skip_count", np.int32, 0),
    ("frame_delta_time", np.float64, 0.0), ("now_time_scale", np.float64, 0.0),
    ("frame_add", np.float64, 0.0), ("frame_interpolation", np.float64, 1.0),
    ("running", np.bool_, False), ("step_running", np.bool_, False),
)


class TeamTimeState:
    """Per-team timing arrays, sized by capacity (see the module docstring for each field)."""

    FIELDS = tuple(name for name, _, _ in _FIELDS)

    def __init__(self, capacity: int):
        if capacity < 0:
            raise ValueError(f"capacity: expected >= 0, got {capacity}")
        self.capacity = int(capacity)
        for name, dtype, fill in _FIELDS:
            setattr(self, name, np.full(self.capacity, fill, dtype=dtype))

    @classmethod
    def allocate(cls, capacity: int) -> "TeamTimeState":
        return cls(capacity)

    def resize(self, capacity: int) -> None:
        """Grow (or shrink) to ``capacity`` slots, keeping the first ones."""
        keep = min(capacity, self.capacity)
        for name, dtype, fill in _FIELDS:
            new = np.full(capacity, fill, dtype=dtype)
            new[:keep] = getattr(self, name)[:keep]
            setattr(self, name, new)
        self.capacity = int(capacity)

    def activate(self, team: int, update_mode="normal", time_scale: float = 1.0) -> None:
        """Put a team in slot ``team`` with a fresh clock (the time reset done at build)."""
        self.active[team] = True
        self.suspended[team] = False
        self.update_mode[team] = update_mode_code(update_mode)
        self.set_time_scale(team, time_scale)
        self.reset([team])

    def deactivate(self, team: int) -> None:
        self.active[team] = False

    def set_time_scale(self, team: int, value: float) -> None:
        """Team time scale, clamped to [0,1] as MagicaCloth2's API does."""
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"team {team}: time scale must be a number in [0, 1], got {value!r}") from None
        if math.isnan(v):
            raise ValueError(f"team {team}: time scale must be a number in [0, 1], got nan")
        self.team_time_scale[team] = min(max(v, 0.0), 1.0)

    def reset(self, teams) -> None:
        """Time reset of the listed teams (build, ResetCloth(false))."""
        ids = np.ascontiguousarray(np.atleast_1d(teams), dtype=np.int32)
        if ids.size and (ids.min() < 0 or ids.max() >= self.capacity):
            raise IndexError(f"team ids {ids.tolist()} out of range [0, {self.capacity})")
        team_time_reset(ids, self.time, self.old_time, self.now_update_time, self.old_update_time,
                        self.frame_update_time, self.frame_old_time, self.update_count,
                        self.skip_count, self.frame_interpolation, self.running, self.step_running)

    def max_update_count(self) -> int:
        """Most steps any active team runs this frame (the solver's step loop bound)."""
        if not self.active.any():
            return 0
        return int(self.update_count[self.active].max())
