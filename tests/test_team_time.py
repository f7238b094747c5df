"""MagicaCloth2 per-team timing (magica_py/runtime/team_time.py) against docs/solver.md §A.3-§A.7."""
from __future__ import annotations


import numpy as np
import pytest

from magica_py.runtime.clock import FixedFrameRate, FrameTimeList, TimeManager, UnityTime
from team_time_driver import begin_step, end_frame, frame_update
from magica_py.runtime.team_time import (
    UPDATE_NORMAL,
    UPDATE_UNITY_PHYSICS,
    UPDATE_UNSCALED,
    SimulationTimeSettings,
    TeamTimeState,
    update_mode_code,
)


# ----------------------------------------------------------------------------- slow twin
class NaiveTeamClock:
    """Line-by-line transcription of §A.4 / §A.6 / §A.7 for one team, in plain Python.

    ``f32`` rounds every operation through numpy.float32, as the C# source computes.
    """

    def __init__(self, mode=UPDATE_NORMAL, team_scale=1.0, f32=False, epsilon=0.0):
        self.mode, self.team_scale, self.epsilon = mode, team_scale, epsilon
        self.f = (lambda x: float(np.float32(x))) if f32 else (lambda x: x)
        self.time = self.old_time = self.now_update_time = self.old_update_time = 0.0
        self.frame_update_time = self.frame_old_time = 0.0
        self.interpolations = []

    def frame(self, ut, dt, max_count, global_scale=1.0, fixed_count=None):
        f = self.f
        fixed_count = ut.fixed_update_count if fixed_count is None else fixed_count
        if self.mode == UPDATE_UNITY_PHYSICS:
            frame_delta = f(fixed_count * f(ut.fixed_delta_time))
        elif self.mode == UPDATE_UNSCALED:
            frame_delta = f(ut.unscaled_delta_time)
        else:
            frame_delta = f(ut.delta_time)
        scale = self.team_scale * (1.0 if self.mode == UPDATE_UNSCALED else global_scale)
        scale = f(scale)
        add = f(frame_delta * scale)
        T = f(self.time + add)
        n = int(f(f(T - self.now_update_time) / dt) + self.epsilon)
        update_count = min(n, max_count)
        skip = n - update_count
        if skip > 0:
            T = f(T - f(dt * skip))
        if update_count > 0 and add == 0:
            update_count = skip = 0
            self.now_update_time = f(f(T - dt) + 0.0001)
        if update_count > 0:
            self.frame_old_time = self.frame_update_time
            self.frame_update_time = T
            self.old_update_time = self.now_update_time
        self.old_time, self.time = self.time, T
        self.interpolations = []
        for _ in range(update_count):
            self.now_update_time = f(self.now_update_time + dt)
            span = f(self.time - self.frame_old_time)
            r = f(f(self.now_update_time - self.frame_old_time) / span) if span > 0 else 1.0
            self.interpolations.append(min(max(r, 0.0), 1.0))
        if self.time > 7200:
            for name in ("time", "old_time", "now_update_time", "old_update_time",
                         "frame_update_time", "frame_old_time"):
                setattr(self, name, f(getattr(self, name) - 3600))
        return update_count, skip, frame_delta, scale


def run_frame(state, settings, ut, fixed_count=None):
    """One frame of the calling sequence; returns per-team lists of frame_interpolation."""
    frame_update(state, settings, ut, fixed_count)
    interps = [[] for _ in range(state.capacity)]
    for k in range(settings.max_steps_per_frame):
        begin_step(state, settings, k)
        for t in np.nonzero(state.step_running)[0]:
            interps[t].append(float(state.frame_interpolation[t]))
    counts = state.update_count.copy()
    skips = state.skip_count.copy()
    end_frame(state, settings)
    return counts, skips, interps


def counts_at_fps(fps, timing, frames=120, frequency=90, mode="normal"):
    settings = SimulationTimeSettings(frequency=frequency, timing=timing)
    state = TeamTimeState.allocate(1)
    state.activate(0, mode)
    tm, src = TimeManager(), FixedFrameRate(fps)
    out = []
    for _ in range(frames):
        counts, skips, _ = run_frame(state, settings, tm.advance(src.next_delta()))
        out.append((int(counts[0]), int(skips[0])))
    return out


