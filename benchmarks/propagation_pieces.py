"""What one segment of the hierarchy propagation costs, piece by piece (issue 15, item 4).

    python benchmarks/propagation_pieces.py [--lanes 512] [--nodes 20000] [--calls 2000] [--rounds 5]

A propagation plan (``scene/propagation.py``) computes each segment of a depth level in three
passes: ``gather_local`` copies the nodes' local poses from the hierarchy's (n, 3) / (n, 4)
arrays into structure-of-arrays rows, ``compose_lanes`` computes the world poses across the
lanes (vectorised), ``scatter_lanes`` writes them back to the hierarchy's arrays. This script
calls each pass on one segment of ``--lanes`` nodes, ``--calls`` times in a row (the rows stay
in the cache: the passes' own cost, not memory traffic), for nodes in a random order of
``--nodes`` (a forest's level: every node's rows on their own cache lines) and in node order,
and prints the median over ``--rounds`` rounds in ns a node. The light scene propagates about
17,000 nodes a frame, so 100 us a frame is 5.9 ns a node for all three passes together.
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np


def per_node(fn, args, calls: int, lanes: int) -> float:
    """ns a node of ``fn(*args)`` called ``calls`` times in a row."""
    fn(*args)
    start = time.perf_counter()
    for _ in range(calls):
        fn(*args)
    return (time.perf_counter() - start) / calls / lanes * 1e9


def measure(lanes: int, nodes: int, calls: int) -> dict[str, float]:
    from magica_py.scene import propagation as pr

    if lanes > pr.SEGMENT_WIDTH:
        raise SystemExit(f"--lanes: at most SEGMENT_WIDTH = {pr.SEGMENT_WIDTH}")
    rows = pr.LANE_STRIDE
    rng = np.random.default_rng(1)
    inputs = rng.random(pr.LANE_INPUT * rows)
    parents = rng.random(pr.LANE_PARENT * rows)
    outputs = np.zeros(pr.LANE_OUTPUT * rows)
    local_position, local_rotation, local_scale = rng.random((nodes, 3)), rng.random((nodes, 4)), rng.random((nodes, 3))
    world_position, world_rotation = np.zeros((nodes, 3)), np.zeros((nodes, 4))
    lossy_scale, local_to_world = np.zeros((nodes, 3)), np.zeros((nodes, 4, 4))
    scattered = rng.permutation(nodes)[:lanes].astype(np.int32)
    in_order = np.arange(lanes, dtype=np.int32)
    result = {"compose": per_node(pr.compose_lanes, (lanes, inputs, parents, outputs), calls, lanes)}
    for name, order in (("random order", scattered), ("node order", in_order)):
        result[f"gather, {name}"] = per_node(
            pr.gather_local, (order, 0, lanes, local_position, local_rotation, local_scale, inputs), calls, lanes)
        result[f"scatter, {name}"] = per_node(
            pr.scatter_lanes, (order, 0, lanes, world_position, world_rotation, lossy_scale, local_to_world,
                               outputs), calls, lanes)
    return result


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lanes", type=int, default=512, help="nodes in the segment (default: SEGMENT_WIDTH)")
    ap.add_argument("--nodes", type=int, default=20000, help="nodes in the hierarchy's arrays")
    ap.add_argument("--calls", type=int, default=2000, help="calls of each pass in a row")
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args(argv)
    rounds = [measure(args.lanes, args.nodes, args.calls) for _ in range(args.rounds)]
    print(f"one segment of {args.lanes} nodes, median of {args.rounds} rounds of {args.calls} calls (ns a node):")
    for name in rounds[0]:
        print(f"   {name:24s} {statistics.median(r[name] for r in rounds):7.2f}")
    total = statistics.median(r["compose"] + r["gather, random order"] + r["scatter, random order"] for r in rounds)
    print(f"   {'all three, random order':24s} {total:7.2f}   ({total * 17000 / 1000:.0f} us for 17,000 nodes)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
