"""The threads' shares of a parallel frame, from how fast each thread went in the frames before.

A parallel frame deals its blocks to the threads in runs of consecutive blocks
(``frame.assign_workers``), thread w's run holding about ``worker_share[w]`` of the frame's
load (a block's load: particles x lanes x steps, ``frame.block_load``). Equal shares leave
the threads unequal where a unit of load does not cost the same on every thread: one thread's
blocks run costlier stages (a skirt's bending beside a strand's line), or one thread goes
slower (the calling thread's core, a neighbour on the host). Measured on the light scene,
2 threads: the calling thread's run took 2.7-2.9 ms where the other's took 2.5-2.6 ms for
about the same load, and the frame waits for the slower (docs/BENCHMARKS.md, session 34).

``WorkerBalance`` keeps each thread's seconds per unit of load, a running mean over the
frames (``SMOOTHING``), and gives each thread a share in proportion to its speed (the
inverse), so that the runs end together (a thread's time is counted to the end of its run from the
moment the threads are handed their runs: the other threads' wake-up, 30-50 µs, counts too). The shares decide only which thread runs a block:
blocks are independent, so the results are the same bits whatever the shares (tests:
``tests/test_worker_balance.py``). A share never falls below ``FLOOR`` of an equal share,
so that a thread stalled for a few frames by the host gets its blocks back when it recovers.
"""
from __future__ import annotations

import numpy as np

# weight of one frame's measurement in a thread's running seconds per unit of load: about the
# last ten frames count (a frame's own timing varies by 10-30 % on a shared host)
SMOOTHING = 0.1
# lowest share of a thread, as a fraction of an equal share
FLOOR = 0.25


class WorkerBalance:
    """Running seconds per unit of load of ``threads`` threads, and the shares they give."""

    def __init__(self, threads: int):
        self.threads = max(int(threads), 1)
        # (threads,) s per unit of load, running mean; 0 where not measured yet
        self.rate = np.zeros(self.threads)

    def update(self, seconds, load, workers: int, share: np.ndarray) -> None:
        """Fold in one frame: ``seconds[w]`` when thread w's run ended (from the moment the
        threads were handed their runs, so that a thread's wake-up counts), ``load[w]`` its
        load (``WorkerTable.worker_load``), for the ``workers`` threads that had blocks; then
        write the next frame's shares to ``share`` (``WorkerTable.worker_share``). The shares
        change only once every thread has been measured."""
        rate = self.rate
        workers = min(int(workers), self.threads)
        measured = 0
        mean = 0.0
        for w in range(workers):
            if load[w] > 0 and seconds[w] > 0.0:
                r = seconds[w] / float(load[w])
                rate[w] = r if rate[w] == 0.0 else rate[w] + SMOOTHING * (r - rate[w])
                measured += 1
                mean += rate[w]
        if workers < 2 or measured == 0:
            return
        # a thread that got no block (its share below half a block) drifts back towards the
        # others' mean, so that it gets blocks again rather than keep an old measure for ever
        mean /= measured
        for w in range(workers):
            if load[w] == 0 and rate[w] > 0.0:
                rate[w] += SMOOTHING * (mean - rate[w])
        speed = [0.0] * workers
        for w in range(workers):
            if rate[w] <= 0.0:
                return
            speed[w] = 1.0 / rate[w]
        total = sum(speed)
        floor = FLOOR / workers
        low = [speed[w] / total < floor for w in range(workers)]
        # the threads below the floor get the floor, the others the rest in proportion to speed
        rest = sum(speed[w] for w in range(workers) if not low[w])
        scale = (1.0 - floor * sum(low)) / rest
        for w in range(workers):
            share[w] = floor if low[w] else speed[w] * scale
