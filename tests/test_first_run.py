"""The first run's interpreted tier (magica_py/first_run.py): a short run with no compiled cloth
frame in the cache goes interpreted while the solver compiles in the background; a long one
compiles in its own process; the recording is the compiled run's, bit for bit."""
import os
import pathlib
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from magica_py import first_run
from magica_py.config import load_scene

ROOT = pathlib.Path(__file__).resolve().parents[1]
TAIL = str(ROOT / "configs" / "tail_orbit.yaml")
CHARACTER = str(ROOT / "configs" / "character_walk.yaml")


def _cli(args, env_updates, timeout=900):
    env = dict(os.environ)
    env.pop("NUMBA_DISABLE_JIT", None)
    env.update(env_updates)
    return subprocess.run([sys.executable, "-m", "magica_py.cli", *args], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=timeout)


@pytest.mark.parametrize("path, frames, particles", [(TAIL, 10, 8), (CHARACTER, 7, 78)])
def test_the_estimate_is_frames_times_steps_times_particles(path, frames, particles):
    """60 fps at 90 Hz is 1.5 steps a frame; the tail has 8 particles, the character's hair
    and skirt 78 (the run's own summary reports 120 and 1,170 particle-steps for 10 frames)."""
    scene = load_scene(path)
    assert first_run.cloth_particles(scene) == particles
    assert first_run.estimate_particle_steps(scene, frames) == frames * 1.5 * particles
    # a run of the scene's own length: its duration at its frame rate
    expected = scene.settings.frame_count() * 1.5 * particles
    assert first_run.estimate_particle_steps(scene, None) == expected


def test_a_cache_folder_holds_a_compiled_frame_only_with_the_frame_kernel_s_index(tmp_path):
    assert not first_run.frame_kernel_cached(tmp_path / "missing")
    assert not first_run.frame_kernel_cached(tmp_path)
    (tmp_path / "solver_0123").mkdir()
    (tmp_path / "solver_0123" / "step.predict_block-194.py311.nbi").write_bytes(b"")
    assert not first_run.frame_kernel_cached(tmp_path)
    (tmp_path / "solver_0123" / "frame.simulate_frame-609.py311.nbi").write_bytes(b"")
    assert first_run.frame_kernel_cached(tmp_path)


class _Args:
    no_simulation = False


@pytest.mark.parametrize("env, cached, expected", [
    ({"MAGICA_FIRST_RUN": "auto"}, False, True),
    ({"MAGICA_FIRST_RUN": "auto"}, True, False),          # a compiled frame cached: compile
    ({"MAGICA_FIRST_RUN": "interpret"}, True, True),
    ({"MAGICA_FIRST_RUN": "compile"}, False, False),
    ({"MAGICA_FIRST_RUN": "auto", "NUMBA_DISABLE_JIT": "1"}, False, False),   # interpreted already
    ({"MAGICA_FIRST_RUN": "auto", "MAGICA_NO_CACHE": "1"}, False, False),     # nothing to fill
    ({"MAGICA_FIRST_RUN": "auto", "MAGICA_RUN_TIER": "interpreted"}, False, False),   # the child itself
])
def test_the_interpreted_tier_is_tried_only_on_a_first_run_with_a_cache_to_fill(monkeypatch, tmp_path, env,
                                                                                cached, expected):
    for name in ("NUMBA_DISABLE_JIT", "MAGICA_NO_CACHE", "MAGICA_RUN_TIER"):
        monkeypatch.delenv(name, raising=False)
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    if cached:
        (tmp_path / "solver_0").mkdir()
        (tmp_path / "solver_0" / "frame.simulate_frame-1.py311.nbi").write_bytes(b"")
    assert first_run.wanted(_Args()) is expected
    no_cloth = _Args()
    no_cloth.no_simulation = True
    assert first_run.wanted(no_cloth) is False


@pytest.mark.parametrize("name, value", [("MAGICA_FIRST_RUN", "sometimes"), ("MAGICA_INTERPRET_BUDGET", "-3"),
                                         ("MAGICA_INTERPRET_BUDGET", "lots")])
