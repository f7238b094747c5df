"""The small frictions of a first run (issue 18 item 5): numbers, vectors, empty and huge
files, non-scene files, missing output folders, recordings that are not written, units."""
import io
import time

import numpy as np
import pytest

from magica_py import cli
from magica_py.config import ConfigError, load_scene, load_scene_text
from magica_py.config.document import MAX_DOCUMENT_BYTES, load_yaml_value

BASE = """\
version: 1
scene: {name: f, fps: 60, frames: 3}
rigs:
  - name: r
    bones: [{name: root, position: [0, 1, 0]}]
    parts: [{chain: {name: tail, parent: root, bones: 3, length: 0.2, direction: [0, 0, -1]}}]
cloths:
  - {name: tail, root_bones: [tail_0], preset: tail}
"""


def test_yaml_12_exponent_numbers_are_numbers():
    assert [load_yaml_value(t) for t in ("1e-4", "1e4", "1.0e30", "2E5", "-3e-2", ".5e1")] == \
        [1e-4, 1e4, 1e30, 2e5, -3e-2, 5.0]
    assert load_yaml_value("1e") == "1e" and load_yaml_value("e4") == "e4"   # text stays text
    scene = load_scene_text(BASE.replace("preset: tail}", "preset: tail, parameters: {damping: 1e-1}}"),
                            overrides=["cloths.tail.parameters.gravity=5e-1"])
    assert scene.cloths[0].parameters["damping"].value == pytest.approx(0.1)
    assert scene.cloths[0].parameters["gravity"] == pytest.approx(0.5)


def test_every_bad_element_of_a_vector_is_reported():
    text = BASE.replace("position: [0, 1, 0]", "position: [x, 1, .nan]")
    with pytest.raises(ConfigError) as info:
        load_scene_text(text)
    paths = info.value.paths()
    assert "rigs[0].bones[0].position[0]" in paths and "rigs[0].bones[0].position[2]" in paths


@pytest.mark.parametrize("content", ["", "# only a comment\n\n", "---\n"])
def test_an_empty_file_says_it_is_empty(tmp_path, content):
    path = tmp_path / "empty.yaml"
    path.write_text(content)
    with pytest.raises(ConfigError) as info:
        load_scene(path)
    assert "the file is empty" in str(info.value) and "rigs: is required" not in str(info.value)


def test_a_huge_scene_file_fails_fast_without_being_parsed(tmp_path):
    path = tmp_path / "huge.yaml"
    line = "  - {name: b%d, parent: root, position: [0, 0.01, 0]}\n"
    with open(path, "w") as fh:
        fh.write(BASE)
        n = 0
        while fh.tell() < MAX_DOCUMENT_BYTES + 1000:
            fh.write(line % n)
            n += 1
    start = time.perf_counter()
    with pytest.raises(ConfigError) as info:
        load_scene(path)
    assert time.perf_counter() - start < 1.0
    assert "limited to 4.2 MB" in str(info.value)


def test_absurd_bone_counts_fail_before_the_bones_are_made():
    start = time.perf_counter()
    with pytest.raises(ConfigError) as info:
        load_scene_text(BASE.replace("direction: [0, 0, -1]}}]",
                                     "direction: [0, 0, -1]}}]\n    instances: {count: 10000000}"))
    assert "rigs[0].instances.count" in info.value.paths() and "limited to 500,000 bones" in str(info.value)
    with pytest.raises(ConfigError) as info:
        load_scene_text(BASE.replace("bones: 3, length", "bones: 2000000, length"))
    assert "limited to 500,000 bones" in str(info.value)
    assert time.perf_counter() - start < 5.0


