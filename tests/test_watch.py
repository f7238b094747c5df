"""magica-py watch, headless: each run is written to --rrd-dir (the viewer is not needed)."""
import io
import os
import pathlib
import threading
import time

import pytest

from magica_py import watch as W
from magica_py.sinks.readback import Recording

SCENE = """\
version: 1
scene: {name: wt, fps: 60, frames: 6}
rigs:
  - name: r
    bones: [{name: root, position: [0, 1, 0]}]
    parts: [{chain: {name: tail, parent: root, bones: 4, length: 0.3, direction: [0, 0, -1]}}]
animation:
  - {target: root, oscillate: {property: rotation, axis: [0, 1, 0], amplitude: 30, frequency: 1}}
cloths:
  - {name: tail, root_bones: [tail_0], preset: tail, parameters: {damping: 0.05}}
"""


def test_describe_change_names_what_differs():
    old = {"scene": {"fps": 60}, "cloths": [{"name": "tail", "parameters": {"damping": 0.05}}]}
    new = {"scene": {"fps": 60}, "cloths": [{"name": "tail", "parameters": {"damping": 0.2, "gravity": 3}}]}
    assert W.describe_change(None, new) == "first run"
    assert W.describe_change(old, new) == "tail.parameters.damping 0.05→0.2, +tail.parameters.gravity=3"
    assert W.describe_change(old, old) == "saved unchanged"
    assert W.describe_change(old, old, [pathlib.Path("a/Fox.glb")]) == "Fox.glb changed"
    many = {"scene": {"fps": 30, "frames": 9, "seed": 2, "name": "x"}}
    assert W.describe_change({"scene": {}}, many).endswith("and 1 more")
    # vectors are one value; cloths are matched by name, not by position in the list
    assert W.describe_change({"g": [0, -1, 0]}, {"g": [0, -2, 0]}) == "g [0, -1, 0]→[0, -2, 0]"
    swapped = {"cloths": [{"name": "b", "x": 1}, {"name": "a", "x": 2}]}
    assert W.describe_change({"cloths": [{"name": "a", "x": 2}, {"name": "b", "x": 1}]}, swapped) == "saved unchanged"


def test_scene_assets_are_resolved_beside_the_scene(tmp_path):
    data = {"rigs": [{"name": "a", "file": "../m/avatar.vrm"}, {"name": "b", "bones": []}],
            "animation": [{"clip": "clips/Fox.glb#Run"}, {"target": "x"}]}
    scene = tmp_path / "s" / "scene.yaml"
    assert W.scene_assets(data, scene) == sorted([tmp_path / "m" / "avatar.vrm", tmp_path / "s" / "clips" / "Fox.glb"])
    assert W.scene_assets(None, scene) == []


def _quick_watch(tmp_path, stream=None, **options):
    """A watch of ``SCENE`` (written to tmp_path/wt.yaml) that notices a save within 50 ms and
    records into tmp_path/runs; returns (scene path, watch)."""
    scene = tmp_path / "wt.yaml"
    scene.write_text(SCENE)
    watch = W.Watch(scene, rrd_dir=tmp_path / "runs", debounce=0.05, poll=0.02,
                    stream=io.StringIO() if stream is None else stream, **options)
    return scene, watch


def _start(watch, runs):
    thread = threading.Thread(target=watch.run_forever, kwargs={"max_runs": runs}, daemon=True)
    thread.start()
    return thread


def _wait(watch, count, timeout=600.0):
    end = time.monotonic() + timeout
    while len(watch.reports) < count:
        assert time.monotonic() < end, f"only {len(watch.reports)} runs"
        time.sleep(0.02)
    time.sleep(0.05)


def _save(path, content):
    path.write_bytes(content.encode() if isinstance(content, str) else content)
    stamp = path.stat().st_mtime_ns + 10_000_000    # coarse file-system clocks: a new stamp for sure
    import os
    os.utime(path, ns=(stamp, stamp))


def test_watch_reruns_on_save_names_each_recording_and_survives_a_bad_edit(tmp_path):
    out = io.StringIO()
    scene, watch = _quick_watch(tmp_path, out)
    thread = _start(watch, 4)
    _wait(watch, 1)
    _save(scene, SCENE.replace("damping: 0.05", "damping: 0.2"))
    _wait(watch, 2)
    _save(scene, SCENE.replace("damping: 0.05", "damping: 7"))          # out of range
    _wait(watch, 3)
    _save(scene, SCENE.replace("damping: 0.05", "damping: 1e-1"))       # fixed (YAML 1.2 number)
    thread.join(600)
    first, second, bad, fixed = watch.reports
    assert [r.ok for r in watch.reports] == [True, True, False, True]
    assert first.description == "first run" and first.frames == 6
    assert second.description == "tail.parameters.damping 0.05→0.2"
    assert "cloths[0].parameters.damping" in bad.error and "out of range [0, 1]" in bad.error
    assert fixed.description == "tail.parameters.damping 0.2→0.1"       # against the last good run
    for report in (first, second, fixed):
        rec = Recording(report.recording)
        assert rec.static_value("/__properties", "RecordingInfo:name") == [report.recording_name]
        assert report.latency is not None and report.latency >= 0.0
    assert second.recording_name == "wt · tail.parameters.damping 0.05→0.2"
    assert len(list((tmp_path / "runs").glob("*.rrd"))) == 3
    text = out.getvalue()
    assert "the scene has problems" in text and "Traceback" not in text


