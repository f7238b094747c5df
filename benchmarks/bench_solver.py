"""Solver benchmark: per-frame wall time by phase and particle-steps per second.

    python benchmarks/bench_solver.py [--frames N] [--scenes tail_orbit crowd ...] [--parallel] [--stages]
                                      [--set rigs.0.instances.count=200 ...]

For each scene (``configs/<name>.yaml``): load, build the ``ClothSystem``, attach it to a
``Player`` (no recording sink), warm up (JIT from the cache, first frames), then time
``--frames`` frames (``player.run`` in ten blocks). Reported per frame: the whole loop (restore
to write-back, i.e. the player's frame minus nothing: there is no sink; the mean over every
frame and the mean of the fastest block), each phase, the cloth kernel and the
hierarchy propagation; and particle-steps per second of the cloth kernel (particles x steps
run / kernel time) and of the whole frame. ``--stages`` adds the stage profile of
``bench_stages.py`` (each stage driver alone over every block, per call and per particle).
"""
from __future__ import annotations

import argparse
import pathlib
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent


def bench(name: str, frames: int, warmup: int = 30, parallel: bool = False, stages: bool = False,
          overrides: tuple = ()) -> dict:
    from magica_py.config import load_scene
    from magica_py.runtime.player import Player
    from magica_py.solver.system import ClothSystem

    scene = load_scene(ROOT / "configs" / f"{name}.yaml", overrides=list(overrides))
    player = Player.for_scene(scene)
    t0 = time.perf_counter()
    system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings,
                         parallel=parallel).attach(player)
    build = time.perf_counter() - t0
    t0 = time.perf_counter()
    player.run(warmup)
    warm = time.perf_counter() - t0
    # the frames in ten blocks of player.run (the player sums the metrics itself); the
    # fastest block is reported beside the mean: on a shared host whole seconds run slower
    totals: dict[str, float] = {}
    wall = 0.0
    fastest = float("inf")
    blocks = [frames // 10 + (1 if k < frames % 10 else 0) for k in range(10)]
    for n in blocks:
        if n == 0:
            continue
        summary = player.run(n)
        wall += summary.wall_time
        fastest = min(fastest, summary.wall_time / n)
        for k, v in summary.totals.items():
            totals[k] = totals.get(k, 0.0) + v
    particles = int(system.model.team_particle_count.sum())
    profile = None
    if stages:
        from bench_stages import stage_profile

        profile = stage_profile(system)
    stages = [name for name, on in system.stages._asdict().items() if on is not None]
    return {"stages": stages, "profile": profile, "scene": name, "teams": len(system.models), "particles": particles, "build_s": build,
            "warmup_s": warm, "frames": frames, "frame_us": wall / frames * 1e6, "fastest_block_us": fastest * 1e6,
            "phases_us": {k: v / frames * 1e6 for k, v in totals.items() if k.startswith(("time.", "cloth.k", "cloth.p"))},
            "steps_per_frame": totals.get("cloth.steps", 0.0) / frames,
            "kernel_pss": totals.get("cloth.steps", 0.0) / max(totals.get("cloth.kernel", 1e-12), 1e-12),
            "frame_pss": totals.get("cloth.steps", 0.0) / wall}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--scenes", nargs="+", default=["tail_orbit", "character_walk", "crowd"])
    ap.add_argument("--parallel", action="store_true", help="teams spread over numba threads")
    ap.add_argument("--stages", action="store_true", help="also time each stage kernel alone")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="scene override, as magica-py run --set (e.g. rigs.0.instances.count=200)")
    args = ap.parse_args(argv)
    for name in args.scenes:
        r = bench(name, args.frames, parallel=args.parallel, stages=args.stages,
                  overrides=tuple(args.set))
        print(f"== {r['scene']}{' (parallel)' if args.parallel else ''}: {r['teams']} teams, {r['particles']} particles, "
              f"build {r['build_s']:.2f} s, warm-up {r['warmup_s']:.2f} s, optional stages: {', '.join(r['stages']) or 'none'}")
        print(f"   whole frame {r['frame_us']:9.1f} us (fastest tenth of the frames {r['fastest_block_us']:.1f} us)"
              f"   particle-steps/frame {r['steps_per_frame']:.0f}")
        for k, v in sorted(r["phases_us"].items()):
            print(f"   {k:22s} {v:9.1f} us")
        print(f"   particle-steps/s: kernel {r['kernel_pss']:.3g}, whole frame {r['frame_pss']:.3g}")
        if r["profile"]:
            from bench_stages import format_profile

            print("   stage profile (each stage alone over every block, min of 7 x 10 calls):")
            for line in format_profile(r["profile"], r["particles"]):
                print("     " + line)
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    raise SystemExit(main())
