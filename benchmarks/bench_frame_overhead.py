"""What the light scene's frame spends outside the per-particle stages (issue 15).

    python benchmarks/bench_frame_overhead.py orchestration [--scene light_chains]
    python benchmarks/bench_frame_overhead.py update [--scene light_chains] [--frames 300]
    python benchmarks/bench_frame_overhead.py tuple-call [--arrays 350]

``orchestration``: the per-team bookkeeping of ``solver/frame.py`` around the stages (scale
suspension and culling, one step's team time, one step's attenuations, the quality prelude,
the frame-end bookkeeping, the frame counts) over every live team from one numba loop each,
best of 20 calls, after 30 frames of the scene.

``update``: the UPDATE phase (drivers and hierarchy propagation) per frame with and without
the cloth system attached: the same plan over the same nodes, so the difference is the
hierarchy coming back from memory after the cloth kernel.

``tuple-call``: the cost of calling a numba function whose argument is a tuple of tuples of
arrays (the alternative to the StructRef tables, ``solver/tables.py``): numba types every
array on every call.
"""
from __future__ import annotations

import argparse
import pathlib
import sys
import time

import numba
import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent


def _player(scene_name: str, cloth: bool):
    from magica_py.config import load_scene
    from magica_py.runtime.player import Player
    from magica_py.solver.system import ClothSystem

    scene = load_scene(ROOT / "configs" / f"{scene_name}.yaml")
    player = Player.for_scene(scene)
    system = None
    if cloth:
        system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings,
                             parallel=False).attach(player)
    return player, system


def orchestration(scene_name: str) -> None:
    from magica_py.solver import frame as F
    from magica_py.solver.attenuations import step_attenuations

    player, system = _player(scene_name, True)
    player.run(30)
    m, ps, prm, ts, cs, tt, h = system.kernel_tables()
    live = system.model.live_teams
    values = F.frame_input_values()
    values[:13] = (1 / 60, 1 / 60, 0.02, 0, 1.0, 1 / 90, 3, 0, 1.0, 1.0, 1.0, 1.0, 1)

    @numba.njit
    def attenuations(prm, live):
        s = 0.0
        for i in range(live.shape[0]):
            s += step_attenuations(prm, live[i], 1.0)[0]
        return s

    @numba.njit
    def prepare(m, ts, prm, tt, h):
        F.prepare_teams(m, ts, prm, tt, h)

    @numba.njit
    def begin_step(tt, values, live):
        fi = F.frame_inputs(values)
        for i in range(live.shape[0]):
            F._begin_step_team(tt, fi, 0, live[i])

    @numba.njit
    def frame_end(ts, cs, tt, live):
        for i in range(live.shape[0]):
            t = live[i]
            F.end_frame_team(ts, t, tt.running[t])
            F.collider_end_frame_team(cs, ts, t, tt.running[t])

    @numba.njit
    def prelude(m, ps, prm, ts, tt, h, live):
        s = 0.0
        for i in range(live.shape[0]):
            s += F.begin_frame_prelude_team(m, ps, prm, ts, tt, h, live[i], None)
        return s

    @numba.njit
    def counts(m, ts, tt):
        return F.frame_counts(m, ts, tt)

    cases = [("scale suspension and culling (per frame)", lambda: prepare(m, ts, prm, tt, h)),
             ("team time of one step", lambda: begin_step(tt, values, live)),
             ("attenuations of one step", lambda: attenuations(prm, live)),
             ("frame prelude (per frame)", lambda: prelude(m, ps, prm, ts, tt, h, live)),
             ("frame-end bookkeeping (per frame)", lambda: frame_end(ts, cs, tt, live)),
             ("frame counts (per frame)", lambda: counts(m, ts, tt))]
    for _name, fn in cases:
        fn()
    print(f"{scene_name}: {live.shape[0]} teams, best of 20 calls")
    for name, fn in cases:
        best = 1e9
        for _ in range(20):
            t0 = time.perf_counter()
            fn()
            best = min(best, time.perf_counter() - t0)
        print(f"  {name:42s} {best * 1e6:8.1f} us")


def update(scene_name: str, frames: int) -> None:
    for cloth in (True, False):
        player, _system = _player(scene_name, cloth)
        player.run(30)
        totals: dict[str, float] = {}
        for _ in range(frames):
            ctx = player.step()
            for key, value in ctx.metrics.items():
                if key.startswith("time."):
                    totals[key] = totals.get(key, 0.0) + value
        per_frame = {k[5:]: round(v / frames * 1e6) for k, v in totals.items()}
        print(f"{scene_name}, {'with' if cloth else 'without'} the cloth system: us per frame {per_frame}")


def tuple_call(arrays: int) -> None:
    kinds = (lambda: np.zeros((100, 3)), lambda: np.zeros(100, dtype=np.int32), lambda: np.zeros((10, 3, 4)))
    flat = [kinds[i % 3]() for i in range(arrays)]
    groups = tuple(tuple(flat[i::7]) for i in range(7))

    @numba.njit
    def first(g):
        return g[0][0][0, 0]

    first(groups)
    for _ in range(3):
        t0 = time.perf_counter()
        for _ in range(2000):
            first(groups)
        print(f"a tuple of 7 tuples of {arrays} arrays in all: {(time.perf_counter() - t0) / 2000 * 1e6:.1f} us a call")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("part", choices=("orchestration", "update", "tuple-call"))
    ap.add_argument("--scene", default="light_chains")
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--arrays", type=int, default=350)
    args = ap.parse_args(argv)
    if args.part == "orchestration":
        orchestration(args.scene)
    elif args.part == "update":
        update(args.scene, args.frames)
    else:
        tuple_call(args.arrays)
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    raise SystemExit(main())
