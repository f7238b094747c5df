"""A first run that does not wait for the compile: a short run goes interpreted while the
solver compiles in the background for the next runs.

With an empty numba cache, ``magica-py run`` compiles every kernel the scene uses before its
first frame: 40-80 s of compile work on a 2-core machine (docs/BENCHMARKS.md, *First run*).
The same kernels run as plain Python with numba's documented ``NUMBA_DISABLE_JIT=1`` and give
the compiled run's bits (``tests/test_jit_off.py``), at about 2 ms a particle-step: a few
hundred frames of a tail or a few dozen of a character take seconds, far less than their
compile. So ``run`` has two tiers:

* **interpreted** (the first run of a short scene): ``run`` starts itself again as a child
  process with ``NUMBA_DISABLE_JIT=1`` (numba reads it once, at import, so the choice is made
  before the child imports numba). The child loads the scene and estimates the run's
  particle-steps (``estimate_particle_steps``: frames x steps a frame x particles). Within
  the budget (``MAGICA_INTERPRET_BUDGET``, default ``INTERPRET_BUDGET``), it starts the
  background compile and runs the scene interpreted: the same recording, summary and exit
  code as a compiled run, its summary saying it ran interpreted.
* **compiled**: any other run. Where the child finds the run too long to interpret, it exits
  with ``DECLINED`` before it has written anything, and ``run`` compiles in its own process
  as it always did (the compile announced, timed apart from the frames, shared with the
  compile helper: ``solver/compile_helper.py``).

**The background compile** (``python -m magica_py.first_run RUN-ARGUMENTS``) is a compiled
run of the same scene and arguments: it loads the scene, attaches the solver and a recording
sink writing to a scratch file, runs the scene's frames (its whole length or the run's
``--frames``, whichever is longer, for at most ``BACKGROUND_SECONDS`` after the first
``COMPILE_FRAMES``), and exits. Everything the run needs (the scene's kernels, the build, the
drivers, the propagation, the cloth frame, the sink's, and what the scene's events reach
later: a teleport's propagation, a parameter change that switches a stage on) is then in
numba's on-disk cache, so the next run of the scene starts compiled. It
runs in a session of its own, after the interpreted run has ended if need be; its pid is in
``first-run-compile.pid`` and its output in ``first-run-compile.log`` in the numba cache
folder. While one runs, no other is started; a run that finds no compiled frame kernel then
still goes interpreted when it is short, and compiles itself when it is long.

**When.** Only for ``run`` (and ``watch``, which hands such a run to ``run``: ``watch.py``)
with the JIT and the cache on, a cloth to simulate, and no compiled cloth frame in the cache
folder (``frame_kernel_cached``: a scene of another kind of cloth on a warm cache compiles in
the compiled tier). ``MAGICA_FIRST_RUN``: ``auto`` (the default: as above), ``compile`` (never
interpreted: the behaviour before this module; the test suite's default), ``interpret``
(interpreted whenever the run is within the budget, compiled frame kernel in the cache or not).

An internal error of the interpreted run (a bug: a difference between the kernels run as
Python and compiled) ends the child with one line, its traceback kept in
``first-run-interpreted-error.log`` in the cache folder, and ``run`` then compiles.

In the interpreted tier numpy's floating-point warnings are off (``numpy.seterr``): the
kernels' branch-free selects compute, and then discard, values that divide by zero, which
compiled (``error_model="numpy"``) warns about nowhere; without this the recording would
carry warning events that a compiled run of the same scene does not.

This module imports nothing heavy at import time: ``run`` consults it before numba is loaded.
"""
from __future__ import annotations

import json
import math
import os
import pathlib
import subprocess
import sys
import time
from typing import NamedTuple