def test_a_bad_setting_is_a_clear_input_error(tmp_path, name, value):
    out = _cli(["run", TAIL, "--no-rrd", "--frames", "1"], {name: value, "NUMBA_CACHE_DIR": str(tmp_path)},
               timeout=120)
    assert out.returncode == 2, out.stderr
    assert f"environment variable {name}={value!r}" in out.stderr
    assert "Traceback" not in out.stderr


def _positions(path):
    from magica_py.sinks.readback import Recording

    recording = Recording(path)
    found = {}
    for entity in recording.entities:
        for component in ("Points3D:positions", "Transform3D:translation", "Transform3D:quaternion"):
            if component in recording.components(entity):
                frames, rows = recording.rows(entity, component)
                if len(rows):
                    found[(entity, component)] = (np.asarray(frames), [np.asarray(r) for r in rows])
    return found


def _wait_for_exit(pid, timeout):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if not first_run._alive(pid):
            return True
        time.sleep(0.5)
    return False


def _end_background(pid):
    """End a background compile's process group: SIGTERM (it removes its scratch folder and
    lock), then SIGKILL what is still there after 30 s."""
    try:
        os.killpg(pid, signal.SIGTERM)
    except (ProcessLookupError, PermissionError):
        return
    if not _wait_for_exit(pid, 30):
        try:
            os.killpg(pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass


def test_a_short_first_run_goes_interpreted_and_the_background_compile_serves_the_next_run(tmp_path):
    """The whole story on an empty cache: the run goes interpreted and says so, its recording
    is written; the background compile fills the cache; the next run compiles nothing and
    records the same particles and bones, bit for bit."""
    cache = tmp_path / "cache"
    env = {"NUMBA_CACHE_DIR": str(cache), "MAGICA_FIRST_RUN": "auto", "MAGICA_STAGES": "used",
           "TMPDIR": str(tmp_path)}
    first = _cli(["run", TAIL, "--frames", "8", "--rrd", str(tmp_path / "first.rrd")], env)
    pid = None
    try:
        assert first.returncode == 0, first.stderr
        assert "this short run goes interpreted" in first.stderr
        assert "interpreted, first run only" in first.stdout
        assert "warning" not in first.stderr.lower()   # the discarded selects' warnings stay quiet
        assert (tmp_path / "first.rrd").is_file()
        pid = first_run._read_lock(cache)[0]
        assert _wait_for_exit(pid, 600), "the background compile did not finish in 10 minutes"
        log = (cache / first_run.LOG_NAME).read_text()
        assert "compiled 'tail_orbit'" in log, log
        assert not (cache / first_run.LOCK_NAME).exists()
        assert first_run.frame_kernel_cached(cache)
    finally:
        if pid is not None:
            _end_background(pid)
    second = _cli(["run", TAIL, "--frames", "8", "--rrd", str(tmp_path / "second.rrd")], env)
    assert second.returncode == 0, second.stderr
    assert "interpreted" not in second.stdout + second.stderr
    assert "compiling the solver" not in second.stderr and "compile" not in second.stdout
    a, b = _positions(tmp_path / "first.rrd"), _positions(tmp_path / "second.rrd")
    assert a.keys() == b.keys() and any(key[1] == "Points3D:positions" for key in a)
    for key in a:
        assert np.array_equal(a[key][0], b[key][0]), key
        assert len(a[key][1]) == 8 or key[1] != "Points3D:positions"
        for x, y in zip(a[key][1], b[key][1]):
            assert x.tobytes() == y.tobytes(), key


def test_a_run_over_the_budget_declines_before_writing_and_compiles_in_its_own_process(tmp_path):
    out = _cli(["run", TAIL, "--frames", "4", "--rrd", str(tmp_path / "out.rrd")],
               {"MAGICA_FIRST_RUN": "interpret", "MAGICA_INTERPRET_BUDGET": "10"})
    assert out.returncode == 0, out.stderr
    assert "interpreted" not in out.stdout + out.stderr
    assert (tmp_path / "out.rrd").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.rrd"]   # nothing left by the child


class _FakePopen:
    started = []

    def __init__(self, args, **kwargs):
        self.pid = 4_000_000 + len(_FakePopen.started)   # beyond any pid_max: never alive
        _FakePopen.started.append(args)


def test_one_background_compile_at_a_time_and_a_dead_one_s_lock_is_taken_over(monkeypatch, tmp_path):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(first_run.subprocess, "Popen", _FakePopen)
    _FakePopen.started.clear()
    lock = tmp_path / first_run.LOCK_NAME
    log = tmp_path / first_run.LOG_NAME
    # a live compile of the same command (this process stands in for it), then of another one
    lock.write_text(first_run._lock_text(os.getpid(), ["x.yaml"]))
    assert first_run.start_background_compile(["x.yaml"]) == (os.getpid(), log, "running")
    assert first_run.start_background_compile(["y.yaml"]) == (os.getpid(), log, "other")
    assert _FakePopen.started == []
    lock.write_text(first_run._lock_text(4_999_999, ["x.yaml"]))   # its process is gone
    started = first_run.start_background_compile(["x.yaml", "--frames", "3"])
    assert started == (4_000_000, log, "started")
    assert _FakePopen.started[0][-4:] == ["magica_py.first_run", "x.yaml", "--frames", "3"]
    assert first_run._read_lock(tmp_path) == (4_000_000, {"argv": ["x.yaml", "--frames", "3"], "cwd": os.getcwd()})
    for background in (started, first_run.Background(os.getpid(), log, "running"),
                       first_run.Background(os.getpid(), log, "other"), first_run.Background(None, None, "failed")):
        note = first_run.interpreted_note(background)
        assert note.startswith("first run: no compiled solver in the cache yet; this short run goes interpreted")
        assert (str(background.pid) in note) == (background.pid is not None)


def test_a_terminated_interpreted_run_ends_its_child_and_leaves_no_recording(tmp_path):
    """SIGTERM to ``run`` (a job scheduler ending it) reaches the interpreted child, which
    removes its unfinished recording and exits 143 like the parent."""
    cache = tmp_path / "cache"
    env = dict(os.environ)
    env.pop("NUMBA_DISABLE_JIT", None)
    env.update({"NUMBA_CACHE_DIR": str(cache), "MAGICA_FIRST_RUN": "auto", "MAGICA_STAGES": "used",
                "TMPDIR": str(tmp_path)})
    out = tmp_path / "out"
    out.mkdir()
    run = subprocess.Popen([sys.executable, "-m", "magica_py.cli", "run", CHARACTER, "--frames", "25",
                            "--rrd", str(out / "walk.rrd")], cwd=ROOT, env=env, stderr=subprocess.PIPE,
                           stdout=subprocess.PIPE, text=True)
    pid = None
    try:
        line = run.stderr.readline()
        assert "this short run goes interpreted" in line, line
        pid = first_run._read_lock(cache)[0]
        time.sleep(1.0)   # frames are running (about 0.2 s each)
        run.send_signal(signal.SIGTERM)
        assert run.wait(timeout=60) == 143
        assert "magica-py: terminated" in run.stderr.read()
        assert list(out.iterdir()) == []   # neither the recording nor its temporary file
    finally:
        if run.poll() is None:
            run.kill()
        if pid is not None:
            _end_background(pid)


def test_a_terminated_background_compile_removes_its_scratch_folder_and_lock_and_says_so(tmp_path):
    """``kill PID`` of the background compile (its pid is in the run's note and the lock):
    it unwinds like ^C, so that its scratch folder (the recording it writes) and its lock go,
    and its log says it was terminated."""
    cache, scratch = tmp_path / "cache", tmp_path / "tmp"
    cache.mkdir()
    scratch.mkdir()
    env = dict(os.environ)
    env.pop("NUMBA_DISABLE_JIT", None)
    env.update({"NUMBA_CACHE_DIR": str(cache), "TMPDIR": str(scratch), "MAGICA_COMPILE_HELPER": "0"})
    child = subprocess.Popen([sys.executable, "-m", "magica_py.first_run", TAIL, "--frames", "3"], cwd=ROOT,
                             env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        (cache / first_run.LOCK_NAME).write_text(first_run._lock_text(child.pid, [TAIL, "--frames", "3"]))
        end = time.monotonic() + 120
        while not list(scratch.glob("magica-first-run-*")) and time.monotonic() < end and child.poll() is None:
            time.sleep(0.05)
        assert list(scratch.glob("magica-first-run-*")), "the compile did not start"
        time.sleep(1.0)   # compiling the tail's kernels (tens of seconds from an empty cache)
        child.send_signal(signal.SIGTERM)
        assert child.wait(timeout=60) == 143
        assert "background compile terminated after" in child.stdout.read()
        assert list(scratch.iterdir()) == []
        assert not (cache / first_run.LOCK_NAME).exists()
    finally:
        if child.poll() is None:
            child.kill()


def test_a_compiling_run_waits_for_a_running_background_compile_and_says_so(monkeypatch, tmp_path):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    notes = []
    assert first_run.wait_for_background_compile(notes.append) == 0.0 and notes == []   # none runs
    stand_in = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(1.5)"])
    try:
        (tmp_path / first_run.LOCK_NAME).write_text(first_run._lock_text(stand_in.pid, ["x.yaml"]))
        waited = first_run.wait_for_background_compile(notes.append, poll=0.05)
        assert stand_in.poll() is not None or not first_run._alive(stand_in.pid)
        assert 0.5 < waited < 30.0
        assert len(notes) == 1 and f"pid {stand_in.pid}" in notes[0]
        # a compile that does not end is waited for up to the limit only
        (tmp_path / first_run.LOCK_NAME).write_text(first_run._lock_text(os.getpid(), ["x.yaml"]))
        assert 0.2 <= first_run.wait_for_background_compile(notes.append, poll=0.05, limit=0.2) < 5.0
    finally:
        stand_in.kill()
        stand_in.wait()


class _KilledChild:
    def __init__(self, args, env=None, **kwargs):
        self.env = env

    def wait(self):
        return -signal.SIGKILL   # subprocess's code for a child ended by a signal

    def send_signal(self, signum):
        pass


def test_a_child_ended_by_a_signal_gives_the_shell_s_exit_code(monkeypatch):
    monkeypatch.setattr(first_run.subprocess, "Popen", _KilledChild)
    assert first_run.run_interpreted(["x.yaml"]) == 128 + signal.SIGKILL


def test_an_internal_error_of_the_interpreted_run_is_one_line_and_its_traceback_is_kept(monkeypatch, tmp_path,
                                                                                        capsys):
    """A bug that only the interpreted kernels hit must not greet a new user with a traceback:
    the child says one line and keeps the traceback; the parent then compiles (exit 1 is the
    code that makes ``run`` fall back)."""
    from magica_py import cli, runner

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv(first_run.TIER_ENV, first_run.INTERPRETED)
    monkeypatch.setattr(first_run, "start_background_compile", lambda argv: first_run.Background(None, None, "failed"))

    def broken_play(*args, **kwargs):
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setattr(runner, "play", broken_play)
    errors = np.geterr()   # the interpreted tier turns numpy's warnings off (quiet_floating_point)
    try:
        assert cli.main(["run", str(ROOT / "configs" / "tail_orbit.yaml"), "--no-rrd", "--frames", "2"]) == \
            cli.EXIT_FAILURE
    finally:
        np.seterr(**errors)
    err = capsys.readouterr().err
    kept = tmp_path / first_run.FAILURE_LOG_NAME
    assert ("magica-py: internal error in the interpreted first run: ZeroDivisionError: float division by zero "
            f"(traceback in {kept})") in err
    assert "Traceback" not in err
    assert "Traceback" in kept.read_text() and "broken_play" in kept.read_text()
    # outside the interpreted tier an internal error still shows its traceback
    monkeypatch.delenv(first_run.TIER_ENV)
    monkeypatch.setenv("MAGICA_FIRST_RUN", "compile")
    assert cli.main(["run", str(ROOT / "configs" / "tail_orbit.yaml"), "--no-rrd", "--frames", "2"]) == cli.EXIT_FAILURE
    err = capsys.readouterr().err
    assert "Traceback" in err and "magica-py: internal error: float division by zero" in err
