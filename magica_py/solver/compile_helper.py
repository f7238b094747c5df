"""A first run's compile on two cores: a forked process compiles the step's stages and the last
of the begin of frame.

numba compiles one function at a time in a process (a process-wide compiler lock), and a
scene's first frame with an empty kernel cache compiles every stage it uses (docs/BENCHMARKS.md,
*First run*). The frame kernel's typing reaches the stages in order: each block's begin of
frame, its steps, then its end of frame (guards, display, rotations, write-back). On a first
run the work is split in two: a forked copy of the process compiles the step's stages with
exactly the frame kernel's argument types (``frame.compile_step_stages``: typed and compiled,
run with ``run=0`` so nothing executes) and writes them to numba's on-disk cache
(``cache=True``, the documented cache; the cache starts empty and is filled by the two
processes), while the system's process compiles the end-of-frame stages
(``frame.compile_end_stages``, likewise not run) and then, typing the frame kernel, the begin
of frame. The step's stages are the largest of the three shares (on the tail about 14 s
against about 10 s each for the other two), so the helper has finished them when the frame
kernel's typing reaches them, and that typing loads them from the cache. The helper then
compiles what that typing reaches last, in reverse order (``frame.compile_late_stages``: the
close of frame, the team clocks' step, the colliders' frame, the center and inertia), so that
the two processes meet in the middle of the begin of frame instead of the helper leaving
while the system's process works through it alone (the tail's last stage compiled ~2 s
sooner). Any function the helper has not finished, the system's process compiles itself. The
results are the same functions, so the same bits.

Only where it is safe and useful: Linux (``os.fork``), the JIT and the cache on, at least two
CPUs of which one is free (the 1-minute load average at most the CPUs less a half: on a machine
kept busy by other jobs the helper would share this process's CPU and lengthen the run), called
from the main thread (a batch runner's worker threads never fork), and only while
the frame kernel has no compiled signature in this process. ``MAGICA_COMPILE_HELPER=0`` turns it
off. The helper leaves with ``os._exit`` (no buffered output is flushed twice, no exit handler
runs); ``finish`` reaps it after the frame kernel's first call, ending it if it is still
compiling (what it had not finished, the system's process has compiled by then).
"""
from __future__ import annotations

import os
import signal
import sys
import threading

from numba import config

from magica_py import jit
from magica_py.solver.frame import compile_end_stages, compile_late_stages, compile_step_stages


def wanted(kernel) -> bool:
    """Is a helper worth starting before ``kernel``'s (``simulate_frame`` or its parallel
    twin) call: its first in this process, with a cache to share, on two or more CPUs?"""
    if os.environ.get("MAGICA_COMPILE_HELPER", "1") == "0" or config.DISABLE_JIT or not jit.CACHE:
        return False
    if not sys.platform.startswith("linux") or threading.current_thread() is not threading.main_thread():
        return False
    cpus = len(os.sched_getaffinity(0))
    # a helper pays only with a CPU to itself: with another job keeping every CPU but this
    # process's busy (the 1-minute load average), it would take its compile time from ours
    if cpus < 2 or os.getloadavg()[0] > cpus - 0.5:
        return False
    return not kernel.signatures


def start(F, frame_values, area, wind_zones, stages) -> int | None:
    """Fork the helper (``compile_step_stages`` with the frame's arrays ``F``, frame inputs,
    wind table and ``frame.StageSwitches``), then compile the end-of-frame stages here
    (``compile_end_stages`` with the save area); returns the helper's pid, or None where fork
    failed (the frame kernel then compiles everything in this process)."""
    try:
        pid = os.fork()
    except OSError:
        return None
    if pid == 0:   # the helper: compile, then leave without any of the parent's exit work
        code = 0
        try:
            compile_step_stages(F, frame_values, 0, wind_zones, stages.angle, stages.bending, stages.point_collision,
                                stages.edge_collision, stages.motion, stages.quality, stages.wind)
            compile_late_stages(F, frame_values, 0)
        except BaseException:
            code = 1
        os._exit(code)
    try:
        compile_end_stages(F, frame_values, area, 0, stages.quality, stages.lines, stages.triangles)
    except BaseException:
        finish(pid)
        raise
    return pid


def finish(pid: int | None) -> None:
    """Reap the helper after the frame kernel's first call (ending it if still compiling)."""
    if pid is None:
        return
    try:
        done, _ = os.waitpid(pid, os.WNOHANG)
        if done == 0:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
    except (ChildProcessError, ProcessLookupError):
        pass
