"""The light scene of issue 15 beside its peers: whole frame, phases and cloth kernel of
``configs/light_chains.yaml`` and, in the same run, ``../shared/peers-bench``'s numpy and C
implementations of the same chain model.

    python benchmarks/bench_light.py [--frames 300] [--reps 5] [--threads 1 2] [--no-peers]
                                     [--peers-dir ../shared/peers-bench]

For each thread count (1: the serial kernel and propagation; 2: ``ClothSystem(parallel=True)``,
which also spreads the hierarchy propagation over the numba threads) the scene is loaded,
the cloth system attached to a ``Player`` (no recording sink), warmed up (JIT from the cache,
30 frames), then ``--reps`` runs of ``--frames`` frames are timed around ``player.step()``
(the whole frame: restore, animation, hierarchy, cloth, write-back); the median run is
reported, per frame and per phase (the player's and the systems' metrics: ``animation.drivers``
and ``animation.propagate`` inside UPDATE, ``cloth.kernel`` and ``cloth.propagate`` inside
LATE_UPDATE).

The peers run as their README says, with this interpreter (the project's venv):
``impl_numpy.py --K 1000 --iters 2 --no-errors`` (two distance sweeps per step, as our line
mode's distance constraint runs twice) and ``impl_c.py --variant soa2 --K 1000 --iters 2
--no-errors`` (SIMD across chains, 2 OpenMP threads; the ctypes line is called once per frame
from Python like our kernel, the standalone line has no Python in the loop). Their C build and
caches go to a temporary folder (``PEERS_BUILD`` / ``PEERS_CACHE``), not into the shared
folder. Ratios are peer time / our time: above 1 means faster than the peer. The 1-minute
load average is printed after each part: the peers run minutes after our frames, so on a
shared machine the ratios are only as good as the load was steady between the two.
``--rounds N`` repeats the whole measurement (ours, then the peers) N times and prints each
round's ratios and their median: a host whose speed drifts by minutes then shows it as the
rounds' spread, and each ratio compares runs made within the same minute or two.
"""
from __future__ import annotations

import argparse
import os
import pathlib
import re
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
PEERS = ROOT.parent / "shared" / "peers-bench"
SCENE = ROOT / "configs" / "light_chains.yaml"


