"""The extra threads of a parallel frame and of a parallel hierarchy propagation.

A parallel cloth frame (``ClothSystem`` with ``threads`` > 1) runs thread 0's share of the
blocks in the calling thread and the others' here, one job per thread per frame
(``solver.frame.simulate_worker``); a propagation plan of several chunks runs its first chunk in
the calling thread and the others here (``scene.propagation.PropagationPlan.execute``). The
jobs call ``nogil`` kernels, so the threads run side by side; the package has no ``prange`` and
runs nothing on numba's parallel threading layers. Each thread waits on a lock of its own for
its job and releases another when the job is done: a hand-off is a lock release and a lock
acquire per thread, the cheapest wake-up Python offers (an executor's queue, futures and
conditions cost more per frame, and a frame of the light scene is ~4 ms). Idle threads sleep.
"""
from __future__ import annotations

import os
import threading
import weakref


class FrameThreads:
    """``count`` threads that run one job each per ``run`` / ``join`` pair."""

    def __init__(self, count: int, name: str = "magica-cloth"):
        self.count = count
        self.name = name
        self._closed = False
        self._running = 0
        self._spawn()

    def _spawn(self) -> None:
        """The jobs' slots, the locks and the threads, in this process. ``run`` spawns them again
        in a forked child (a batch worker, a compile helper), where the parent's threads do not
        exist: a job handed to them would never run and ``join`` would wait for ever."""
        count = self.count
        self._pid = os.getpid()
        self._jobs: list = [None] * count
        self._errors: list = [None] * count
        self._start = [threading.Lock() for _ in range(count)]
        self._done = [threading.Lock() for _ in range(count)]
        for lock in self._start + self._done:
            lock.acquire()
        self._threads = [threading.Thread(target=_serve, args=(self._jobs, self._errors, self._start[i],
                                                               self._done[i], i),
                                          name=f"{self.name}-{i + 1}", daemon=True) for i in range(count)]
        for thread in self._threads:
            thread.start()
        # the threads hold no reference to self, so an unused pool is collected and its
        # threads told to leave
        self._finalizer = weakref.finalize(self, _stop, self._jobs, self._start)

    def run(self, jobs) -> None:
        """Start ``jobs`` (at most ``count`` callables without arguments), one per thread."""
        if self._closed:
            raise RuntimeError("FrameThreads: closed")
        if len(jobs) > self.count:
            raise ValueError(f"FrameThreads: {len(jobs)} jobs for {self.count} threads")
        if self._pid != os.getpid():   # a forked child: the threads are the parent's
            self._finalizer.detach()
            self._spawn()
        self._running = len(jobs)
        for i, job in enumerate(jobs):
            self._jobs[i] = job
            self._start[i].release()

    def join(self) -> None:
        """Wait for the jobs of the last ``run``; raise the first error one of them raised."""
        error = None
        for i in range(self._running):
            self._done[i].acquire()
            if self._errors[i] is not None and error is None:
                error = self._errors[i]
            self._errors[i] = None
            self._jobs[i] = None
        self._running = 0
        if error is not None:
            raise error

    def close(self) -> None:
        """Tell the threads to leave (after the last ``join``)."""
        if not self._closed:
            self._closed = True
            _stop(self._jobs, self._start)


_STOP = object()


def _serve(jobs, errors, start, done, i) -> None:
    while True:
        start.acquire()
        job = jobs[i]
        if job is _STOP:
            return
        try:
            job()
        except BaseException as exc:   # handed to join, raised in the calling thread
            errors[i] = exc
        done.release()


def _stop(jobs, start) -> None:
    for i, lock in enumerate(start):
        jobs[i] = _STOP
        try:
            lock.release()
        except RuntimeError:   # a job was started and not yet taken: the thread leaves after it
            pass