def test_a_burst_of_saves_runs_once(tmp_path):
    scene = tmp_path / "wt.yaml"
    scene.write_text(SCENE)
    watch = W.Watch(scene, debounce=0.4, poll=0.02, stream=io.StringIO())
    stop = threading.Event()
    thread = threading.Thread(target=watch.run_forever, kwargs={"stop": stop.is_set}, daemon=True)
    thread.start()
    _wait(watch, 1)
    for damping in (0.1, 0.15, 0.2):      # three saves inside the debounce window
        _save(scene, SCENE.replace("damping: 0.05", f"damping: {damping}"))
        time.sleep(0.05)
    _wait(watch, 2)
    time.sleep(0.6)
    stop.set()
    thread.join(60)
    assert len(watch.reports) == 2
    assert watch.reports[1].description == "tail.parameters.damping 0.05→0.2"


def test_ctrl_c_ends_the_watch_cleanly(tmp_path):
    scene = tmp_path / "wt.yaml"
    scene.write_text(SCENE)
    out = io.StringIO()
    watch = W.Watch(scene, debounce=0.05, poll=0.02, stream=out)

    def interrupt():
        raise KeyboardInterrupt
    assert watch.run_forever(stop=interrupt) == 0
    assert out.getvalue().rstrip().endswith("watch: stopped")


def test_watch_command_checks_its_arguments(tmp_path, capsys):
    assert W.main_watch([str(tmp_path / "missing.yaml")]) == 2
    assert "file not found" in capsys.readouterr().err
    scene = tmp_path / "wt.yaml"
    scene.write_text(SCENE)
    assert W.main_watch([str(scene), "--no-viewer"]) == 2
    assert "without any output" in capsys.readouterr().err


def test_saving_an_asset_the_scene_reads_reruns_it(tmp_path, shared_data):
    import shutil

    shutil.copy(shared_data / "gltf" / "Fox.glb", tmp_path / "Fox.glb")
    scene = tmp_path / "fox.yaml"
    scene.write_text("version: 1\nscene: {name: fox, frames: 2}\n"
                     "rigs:\n  - {name: fox, file: Fox.glb, unit_scale: 0.01}\n")
    watch = W.Watch(scene, debounce=0.05, poll=0.02, stream=io.StringIO())
    assert watch.stamps.paths == [scene]
    thread = _start(watch, 2)
    _wait(watch, 1)
    assert tmp_path / "Fox.glb" in watch.stamps.paths     # learnt from the document
    _save(tmp_path / "Fox.glb", (tmp_path / "Fox.glb").read_bytes())    # re-exported unchanged
    thread.join(600)
    assert [r.description for r in watch.reports] == ["first run", "Fox.glb changed"]
    assert all(r.ok for r in watch.reports)


def test_watch_refuses_to_stream_to_a_viewer_that_is_not_there(tmp_path, capsys):
    import socket

    with socket.socket() as free:
        free.bind(("127.0.0.1", 0))
        port = free.getsockname()[1]          # closed again: nothing listens there
    scene = tmp_path / "wt.yaml"
    scene.write_text(SCENE)
    assert W.main_watch([str(scene), "--connect", f"127.0.0.1:{port}"]) == 2
    assert "no Rerun viewer is listening" in capsys.readouterr().err
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen()
        assert W.viewer_listening(f"rerun+http://127.0.0.1:{server.getsockname()[1]}/proxy")


def test_a_save_during_a_run_stops_it_and_starts_the_new_one(tmp_path):
    scene, watch = _quick_watch(tmp_path, frames=10_000_000)
    thread = threading.Thread(target=watch.run_forever, kwargs={"max_runs": 2}, daemon=True)
    thread.start()
    while not watch.reports and watch.run_index == 0:
        time.sleep(0.02)
    time.sleep(1.0)                              # the first run is under way (it would take hours)
    watch.frames = 3                             # the new run is short
    _save(scene, SCENE.replace("damping: 0.05", "damping: 0.3"))
    thread.join(600)
    first, second = watch.reports
    assert first.superseded and not first.ok and 0 < first.frames < 10_000_000
    assert second.ok and second.frames == 3 and second.description == "tail.parameters.damping 0.05→0.3"
    assert [p.name for p in (tmp_path / "runs").glob("*.rrd")] == [pathlib.Path(second.recording).name]


@pytest.fixture
def empty_cache(tmp_path, monkeypatch):
    """A kernel cache folder with no compiled cloth frame, for the watch's children (this
    process keeps its own), whose background-compile lock a live pid holds, so that the
    interpreted children start no compile of their own here; returns the folder."""
    from magica_py import first_run

    cache = tmp_path / "cache"
    cache.mkdir()
    (cache / first_run.LOCK_NAME).write_text(first_run._lock_text(os.getpid(), ["wt.yaml"]))
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(cache))
    monkeypatch.setenv("MAGICA_FIRST_RUN", "auto")
    return cache