def unity_time(delta, unscaled=None, fixed_delta=0.02, fixed_count=0):
    return UnityTime(frame_count=1, delta_time=delta,
                     unscaled_delta_time=delta if unscaled is None else unscaled,
                     time=0.0, unscaled_time=0.0, fixed_delta_time=fixed_delta, fixed_time=0.0,
                     fixed_update_count=fixed_count, time_scale=1.0, maximum_delta_time=1 / 3)


# ----------------------------------------------------------------------------- global settings
def test_settings_defaults_and_clamps():
    s = SimulationTimeSettings()
    assert (s.frequency, s.max_steps_per_frame, s.global_time_scale) == (90, 3, 1.0)
    assert s.simulation_delta_time == 1 / 90
    assert s.simulation_power == (1.0, 1.0, 1.0, 1.0)
    s = SimulationTimeSettings(frequency=10, max_steps_per_frame=9, global_time_scale=3.0)
    assert (s.frequency, s.max_steps_per_frame, s.global_time_scale) == (30, 5, 1.0)
    s = SimulationTimeSettings(frequency=500, max_steps_per_frame=0, global_time_scale=-1)
    assert (s.frequency, s.max_steps_per_frame, s.global_time_scale) == (150, 1, 0.0)


def test_simulation_power_at_30_and_150_hz():
    x, y, z, w = SimulationTimeSettings(frequency=30).simulation_power
    assert (x, y, z, w) == pytest.approx((3.0, 3 ** 0.5, 3 ** 0.3, 3 ** 1.8))
    x, y, z, w = SimulationTimeSettings(frequency=150).simulation_power
    r = 0.6
    assert (x, y, z, w) == pytest.approx((r, r, r, r ** 1.8))


def test_settings_reject_unknown_timing_and_fractional_frequency():
    with pytest.raises(ValueError, match="timing"):
        SimulationTimeSettings(timing="approximate")
    with pytest.raises(ValueError, match="simulation_frequency"):
        SimulationTimeSettings(frequency=90.5)
    with pytest.raises(ValueError, match="update_mode"):
        update_mode_code("fixed")


def test_faithful32_uses_float32_step():
    s = SimulationTimeSettings(timing="faithful32")
    assert s.simulation_delta_time == float(np.float32(1 / 90))
    assert s.simulation_delta_time != 1 / 90


# ----------------------------------------------------------------------------- steps per frame
def test_30_fps_at_90_hz_runs_3_steps_every_frame_in_exact_mode():
    assert counts_at_fps(30, "exact", frames=600) == [(3, 0)] * 600


def test_exact_90_fps_runs_1_step_every_frame_faithful_does_not():
    assert counts_at_fps(90, "exact", frames=600) == [(1, 0)] * 600
    faithful = [c for c, _ in counts_at_fps(90, "faithful", frames=600)]
    assert faithful[:6] == [1, 1, 0, 2, 1, 0]  # Appendix 3.1
    assert faithful.count(0) > 0 and faithful.count(2) > 0
    # no time is lost: the running step total never strays more than one step from the frames
    assert all(abs(sum(faithful[:i + 1]) - (i + 1)) <= 1 for i in range(600))


def test_faithful_30_fps_sometimes_plans_4_and_drops_a_step():
    # Appendix 3.1: exactly 30 fps plans 2 and then 4 (capped to 3): 2 steps dropped in 40 frames
    faithful = counts_at_fps(30, "faithful", frames=40)
    assert sum(s for _, s in faithful) == 2
    assert [c for c, _ in faithful].count(2) == 2
    assert all(c == 3 for c, s in faithful if s > 0)


def test_144_fps_runs_0_or_1_steps_with_interpolation_in_unit_interval():
    settings = SimulationTimeSettings()
    state = TeamTimeState.allocate(1)
    state.activate(0)
    tm, src = TimeManager(), FixedFrameRate(144)
    counts, all_interps = [], []
    for _ in range(144):
        c, _, interps = run_frame(state, settings, tm.advance(src.next_delta()))
        counts.append(int(c[0]))
        all_interps += interps[0]
    assert set(counts) == {0, 1}
    assert sum(counts) == 90  # one second of frames = 90 steps
    assert all(0.0 <= r <= 1.0 for r in all_interps)
    assert min(all_interps) < 0.9  # steps really sit between frames, not all at the end