MODE_ENV = "MAGICA_FIRST_RUN"           # auto | compile | interpret
MODES = ("auto", "compile", "interpret")
BUDGET_ENV = "MAGICA_INTERPRET_BUDGET"  # particle-steps a run may have to go interpreted
TIER_ENV = "MAGICA_RUN_TIER"            # "interpreted" in the interpreted child
INTERPRETED = "interpreted"
# About 12 s of interpreted frames on the 2-core machine of docs/BENCHMARKS.md (1.7-2.4 ms a
# particle-step, measured on the tail, the character and the crowd), against 40-80 s of
# compile there: a run within it ends well before its compile would have.
INTERPRET_BUDGET = 6000
DECLINED = 75            # the child's exit code: too long to interpret, nothing written
COMPILE_FRAMES = 3       # frames the background compile always runs (the first frame's reset, then steady frames)
BACKGROUND_SECONDS = 20.0   # then it runs on through the scene while it takes no longer than this
LOCK_NAME = "first-run-compile.pid"
LOG_NAME = "first-run-compile.log"
FAILURE_LOG_NAME = "first-run-interpreted-error.log"   # the traceback of a failed interpreted run
FRAME_KERNEL_INDEX = "frame.simulate_*.nbi"   # numba's cache index of a compiled cloth frame


class FirstRunError(Exception):
    """A bad ``MAGICA_FIRST_RUN`` / ``MAGICA_INTERPRET_BUDGET`` value."""


def mode() -> str:
    value = os.environ.get(MODE_ENV, "").strip().lower() or "auto"
    if value not in MODES:
        raise FirstRunError(f"environment variable {MODE_ENV}={os.environ[MODE_ENV]!r}: expected 'auto' (a short "
                            "first run goes interpreted; the default), 'compile' (always compile) or 'interpret' "
                            "(a short run goes interpreted even with compiled kernels cached)")
    return value


def budget() -> int:
    text = os.environ.get(BUDGET_ENV, "").strip()
    if not text:
        return INTERPRET_BUDGET
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise FirstRunError(f"environment variable {BUDGET_ENV}={text!r}: expected a whole number of "
                            "particle-steps, 0 or more")
    return value


def in_interpreted_tier() -> bool:
    """Is this process the interpreted child of a ``run``?"""
    return os.environ.get(TIER_ENV) == INTERPRETED


def cache_folder() -> pathlib.Path | None:
    """numba's cache folder for this package's sources (``magica_py._configure_numba_cache``)."""
    folder = os.environ.get("NUMBA_CACHE_DIR")
    return pathlib.Path(folder) if folder else None


def frame_kernel_cached(folder: pathlib.Path | None = None) -> bool:
    """Does the cache folder hold a compiled cloth frame (any scene's)?"""
    folder = cache_folder() if folder is None else folder
    return folder is not None and folder.is_dir() and any(folder.glob("*/" + FRAME_KERNEL_INDEX))


def _flag(name: str) -> bool:
    return os.environ.get(name, "0").strip() not in ("", "0")


def wanted(args) -> bool:
    """Should ``run`` (its parsed ``args``) try the interpreted tier? (Made before numba is
    imported; the particle-step budget is checked by the child, once the scene is loaded.)"""
    chosen = mode()
    budget()   # a bad value is reported before anything runs
    if chosen == "compile" or in_interpreted_tier() or getattr(args, "no_simulation", False):
        return False
    if _flag("NUMBA_DISABLE_JIT") or _flag("MAGICA_NO_CACHE") or cache_folder() is None:
        return False   # already interpreted, or no cache for a background compile to fill
    return chosen == "interpret" or not frame_kernel_cached()


def interpreted_child(argv: list[str], **popen_options) -> subprocess.Popen:
    """Start ``magica-py run ARGV`` as the interpreted child: the JIT off and this tier's
    variable set (``popen_options``: ``subprocess.Popen``'s, e.g. ``stdout``)."""
    env = dict(os.environ)
    env["NUMBA_DISABLE_JIT"] = "1"
    env[TIER_ENV] = INTERPRETED
    return subprocess.Popen([sys.executable, "-m", "magica_py.cli", "run", *argv], env=env, **popen_options)


