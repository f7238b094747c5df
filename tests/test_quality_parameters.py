"""Quality-mode parameters (issue 8): validation, and the per-team rows they produce.

Faithful mode must leave every quality column at its "off" value (the kernels then take
exactly MagicaCloth2's paths); ``solver.mode: quality`` turns on the measured defaults.
"""
import math

import pytest

from magica_py.params import ParameterError, resolve_parameters
from magica_py.solver.center import mean_velocity_weight, smoothing_time_constant
from magica_py.solver.parameters import INEXTENSIBILITY, QUALITY_AUTO, allocate_parameters, write_row


def row(**overrides):
    table = allocate_parameters(1)
    write_row(table, 0, resolve_parameters("tail", overrides, where="test"))
    return table


def test_faithful_mode_leaves_every_quality_column_off():
    t = row()
    assert t.rate_mode[0] == 0
    for name in ("quality", "time_based_smoothing", "inextensibility", "distance_full_velocity",
                 "collision_last"):
        assert getattr(t, name)[0] == 0, name


def test_quality_mode_turns_on_the_measured_defaults():
    t = row(**{"solver.mode": "quality"})
    assert t.quality[0] == 1
    assert t.rate_mode[0] == 1                       # implies frequency-consistent rates
    assert t.time_based_smoothing[0] == 1
    assert INEXTENSIBILITY[t.inextensibility[0]] == QUALITY_AUTO["solver.inextensibility"] == "ftl_edges"
    assert t.distance_full_velocity[0] == 1
    assert t.collision_last[0] == 1
    assert t.distance_iterations[0] == 2
    assert t.tether_limit[0] == pytest.approx(0.02)
    assert t.restoration_drift[0] == 1


def test_each_switch_overrides_the_quality_default():
    t = row(**{"solver.mode": "quality", "solver.inextensibility": "tether", "solver.collision_last": "disabled",
               "solver.time_based_smoothing": "disabled", "solver.distance_velocity": "attenuated"})
    assert INEXTENSIBILITY[t.inextensibility[0]] == "tether"
    assert t.collision_last[0] == 0 and t.time_based_smoothing[0] == 0 and t.distance_full_velocity[0] == 0
    # a switch can also be used alone in faithful mode
    t = row(**{"solver.collision_last": "enabled"})
    assert t.quality[0] == 0 and t.collision_last[0] == 1 and t.restoration_drift[0] == 0


def test_bad_quality_values_name_the_path_and_the_choices():
    with pytest.raises(ParameterError) as e:
        resolve_parameters("tail", {"solver.inextensibility": "rope"}, where="cloths.tail.parameters")
    assert "cloths.tail.parameters.solver.inextensibility" in str(e.value) and "ftl_edges" in str(e.value)
    with pytest.raises(ParameterError) as e:
        resolve_parameters("tail", {"solver.tether_limit": 0.5}, where="cloths.tail.parameters")
    assert "out of range" in str(e.value)
    with pytest.raises(ValueError, match="distance_iterations"):
        row(**{"solver.distance_iterations": 2.5})


def test_smoothing_time_constant_reproduces_the_per_frame_ratio_at_90_fps():
    for s in (0.1, 0.4, 0.9):
        a = (1.0 - s) ** 3 * 0.99 + 0.01
        tau = smoothing_time_constant(s)
        assert 1.0 - math.exp(-(1.0 / 90.0) / tau) == pytest.approx(a, rel=1e-12)
    assert smoothing_time_constant(0.0) == 0.0       # a = 1: no smoothing
    assert smoothing_time_constant(0.4) == pytest.approx(0.043849, abs=1e-6)   # 44 ms