def test_one_second_hitch_runs_max_steps_and_drops_the_rest():
    settings = SimulationTimeSettings()
    state = TeamTimeState.allocate(1)
    state.activate(0)
    tm = TimeManager(maximum_delta_time=10.0)  # let the full second through Unity's clamp
    src = FrameTimeList([1 / 60] * 10 + [1.0] + [1 / 60] * 10, cycle=False)
    results = [run_frame(state, settings, tm.advance(src.next_delta())) for _ in range(21)]
    counts, skips, _ = results[10]
    assert counts[0] == 3
    assert skips[0] == 87  # 1 s = 90 steps planned, 3 run
    assert state.time[0] - state.now_update_time[0] < 1 / 90  # dropped time is not queued
    assert [int(r[0][0]) for r in results[11:]] == [1, 2] * 5  # back to the 60 fps rhythm


def test_unity_clamped_hitch_still_caps_at_3_steps():
    # Unity's maximumDeltaTime (1/3 s) lets 30 steps through: 3 run, 27 dropped
    c = counts_at_fps(1.0, "exact", frames=1)
    assert c == [(3, 27)]


def test_max_steps_cap_and_frequency_scale_the_step_count():
    # 150 Hz at 30 fps plans 5 steps a frame: the default cap of 3 drops 2 every frame
    assert counts_at_fps(30, "exact", frames=10, frequency=150) == [(3, 2)] * 10
    settings = SimulationTimeSettings(frequency=150, max_steps_per_frame=5)
    state = TeamTimeState.allocate(1)
    state.activate(0)
    counts, skips, _ = run_frame(state, settings, unity_time(1 / 30))
    assert (counts[0], skips[0]) == (5, 0)
    settings = SimulationTimeSettings(frequency=60, max_steps_per_frame=1)
    state.activate(0)
    counts, skips, _ = run_frame(state, settings, unity_time(1 / 20))
    assert (counts[0], skips[0]) == (1, 2)


# ----------------------------------------------------------------------------- time scale, modes
def test_time_scale_zero_runs_no_steps():
    settings = SimulationTimeSettings(global_time_scale=0.0)
    state = TeamTimeState.allocate(2)
    state.activate(0)
    state.activate(1)
    state.set_time_scale(1, 0.0)
    settings_team = SimulationTimeSettings()
    for _ in range(30):
        counts, _, _ = run_frame(state, settings, unity_time(1 / 30))
        assert counts.tolist() == [0, 0]
    assert state.time.tolist() == [0.0, 0.0]
    counts, _, _ = run_frame(state, settings_team, unity_time(1 / 30))
    assert counts.tolist() == [3, 0]  # team 1 keeps its own scale 0


def test_unscaled_mode_ignores_global_time_scale_and_uses_unscaled_delta():
    settings = SimulationTimeSettings(global_time_scale=0.0)
    state = TeamTimeState.allocate(2)
    state.activate(0, "normal")
    state.activate(1, "unscaled")
    # Unity time scale 0: delta_time 0, unscaled 1/30
    counts, _, _ = run_frame(state, settings, unity_time(0.0, unscaled=1 / 30))
    assert counts.tolist() == [0, 3]
    assert state.now_time_scale.tolist() == [0.0, 1.0]
    assert state.frame_delta_time.tolist() == [0.0, 1 / 30]


def test_team_time_scale_halves_the_steps():
    settings = SimulationTimeSettings()
    state = TeamTimeState.allocate(1)
    state.activate(0, time_scale=0.5)
    total = sum(int(run_frame(state, settings, unity_time(1 / 30))[0][0]) for _ in range(60))
    assert total == 90  # 2 s of frames at half speed = 1 s of simulation
    state.set_time_scale(0, 7.0)
    assert state.team_time_scale[0] == 1.0  # clamped to [0,1]


def test_unity_physics_mode_counts_fixed_updates():
    settings = SimulationTimeSettings()
    state = TeamTimeState.allocate(2)
    state.activate(0, "unity_physics")
    state.activate(1, "normal")
    tm = TimeManager(fixed_delta_time=0.02)  # 50 Hz physics under 144 fps rendering
    src = FixedFrameRate(144)
    steps = [0, 0]
    for _ in range(144):
        ut = tm.advance(src.next_delta())
        counts, _, _ = run_frame(state, settings, ut)
        assert state.frame_delta_time[0] == pytest.approx(ut.fixed_update_count * 0.02)
        if ut.fixed_update_count == 0:
            assert counts[0] == 0
        steps[0] += int(counts[0])
        steps[1] += int(counts[1])
    assert steps == [90, 90]
    # the player's live counter can override the planned count
    counts, _, _ = run_frame(state, settings, unity_time(0.0, fixed_count=0), fixed_count=3)
    assert state.frame_delta_time[0] == pytest.approx(0.06)