def run_interpreted(argv: list[str]) -> int:
    """Run ``magica-py run ARGV`` in the interpreted child; its exit code (128 + N when a signal
    N ended it; ``DECLINED`` when it found the run too long and wrote nothing; ``magica_py.cli`` then compiles, as it does when
    the child failed unexpectedly). Its output goes to this process's terminal."""
    import signal
    import threading

    child = interpreted_child(argv)
    forwarding = threading.current_thread() is threading.main_thread() and hasattr(signal, "SIGTERM")
    if forwarding:   # a run ended from outside (a job scheduler's SIGTERM) ends its child as well
        previous = signal.signal(signal.SIGTERM, lambda signum, frame: child.send_signal(signum))
    try:
        while True:
            try:
                code = child.wait()
                break
            except KeyboardInterrupt:   # the child has the same ^C and reports it itself
                continue
        return 128 - code if code < 0 else code   # a child ended by signal N: the shell's 128 + N
    finally:
        if forwarding:
            signal.signal(signal.SIGTERM, previous)


# ----------------------------------------------------------------------------- estimate
def cloth_particles(scene) -> int:
    """Particles of the scene's cloths: every bone in the subtrees of each cloth's root bones
    (BoneCloth makes one particle per transform; a bone under two roots of a cloth once)."""
    h = scene.hierarchy
    total = 0
    for spec in scene.cloths:
        nodes: set[int] = set()
        for root in spec.root_bones:
            index = h.index_of(root) if isinstance(root, str) else int(root)
            nodes.update(h.descendants(index))
        total += len(nodes)
    return total


def estimate_particle_steps(scene, frames: int | None) -> float:
    """The run's particle-steps: frames x simulation steps a frame x particles. ``frames``
    None (a realtime clock) counts the scene's duration at its frame rate."""
    settings = scene.settings
    fps = settings.fps or 60.0
    if frames is None:
        frames = math.ceil((settings.duration or 0.0) * fps)
    steps = min(float(settings.max_steps_per_frame), max(1.0, settings.simulation_frequency / fps))
    return float(frames) * steps * cloth_particles(scene)


def interpret(scene, frames: int | None) -> bool:
    """In the interpreted child: is the run within the budget (else the child declines)?"""
    return estimate_particle_steps(scene, frames) <= budget()


def record_failure(text: str) -> pathlib.Path | None:
    """Keep the traceback of an interpreted run's internal error in the cache folder (the run
    then compiles: ``magica_py.cli``); returns the file, or None when it cannot be written."""
    folder = cache_folder()
    if folder is None:
        return None
    try:
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / FAILURE_LOG_NAME
        path.write_text(text)
        return path
    except OSError:
        return None


def quiet_floating_point() -> None:
    """numpy's floating-point warnings off for the interpreted tier (module docstring)."""
    import numpy as np

    np.seterr(all="ignore")


# ----------------------------------------------------------------------------- background compile
def _lock_path(folder: pathlib.Path) -> pathlib.Path:
    return folder / LOCK_NAME


