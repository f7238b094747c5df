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
printed, then each variant is called twice in a row after a whole frame ("after a frame" and
"again": the second call finds the rows in the cache).

``--floors`` adds three measurements of what any propagation of these nodes pays in the frame,
each followed (untimed) by putting back the rows it overwrote (the static nodes' saved rows, the
default plan's pass) so that the cloth sees the scene's poses:

* ``floor: write the derived rows``: the four derived arrays (world position, rotation, lossy
  scale, matrices: 3.7 MB) written whole, in address order with vector stores;
* ``floor: read the local rows``: the three local pose arrays (1.3 MB) read whole;
* ``floor: an empty call``: a numba function that does nothing, called with the 20 arrays the
  plan's pass takes (the interpreter and numba's dispatcher, cold after the cloth kernel).
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


def floor_kernels():
    from magica_py.jit import kernel

    @kernel
    def write_rows(a, b, c, d):
        for rows in (a.reshape(-1), b.reshape(-1), c.reshape(-1)):
            for k in range(rows.shape[0]):
                rows[k] = 0.0
        rows = d.reshape(-1)
        for k in range(rows.shape[0]):
            rows[k] = 0.0

    @kernel
    def read_rows(a, b, c):
        s0 = s1 = s2 = s3 = 0.0
        for rows in (a.reshape(-1), b.reshape(-1), c.reshape(-1)):
            for k in range(0, rows.shape[0] - 3, 4):
                s0 += rows[k]
                s1 += rows[k + 1]
                s2 += rows[k + 2]
                s3 += rows[k + 3]
        return s0 + s1 + s2 + s3

    @kernel
    def empty(*arrays):
        return 0

    return write_rows, read_rows, empty


def run(threads: int, frames: int, tiles: list[int], floors: bool = False, seed: int = 1) -> None:
    import numba
    import numpy as np

    from magica_py.config import load_scene
    from magica_py.runtime.phases import Phase, System
    from magica_py.runtime.player import Player
    from magica_py.scene.hierarchy import propagate_world
    from magica_py.scene.propagation import build_plan
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
    default = build_plan(h.parent, nodes, threads)
    timed = {name: (lambda plan=plan: h.propagate(plan)) for name, plan in plans.items()}
    if floors:
        write_rows, read_rows, empty = floor_kernels()
        # (read with no deferred pass pending: each floor is timed after ``discard_deferred``,
        # and the default plan that follows it covers the deferred nodes)
        derived = lambda: (h.world_position, h.world_rotation, h.lossy_scale, h.local_to_world)
        timed["floor: write the derived rows"] = lambda: write_rows(*derived())
        timed["floor: read the local rows"] = lambda: read_rows(h.local_position,
                                                               h.local_rotation, h.local_scale)
        timed["floor: an empty call"] = lambda: empty(
            default.roots, default.chunk_roots, default.order, default.segment_start,
            default.chunk_tiles, default.tile_segments, default.tile_warm, default.warm_start,
            default.warm_stop, default.segment_slot, default.parent_slot, default.scratch,
            h.parent, h.local_position, h.local_rotation, h.local_scale, *derived())
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

    # after a floor (untimed): the rows of the nodes outside the plan (static: the instances'
    # spots) as they were, the constant bottom row, and the plan's nodes recomputed, so that the
    # cloth reads the poses of the scene
    outside = np.setdiff1d(np.arange(h.count), default.nodes)
    kept = [a[outside].copy() for a in (h.world_position, h.world_rotation, h.lossy_scale,
                                         h.local_to_world)]

    def put_back():
        for a, rows in zip((h.world_position, h.world_rotation, h.lossy_scale, h.local_to_world),
                           kept):
            a[outside] = rows
        h.local_to_world[:, 3] = (0.0, 0.0, 0.0, 1.0)
        h.propagate(default)

    keys = list(timed)
    times = {k: [] for k in keys}
    chosen = {"name": keys[0]}

    def animation(ctx):
        anim.apply(h, ctx)
        name = chosen["name"]
        if name not in plans:
            h.discard_deferred()
        t0 = time.perf_counter()
        timed[name]()
        times[name].append(time.perf_counter() - t0)
        if name not in plans:
            put_back()

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
            if name not in plans:
                h.discard_deferred()
            t0 = time.perf_counter()
            timed[name]()
            t1 = time.perf_counter()
            timed[name]()
            after[name].append(t1 - t0)
            again[name].append(time.perf_counter() - t1)
            if name not in plans:
                put_back()
    player.schedule.remove("animation")
    player.schedule.add(Phase.UPDATE, old)
    # the run left the scene's poses: what a full forward pass gives from its local poses
    final = [a.copy() for a in (h.world_position, h.world_rotation, h.lossy_scale,
                                h.local_to_world)]
    propagate_world(h.parent, h.local_position, h.local_rotation, h.local_scale,
                    h.world_position, h.world_rotation, h.lossy_scale, h.local_to_world)
    if not all(np.array_equal(a.view(np.int64), b.view(np.int64)) for a, b in zip(
            final, (h.world_position, h.world_rotation, h.lossy_scale, h.local_to_world))):
        raise SystemExit("the run left world poses that a full pass does not give")
    load = pathlib.Path("/proc/loadavg").read_text().split()[:3]
    print(f"== light_chains, {threads} thread(s), {default.size} nodes, load {' '.join(load)} "
          f"after the run")
    print(f"   {'in the frame (UPDATE)':48s} {'min':>8s} {'median':>8s} | {'after a frame':>13s} "
          f"{'again':>8s} (min)")
    for name in timed:
        v = times[name]
        print(f"   {name:44s} {len(v):3d}x {min(v) * 1e6:8.1f} {statistics.median(v) * 1e6:8.1f} | "
              f"{min(after[name]) * 1e6:13.1f} {min(again[name]) * 1e6:8.1f} us")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, nargs="+", default=[1])
    ap.add_argument("--frames", type=int, default=600)
    ap.add_argument("--tiles", type=int, nargs="+", default=[512, 1024, 2048])
    ap.add_argument("--floors", action="store_true",
                    help="also time what any propagation of these nodes pays in the frame")
    args = ap.parse_args(argv)
    load = pathlib.Path("/proc/loadavg").read_text().split()[0]
    print(f"load average {load} (1 min) at the start")
    for t in args.threads:
        run(t, args.frames, args.tiles, args.floors)
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    raise SystemExit(main())
