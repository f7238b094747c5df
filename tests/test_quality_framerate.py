"""Quality mode is frame-rate independent (issue 8 item 1): the tip positions of the tail and
character showcases at 30 / 60 / 144 / 240 fps agree at the times every run has a frame.

Faithful mode keeps MagicaCloth2's once-per-frame smoothing and display filter: its spread is
tens of % of the tail (docs/solver.md Appendix 4), which the test also checks so that it can fail.
"""
import importlib.util
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]


def bench_quality():
    spec = importlib.util.spec_from_file_location("bench_quality", ROOT / "benchmarks" / "bench_quality.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def bq(tmp_path_factory):
    module = bench_quality()
    module.SCENES = module.scenes(tmp_path_factory.mktemp("quality_scenes"))
    return module


def spreads(bq, name, params, duration):
    path, raw, _ = bq.SCENES[name]
    recs, length = bq.frame_rate_records((path, raw, duration), params)
    return (100 * bq.spread_at_common_times(recs, length),
            100 * bq.spread_at_common_times(recs, length, start=1.5))


def jumping_tail_orbit(folder):
    """``configs/tail_orbit.yaml`` with the root resting facing +Z: its orbit (``face_path``)
    turns it by 180 degrees at the first frame, a jump beyond the teleport rotation threshold
    that keeps MagicaCloth2's first-frame reset."""
    import yaml

    doc = yaml.safe_load((ROOT / "configs" / "tail_orbit.yaml").read_text())
    doc["scene"]["name"] = "tail_orbit_jump"
    doc["rigs"][0]["bones"][0]["euler"] = [0, 0, 0]
    doc.pop("output", None)
    path = folder / "tail_orbit_jump.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return str(path)


def test_tail_tip_spread_across_frame_rates_is_under_half_a_percent(bq):
    """The committed tail rests in its t = 0 pose: quality mode resets at the build (t = 0), so
    every frame rate starts from the same state and the spread is small from the first frame on."""
    whole, late = spreads(bq, "tail_orbit", bq.QUALITY, 2.5)
    faithful_whole, faithful_late = spreads(bq, "tail_orbit", bq.FAITHFUL, 2.5)
    assert whole <= 0.5           # measured 0.27 % (4 s run, python benchmarks/bench_quality.py --part spread)
    assert late <= 0.5            # measured 0.26 % (1 s on)
    assert faithful_late >= 10.0  # MagicaCloth2's per-frame smoothing: 17.8 %
    assert whole < faithful_whole / 10


def test_tail_whose_first_frame_jumps_keeps_the_first_frame_reset_and_settles_within_half_a_percent(bq, tmp_path):
    """A root that turns 180 degrees at the first frame cannot be treated as motion from the
    build pose: each frame rate resets at its own first frame (1/30 s against 1/240 s), and the
    lightly damped tail carries that difference for about a second."""
    path = jumping_tail_orbit(tmp_path)
    recs, length = bq.frame_rate_records((path, {}, 2.5), bq.QUALITY)
    whole = 100 * bq.spread_at_common_times(recs, length)
    late = 100 * bq.spread_at_common_times(recs, length, start=1.5)
    assert whole <= 1.0           # measured 0.83 % (start-up transient)
    assert late <= 0.5            # measured 0.31 % (1 s on)


def test_build_reset_is_used_only_when_the_first_frame_continues_the_build_pose(bq, tmp_path):
    """The committed tail_orbit continues its build pose; the jumping variant turns its root by
    180 degrees at the first frame (beyond the 90 degree teleport rotation threshold) and keeps
    the first-frame reset. Faithful mode always keeps it."""
    from magica_py.bench.variants import prepare

    flags = {}
    for name, path in (("jump", jumping_tail_orbit(tmp_path)), ("matched", bq.SCENES["tail_orbit"][0])):
        for params in (bq.QUALITY, bq.FAITHFUL):
            p = prepare(bq.variant((path, {}, 0.1), "first", params, fps=60))
            p.player.step()
            flags[name, bool(params)] = int(p.system.teams.ramp_from_build[0])
            assert p.system._hierarchy.build_pose_pending[0] == 0
    assert flags == {("jump", True): 0, ("jump", False): 0, ("matched", True): 1, ("matched", False): 0}


def test_character_tip_spread_across_frame_rates_is_under_half_a_percent(bq):
    whole, _late = spreads(bq, "character_walk", bq.QUALITY, 2.5)
    faithful_whole, _ = spreads(bq, "character_walk", bq.FAITHFUL, 2.5)
    assert whole <= 0.25          # measured 0.13 % over 2.5 s (it stands still at its start)
    assert faithful_whole >= 4.0  # 8.1 %


def test_common_time_spread_oracle():
    """The spread helper on hand-made records: two runs differing by 3 mm at t = 1/3 s only."""
    import numpy as np

    bq_ = bench_quality()
    t30 = np.arange(1, 16) / 30.0
    t60 = np.arange(1, 31) / 60.0
    tips30 = np.zeros((15, 1, 3))
    tips60 = np.zeros((30, 1, 3))
    tips60[19, 0, 0] = 0.003       # t = 20/60 = 1/3 s, a common time
    tips60[20, 0, 0] = 0.5         # t = 21/60: not a common time, ignored
    assert bq_.spread_at_common_times([(t30, tips30), (t60, tips60)], 0.3) == pytest.approx(0.01)