def test_suspended_team_time_does_not_advance():
    settings = SimulationTimeSettings()
    state = TeamTimeState.allocate(2)
    state.activate(0)
    state.activate(1)
    state.suspended[1] = True
    for _ in range(5):
        counts, _, _ = run_frame(state, settings, unity_time(1 / 30))
    assert counts.tolist() == [3, 0]
    assert state.time[1] == 0.0 and state.time[0] == pytest.approx(5 / 30)


def test_inactive_slots_are_untouched():
    settings = SimulationTimeSettings()
    state = TeamTimeState.allocate(3)
    state.activate(1)
    state.time[2] = 123.0
    run_frame(state, settings, unity_time(1 / 30))
    assert state.time[2] == 123.0 and state.update_count[2] == 0


# ----------------------------------------------------------------------------- counters
def test_counters_after_two_frames_by_hand():
    # 60 fps at 90 Hz, exact: frame 1 T=1/60 -> 1 step; frame 2 T=2/60 -> 2 steps
    settings = SimulationTimeSettings()
    state = TeamTimeState.allocate(1)
    state.activate(0)
    dt = 1 / 90
    _, _, interps = run_frame(state, settings, unity_time(1 / 60))
    assert state.update_count[0] == 1
    assert state.frame_update_time[0] == pytest.approx(1 / 60)
    assert state.frame_old_time[0] == 0.0
    assert interps[0] == [pytest.approx(dt / (1 / 60))]  # 2/3 of the way to this frame
    _, _, interps = run_frame(state, settings, unity_time(1 / 60))
    assert state.update_count[0] == 2
    assert state.old_time[0] == pytest.approx(1 / 60) and state.time[0] == pytest.approx(2 / 60)
    assert state.frame_old_time[0] == pytest.approx(1 / 60)
    assert state.old_update_time[0] == pytest.approx(dt)
    assert state.now_update_time[0] == pytest.approx(3 * dt)
    # steps at 2/90 and 3/90 between frames at 1/60 and 2/60
    assert interps[0] == [pytest.approx((2 * dt - 1 / 60) / (1 / 60)), pytest.approx(1.0)]


def test_float_drift_guard_when_no_time_was_added():
    settings = SimulationTimeSettings(timing="faithful")
    state = TeamTimeState.allocate(1)
    state.activate(0)
    state.time[0] = 1.0
    state.now_update_time[0] = 1.0 - 1 / 90 - 1e-12  # drifted behind by a hair
    counts, _, _ = run_frame(state, settings, unity_time(0.0))
    assert counts[0] == 0
    assert state.now_update_time[0] == pytest.approx(1.0 - 1 / 90 + 0.0001)


def test_truncation_not_floor_when_now_update_time_is_slightly_ahead():
    settings = SimulationTimeSettings(timing="faithful")
    state = TeamTimeState.allocate(1)
    state.activate(0)
    state.time[0] = 1.0
    state.now_update_time[0] = 1.0 + 1e-9
    counts, skips, _ = run_frame(state, settings, unity_time(1e-12))
    assert (counts[0], skips[0]) == (0, 0)


def test_time_reset_zeroes_the_six_counters():
    settings = SimulationTimeSettings()
    state = TeamTimeState.allocate(2)
    state.activate(0)
    state.activate(1)
    for _ in range(7):
        run_frame(state, settings, unity_time(1 / 30))
    state.reset([1])
    for name in ("time", "old_time", "now_update_time", "old_update_time", "frame_update_time",
                 "frame_old_time"):
        assert getattr(state, name)[1] == 0.0, name
        assert getattr(state, name)[0] > 0.0, name
    with pytest.raises(IndexError):
        state.reset([5])


def test_clocks_wrap_by_3600_s_past_7200_s():
    settings = SimulationTimeSettings()
    state = TeamTimeState.allocate(1)
    state.activate(0)
    for name in ("time", "old_time", "now_update_time", "old_update_time", "frame_update_time",
                 "frame_old_time"):
        getattr(state, name)[0] = 7199.99
    run_frame(state, settings, unity_time(1 / 30))
    assert state.time[0] == pytest.approx(7199.99 + 1 / 30 - 3600)
    assert state.now_update_time[0] == pytest.approx(7199.99 + 3 / 90 - 3600)
    assert state.old_time[0] == pytest.approx(7199.99 - 3600)


