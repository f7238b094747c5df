"""Frame-time sources and the Unity-semantics TimeManager (magica_py/runtime/clock.py)."""
from __future__ import annotations

import math
import random
from fractions import Fraction

import numpy as np
import pytest

from magica_py.runtime.clock import (
    FixedFrameRate,
    FrameTimeList,
    RealClock,
    TimeManager,
    time_from_settings,
)


def exact_fixed_counts(deltas, fixed_dt, max_dt, scale=1):
    """Oracle in exact rational arithmetic (fractions): Unity's accumulation with the cap."""
    max_dt = max(max_dt, fixed_dt)
    time = Fraction(0)
    fixed = Fraction(0)
    out = []
    for raw in deltas:
        time += min(raw, max_dt) * scale
        if time - fixed > max_dt:
            fixed = time - max_dt
        k = (time - fixed) // fixed_dt
        fixed += k * fixed_dt
        out.append(int(k))
    return out


def test_fixed_frame_rate_returns_one_over_fps():
    src = FixedFrameRate(60)
    assert [src.next_delta() for _ in range(3)] == [1 / 60] * 3


@pytest.mark.parametrize("bad", [0, -30, float("nan"), float("inf"), "fast"])
def test_fixed_frame_rate_rejects_bad_fps(bad):
    with pytest.raises(ValueError, match="fps"):
        FixedFrameRate(bad)


def test_frame_time_list_cycles():
    src = FrameTimeList([0.01, 0.02, 0.5])
    assert [src.next_delta() for _ in range(7)] == [0.01, 0.02, 0.5, 0.01, 0.02, 0.5, 0.01]
    src.reset()
    assert src.next_delta() == 0.01


def test_frame_time_list_without_cycle_continues_with_then_or_raises():
    src = FrameTimeList([1.0], cycle=False, then=1 / 30)
    assert [src.next_delta() for _ in range(3)] == [1.0, 1 / 30, 1 / 30]
    src = FrameTimeList([0.1, 0.2], cycle=False)
    src.next_delta(), src.next_delta()
    with pytest.raises(IndexError, match="exhausted at frame 2"):
        src.next_delta()


@pytest.mark.parametrize("times, where", [([], "non-empty"), ([0.1, -0.2], r"frame_times\[1\]"),
                                          ([0.1, float("nan")], r"frame_times\[1\]")])
def test_frame_time_list_rejects_bad_input(times, where):
    with pytest.raises(ValueError, match=where):
        FrameTimeList(times)


def test_real_clock_measures_and_caps_to_target_fps():
    now = [0.0]
    slept = []

    def fake_now():
        return now[0]

    def fake_sleep(s):
        slept.append(s)
        now[0] += s

    clock = RealClock(first_delta=0.05, target_fps=50, now=fake_now, sleep=fake_sleep)
    assert clock.next_delta() == 0.05
    now[0] += 0.03  # a slow frame: measured as is
    assert clock.next_delta() == pytest.approx(0.03)
    now[0] += 0.005  # a fast frame: the clock sleeps up to 1/50 s
    assert clock.next_delta() == pytest.approx(0.02)
    assert slept == [pytest.approx(0.015)]


def test_delta_time_is_clamped_then_scaled_and_unscaled_is_raw():
    tm = TimeManager(fixed_delta_time=0.02, maximum_delta_time=0.1, time_scale=0.5)
    t = tm.advance(1.0)  # a 1 s hitch
    assert t.unscaled_delta_time == 1.0
    assert t.delta_time == pytest.approx(0.05)  # min(1.0, 0.1) * 0.5
    assert t.time == pytest.approx(0.05)
    assert t.unscaled_time == 1.0
    t = tm.advance(0.04)
    assert t.delta_time == pytest.approx(0.02)
    assert t.time == pytest.approx(0.07)
    assert t.unscaled_time == pytest.approx(1.04)
    assert t.frame_count == 2


def test_fixed_update_count_follows_fixed_delta_accumulation():
    # 60 fps with fixedDeltaTime 0.02: 50 fixed steps per 60 frames; 1 s of frames gives exactly 50
    tm = TimeManager(fixed_delta_time=0.02)
    counts = [tm.advance(1 / 60).fixed_update_count for _ in range(60)]
    assert sum(counts) == 50
    assert set(counts) == {0, 1}
    # the fixed clock never runs ahead of scaled time and lags it by less than one fixed step
    assert 0 <= tm.time - tm.fixed_time < 0.02 + 1e-12


def test_fixed_updates_at_50_fps_are_exactly_one_per_frame():
    tm = TimeManager(fixed_delta_time=0.02)
    assert [tm.advance(0.02).fixed_update_count for _ in range(500)] == [1] * 500


