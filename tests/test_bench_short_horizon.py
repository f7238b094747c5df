"""The short-horizon (re-synchronised) error of ``magica-py bench`` (bench/short_horizon.py,
docs/BENCHMARKS.md): zero for a candidate identical to its reference (a restored state gives
the same bits: every array of the state, at a reference's own frequency, in quality mode too),
falling as the candidate's frequency rises on a pendulum, and a per-family reference check
whose verdicts (resolved / not resolved / unresolvable) follow the stated rule, the bench
failing loudly when a converging reference is too coarse."""
import math

import numpy as np
import pytest

from magica_py.bench import short_horizon as S
from magica_py.bench.variants import Variant, resolve_scene_path
from solver_scenes import pendulum_yaml

FC = {"solver.rate_mode": "frequency_consistent"}


def pendulum(tmp_path, duration=1.0):
    path = tmp_path / "pendulum.yaml"
    path.write_text(pendulum_yaml(math.radians(40.0), fps=60, duration=duration, solver="rate_mode: frequency_consistent"))
    return Variant("pendulum", str(path), parameters=dict(FC))


def test_windows_tile_the_run_and_last_a_quarter_second():
    assert S.window_frames(60) == 15 and S.window_frames(144) == 36 and S.window_frames(30) == 8
    assert S.window_starts(61, 15).tolist() == [0, 15, 30, 45]
    assert S.window_starts(14, 15).tolist() == []


def test_a_candidate_identical_to_its_reference_has_zero_error_in_every_window():
    v = Variant("tail", resolve_scene_path("tail_orbit"), parameters=dict(FC), frequency=90, duration=0.75)
    run, ref = S.run_reference(v, 15)
    assert len(ref.snapshots) == 3 and ref.ends.tolist() == [14, 29, 44]
    errors = S.candidate_window_errors(v, ref)
    assert errors.rms.tolist() == [0.0, 0.0, 0.0] and errors.worst == 0.0
    # the same candidate without the restores has moved on: the windows do restart it
    assert np.abs(run.positions[14] - run.positions[29]).max() > 1e-3


def test_the_short_horizon_error_falls_as_the_candidate_frequency_rises(tmp_path):
    base = pendulum(tmp_path)
    _run, ref = S.run_reference(base.with_(frequency=1440), S.window_frames(60))
    errors = [S.candidate_window_errors(base.with_(frequency=f), ref).mean_rms for f in (45, 90, 180)]
    assert errors[0] > 1.5 * errors[1] > 0 and errors[1] > 1.5 * errors[2] > 0, errors


def state_differences(a, b, path=""):
    """Paths where two snapshots' parts differ (arrays bit for bit; the player's metric totals,
    wall-clock timings among them, are not state)."""
    if isinstance(a, dict):
        keys = set(a) | set(b)
        return [d for k in sorted(keys, key=str) if k != "metric_totals"
                for d in state_differences(a.get(k), b.get(k), f"{path}/{k}")]
    if isinstance(a, (list, tuple)):
        if len(a) != len(b):
            return [path]
        return [d for i, (x, y) in enumerate(zip(a, b)) for d in state_differences(x, y, f"{path}[{i}]")]
    if isinstance(a, np.ndarray):
        same = isinstance(b, np.ndarray) and a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()
        return [] if same else [path]
    return [] if a == b else [path]


@pytest.mark.parametrize("parameters, frequency", [({"solver.mode": "quality"}, 2880), (dict(FC), 1440)])
def test_a_restore_at_the_reference_frequency_reproduces_every_array_of_the_next_snapshot(parameters, frequency):
    """Restore + the same frequency = the same bits, for the whole state (not only the bones the
    error reads): a candidate restarted from window k's snapshot (keep_model=True, as the bench
    does) and run to window k+1's start holds exactly the reference's snapshot there. A state
    the capture missed would put a floor under every short-horizon error."""
    v = Variant("tail", resolve_scene_path("tail_orbit"), parameters=dict(parameters), frequency=frequency,
                duration=0.2)
    _run, ref = S.run_reference(v, 3)
    assert len(ref.snapshots) == 4
    from magica_py.bench.variants import prepare

    candidate = prepare(v)
    for k in range(len(ref.snapshots) - 1):
        candidate.player.restore(ref.snapshots[k], keep_model=True)
        for _ in range(ref.frames_per_window):
            candidate.player.step()
        after = candidate.player.capture()
        assert after.frame == ref.snapshots[k + 1].frame
        assert state_differences(after.parts, ref.snapshots[k + 1].parts) == [], k
    # the oracle is not vacuous: the state does move between the windows
    assert state_differences(ref.snapshots[1].parts, ref.snapshots[2].parts)


