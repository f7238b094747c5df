"""A first run's compile on two cores: a forked process compiles the step's stages and the last
of the begin of frame while the system's process builds the cloths and compiles the rest.

numba compiles one function at a time in a process (a process-wide compiler lock), and a
scene's first frame with an empty kernel cache compiles every stage it uses (docs/BENCHMARKS.md,
*First run*). The frame kernel's typing reaches the stages in order: each block's begin of
frame, its steps, then its end of frame (guards, display, rotations, write-back). On a first
run the work is split in two:

* **The helper** is forked when the ``ClothSystem`` is constructed, before its cloths are built
  (``start_early``). It makes the tables of a system with no cloth: the frame kernel's argument
  types are those of any system's tables (arrays of fixed dtypes and dimensions, checked by
  ``tests/test_compile_helper.py``), so nothing has to be built to know them. It compiles the
  step's stages with those types (``frame.compile_step_stages``: typed and compiled, never
  run) for the stages the specs announce
  (``ClothSystem.expected_stage_switches``: what the parameters, connection modes and
  colliders ask for, a superset of what the built models use) and writes them to numba's
  on-disk cache (``cache=True``, the documented cache; the cache starts empty and is filled by
  the two processes). It then compiles what the frame kernel's typing reaches last, in
  reverse order (``frame.compile_late_stages``: the close of frame, the team clocks' step, the
  colliders' frame, the center and inertia), so that the two processes meet in the middle of
  the begin of frame.
* **The system's process** meanwhile builds the cloths, runs the first frame's animation and
  hierarchy (compiling them), and at its first frame call compiles the end-of-frame stages
  (``meet``: ``frame.compile_end_stages``, likewise not run), then, typing the frame kernel,
  the begin of frame; the step's stages it finds in the cache.

Any function the helper has not finished, the system's process compiles itself. The results
are the same functions, so the same bits. Started at construction, the helper has the build,
the first frame's animation and the end of frame to work beside (docs/BENCHMARKS.md, *Figures
of session 15*: first runs 5-9 s shorter than with a helper forked at the first frame call). A
system constructed without cloths (teams added later) forks at its first frame call instead
(``start``), as does any system whose early helper was not wanted.

Only where it is safe and useful: Linux (``os.fork``), the JIT and the cache on, at least two
CPUs of which one is free (the 1-minute load average at most the CPUs less a half, or, where it
still counts a run just ended, one and a half CPUs idle over a tenth of a second: on a machine
kept busy by other jobs the helper would share this process's CPU and lengthen the run), called
from the main thread (a batch runner's worker threads never fork), and only while the frame
kernels have no compiled signature in this process; one early helper per process.
``MAGICA_COMPILE_HELPER=0`` turns it off. The helper writes nothing (its standard output and
error go to the null device) and leaves with ``os._exit`` (no buffered output is flushed twice,
no exit handler runs); ``finish`` reaps it after the frame kernel's first call, ending it if it
is still compiling (what it had not finished, the system's process has compiled by then), or
at this process's exit when the system never ran a frame.
"""
from __future__ import annotations

import atexit
import os
import signal
import sys
import threading
import time

from numba import config

from magica_py import jit
from magica_py.solver.frame import (
    compile_end_stages, compile_late_stages, compile_step_stages, simulate_frame, simulate_worker,
)

_early = {"started": False, "pid": None}   # one early helper per process (start_early) and its pid
_reaped: set[int] = set()   # helpers reaped (finish, early_helper_running): never waited for again


def wanted(*kernels) -> bool:
    """Is a helper worth starting before the first call of ``kernels`` (``simulate_frame`` or
    its parallel twin): none compiled in this process yet, a cache to share, two or more CPUs?"""
    if os.environ.get("MAGICA_COMPILE_HELPER", "1") == "0" or config.DISABLE_JIT or not jit.CACHE:
        return False
    if not sys.platform.startswith("linux") or threading.current_thread() is not threading.main_thread():
        return False
    if any(k.signatures for k in kernels) or early_helper_running():
        return False
    cpus = len(os.sched_getaffinity(0))
    # a helper pays only with a CPU to itself: with another job keeping every CPU but this
    # process's busy, it would take its compile time from ours. The 1-minute load average
    # lags: right after another run it still counts that run, so where it says busy the CPUs'
    # idle time over a tenth of a second decides
    if cpus < 2:
        return False
    return os.getloadavg()[0] <= cpus - 0.5 or idle_cpus() >= 1.5


def early_helper_running() -> bool:
    """Is this process's early helper (``start_early``) still compiling? Another system's first
    frame then forks no second helper: the two would share the CPU that one of them needs."""
    pid = _early.get("pid")
    if pid is None:
        return False
    if pid in _reaped:
        done = pid
    else:
        try:
            done, _status = os.waitpid(pid, os.WNOHANG)
        except ChildProcessError:   # reaped elsewhere
            done = pid
    if done != 0:
        _early["pid"] = None
        _reaped.add(pid)
    return done == 0