def test_fixed_updates_at_20_fps_are_two_or_three_per_frame_summing_to_fixed_rate():
    # 20 fps with fixedDeltaTime 1/60 -> 3 per frame
    tm = TimeManager(fixed_delta_time=1 / 60)
    assert [tm.advance(0.05).fixed_update_count for _ in range(100)] == [3] * 100


def test_fixed_updates_match_independent_accumulation_on_variable_frames():
    rng = random.Random(3)
    choices = [Fraction(1, 144), Fraction(1, 60), Fraction(1, 30), Fraction(1, 20), Fraction(1, 5),
               Fraction(9, 10)]
    deltas = [rng.choice(choices) for _ in range(300)]
    tm = TimeManager(fixed_delta_time=0.02, maximum_delta_time=1 / 3)
    got = [tm.advance(float(d)).fixed_update_count for d in deltas]
    expected = exact_fixed_counts(deltas, Fraction(1, 50), Fraction(1, 3))
    assert got == expected
    assert sum(expected) > 300 and max(expected) == 16  # the 0.9 s hitches hit the cap


def test_hitch_runs_at_most_maximum_delta_over_fixed_delta_fixed_updates():
    tm = TimeManager(fixed_delta_time=0.02, maximum_delta_time=1 / 3)
    tm.advance(0.01)
    t = tm.advance(5.0)
    assert t.delta_time == pytest.approx(1 / 3)
    assert t.fixed_update_count == 16  # floor(0.3333 / 0.02)


def test_time_scale_above_one_is_capped_by_maximum_delta_time():
    tm = TimeManager(fixed_delta_time=0.02, maximum_delta_time=0.1, time_scale=4.0)
    t = tm.advance(0.1)
    assert t.delta_time == pytest.approx(0.4)
    assert t.fixed_update_count == 5  # maximum_delta_time / fixed_delta_time, not 20


def test_time_scale_zero_freezes_scaled_time_and_fixed_updates():
    tm = TimeManager(time_scale=0.0)
    for _ in range(10):
        t = tm.advance(1 / 30)
        assert t.delta_time == 0.0 and t.fixed_update_count == 0
    assert t.time == 0.0
    assert t.unscaled_time == pytest.approx(10 / 30)


def test_maximum_delta_time_is_never_below_fixed_delta_time():
    tm = TimeManager(fixed_delta_time=0.05, maximum_delta_time=0.01)
    assert tm.maximum_delta_time == 0.05
    assert tm.advance(1.0).delta_time == 0.05


def test_changing_fixed_delta_time_keeps_the_fixed_clock_continuous():
    tm = TimeManager(fixed_delta_time=0.02)
    for _ in range(10):
        tm.advance(0.02)
    before = tm.fixed_time
    tm.fixed_delta_time = 0.01
    assert tm.fixed_time == pytest.approx(before)
    assert tm.advance(0.02).fixed_update_count == 2


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf")])
def test_time_scale_rejects_negative_and_non_finite(bad):
    with pytest.raises(ValueError, match="time_scale"):
        TimeManager(time_scale=bad)


def test_time_from_settings_picks_the_source_and_unity_parameters():
    src, tm = time_from_settings({"fps": 30, "fixed_delta_time": 0.01, "time_scale": 0.5})
    assert isinstance(src, FixedFrameRate) and src.delta == 1 / 30
    assert tm.fixed_delta_time == 0.01 and tm.time_scale == 0.5
    assert math.isclose(tm.maximum_delta_time, 1 / 3)
    src, _ = time_from_settings({"frame_times": [0.1, 0.2]})
    assert isinstance(src, FrameTimeList) and src.times == (0.1, 0.2)
    src, _ = time_from_settings({"frame_times": [0.1, 0.2], "frame_times_cycle": False})
    assert [src.next_delta() for _ in range(4)] == [0.1, 0.2, 0.2, 0.2]
    src, _ = time_from_settings({"clock": "realtime", "fps": 50})
    assert isinstance(src, RealClock) and src.first_delta == 1 / 50


def test_unity_time_is_immutable_and_lists_its_fields_in_order():
    t = TimeManager().advance(1.0 / 60.0)
    assert t._fields == ("frame_count", "delta_time", "unscaled_delta_time", "time", "unscaled_time",
                         "fixed_delta_time", "fixed_time", "fixed_update_count", "time_scale",
                         "maximum_delta_time")
    with pytest.raises(AttributeError):
        t.time = 2.0


def test_frame_times_that_are_not_python_floats_give_the_same_clock():
    a, b = TimeManager(), TimeManager()
    for raw in (1 / 60, 1 / 30, 0.5, 1 / 144):
        assert a.advance(raw) == b.advance(np.float64(raw))
    for bad in (float("nan"), float("inf"), 0.0, -1 / 60):
        with pytest.raises(ValueError, match="frame time"):
            TimeManager().advance(bad)