def test_asset_files_given_as_scenes_are_named_with_the_command_that_fits(tmp_path, capsys):
    cases = {"model.vrm": (b"glTF\x02\x00\x00\x00", "this is a VRM avatar, not a scene: run it directly: magica-py run"),
             "fox.glb": (b"glTF\x02\x00\x00\x00", "this is a glTF binary (GLB) model, not a scene"),
             "run.rrd": (b"RRF2\x00\x00\x00\x00\xff\xfe", "this is a Rerun recording, not a scene: open it with: rerun"),
             "walk.bvh": (b"HIERARCHY\nROOT Hips\n", "magica-py run AVATAR.vrm --clip"),
             "noise.yaml": (b"\xff\xfe\x00binary", "not UTF-8 text")}
    for name, (data, expected) in cases.items():
        path = tmp_path / name
        path.write_bytes(data)
        assert cli.main(["validate", str(path)]) == 2
        err = capsys.readouterr().err
        assert expected in err and "codec can't decode" not in err and "Traceback" not in err
    assert cli.main(["run", str(tmp_path / "run.rrd")]) == 2
    assert "magica-py inspect" in capsys.readouterr().err


def test_a_run_that_records_nothing_says_so(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "s.yaml").write_text(BASE)
    assert cli.main(["run", "s.yaml"]) == 0
    err = capsys.readouterr().err
    assert "writes no recording" in err and "--rrd replays/f.rrd" in err
    assert cli.main(["run", "s.yaml", "--no-rrd"]) == 0     # asked for: no note
    assert "writes no recording" not in capsys.readouterr().err


def test_rrd_and_output_rrd_create_missing_folders_alike(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "s.yaml").write_text(BASE + "output: {rrd: a/b/from_scene.rrd}\n")
    assert cli.main(["run", "s.yaml", "-q"]) == 0
    assert cli.main(["run", "s.yaml", "-q", "--rrd", "c/d/from_flag.rrd"]) == 0
    assert (tmp_path / "a/b/from_scene.rrd").is_file() and (tmp_path / "c/d/from_flag.rrd").is_file()


def test_reports_default_to_the_current_folder(tmp_path, monkeypatch):
    from magica_py.bench.report import default_report_dir

    monkeypatch.chdir(tmp_path)
    assert default_report_dir() == tmp_path / "reports"


def test_inspect_shows_units(tmp_path):
    from magica_py.sinks.inspect import format_summary, metric_unit, summarize

    assert metric_unit("time/late_update") == "ms" and metric_unit("cloth/kernel") == "s"
    assert metric_unit("max_speed") == "m/s" and metric_unit("unknown/thing") == ""
    # the sink's names carry their unit (layout.series_label)
    assert metric_unit("quality/max_edge_stretch_pct") == "%" and metric_unit("quality/max_penetration_mm") == "mm"
    assert metric_unit("motion/max_speed_m_per_s") == "m/s" and metric_unit("solver/steps_per_frame") == "steps"
    (tmp_path / "s.yaml").write_text(BASE)
    target = tmp_path / "r.rrd"
    assert cli.main(["run", str(tmp_path / "s.yaml"), "--rrd", str(target), "-q"]) == 0
    text = format_summary(summarize(target))
    lines = {line.split()[0]: line for line in text.splitlines()[1:] if line.startswith("            ")}
    late_update = next(v for k, v in lines.items() if k.startswith("time/late_update"))
    assert " ms " in late_update and " steps " in lines["solver/steps_per_frame"]
    assert " m/s " in lines["motion/max_speed_m_per_s"]


def test_counts_are_plural_only_when_they_should_be():
    assert cli.plural(1, "collider") == "1 collider" and cli.plural(2, "rig") == "2 rigs"
    assert cli.plural(0, "cloth") == "0 cloths" and cli.plural(1000, "bone") == "1,000 bones"


def test_bench_help_has_no_rst_backticks(capsys):
    from magica_py.bench.cli import main_bench

    with pytest.raises(SystemExit):
        main_bench(["--help"])
    out = capsys.readouterr().out
    assert "``" not in out and "bench.md" in out


# ----------------------------------------------------------------------------- the run loop
def test_the_first_compile_is_announced_before_it_starts_and_timed_apart():
    import numba

    from magica_py.runner import COMPILE_MESSAGE, CompileWatch

    calls = []

    @numba.njit(cache=False)
    def add_one(x):
        return x + 1

    @numba.njit(cache=False)
    def add_two(x):
        return add_one(x) + 1

    with CompileWatch(announce=lambda text: calls.append((text, add_two.signatures[:]))) as watch:
        assert add_two(1) == 3
        assert add_two(2.5) == 4.5      # a second compile: announced once only
    assert calls == [(COMPILE_MESSAGE, [])]          # said before anything was compiled
    assert watch.count == 2 and watch.seconds > 0.0  # nested helper compiles count once
    with CompileWatch(announce=calls.append) as warm:
        add_two(5)                                   # already compiled: nothing to say
    assert warm.count == 0 and len(calls) == 1