def idle_cpus(window: float = 0.1) -> float:
    """How many CPUs were idle on average over the next ``window`` seconds (``/proc/stat``:
    idle and I/O-wait time over all time), this process sleeping meanwhile; 0 where it cannot
    be read."""
    def times():
        with open("/proc/stat") as f:
            values = [int(v) for v in f.readline().split()[1:9]]
        return values[3] + values[4], sum(values)

    try:
        idle0, total0 = times()
        time.sleep(window)
        idle1, total1 = times()
    except (OSError, ValueError, IndexError):
        return 0.0
    total = total1 - total0
    return os.cpu_count() * (idle1 - idle0) / total if total > 0 else 0.0


def start_early(system, settings, parallel, wind) -> int | None:
    """At a ``ClothSystem``'s construction, before its cloths are built: on a first run (the
    frame kernels not compiled in this process, ``wanted``), fork the helper. It makes the
    tables of a system with no cloth (the same array types as any system's: nothing of them is
    read, the compile functions do not run) and compiles the step's stages for the stage
    switches the specs announce (``ClothSystem.expected_stage_switches``), then the late
    stages, while this process builds the cloths, runs the first frame's animation and
    compiles the end of frame (``meet``). Returns the helper's pid, or None. Once per process."""
    if _early["started"] or not wanted(simulate_frame, simulate_worker):
        return None
    _early["started"] = True
    pid = fork_early(system, settings, parallel, wind)
    if pid is not None:
        _early["pid"] = pid
        atexit.register(finish, pid)   # a system never run: the helper does not outlive this process
    return pid


def fork_early(system, settings, parallel, wind) -> int | None:
    """``start_early``'s fork, unconditionally: the helper's pid (its exit status 0 when it
    compiled its share, 1 when anything in it failed), or None where fork failed."""
    stages = system.expected_stage_switches()
    try:
        pid = os.fork()
    except OSError:
        return None
    if pid == 0:
        code = 0
        try:
            _quiet()
            from magica_py.solver.system import ClothSystem

            empty = ClothSystem(system.hierarchy, [], system.colliders, settings, parallel=parallel, wind=wind)
            _compile_helper_share(empty._frame_arrays(), empty._frame_values, empty._wind_zones(), stages)
        except BaseException:
            code = 1
        os._exit(code)
    return pid


def _quiet() -> None:
    """The helper writes nothing: its standard output and error go to the null device (the
    run's compile announcement and progress belong to the system's process)."""
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 1)
    os.dup2(null, 2)
    os.close(null)


def _compile_helper_share(F, frame_values, wind_zones, stages) -> None:
    """The helper's compile, with Python's garbage collector running less often (the helper
    does nothing else: ``jit.fewer_collections``)."""
    with jit.fewer_collections():
        compile_step_stages(F, frame_values, wind_zones, stages.angle, stages.bending, stages.point_collision,
                            stages.edge_collision, stages.motion, stages.quality, stages.wind, stages.colliders)
        compile_late_stages(F, frame_values, stages.colliders)


def start(F, frame_values, area, wind_zones, stages) -> int | None:
    """Fork the helper at the first frame call (``compile_step_stages`` with the frame's arrays
    ``F``, frame inputs, wind table and ``frame.StageSwitches``), then ``meet`` it here; returns
    the helper's pid, or None where fork failed (the frame kernel then compiles everything in
    this process)."""
    try:
        pid = os.fork()
    except OSError:
        return None
    if pid == 0:   # the helper: compile, then leave without any of the parent's exit work
        code = 0
        try:
            _quiet()
            _compile_helper_share(F, frame_values, wind_zones, stages)
        except BaseException:
            code = 1
        os._exit(code)
    return meet(pid, F, frame_values, area, stages)


def meet(pid: int, F, frame_values, area, stages) -> int:
    """This process's share while the helper ``pid`` compiles: the end-of-frame stages
    (``compile_end_stages`` with the save area, not run); the frame kernel's typing then finds
    the helper's stages in the cache. Returns ``pid``."""
    try:
        compile_end_stages(F, frame_values, area, stages.quality, stages.lines, stages.triangles, stages.colliders)
    except BaseException:
        finish(pid)
        raise
    return pid


def finish(pid: int | None) -> None:
    """Reap the helper after the frame kernel's first call (ending it if still compiling).
    A helper already reaped is left alone: its pid may since belong to another process."""
    if pid is None or pid in _reaped:
        return
    try:
        done, _ = os.waitpid(pid, os.WNOHANG)
        if done == 0:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
    except (ChildProcessError, ProcessLookupError):
        pass
    _reaped.add(pid)
