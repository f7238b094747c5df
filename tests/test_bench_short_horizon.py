"""The short-horizon (re-synchronised) error of ``magica-py bench`` (bench/short_horizon.py,
docs/BENCHMARKS.md): zero for a candidate identical to its reference (a restored state gives
the same bits), falling as the candidate's frequency rises on a pendulum, and a reference check
that fails loudly when the reference does not resolve the errors."""
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


def test_the_reference_check_fails_when_the_residual_is_not_ten_times_below_every_error():
    good = S.resolution_check("s/ref", 0.001, {"a 90 Hz": 0.05, "a 180 Hz": 0.011})
    assert good.ok and good.smallest_of == "a 180 Hz" and good.margin == pytest.approx(11.0)
    bad = S.resolution_check("s/ref", 0.002, {"a 90 Hz": 0.05, "a 180 Hz": 0.011})
    assert not bad.ok and "DOES NOT RESOLVE" in bad.message() and "a 180 Hz" in bad.message()
    assert not S.resolution_check("s/ref", 0.001, {"a": math.nan}).ok      # nothing to vouch for


def test_the_bench_fails_loudly_with_a_reference_that_does_not_resolve(tmp_path, monkeypatch, capsys):
    """A 60 Hz 'reference' checked at 90 Hz cannot vouch for a 45 Hz candidate's error: the
    bench still writes its report, says so first in bench.md and on stderr, and exits 1."""
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
    assert "DOES NOT RESOLVE" in text[check:text.index("## Definitions")]
    assert "| NO |" in text
    assert "DOES NOT RESOLVE" in capsys.readouterr().err
