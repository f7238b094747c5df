"""Every command that simulates says when a first run starts compiling the solver, before the
compile starts, leaves the compile out of the times it reports and reports it apart (issue 15
item 2; ``magica-py run`` and ``watch`` are pinned in test_cli_frictions.py and test_watch.py).

A compile is made to happen inside a command's frames by wrapping ``Player.step`` so that its
first call compiles a fresh numba function (``cache=False``: compiled in every test run, even
with a warm kernel cache)."""
from __future__ import annotations

import time

import numba
import numpy as np
import pytest

from magica_py.runner import COMPILE_MESSAGE, Stopwatch, compile_text


def fresh_function():
    """A new numba function, compiled at its first call (``cache=False``), whose compile takes
    well over the 0.05 s below which the summaries leave a compile unreported (sorting and a
    median: some tenths of a second)."""
    @numba.njit(cache=False)
    def fresh(n):
        a = np.arange(n * 1.0)
        return np.sort(a)[::-1][0] + np.median(a)

    return fresh


@pytest.fixture
def compile_in_the_first_frame(monkeypatch):
    """``Player.step`` compiles a fresh function on its first call; returns the call log."""
    from magica_py.runtime.player import Player

    fresh = fresh_function()
    calls = []
    step = Player.step

    def step_that_compiles(self):
        if not calls:
            assert fresh(3) == 3.0
        calls.append(1)
        return step(self)

    monkeypatch.setattr(Player, "step", step_that_compiles)
    return calls


class _Watch:
    """Stands in for a CompileWatch: ``seconds`` is set by the test."""
    seconds = 0.0


def test_a_stopwatch_leaves_out_the_compiles_inside_its_block():
    watch = _Watch()
    watch.seconds = 5.0                  # compiles before the block do not count
    with Stopwatch(watch) as block:
        time.sleep(0.05)
        watch.seconds += 0.03            # a 0.03 s compile inside the block
        assert 0.015 <= block.elapsed() < 0.5   # so far, less the compile so far
        watch.seconds += 10.0
        assert block.elapsed() == 0.0    # never negative
        watch.seconds -= 10.0
    assert block.compiled == pytest.approx(0.03)
    assert 0.015 <= block.seconds < 0.5
    with Stopwatch(watch) as bigger:
        watch.seconds += 100.0           # more compile than wall time: never negative
    assert bigger.seconds == 0.0 and bigger.compiled == pytest.approx(100.0)
    with Stopwatch() as plain:           # no watch: the plain wall time
        time.sleep(0.01)
    assert plain.compiled == 0.0 and plain.seconds >= 0.009


def test_the_compile_is_reported_only_when_something_compiled():
    assert compile_text(0.0) == "" and compile_text(0.04) == ""
    assert compile_text(42.06) == "; compile 42.1 s, first run only"


def test_bake_leaves_the_compile_out_of_its_times(tmp_path, repo_root, monkeypatch):
    """With a watch whose compile time jumps by 100 s during the frames, the simulate time
    cannot hold it: it is reported as the bake's compile time instead."""
    from magica_py.bake.bake import bake_scene
    from magica_py.bake.capture import PoseCapture

    watch = _Watch()
    run = PoseCapture.run

    def run_and_compile(self, ctx):
        if self.count == 0:
            watch.seconds += 100.0
        return run(self, ctx)

    scene = repo_root / "configs" / "tail_orbit.yaml"
    bake_scene(scene, tmp_path / "warm.bvh", frames=2)   # nothing left to compile in the bake below
    monkeypatch.setattr(PoseCapture, "run", run_and_compile)
    start = time.perf_counter()
    result = bake_scene(scene, tmp_path / "tail.bvh", frames=3, compile_watch=watch)
    wall = time.perf_counter() - start
    assert result.compile_seconds == pytest.approx(100.0)
    assert result.simulate_seconds == 0.0          # its wall time was far below the "compile"
    assert result.load_seconds + result.write_seconds <= wall


def test_bake_says_it_compiles_before_the_compile_and_reports_it_apart(tmp_path, repo_root, capsys,
                                                                       compile_in_the_first_frame):
    from magica_py.cli import main

    out = tmp_path / "tail.bvh"
    assert main(["bake", str(repo_root / "configs" / "tail_orbit.yaml"), "--out", str(out), "--frames", "3"]) == 0
    captured = capsys.readouterr()
    assert f"magica-py bake: {COMPILE_MESSAGE}" in captured.err
    assert "bones x 3 frames" in captured.out and "first run only" in captured.out
    assert compile_in_the_first_frame and out.exists()


