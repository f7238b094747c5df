"""The floor of the light scene's UPDATE propagation: its world poses composed from rows already
in structure-of-arrays level order, nothing gathered and nothing scattered (issue 15, item 4).

    python benchmarks/propagation_floor.py [--chains 1000] [--levels 17] [--calls 300] [--threads 1 2]

The light scene's UPDATE plan composes 17,000 world poses a frame: the 1,000 orbiting roots and
their 16-bone chains, one depth level after another. Today each level's nodes are gathered from
the hierarchy's node-ordered arrays into lane rows, composed there (``propagation.compose_lanes``)
and scattered back (``benchmarks/propagation_pieces.py`` times the three). This script keeps
only the middle step: it lays the poses out as the hierarchy would have to store them to need
no gather and no scatter (structure of arrays, level by level, a chain's nodes in the same lane
on every level), and calls ``compose_lanes`` on each level's segments of ``SEGMENT_WIDTH``
lanes, each level's parents read from the level above's output rows. With ``--threads 2`` the
chains are split in two halves, each composed by its own thread in one ``nogil`` call (the
second a ``magica_py.threads.FrameThreads`` worker, the hand-off the propagation plans use). It prints the min and median of
``--calls`` whole passes: what the UPDATE propagation would cost at best with the project's
arithmetic (the same bits as ``propagate_node``), against the 100 µs of issue 15.
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np


def make_levels(chains: int, levels: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """``(store, counts)``: one scratch block per level and segment of at most
    ``SEGMENT_WIDTH`` chains, ``store[level * segments + s]``, of ``LANE_INPUT + LANE_PARENT +
    LANE_OUTPUT`` rows of ``LANE_STRIDE`` doubles (local pose rows, parent rows, output rows),
    filled with plausible local poses (unit quaternions, unit scales; the first level's parent
    rows an identity matrix and rotation); ``counts[s]``: the chains of segment s."""
    from magica_py.scene import propagation as pr

    stride = pr.LANE_STRIDE
    rows = pr.LANE_INPUT + pr.LANE_PARENT + pr.LANE_OUTPUT
    counts = np.array([min(pr.SEGMENT_WIDTH, chains - start) for start in range(0, chains, pr.SEGMENT_WIDTH)],
                      dtype=np.int64)
    store = np.zeros((levels * counts.size, rows * stride))
    for k in range(levels):
        for s, count in enumerate(counts):
            block = store[k * counts.size + s]
            q = rng.normal(size=(4, count))
            q /= np.linalg.norm(q, axis=0)
            for r in range(3):
                block[r * stride:r * stride + count] = rng.normal(size=count) * 0.05
                block[(7 + r) * stride:(7 + r) * stride + count] = 1.0
            for r in range(4):
                block[(3 + r) * stride:(3 + r) * stride + count] = q[r]
            base = pr.LANE_INPUT * stride
            for r in (0, 5, 10, 15):
                block[base + r * stride:base + r * stride + count] = 1.0
    return store, counts


def _pass_kernel():
    from magica_py.jit import kernel
    from magica_py.scene import propagation as pr

    stride = pr.LANE_STRIDE
    i0, i1 = pr.LANE_INPUT * stride, (pr.LANE_INPUT + pr.LANE_PARENT) * stride
    o1 = i1 + pr.LANE_OUTPUT * stride
    p1 = i1 + pr.LANE_PARENT * stride
    compose = pr.compose_lanes

    @kernel(cache=False)
    def pass_over(store, counts, levels, s0, s1):
        """Every level of segments s0..s1 in order; a level's parents are the level above's
        output rows (the first level's its own parent rows)."""
        segments = counts.shape[0]
        for k in range(levels):
            for s in range(s0, s1):
                block = store[k * segments + s]
                if k > 0:
                    parents = store[(k - 1) * segments + s][i1:p1]
                else:
                    parents = block[i0:i1]
                compose(counts[s], block[:i0], parents, block[i1:o1])

    return pass_over


def measure(store, counts, levels: int, threads: int, calls: int, pass_over) -> list[float]:
    """``calls`` whole passes; with two threads the second half of the segments goes to a
    ``FrameThreads`` worker (the project's hand-off: one lock each way), one call each."""
    from magica_py.threads import FrameThreads

    segments = counts.size
    if threads == 1 or segments < 2:
        ranges = [(0, segments)]
        pool = None
    else:
        half = segments // 2
        ranges = [(0, half), (half, segments)]
        pool = FrameThreads(1, name="propagation-floor")
    second = (lambda: pass_over(store, counts, levels, *ranges[1])) if pool is not None else None
    times = []
    for _ in range(calls):
        start = time.perf_counter()
        if pool is None:
            pass_over(store, counts, levels, *ranges[0])
        else:   # one call a thread: the kernel releases the GIL for the whole pass
            pool.run([second])
            pass_over(store, counts, levels, *ranges[0])
            pool.join()
        times.append(time.perf_counter() - start)
    if pool is not None:
        pool.close()
    return times


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--chains", type=int, default=1000)
    ap.add_argument("--levels", type=int, default=17, help="depth levels (the light scene: the root and 16 bones)")
    ap.add_argument("--calls", type=int, default=300)
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    args = ap.parse_args(argv)
    store, counts = make_levels(args.chains, args.levels, np.random.default_rng(1))
    nodes = args.chains * args.levels
    pass_over = _pass_kernel()
    measure(store, counts, args.levels, 1, 3, pass_over)   # compile / warm
    for t in args.threads:
        v = measure(store, counts, args.levels, t, args.calls, pass_over)
        print(f"{nodes} nodes in {args.levels} levels, {t} thread(s): min {min(v) * 1e6:7.1f} us   "
              f"median {statistics.median(v) * 1e6:7.1f} us   ({min(v) / nodes * 1e9:.1f} ns a node at the min)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
