"""The frame around the solver, alone: animation drivers and hierarchy propagation of a scene,
the plain forward pass over every node against the propagation plans, interleaved.

    python benchmarks/bench_hierarchy.py [--scenes light_chains crowd] [--calls 300] [--threads 1 2]

For each scene the cloth system is built (not run: its bones are the ones written back) and
each of these is called ``--calls`` times, the variants taking turns call by call so that
the machine's load falls on all of them alike; min and median per call are printed:

* ``drivers``: ``Animation.apply`` (every driver, the events due), also called back to back
  before the interleaved calls (warm rows: the kernel's own cost);
* ``forward pass (all nodes)``: ``hierarchy.propagate_world`` over every node in index order,
  what UPDATE and LATE_UPDATE each ran before the plans;
* ``UPDATE plan``: the player's plan (subtrees of the driven and the restored bones);
* ``LATE_UPDATE plan``: the cloth system's plan (subtrees of the cloth bones);
* ``UPDATE plan without the cloth bones``: the driven bones' subtrees with the cloth bones
  (and what hangs below them) cut off: what UPDATE would still propagate if the cloth kernel
  computed its bones' animated poses itself (docs/BENCHMARKS.md, session 29);

the plans once per ``--threads`` value. Before each call the local poses are those of a frame
in the middle of the run (drivers evaluated at t = 1 s), so every variant does the same work.
"""
from __future__ import annotations

import argparse
import os
import pathlib
import statistics
import sys
import time
from types import SimpleNamespace

ROOT = pathlib.Path(__file__).resolve().parent.parent


def bench(name: str, calls: int, threads: list[int]) -> list[tuple[str, float, float]]:
    from magica_py.config import load_scene
    from magica_py.scene.hierarchy import propagate_world
    from magica_py.solver.system import ClothSystem

    scene = load_scene(ROOT / "configs" / f"{name}.yaml")
    h = scene.hierarchy
    # the system is built only for its bones and never runs a frame: without this its first-run
    # compile helper (solver/compile_helper.py) would be forked and, never told to stop by a
    # first frame, load or compile its stages for seconds on the second core while the calls
    # below are timed
    os.environ["MAGICA_COMPILE_HELPER"] = "0"
    written = ClothSystem(h, scene.cloths, scene.colliders, scene.settings).restored_bones()
    anim = scene.animation
    ctx = SimpleNamespace(time=SimpleNamespace(time=1.0), events=[])
    anim.apply(h, ctx)
    variants = {
        "drivers": lambda: anim.apply(h, ctx),
        "forward pass (all nodes)": lambda: propagate_world(
            h.parent, h.local_position, h.local_rotation, h.local_scale, h.world_position,
            h.world_rotation, h.lossy_scale, h.local_to_world),
    }
    import numpy as np

    from magica_py.scene.propagation import build_plan

    # the cloth bones made roots: a plan of the driven bones over this parent array stops at them
    cut = h.parent.copy()
    cut[written] = -1
    driven_only = np.setdiff1d(np.asarray(anim.driven, dtype=np.int64), written)
    for t in threads:   # a plan of t chunks runs them on t threads (scene/propagation.py)
        h.threads = t
        update = h.plan(np.concatenate([written, anim.driven]).astype(np.int64))
        late = h.plan(written)
        uncut = build_plan(cut, driven_only, t)
        variants[f"UPDATE plan, {t} thread(s), {update.size} nodes"] = (lambda p=update: h.propagate(p))
        variants[f"LATE_UPDATE plan, {t} thread(s), {late.size} nodes"] = (lambda p=late: h.propagate(p))
        variants[f"UPDATE plan without the cloth bones, {t} thread(s), {uncut.size} nodes"] = (
            lambda p=uncut: h.propagate(p))
    for fn in variants.values():  # compile / warm
        fn()
    warm = []   # the drivers called back to back: their rows stay in cache
    for _ in range(calls):
        t0 = time.perf_counter()
        variants["drivers"]()
        warm.append(time.perf_counter() - t0)
    times = {k: [] for k in variants}
    for _ in range(calls):
        for k, fn in variants.items():
            t0 = time.perf_counter()
            fn()
            times[k].append(time.perf_counter() - t0)
    print(f"== {name}: {h.count} nodes, {anim.kind.size} drivers, {written.size} cloth bones")
    rows = []
    times = {"drivers, back to back": warm, **times}
    for k, v in times.items():
        rows.append((k, min(v) * 1e6, statistics.median(v) * 1e6))
        print(f"   {k:48s} min {rows[-1][1]:8.1f} us   median {rows[-1][2]:8.1f} us")
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=["light_chains", "crowd"])
    ap.add_argument("--calls", type=int, default=300)
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    args = ap.parse_args(argv)
    load = pathlib.Path("/proc/loadavg").read_text().split()[0]
    print(f"load average {load} (1 min) at the start")
    for name in args.scenes:
        bench(name, args.calls, args.threads)
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    raise SystemExit(main())