def test_bake_says_nothing_about_a_compile_when_nothing_compiles(tmp_path, repo_root, capsys):
    from magica_py.cli import main

    main(["bake", str(repo_root / "configs" / "tail_orbit.yaml"), "--out", str(tmp_path / "warm.bvh"),
          "--frames", "2"])            # the kernels are loaded (or compiled) here
    capsys.readouterr()
    assert main(["bake", str(repo_root / "configs" / "tail_orbit.yaml"), "--out", str(tmp_path / "tail.bvh"),
                 "--frames", "2"]) == 0
    captured = capsys.readouterr()
    assert "compil" not in captured.err and "first run only" not in captured.out


def test_record_all_says_it_compiles_and_reports_the_compile_apart(tmp_path, repo_root, capsys,
                                                                   compile_in_the_first_frame):
    from magica_py.sinks.record_all import main_record_all

    code = main_record_all(["--configs", str(repo_root / "configs"), "--out", str(tmp_path), "--only", "tail_orbit",
                            "--frames", "3"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert f"magica-py record-all: tail_orbit: {COMPILE_MESSAGE}" in captured.err
    line = [text for text in captured.out.splitlines() if text.startswith("tail_orbit")][0]
    assert line.endswith("first run only") and "; compile " in line
    assert (tmp_path / "tail_orbit.rrd").exists()


def test_record_scene_leaves_the_compile_out_of_the_simulation_time(tmp_path, repo_root, monkeypatch):
    from magica_py.config import load_scene
    from magica_py.runtime.player import Player
    from magica_py.sinks.record_all import record_scene

    watch = _Watch()
    step = Player.step

    def step_and_compile(self):
        watch.seconds += 100.0 if self.frame == 0 else 0.0
        return step(self)

    scene = repo_root / "configs" / "tail_orbit.yaml"
    record_scene(load_scene(scene), tmp_path / "warm.rrd", frames=2)   # nothing left to compile below
    monkeypatch.setattr(Player, "step", step_and_compile)
    result = record_scene(load_scene(scene), tmp_path / "t.rrd", frames=3, compile_watch=watch)
    assert result.compile_seconds == pytest.approx(100.0)
    assert result.wall_seconds == 0.0      # its real wall time was far below the "compile"


def test_resim_says_it_compiles_and_reports_the_compile_apart(tmp_path, repo_root, capsys, monkeypatch):
    from magica_py.config import load_scene
    from magica_py.runtime.player import Player
    from magica_py.sinks.record_all import record_scene
    from magica_py.sinks.resim import main_resim

    path = tmp_path / "tail.rrd"
    record_scene(load_scene(repo_root / "configs" / "tail_orbit.yaml"), path, frames=4)

    fresh = fresh_function()
    step = Player.step

    def step_that_compiles(self):
        if self.frame == 0:
            assert fresh(3) == 3.0
        return step(self)

    monkeypatch.setattr(Player, "step", step_that_compiles)
    assert main_resim([str(path), "--rrd", str(tmp_path / "again.rrd")]) == 0
    captured = capsys.readouterr()
    assert f"magica-py resim: {COMPILE_MESSAGE}" in captured.err
    assert "ms/frame; compile " in captured.out and captured.out.rstrip().endswith("first run only)")


def test_stability_says_it_compiles_above_its_bar(capsys):
    from magica_py.bench.cli import Progress

    @numba.njit(cache=False)
    def fresh(x):
        return x + 5

    bar = Progress(2)
    with bar.compile_watch("magica-py stability") as watch:
        assert fresh(1) == 6
        bar.add(1)
    bar.close()
    assert watch.count == 1
    assert f"magica-py stability: {COMPILE_MESSAGE}" in capsys.readouterr().err
    quiet = Progress(2, quiet=True)
    with quiet.compile_watch("magica-py stability"):
        assert fresh(2.5) == 7.5           # a new signature: a compile, said nowhere
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("cached", [False, True])
def test_batch_says_when_its_workers_will_compile_first(repo_root, tmp_path, capsys, monkeypatch, cached):
    from magica_py import first_run
    from magica_py.batch import runner
    from magica_py.batch.cli import main_batch

    def stop(*_args, **_kwargs):
        raise KeyboardInterrupt   # the note is printed before the jobs start; stop there

    monkeypatch.setattr(first_run, "frame_kernel_cached", lambda folder=None: cached)
    monkeypatch.setattr(runner, "run_batch", stop)
    main_batch([str(repo_root / "configs" / "batches" / "presets_by_rate.yaml"), "--out", str(tmp_path / "b")])
    err = capsys.readouterr().err
    assert ("each worker compiles it before its first job" in err) is not cached
    assert "interrupted" in err

