"""What the light scene's frame spends outside the per-particle stages (issue 15).

    python benchmarks/bench_frame_overhead.py orchestration [--scene light_chains]
    python benchmarks/bench_frame_overhead.py update [--scene light_chains] [--frames 300]
    python benchmarks/bench_frame_overhead.py tuple-call [--arrays 350] [--scene light_chains]

``orchestration``: the bookkeeping of ``solver/frame.py`` around the stages (scale
suspension and culling, one step's team time, one step's attenuations, the quality prelude,
the check for lanes that do not run and the save of a block's lanes, the frame-end
bookkeeping, the frame counts) over every live block and lane (the lane form,
``solver/lanes.py``) from one numba loop each, best of 20 calls, after 30 frames of the scene.

``update``: the UPDATE phase (drivers and hierarchy propagation) per frame with and without
the cloth system attached: the same plan over the same nodes, so the difference is the
hierarchy coming back from memory after the cloth kernel.

``tuple-call``: the cost of calling a numba function whose argument is a tuple of tuples of
arrays (numba types every array on every call), and of one whose argument is the scene's
``frame.Tables`` (the namedtuple of packed tables the frame kernel takes).
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
    from magica_py.runtime.team_time import team_time_begin_step_team
    from magica_py.solver import blocks as bk
    from magica_py.solver import frame as F
    from magica_py.solver import state as st
    from magica_py.solver.attenuations import step_attenuations
    from magica_py.solver.center import end_frame_block
    from magica_py.solver.colliders import collider_end_frame_block
    from magica_py.solver.lanes import put1

    player, system = _player(scene_name, True)
    player.run(30)
    T, tt, FA = system.tables, system._time, system._frame_arrays()
    area = system._save_area[0]
    values = F.frame_input_values()
    values[:13] = (1 / 60, 1 / 60, 0.02, 0, 1.0, 1 / 90, 3, 0, 1.0, 1.0, 1.0, 1.0, 1)

    @numba.njit
    def attenuations(T):
        s = 0.0
        for i in range(T.blocks.shape[0]):
            s += step_attenuations(T.P, T.blocks[i], 1.0)[0]
        return s

    @numba.njit
    def prepare(FA):
        F.prepare_lanes(FA)

    @numba.njit
    def begin_step(T, tt, values):
        fi = F.frame_inputs(values)
        for i in range(T.blocks.shape[0]):
            b = T.blocks[i]
            for l in range(bk.lane_width(T.BI, b)):
                t = T.TI[b, bk.TI_TEAM + l]
                if t >= 0:
                    team_time_begin_step_team(0, t, tt.active, tt.update_count, tt.time, tt.now_update_time,
                                              tt.frame_old_time, tt.frame_interpolation, tt.step_running, fi.dt,
                                              fi.timing)
                    put1(T.TS, b, st.FRAME_INTERPOLATION, l, tt.frame_interpolation[t])

    @numba.njit
    def frozen(T):
        n = 0
        for i in range(T.blocks.shape[0]):
            b = T.blocks[i]
            n += F.frozen_lanes(T.TS, T.TI, b, bk.lane_width(T.BI, b))
        return n

    @numba.njit
    def save(T, area):
        for i in range(T.blocks.shape[0]):
            b = T.blocks[i]
            for l in range(bk.lane_width(T.BI, b)):
                F.save_lane(T.PS, T.TS, T.CS, T.BI, b, l, area)

    @numba.njit
    def frame_end(T, tt):
        for i in range(T.blocks.shape[0]):
            b = T.blocks[i]
            w = bk.lane_width(T.BI, b)
            end_frame_block(T.TS, T.TI, b, w, tt.running)
            collider_end_frame_block(T.CS, T.TS, T.TI, T.BI, b, w, tt.running)

    @numba.njit
    def prelude(FA):
        for i in range(FA.blocks.shape[0]):
            b = FA.blocks[i]
            F.begin_frame_prelude_block(FA, b, bk.lane_width(FA.BI, b), None)

    @numba.njit
    def counts(FA):
        return F.frame_counts(FA)

    cases = [("scale suspension and culling (per frame)", lambda: prepare(FA)),
             ("team time of one step", lambda: begin_step(T, tt, values)),
             ("attenuations of one step", lambda: attenuations(T)),
             ("frame prelude (per frame)", lambda: prelude(FA)),
             ("lanes that do not run: check (per frame)", lambda: frozen(T)),
             ("lanes that do not run: save every block", lambda: save(T, area)),
             ("frame-end bookkeeping (per frame)", lambda: frame_end(T, tt)),
             ("frame counts (per frame)", lambda: counts(FA))]
    for _name, fn in cases:
        fn()
    print(f"{scene_name}: {len(system.live_teams)} teams in {T.blocks.shape[0]} blocks, best of 20 calls")
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


def tuple_call(arrays: int, scene_name: str) -> None:
    kinds = (lambda: np.zeros((100, 3)), lambda: np.zeros(100, dtype=np.int32), lambda: np.zeros((10, 3, 4)))
    flat = [kinds[i % 3]() for i in range(arrays)]
    groups = tuple(tuple(flat[i::7]) for i in range(7))

    @numba.njit
    def first(g):
        return g[0][0][0, 0]

    @numba.njit
    def block_count(T):
        return T.blocks.shape[0]

    _player_, system = _player(scene_name, True)
    tables = system.tables
    first(groups)
    block_count(tables)
    for _ in range(3):
        t0 = time.perf_counter()
        for _ in range(2000):
            first(groups)
        t1 = time.perf_counter()
        for _ in range(2000):
            block_count(tables)
        t2 = time.perf_counter()
        print(f"a tuple of 7 tuples of {arrays} arrays in all: {(t1 - t0) / 2000 * 1e6:.1f} us a call; "
              f"{scene_name}'s frame.Tables ({len(tables)} fields): {(t2 - t1) / 2000 * 1e6:.1f} us a call")


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
        tuple_call(args.arrays, args.scene)
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    raise SystemExit(main())