def test_mean_velocity_weight_is_the_time_average_of_the_ramp():
    # ramp w(t) = min(1, w0 + t/stab), averaged over [0, span]: numeric oracle
    for w0, stab, span in ((0.0, 0.1, 0.0333), (0.0, 0.1, 0.25), (0.4, 0.1, 0.05), (0.9, 0.3, 0.004)):
        n = 200000
        ts = (range(n))
        avg = sum(min(1.0, w0 + (i + 0.5) * span / n / stab) for i in ts) / n
        assert mean_velocity_weight(w0, stab, span) == pytest.approx(avg, abs=1e-6)
    assert mean_velocity_weight(0.3, 0.0, 0.01) == 1.0
    assert mean_velocity_weight(0.3, 0.1, 0.0) == 0.3


def test_time_based_smoothing_does_not_depend_on_how_time_is_cut_into_frames():
    """Constant component velocity: the felt displacement over 1/30 s is the same whether the
    time comes as one frame or as 8 frames of 1/240 s, and matches the exact filter integral."""
    import numpy as np

    from magica_py.solver import state as st
    from magica_py.solver.center import time_based_smoothing

    def smoothed(ts):   # the lane's filter state (lane 0 of block 0)
        return st.TEAM.view(ts, "smoothing_velocity", 0, 0)[0]

    v = np.array([1.5, 0.0, -0.5])
    s = 0.4
    tau = smoothing_time_constant(s)
    totals = []
    for frames in (1, 4, 8):
        ts = st.TEAM.allocate(1)
        h = (1.0 / 30.0) / frames
        felt = np.zeros(3)
        for _ in range(frames):
            felt += np.array(time_based_smoothing(ts, 0, 0, tuple(v * h), h, s, -1.0))
        totals.append(felt)
        # filter state after 1/30 s: v (1 - exp(-t/tau))
        assert smoothed(ts) == pytest.approx(v * (1 - math.exp(-(1 / 30) / tau)), abs=1e-12)
    T = 1.0 / 30.0
    exact = v * (T - tau * (1.0 - math.exp(-T / tau)))     # integral of v (1 - exp(-t/tau))
    for felt in totals:
        assert felt == pytest.approx(exact, abs=1e-12)
    # the speed limit caps the input velocity (m/s)
    ts = st.TEAM.allocate(1)
    time_based_smoothing(ts, 0, 0, tuple(v * 10.0), 10.0, s, 1.0)
    assert np.linalg.norm(smoothed(ts)) == pytest.approx(1.0, rel=1e-9)


def test_switches_written_in_yaml_are_not_read_as_booleans():
    """``on``/``off`` are YAML booleans: the switches use enabled/disabled, and a boolean is
    rejected with the accepted words in the message."""
    import yaml

    doc = yaml.safe_load("solver.collision_last: disabled\nsolver.time_based_smoothing: enabled\n")
    params = resolve_parameters("tail", {**doc, "solver.mode": "quality"}, where="cloths.tail.parameters")
    table = allocate_parameters(1)
    write_row(table, 0, params)
    assert table.collision_last[0] == 0 and table.time_based_smoothing[0] == 1
    with pytest.raises(ParameterError, match="auto, enabled, disabled"):
        resolve_parameters("tail", yaml.safe_load("solver.collision_last: off"), where="cloths.tail.parameters")


def test_extended_range_allows_reference_frequencies_and_keeps_the_magica_clamp_by_default():
    from magica_py.runtime.team_time import SimulationTimeSettings

    assert SimulationTimeSettings(frequency=360).frequency == 150            # MagicaCloth2's clamp
    assert SimulationTimeSettings(max_steps_per_frame=12).max_steps_per_frame == 5
    s = SimulationTimeSettings(frequency=360, max_steps_per_frame=12, extended_range=True)
    assert (s.frequency, s.max_steps_per_frame) == (360, 12)
    assert SimulationTimeSettings(frequency=5000, extended_range=True).frequency == 2880
    s = SimulationTimeSettings.from_scene_settings({"simulation_frequency": 720, "extended_range": True})
    assert s.frequency == 720 and s.simulation_delta_time == pytest.approx(1 / 720)