def test_resize_keeps_existing_teams():
    state = TeamTimeState.allocate(1)
    state.activate(0, "unscaled", 0.25)
    state.time[0] = 3.0
    state.resize(4)
    assert state.capacity == 4 and state.time[0] == 3.0
    assert state.update_mode.tolist() == [UPDATE_UNSCALED, 0, 0, 0]
    assert state.active.tolist() == [True, False, False, False]


# ----------------------------------------------------------------------------- twin comparison
@pytest.mark.parametrize("timing, f32, epsilon", [("faithful", False, 0.0),
                                                  ("faithful32", True, 0.0),
                                                  ("exact", False, 1e-6)])
def test_kernel_matches_naive_twin_on_random_frames(timing, f32, epsilon):
    rng = np.random.default_rng(11)
    settings = SimulationTimeSettings(frequency=int(rng.integers(30, 151)), max_steps_per_frame=3,
                                      global_time_scale=0.8, timing=timing)
    dt = settings.simulation_delta_time
    modes = [UPDATE_NORMAL, UPDATE_UNITY_PHYSICS, UPDATE_UNSCALED, UPDATE_NORMAL]
    scales = [1.0, 1.0, 0.6, 0.0]
    state = TeamTimeState.allocate(4)
    twins = []
    for t in range(4):
        state.activate(t, int(modes[t]), scales[t])
        twins.append(NaiveTeamClock(modes[t], scales[t], f32=f32, epsilon=epsilon))
    tm = TimeManager(fixed_delta_time=0.02, time_scale=0.9)
    deltas = rng.choice([1 / 240, 1 / 144, 1 / 90, 1 / 60, 1 / 45, 1 / 30, 0.1, 0.5], size=400)
    for i, d in enumerate(deltas):
        if i == 200:
            tm.time_scale = 0.0  # a pause: exercises the drift guard and the unscaled team
        ut = tm.advance(float(np.float32(d)) if f32 else float(d))
        counts, skips, interps = run_frame(state, settings, ut)
        for t, twin in enumerate(twins):
            c, s, fd, sc = twin.frame(ut, dt, 3, settings.global_time_scale)
            assert (counts[t], skips[t]) == (c, s), (i, t)
            assert state.time[t] == twin.time
            assert state.now_update_time[t] == twin.now_update_time
            assert state.frame_old_time[t] == twin.frame_old_time
            assert interps[t] == twin.interpolations


# ----------------------------------------------------------------------------- invariants
from hypothesis import given, settings as hyp_settings, strategies as st  # noqa: E402


@hyp_settings(max_examples=60, deadline=None)
@given(deltas=st.lists(st.floats(min_value=1e-4, max_value=0.5), min_size=1, max_size=60),
       frequency=st.integers(30, 150), max_steps=st.integers(1, 5),
       scale=st.floats(min_value=0.0, max_value=1.0))
def test_time_is_conserved_and_now_update_time_lags_by_less_than_a_step(deltas, frequency,
                                                                          max_steps, scale):
    settings = SimulationTimeSettings(frequency=frequency, max_steps_per_frame=max_steps,
                                      global_time_scale=scale)
    dt = settings.simulation_delta_time
    state = TeamTimeState.allocate(1)
    state.activate(0)
    added = steps = skipped = 0
    for d in deltas:
        counts, skips, interps = run_frame(state, settings, unity_time(d))
        added += d * scale
        steps += int(counts[0])
        skipped += int(skips[0])
        assert 0 <= counts[0] <= max_steps
        assert skips[0] == 0 or counts[0] == max_steps  # time is dropped only beyond the cap
        lag = state.time[0] - state.now_update_time[0]
        assert -1e-6 * dt - 1e-12 <= lag < dt
        r = interps[0]
        assert all(0.0 <= x <= 1.0 for x in r) and r == sorted(r)
        if r:  # the last step sits less than one step before the frame
            span = state.time[0] - state.frame_old_time[0]
            assert (1.0 - r[-1]) * span < dt + 1e-12
    # every whole step of added time was either run or dropped, none invented
    assert abs((steps + skipped) - added / dt) <= 1.0 + 1e-6