def test_the_reference_check_fails_when_the_residual_is_not_ten_times_below_every_error():
    good = S.resolution_check("s/ref", 0.001, {"a 90 Hz": 0.05, "a 180 Hz": 0.011})
    assert good.ok and good.smallest_of == "a 180 Hz" and good.margin == pytest.approx(11.0)
    bad = S.resolution_check("s/ref", 0.002, {"a 90 Hz": 0.05, "a 180 Hz": 0.011})
    assert not bad.ok and "NOT RESOLVED" in bad.message() and "a 180 Hz" in bad.message()
    assert not S.resolution_check("s/ref", 0.001, {"a": math.nan}).ok      # nothing to vouch for


@pytest.mark.parametrize("residual, half, smallest, verdict", [
    (0.001, 0.002, 0.011, S.RESOLVED),        # 11x below, first-order reference (order 1)
    (0.001, math.nan, 0.011, S.RESOLVED),     # order not measured: the ratio alone
    (0.002, 0.004, 0.011, S.NOT_RESOLVED),    # 5.5x below, the reference converges: a finer one would do
    (0.002, 0.0025, 0.011, S.UNRESOLVABLE),   # 5.5x below, order 0.32: a floor, no finer reference helps
    (0.001, 0.0012, 0.011, S.UNRESOLVABLE),   # 11x below but a floor, and 1.2 x 10 > 11: not vouched for
    (0.001, 0.0011, 0.02, S.RESOLVED),        # a floor, but the half-frequency residual is 18x below too
    (0.002, 0.001, 0.05, S.RESOLVED),         # residual grows with the frequency, both 25x / 50x below
])
def test_the_verdict_follows_the_stated_rule(residual, half, smallest, verdict):
    """Oracle: resolved <=> residual <= 0.1 smallest and (log2(half / residual) >= 0.5 or
    half <= 0.1 smallest); otherwise unresolvable when log2(half / residual) < 0.5, else not
    resolved. Rows of the sweep are judged by the same rule."""
    check = S.resolution_check("s/f", residual, {"f 720 Hz": smallest, "f 90 Hz": 10 * smallest}, half_residual=half)
    assert check.verdict == verdict and check.ok == (verdict == S.RESOLVED)
    assert check.smallest == smallest and check.smallest_of == "f 720 Hz"
    expected_order = math.log2(half / residual) if math.isfinite(half) else math.nan
    assert check.order == pytest.approx(expected_order, nan_ok=True)
    assert S.point_resolved(smallest, residual, half) == (verdict == S.RESOLVED)
    assert verdict.upper() in check.message() or verdict in check.message()


def test_the_exit_status_fails_on_references_too_coarse_and_reports_unresolvable_ones(capsys):
    from magica_py.bench.cli import report_verdicts

    resolved = S.resolution_check("a/f", 0.001, {"x": 0.05}, half_residual=0.002)
    coarse = S.resolution_check("a/g", 0.002, {"x": 0.011}, half_residual=0.004)
    floor = S.resolution_check("a/h", 0.002, {"x": 0.011}, half_residual=0.0025)
    assert report_verdicts([resolved]) == 0 and capsys.readouterr().err == ""
    assert report_verdicts([resolved, floor]) == 0
    err = capsys.readouterr().err
    assert "UNRESOLVABLE" in err and "a/h" in err and "a/f" not in err
    assert report_verdicts([resolved, floor], strict=True) == 1
    assert report_verdicts([resolved, coarse, floor]) == 1
    assert "NOT RESOLVED" in capsys.readouterr().err


def test_the_bench_fails_loudly_with_a_reference_that_does_not_resolve(tmp_path, monkeypatch, capsys):
    """A 60 Hz 'reference' checked at 90 Hz (and 30 Hz) cannot vouch for a 45 Hz candidate's
    error, and it converges (a finer reference would do): the bench still writes its report,
    says so first in bench.md and on stderr, and exits 1."""
    from magica_py.bench import reference
    from magica_py.bench.cli import main_bench

    monkeypatch.setattr(reference, "REFERENCE_FREQUENCY", 60)
    monkeypatch.setattr(reference, "CHECK_FREQUENCY", 90)
    scene = pendulum(tmp_path, duration=0.5)
    code = main_bench(["--scenes", scene.scene, "--frequencies", "45", "--families", "frequency_consistent",
                       "--repeats", "1", "--skip", "fps,numpy,features,crowd", "--out", str(tmp_path / "r"),
                       "--quiet"])
    assert code == 1
    text = (tmp_path / "r" / "bench.md").read_text()
    check = text.index("## Reference check")
    assert "NOT RESOLVED (the reference converges" in text[check:text.index("## Definitions")]
    assert "| NO |" in text and "| not resolved (" in text
    assert "NOT RESOLVED" in capsys.readouterr().err
