"""Quality mode's cost on the crowd against faithful mode, both in one process (issue 16: at most 1.5x).

    python benchmarks/crowd_cost.py [--blocks 30] [--scene crowd] [--quality-param solver.KEY=VALUE ...]

Separate ``bench_solver.py`` runs of the two modes on a shared machine differ by 10-30 % from
process to process, more than the cost being measured. This script builds the scene twice in
one process (faithful; every cloth in quality mode), runs 30 warm-up frames on each, then
alternates 10-frame blocks between them over frames 30-330 (``bench_solver.py``'s window) and
prints the ratio of the mean frame times, the median of the per-block ratios and the ratio per
50 frames. ``--quality-param`` sets a parameter of every quality cloth besides the mode (e.g.
``solver.time_based_smoothing=disabled``: what one quality feature costs).
"""
from __future__ import annotations

import argparse
import pathlib
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def main(argv=None) -> int:
    from magica_py.config import load_scene
    from magica_py.runtime.player import Player
    from magica_py.solver.system import ClothSystem

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="crowd")
    ap.add_argument("--blocks", type=int, default=30)
    ap.add_argument("--quality-param", action="append", default=[], metavar="KEY=VALUE",
                    help="a parameter of every quality cloth besides solver.mode (repeatable)")
    args = ap.parse_args(argv)
    path = ROOT / "configs" / f"{args.scene}.yaml"
    cloths = len(load_scene(path).cloths)
    base = len({c.name.split("#")[0] for c in load_scene(path).cloths}) if cloths else 0
    extra = "".join(f", {key}: {value}" for key, value in (kv.split("=", 1) for kv in args.quality_param))
    quality = [f"cloths[{i}].parameters={{solver.mode: quality{extra}}}" for i in range(base)]
    players = {}
    for name, overrides in (("faithful", []), ("quality", quality)):
        scene = load_scene(path, overrides=overrides)
        player = Player.for_scene(scene)
        ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings).attach(player)
        player.run(30)
        players[name] = player
    times = {name: [] for name in players}
    for _ in range(args.blocks):
        for name, player in players.items():
            t0 = time.perf_counter()
            for _ in range(10):
                player.step()
            times[name].append((time.perf_counter() - t0) / 10)
    f, q = np.array(times["faithful"]), np.array(times["quality"])
    print(f"{args.scene}: faithful {f.mean() * 1e3:.2f} ms/frame, quality {q.mean() * 1e3:.2f} ms/frame, "
          f"ratio of means {q.mean() / f.mean():.3f}, median block ratio {np.median(q / f):.3f}; per 50 frames: "
          + " ".join(f"{q[i:i + 5].sum() / f[i:i + 5].sum():.2f}" for i in range(0, len(q), 5)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
