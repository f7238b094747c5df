"""The light scene's hierarchy cost per frame with the cloth's write-back propagation deferred
(the default, ``TransformHierarchy.propagate_later``) or run at once (as before), in one run.

    python benchmarks/bench_deferred.py [--blocks 6] [--block 60] [--threads 1]

The player runs ``--blocks`` blocks of ``--block`` frames, the two variants taking turns block
by block so that the machine's load falls on both alike; the first two frames of a block are
left out (the cache state of the other variant). Per frame, min and median of the player's
metrics: ``animation.drivers``, ``animation.propagate`` (UPDATE), ``cloth.propagate`` (after
the write-back: the deferral itself, or the whole pass when run at once) and their sum. With
no sink nothing reads the written-back world poses, so the deferred pass is never run: the
next frame's UPDATE plan covers its nodes. An immediate pass leaves the hierarchy's arrays in
cache for the next UPDATE, which is then cheaper: compare the sums.
"""
from __future__ import annotations

import argparse
import pathlib
import statistics
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent
KEYS = ("animation.drivers", "animation.propagate", "cloth.propagate")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--blocks", type=int, default=6)
    ap.add_argument("--block", type=int, default=60)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args(argv)
    if args.blocks < 2 or args.block < 3 or args.threads < 1:
        ap.error("expected --blocks >= 2, --block >= 3, --threads >= 1")
    import numba

    from magica_py.config import load_scene
    from magica_py.runtime.player import Player
    from magica_py.solver.system import ClothSystem

    numba.set_num_threads(min(args.threads, numba.config.NUMBA_NUM_THREADS))
    scene = load_scene(ROOT / "configs" / "light_chains.yaml")
    player = Player.for_scene(scene)
    ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings,
                parallel=args.threads > 1).attach(player)
    h = scene.hierarchy
    deferred = h.propagate_later
    load = pathlib.Path("/proc/loadavg").read_text().split()[0]
    print(f"load average {load} (1 min) at the start; {args.threads} thread(s)")
    player.run(30)                                           # compile and settle
    rows = {"deferred": {}, "at once": {}}
    for frame in range(args.blocks * args.block):
        variant = "at once" if (frame // args.block) % 2 else "deferred"
        h.propagate_later = h.propagate if variant == "at once" else deferred
        ctx = player.step()
        if frame % args.block < 2:
            continue
        values = [ctx.metrics[k] * 1e6 for k in KEYS]
        for k, v in zip(KEYS + ("sum",), values + [sum(values)]):
            rows[variant].setdefault(k, []).append(v)
    del h.propagate_later
    for variant, r in rows.items():
        cells = "  ".join(f"{k} {min(v):7.0f} ({statistics.median(v):5.0f})" for k, v in r.items())
        print(f"   {variant:9s} min (median) us: {cells}")
    load = pathlib.Path("/proc/loadavg").read_text().split()[0]
    print(f"load average {load} (1 min) at the end")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    raise SystemExit(main())
