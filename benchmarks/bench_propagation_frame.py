"""The UPDATE propagation inside the light scene's frame: variants of the propagation plan taking
turns frame by frame, each timed where the player runs it (after RESTORE and the drivers, with
the caches as the cloth kernel of the frame before left them).

    python benchmarks/bench_propagation_frame.py [--threads 1] [--frames 600] [--tiles 512 1024 2048]

The light scene (``configs/light_chains.yaml``) runs with its cloth system attached (no sink);
its UPDATE system is replaced by one that runs the drivers and then, chosen at random each
frame, one of these plans over the driven and restored bones' subtrees (17,000 nodes):

* ``level order, no warm-up``: one tile per chunk and no warm-up read, i.e. every level of the
  chunk at once, the order of the plans before tiles (session 9);
* ``tiles of T, no warm-up``: tiles of T nodes, the rows not read in first;
* ``tiles of T``: tiles of T nodes with their warm-up read (the plans as built by default for
  T = ``propagation.TILE_NODES``).

Every variant computes the same bits (checked before the run); min and median per frame are
printed, then each variant is called twice in a row after a whole frame ("after the frame" and
"again": the second call finds the rows in the cache).
"""
from __future__ import annotations

import argparse
import pathlib
import random
import statistics
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent


def variants(h, nodes, threads: int, tiles: list[int]) -> dict:
    import numpy as np

    from magica_py.scene.propagation import build_plan

    def no_warm_up(plan):
        plan.tile_warm = np.zeros_like(plan.tile_warm)   # every tile: no run to read
        return plan

    plans = {"level order, no warm-up": no_warm_up(build_plan(h.parent, nodes, threads,
                                                              tile=h.count + 1))}
    for tile in tiles:
        plans[f"tiles of {tile}, no warm-up"] = no_warm_up(build_plan(h.parent, nodes, threads,
                                                                      tile=tile))
        plans[f"tiles of {tile}"] = build_plan(h.parent, nodes, threads, tile=tile)
    return plans


def run(threads: int, frames: int, tiles: list[int], seed: int = 1) -> None:
    import numba
    import numpy as np

    from magica_py.config import load_scene
    from magica_py.runtime.phases import Phase, System
    from magica_py.runtime.player import Player
    from magica_py.scene.hierarchy import propagate_world
    from magica_py.solver.system import ClothSystem

    if threads > 1:
        numba.set_num_threads(threads)
    scene = load_scene(ROOT / "configs" / "light_chains.yaml")
    player = Player.for_scene(scene)
    ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings,
                parallel=threads > 1).attach(player)
    h, anim = scene.hierarchy, scene.animation
    nodes = np.concatenate([player.restored_bones, anim.driven]).astype(np.int64)
    plans = variants(h, nodes, threads, tiles)
    player.run(10)

    # the same bits from every variant as from the plain forward pass over every node
    propagate_world(h.parent, h.local_position, h.local_rotation, h.local_scale,
                    h.world_position, h.world_rotation, h.lossy_scale, h.local_to_world)
    reference = [a.copy() for a in (h.world_position, h.world_rotation, h.lossy_scale,
                                    h.local_to_world)]
    for name, plan in plans.items():
        for a in (h.world_position, h.world_rotation, h.lossy_scale):
            a[plan.nodes] = 0.0
        h.local_to_world[plan.nodes, :3] = 0.0
        h.propagate(plan)
        same = all(np.array_equal(a.view(np.int64), r.view(np.int64)) for a, r in zip(
            (h.world_position, h.world_rotation, h.lossy_scale, h.local_to_world), reference))
        if not same:
            raise SystemExit(f"{name}: not the bits of the full pass")

    keys = list(plans)
    times = {k: [] for k in keys}
    chosen = {"name": keys[0]}

    def animation(ctx):
        anim.apply(h, ctx)
        plan = plans[chosen["name"]]
        t0 = time.perf_counter()
        h.propagate(plan)
        times[chosen["name"]].append(time.perf_counter() - t0)

    old = player.schedule.remove("animation")
    player.schedule.add(Phase.UPDATE, System("animation", animation))
    rnd = random.Random(seed)
    for name in keys * 3:                               # compile, warm up
        chosen["name"] = name
        player.step()
    for v in times.values():
        v.clear()
    for _ in range(frames):
        chosen["name"] = rnd.choice(keys)
        player.step()
    after, again = {k: [] for k in keys}, {k: [] for k in keys}
    for _ in range(max(frames // (4 * len(keys)), 5)):
        rnd.shuffle(keys)
        for name in keys:
            chosen["name"] = keys[0]
            player.step()
            t0 = time.perf_counter()
            h.propagate(plans[name])
            t1 = time.perf_counter()
            h.propagate(plans[name])
            after[name].append(t1 - t0)
            again[name].append(time.perf_counter() - t1)
    player.schedule.remove("animation")
    player.schedule.add(Phase.UPDATE, old)
    load = pathlib.Path("/proc/loadavg").read_text().split()[:3]
    print(f"== light_chains, {threads} thread(s), {plans[keys[0]].size} nodes, load {' '.join(load)} "
          f"after the run")
    print(f"   {'in the frame (UPDATE)':48s} {'min':>8s} {'median':>8s} | {'after a frame':>13s} "
          f"{'again':>8s} (min)")
    for name in plans:
        v = times[name]
        print(f"   {name:44s} {len(v):3d}x {min(v) * 1e6:8.1f} {statistics.median(v) * 1e6:8.1f} | "
              f"{min(after[name]) * 1e6:13.1f} {min(again[name]) * 1e6:8.1f} us")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, nargs="+", default=[1])
    ap.add_argument("--frames", type=int, default=600)
    ap.add_argument("--tiles", type=int, nargs="+", default=[512, 1024, 2048])
    args = ap.parse_args(argv)
    load = pathlib.Path("/proc/loadavg").read_text().split()[0]
    print(f"load average {load} (1 min) at the start")
    for t in args.threads:
        run(t, args.frames, args.tiles)
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    raise SystemExit(main())