def _alive(pid: int) -> bool:
    """Does process ``pid`` run? A zombie (ended, not yet reaped: an orphan under a PID 1 that
    does not reap) counts as ended."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            return f.read().rsplit(b")", 1)[1].split()[0] != b"Z"
    except (OSError, IndexError):
        return True


class Background(NamedTuple):
    """The background compile a run goes interpreted beside: ``pid`` (None where none runs),
    ``log`` (its output), ``state``: ``started`` (by this run), ``running`` (started by an
    earlier run of the same command), ``other`` (an earlier run of another command: this one
    may still compile at its next run), ``failed`` (could not start)."""

    pid: int | None
    log: pathlib.Path | None
    state: str


def _lock_text(pid: int, argv: list[str]) -> str:
    return f"{pid}\n{json.dumps({'argv': list(argv), 'cwd': os.getcwd()})}\n"


def _read_lock(folder: pathlib.Path) -> tuple[int | None, dict]:
    """(pid, {"argv", "cwd"}) of the lock, (None, {}) where there is none or it is unreadable."""
    try:
        lines = _lock_path(folder).read_text().splitlines()
        pid = int(lines[0])
    except (OSError, ValueError, IndexError):
        return None, {}
    try:
        run = json.loads(lines[1]) if len(lines) > 1 else {}
    except ValueError:
        run = {}
    return pid, run if isinstance(run, dict) else {}


def background_compile_pid(folder: pathlib.Path | None = None) -> int | None:
    """The pid of a background compile running for this cache folder, or None."""
    folder = cache_folder() if folder is None else folder
    if folder is None:
        return None
    pid, _run = _read_lock(folder)
    return pid if pid is not None and _alive(pid) else None


def start_background_compile(argv: list[str]) -> Background:
    """Start the background compile of ``run ARGV``, unless one runs already for this cache
    folder (at most one at a time: each uses the CPUs the next runs want)."""
    folder = cache_folder()
    if folder is None:
        return Background(None, None, "failed")
    log = folder / LOG_NAME
    env = dict(os.environ)
    env.pop("NUMBA_DISABLE_JIT", None)
    env.pop(TIER_ENV, None)
    env[MODE_ENV] = "compile"
    lock = _lock_path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        for _attempt in range(2):
            try:   # the lock is taken atomically: two first runs at once start one compile
                fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
                break
            except FileExistsError:
                pid, run = _read_lock(folder)
                if pid is not None and _alive(pid):
                    same = run.get("argv") == list(argv) and run.get("cwd") == os.getcwd()
                    return Background(pid, log, "running" if same else "other")
                if pid is None and time.time() - lock.stat().st_mtime < 5.0:   # a run starting one now
                    return Background(None, log, "other")
                lock.unlink(missing_ok=True)   # left by a compile that did not finish
        else:
            return Background(None, None, "failed")
        with os.fdopen(fd, "w") as lock_file, open(log, "w", encoding="utf-8") as out:
            process = subprocess.Popen([sys.executable, "-m", "magica_py.first_run", *argv], env=env,
                                       stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT,
                                       start_new_session=True)
            lock_file.write(_lock_text(process.pid, argv))
    except OSError:
        return Background(None, None, "failed")
    return Background(process.pid, log, "started")


WAIT_SECONDS = 600.0   # the longest a compiled run waits for a background compile to end


def wait_for_background_compile(note, poll: float = 0.5, limit: float = WAIT_SECONDS) -> float:
    """In a run about to compile: while a background compile (an earlier short run's) fills
    this cache folder, wait for it, saying so with ``note(text)``: the two would compile the
    same kernels side by side, each on the CPU the other needs. Returns the seconds waited
    (at most ``limit``; after that the run compiles whatever is still missing itself)."""
    pid = background_compile_pid()
    if pid is None:
        return 0.0
    note(f"waiting for the background compile an earlier first run started (pid {pid}; log: "
         f"{cache_folder() / LOG_NAME}); this run then starts from its cache ...")
    started = time.perf_counter()
    while _alive(pid) and background_compile_pid() == pid and time.perf_counter() - started < limit:
        time.sleep(poll)
    return time.perf_counter() - started


def interpreted_note(background: Background) -> str:
    """The line ``run`` prints when it goes interpreted."""
    head = ("first run: no compiled solver in the cache yet; this short run goes interpreted (the same results, "
            "slower frames)")
    pid, log, state = background
    if state == "started":
        return (f"{head} while the solver compiles in the background for the next runs (pid {pid}, about a "
                f"minute; log: {log})")
    if state == "running":
        return f"{head} while an earlier run's background compile of this scene finishes (pid {pid}; log: {log})"
    if state == "other":
        where = f" (pid {pid}; log: {log})" if pid is not None else ""
        return (f"{head}; another run's background compile is filling the cache{where}, so a later run of this "
                "scene may still compile what it alone uses")
    return f"{head}; the background compile could not start, so the next run compiles"


def _peak_memory() -> str:
    """``, peak memory N MB`` of this process or its largest waited-for child (the compile
    helper), where the platform reports it."""
    try:
        import resource
    except ImportError:
        return ""
    kb = max(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)
    return f", peak memory {kb / 1024:.0f} MB"


def background_compile(argv: list[str]) -> int:
    """The background compile's own work (``python -m magica_py.first_run RUN-ARGUMENTS``):
    the run's scene, solver and sink (recording to a scratch file, never to a viewer),
    the scene's frames (module docstring), compiled and cached. Returns 0, or 1 with the reason
    in the log; SIGTERM ends it with 143 (``_end_on_sigterm``)."""
    import tempfile

    from magica_py import cli

    folder = cache_folder()
    started = time.perf_counter()
    scratches: list[str] = []
    previous = _end_on_sigterm(folder, scratches, started)
    try:
        args = cli.build_parser().parse_args(["run", *argv])
        if args.save_scene:
            args.save_scene = None   # the run wrote it; the compile only reads the scene
        from magica_py.runner import CompileWatch
        from magica_py.runtime.player import Player

        # CompileWatch: Python's collector runs less often while numba compiles
        with CompileWatch() as watch, tempfile.TemporaryDirectory(prefix="magica-first-run-") as scratch:
            scratches.append(scratch)
            scene = cli.load_run_scene(args)
            player = Player.for_scene(scene)
            cli._attach_solver(player, scene, [])
            args.rrd = os.path.join(scratch, "compile.rrd")
            args.no_rrd, args.spawn, args.connect = False, False, None
            recorder = cli._attach_sink(player, scene, args, [])
            try:
                frames = max(scene.settings.frame_count() or COMPILE_FRAMES, args.frames or 0)
                deadline = None
                for n in range(frames):
                    player.step()
                    if n + 1 == COMPILE_FRAMES:
                        deadline = time.perf_counter() + BACKGROUND_SECONDS
                    elif deadline is not None and time.perf_counter() > deadline:
                        break
            finally:
                if recorder is not None:
                    recorder.close(False)
        print(f"compiled {scene.name!r} in {time.perf_counter() - started:.1f} s ({watch.seconds:.1f} s compiling"
              f"{_peak_memory()})", flush=True)
        return 0
    except BaseException as exc:   # noqa: BLE001 - the log is the only place to say it
        import traceback

        traceback.print_exc()
        print(f"background compile failed: {exc}", flush=True)
        return 1
    finally:
        if previous is not None:
            import signal

            signal.signal(signal.SIGTERM, previous)
        _release_lock(folder)


def _release_lock(folder: pathlib.Path | None) -> None:
    """Remove the background compile's lock when this process holds it."""
    if folder is not None:
        try:
            if _read_lock(folder)[0] == os.getpid():
                _lock_path(folder).unlink()
        except OSError:
            pass


def _end_on_sigterm(folder: pathlib.Path | None, scratches: list, started: float):
    """Make SIGTERM (``kill PID``, a test's clean-up) end the background compile at once and
    leave nothing behind: its scratch folders (the recording it writes), its lock, a line in
    its log, exit status 143. The handler exits itself rather than raise: an exception raised
    in the middle of numba's compiler can surface as another one or be lost inside it, the
    compile carrying on for tens of seconds. What numba had cached stays (it writes each file
    under a temporary name and renames it). Returns the previous handler (None where the
    platform has no SIGTERM)."""
    import shutil
    import signal

    if not hasattr(signal, "SIGTERM"):
        return None

    def end(signum, frame):
        for path in scratches:
            shutil.rmtree(path, ignore_errors=True)
        _release_lock(folder)
        print(f"background compile terminated after {time.perf_counter() - started:.1f} s (what compiled "
              "so far stays cached)", flush=True)
        os._exit(143)

    return signal.signal(signal.SIGTERM, end)


if __name__ == "__main__":
    sys.exit(background_compile(sys.argv[1:]))