def test_the_garbage_collector_runs_less_often_only_while_compiling():
    import gc

    import numba
    from numba.core import event

    from magica_py.jit import COMPILE_GC_THRESHOLDS
    from magica_py.runner import CompileWatch

    @numba.njit(cache=False)
    def inner(x):
        return x * 2

    @numba.njit(cache=False)
    def outer(x):
        return inner(x) + 1

    seen = []

    class Record(event.Listener):
        def on_start(self, ev):
            seen.append(gc.get_threshold())

        def on_end(self, ev):
            pass

    before = gc.get_threshold()
    assert before != COMPILE_GC_THRESHOLDS
    with CompileWatch() as watch:
        with event.install_listener("numba:compile", Record()):
            assert outer(3) == 7
        assert gc.get_threshold() == before          # restored after the outermost compile
    assert watch.count == 1
    assert len(seen) == 2 and all(t == COMPILE_GC_THRESHOLDS for t in seen)   # outer and nested inner
    assert gc.isenabled()


def test_the_progress_bar_shows_rate_and_an_eta_without_the_compile(monkeypatch):
    from magica_py.runner import FrameProgress

    stream = io.StringIO()
    stream.isatty = lambda: True
    bar = FrameProgress(100, stream=stream, delay=0.0)
    bar.update(10)
    time.sleep(0.3)         # a "compile": excluded from the rate once pause_ended is called
    bar.pause_ended()
    bar.update(20)
    bar.bar.refresh()
    rate = bar.bar.format_dict["rate"] or bar.bar.format_dict["n"] / bar.bar.format_dict["elapsed"]
    bar.close()
    text = stream.getvalue()
    assert "20/100" in text and "frame/s" in text
    assert rate > 100.0     # 20 frames in well under 0.2 s of counted time


def test_the_summary_reports_the_compile_apart():
    import types

    from magica_py.runner import RunStats, summary_line

    stats = RunStats(frames=11, steps=15, steps_known=True, wall_time=1.1, compile_seconds=42.0,
                     first_frame_seconds=0.1)
    line = summary_line(types.SimpleNamespace(name="s", cloths=[1]), stats, True, None)
    assert line == "s: 11 frames, 15 simulation steps, 100.00 ms/frame (wall 1.10 s, first frame 0.10 s; " \
                   "compile 42.0 s, first run only)"


def test_in_a_log_file_each_redraw_is_its_own_line():
    from magica_py.runner import FrameProgress

    stream = io.StringIO()              # not a terminal
    bar = FrameProgress(4, stream=stream, delay=0.0, log_interval=0.0)
    for done in range(1, 5):
        bar.update(done)
    bar.close()
    lines = stream.getvalue().splitlines()
    assert "\r" not in stream.getvalue() and lines[-1].startswith("100%") and "4/4" in lines[-1]


def test_warnings_inside_frames_are_recorded_as_events(repo_root, tmp_path, monkeypatch):
    from magica_py.api import Session
    from magica_py.runtime.phases import Phase, System
    from magica_py.sinks.inspect import summarize

    monkeypatch.chdir(repo_root)
    target = tmp_path / "w.rrd"
    with Session("configs/tail_orbit.yaml", record=target) as session:
        def overflow(ctx):
            if ctx.frame in (1, 3):
                np.exp(np.float64(1000.0))
        session.player.schedule.add(Phase.LATE_UPDATE, System("overflow", overflow))
        session.run(5)
    events = [e for e in summarize(target)["events"] if "warning" in e["text"].split(":")[0]]
    assert [e["frame"] for e in events] == [1, 3]
    assert all(e["text"].startswith("numpy_warning: ") and "overflow" in e["text"] for e in events)