def test_scene_names_resolve_as_the_loader_does():
    assert W.scene_name({"scene": {"name": "wt"}}, "a/b.yaml") == "wt"
    assert W.scene_name({"scene": {"fps": 60}}, "a/b.yaml") == "b"
    assert W.scene_name(None, "a/b.yaml") == "b"
    assert W.scene_name({"scene": {"name": "wt"}}, "a/b.yaml", ["scene.name='other'"]) == "other"


def test_a_first_run_on_an_empty_cache_runs_interpreted_and_the_runs_after_the_compile_here(tmp_path,
                                                                                              empty_cache):
    """With no compiled cloth frame in the kernel cache the watch hands its run to ``run``'s
    interpreted tier (magica_py/first_run.py): the same recording (name, file) at once instead
    of after the compile; a bad edit is reported as usual; once the cache holds a compiled
    frame the runs are this process's again. (A live pid holds the background compile's lock,
    so that the child starts no compile of its own here.)"""
    from magica_py import first_run

    out = io.StringIO()
    scene, watch = _quick_watch(tmp_path, out)
    thread = _start(watch, 3)
    _wait(watch, 1)
    _save(scene, SCENE.replace("damping: 0.05", "damping: 7"))          # out of range: the child says so
    _wait(watch, 2)
    (empty_cache / "kernels").mkdir()
    (empty_cache / "kernels" / "frame.simulate_frame-1.py311.nbi").write_bytes(b"")   # "the compile is done"
    _save(scene, SCENE.replace("damping: 0.05", "damping: 0.2"))
    thread.join(600)
    first, bad, compiled = watch.reports
    assert first.ok and first.frames == 6 and first.latency is None   # the child's: no latency known here
    assert not bad.ok and "problems" in bad.error
    assert compiled.ok and compiled.frames == 6 and compiled.latency is not None
    assert compiled.description == "tail.parameters.damping 0.05→0.2"    # against the last good run
    for report in (first, compiled):
        rec = Recording(report.recording)
        assert rec.static_value("/__properties", "RecordingInfo:name") == [report.recording_name]
    assert first.recording_name == "wt · first run"
    assert sorted(p.name for p in (tmp_path / "runs").glob("*.rrd")) == \
        sorted(pathlib.Path(r.recording).name for r in (first, compiled))
    text = out.getvalue()
    assert "run 1 (first run): 6 frames, interpreted (first run only" in text
    assert "run 2: the scene has problems" in text and "Traceback" not in text
    assert not (empty_cache / first_run.FAILURE_LOG_NAME).exists()


def test_a_save_during_an_interpreted_first_run_stops_its_child_and_keeps_no_file(tmp_path, monkeypatch,
                                                                                   empty_cache):
    from magica_py import first_run

    # a run that does not end by itself: the budget raised so that it is still interpreted
    monkeypatch.setenv(first_run.BUDGET_ENV, "1000000000")
    scene, watch = _quick_watch(tmp_path, frames=10_000_000)
    thread = _start(watch, 2)
    while watch.run_index == 0:
        time.sleep(0.02)
    time.sleep(2.0)                              # the child has started its frames
    watch.frames = 3
    _save(scene, SCENE.replace("damping: 0.05", "damping: 0.3"))
    thread.join(600)
    first, second = watch.reports
    assert first.superseded and not first.ok
    assert second.ok and second.frames == 3
    assert [p.name for p in (tmp_path / "runs").glob("*")] == [pathlib.Path(second.recording).name]


def test_ctrl_c_during_an_interpreted_first_run_ends_its_child_and_the_watch(tmp_path, monkeypatch, empty_cache):
    """A ^C that reaches only the watch (not its child, as a terminal's would) ends the child
    after a grace period, like ^C (no recording file kept); the watch then stops as usual. The
    child is started with SIGINT ignored, as under a job runner (pytest-xdist's workers, where a
    SIGINT never reached it and the watch waited for ever): it is stopped with SIGTERM."""
    import signal

    from magica_py import first_run

    polls = []
    changed = W.FileStamps.changed

    def interrupted_while_the_child_runs(self):
        polls.append(1)
        if len(polls) == 10:     # about 2 s into the child's run
            raise KeyboardInterrupt
        return changed(self)

    monkeypatch.setattr(W.FileStamps, "changed", interrupted_while_the_child_runs)
    out = io.StringIO()
    monkeypatch.setenv(first_run.BUDGET_ENV, "1000000000")   # a long run, still interpreted
    _scene, watch = _quick_watch(tmp_path, out, frames=10_000_000)
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)   # inherited by the child
    try:
        start = time.monotonic()
        assert watch.run_forever() == 0
        assert time.monotonic() - start < 60.0
    finally:
        signal.signal(signal.SIGINT, previous)
    assert out.getvalue().rstrip().endswith("watch: stopped")
    assert list((tmp_path / "runs").glob("*")) == []