def bench_scene(frames: int, reps: int, threads: int, warmup: int = 30) -> dict:
    import numba

    from magica_py.config import load_scene
    from magica_py.runtime.player import Player
    from magica_py.solver.system import ClothSystem

    if threads > 1:
        numba.set_num_threads(threads)
    scene = load_scene(SCENE)
    player = Player.for_scene(scene)
    t0 = time.perf_counter()
    system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings,
                         parallel=threads > 1).attach(player)
    build = time.perf_counter() - t0
    t0 = time.perf_counter()
    player.run(warmup)
    warm = time.perf_counter() - t0
    runs = []
    for _ in range(reps):
        totals: dict[str, float] = {}
        wall = 0.0
        for _ in range(frames):
            start = time.perf_counter()
            ctx = player.step()
            wall += time.perf_counter() - start
            for k, v in ctx.metrics.items():
                totals[k] = totals.get(k, 0.0) + float(v)
        runs.append((wall, totals))
    runs.sort(key=lambda r: r[0])
    wall, totals = runs[len(runs) // 2]
    per_frame = {k: v / frames * 1e6 for k, v in totals.items()
                 if k.startswith(("time.", "cloth.kernel", "cloth.propagate", "animation."))}
    steps = totals.get("cloth.steps", 0.0)
    return {"threads": threads, "build_s": build, "warmup_s": warm, "frames": frames, "reps": reps,
            "frame_us": wall / frames * 1e6, "all_frame_us": [r[0] / frames * 1e6 for r in runs],
            "phases_us": per_frame, "particles": int(system.model.team_particle_count.sum()),
            "kernel_us": totals.get("cloth.kernel", 0.0) / frames * 1e6,
            "kernel_pss": steps / max(totals.get("cloth.kernel", 1e-12), 1e-12),
            "frame_pss": steps / wall}


RESULT = re.compile(r"^RESULT (.*)$", re.M)


def run_peer(peers_dir: pathlib.Path, script: str, args: list[str], env: dict) -> list[dict]:
    """Run one peer script with this interpreter; its RESULT lines as dicts."""
    cmd = [sys.executable, str(peers_dir / script), *args]
    out = subprocess.run(cmd, cwd=peers_dir, env=env, capture_output=True, text=True, check=False)
    if out.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({out.returncode}):\n{out.stderr[-2000:]}")
    rows = []
    for line in RESULT.findall(out.stdout):
        rows.append(dict(tok.split("=", 1) for tok in line.split()))
    if not rows:
        raise RuntimeError(f"{' '.join(cmd)} printed no RESULT line:\n{out.stdout[-2000:]}")
    return rows


def load1() -> float:
    try:
        return float(pathlib.Path("/proc/loadavg").read_text().split()[0])
    except OSError:
        return -1.0


def report_ours(r: dict) -> None:
    threads = r["threads"]
    print(f"== ours, {threads} thread{'s' if threads > 1 else ''} (load {load1():.2f} after): {r['particles']} particles, build "
          f"{r['build_s']:.2f} s, warm-up {r['warmup_s']:.2f} s, median of {r['reps']} x {r['frames']} frames")
    print(f"   whole frame {r['frame_us']:9.1f} us   (runs: "
          + ", ".join(f"{x:.0f}" for x in r["all_frame_us"]) + ")")
    for k, v in sorted(r["phases_us"].items()):
        print(f"   {k:22s} {v:9.1f} us")
    print(f"   particle-steps/s: kernel {r['kernel_pss']:.3g}, whole frame {r['frame_pss']:.3g}")


def ratios(ours: list[dict], peers: list[dict]) -> dict:
    """{(threads, peer, "whole frame" or "cloth kernel"): peer time / our time}."""
    out = {}
    for r in ours:
        for p in peers:
            peer_us = float(p["frame_ms"]) * 1e3
            out[r["threads"], p["impl"], "whole frame"] = peer_us / r["frame_us"]
            out[r["threads"], p["impl"], "cloth kernel"] = peer_us / r["kernel_us"]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--rounds", type=int, default=1,
                    help="repeat ours and the peers this many times; report each round's ratios and their median")
    ap.add_argument("--no-peers", action="store_true", help="our scene only")
    ap.add_argument("--peers-dir", type=pathlib.Path, default=PEERS)
    args = ap.parse_args(argv)
    if args.rounds < 1:
        ap.error(f"--rounds: expected 1 or more, got {args.rounds}")
    print(f"light scene {SCENE.relative_to(ROOT)}; load average {load1():.2f} (1 min) at the start")
    every_round = []
    with tempfile.TemporaryDirectory(prefix="peers-") as tmp:
        env = dict(os.environ, PEERS_BUILD=str(pathlib.Path(tmp) / "build"),
                   PEERS_CACHE=str(pathlib.Path(tmp) / "cache"))
        common = ["--K", "1000", "--iters", "2", "--no-errors", "--reps", str(args.reps)]
        for round_ in range(args.rounds):
            if args.rounds > 1:
                print(f"=== round {round_ + 1} of {args.rounds} ({time.strftime('%H:%M:%S')})")
            ours = []
            for threads in args.threads:
                ours.append(bench_scene(args.frames, args.reps, threads))
                report_ours(ours[-1])
            if args.no_peers:
                continue
            peers = run_peer(args.peers_dir, "impl_numpy.py", common, env)
            peers += run_peer(args.peers_dir, "impl_c.py", [*common, "--variant", "soa2"], env)
            print(f"== peers (same model, K = 1000, 90 Hz, 2 iterations, this interpreter; load {load1():.2f} after)")
            for p in peers:
                print(f"   {p['impl']:32s} frame {float(p['frame_ms']) * 1e3:9.1f} us   pss {p['pss']}")
            print("== ratios (peer time / our time; above 1: we are faster)")
            found = ratios(ours, peers)
            for (threads, impl, what), x in found.items():
                if what == "whole frame":
                    print(f"   {threads} thread{'s' if threads > 1 else ' '} vs {impl:28s} "
                          f"whole frame {x:7.3f}x   cloth kernel {found[threads, impl, 'cloth kernel']:7.3f}x")
            every_round.append(found)
    if len(every_round) > 1:
        print(f"=== the ratios of the {len(every_round)} rounds, and their median")
        for key in every_round[0]:
            threads, impl, what = key
            median = statistics.median(r[key] for r in every_round)
            print(f"   {threads} thread{'s' if threads > 1 else ' '} vs {impl:28s} {what:12s} "
                  + " ".join(f"{r[key]:6.3f}" for r in every_round) + f"   median {median:6.3f}x")
    print(f"load average {load1():.2f} (1 min) at the end")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    raise SystemExit(main())
