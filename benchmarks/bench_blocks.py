"""Block stage profile (issue 4 "Speed"): each block stage of ``solver/batched`` alone over
every block of a scene, in ns per particle (min of repeats), beside the per-team frame stages.

    python benchmarks/bench_blocks.py [--scene crowd] [--instances N] [--frames 30]

The scene runs ``--frames`` frames per team (``batched=False``) to reach a mid-motion state;
its blocks are then formed, the state gathered in full (``gather_block_full``) and each block
stage called over all blocks, repeated, from that state (stages mutate it: figures are costs
on a realistic state, not a simulation). The per-frame lines are the begin of frame in block
form (``frame.begin_frame_block``: skinning, center sums, the per-lane scalar part, the history
gathered through the C.5 shift and stored back in the team rows) and the scatter.
One step is every step stage (distance twice); a frame at 60 fps / 90 Hz runs 1.5 steps.
"""
from __future__ import annotations

import argparse
import pathlib
import sys
import time

import numba
import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT / "tests"))   # block_transfer: the copies into a block

from magica_py.solver.batch_tables import borrow  # noqa: E402
from block_transfer import gather_block_full, load_lanes  # noqa: E402
from magica_py.solver.batched.blocks import form_blocks  # noqa: E402
from magica_py.solver.batched.frame_end import (  # noqa: E402,F401
    _lane_values, display_block, guards_trip_block, line_rotations_block, transform_data_block,
    triangle_rotations_block, write_transforms_block, bone_local_pose_block,
)
from magica_py.solver.batched.transfer import scatter_block, scatter_block_end  # noqa: E402,F401
from magica_py.solver.constraints.angle import angle_block  # noqa: E402,F401
from magica_py.solver.constraints.bending import apply_accumulated_block, bending_block  # noqa: E402,F401
from magica_py.solver.constraints.collision import point_collision_block  # noqa: E402,F401
from magica_py.solver.constraints.distance import distance_block  # noqa: E402,F401
from magica_py.solver.constraints.motion import motion_block  # noqa: E402,F401
from magica_py.solver.constraints.tether import tether_block  # noqa: E402,F401
from magica_py.solver.batched.frame_begin import (  # noqa: E402,F401
    begin_lane_team, center_sums_block, gather_shift_block, lane_starts_block, skin_block,
    touch_bones_block, touch_history_block,
)
from magica_py.solver.frame import FrameInputs, as_kernel_table, begin_frame_prelude_team  # noqa: E402
from magica_py.solver.step import end_step_block, predict_block, step_basic_pose_block  # noqa: E402,F401

DT = 1.0 / 90.0
STAGES = [
    # the begin of frame in block form (frame.begin_frame_block: these, the per-lane team-level
    # stages and a Reset lane's snap; the gather is its gather_shift_block)
    ("skin (C.1, per frame)", "lane_starts_block(m, blk, bs, b); touch_bones_block(m, h.local_to_world, blk, bs, b); "
     "skin_block(m, h.local_to_world, blk, bs, b)", 0),
    ("center sums (C.2, /frame)", "center_sums_block(m, blk, bs, b)", 0),
    ("lanes C.2/C.4/G.2 (/frame)", "begin_lanes(m, ps, prm, ts, cs, tt, h, fi, blk, bs, b)", 0),
    ("gather + C.5 (per frame)", "touch_history_block(ps, blk, bs, b); gather_shift_block(m, ps, blk, bs, b)", 0),
    ("lane values", "load_lanes(blk, bs, ts, tt, cs, b)", 1),
    ("predict (D.1)", "predict_block(m, bs, prm, blk, b, DT, 1.0, 1.0)", 1),
    ("basic pose (D.2)", "step_basic_pose_block(m, bs, prm, blk, b)", 1),
    ("tether (D.3)", "tether_block(m, bs, prm, blk, b, 0.7)", 1),
    ("distance (D.4, x2)", "distance_block(m, bs, prm, blk, b, 1.0, 1.0, 0.3)", 2),
    ("angle (D.5/D.6)", "angle_block(m, bs, prm, blk, b, 1.0, 1.0, 0.9, 0.8)", 1),
    ("bending (D.7)", "bending_block(m, bs, prm, blk, b, 1.0, 1.0); apply_accumulated_block(m, bs, blk, b, True)", 1),
    ("collision (D.8 point)", "point_collision_block(m, bs, prm, blk, b)", 1),
    ("motion (D.9)", "motion_block(m, bs, prm, blk, b, 0.95)", 1),
    ("end of step (D.10)", "end_step_block(m, bs, prm, blk, b, DT, 1.0)", 1),
    ("scatter (per frame)", "scatter_block(m, ps, blk, bs, b)", 0),
    # the end of frame in block form (batched/frame_end), per frame
    ("end: lane values", "_lane_values(m, ts, tt, blk, bs, b, DT)", 0),
    ("end: guards", "guards_trip_block(blk, bs, b)", 0),
    ("end: display (E.1)", "display_block(m, ps, blk, bs, b, DT, True)", 0),
    ("end: line rot. (E.2)", "line_rotations_block(m, prm, blk, bs, b, True)", 0),
    ("end: triangle rot. (E.3)", "triangle_rotations_block(m, blk, bs, b)", 0),
    ("end: transform (E.4)", "transform_data_block(m, blk, bs, b)", 0),
    ("end: scatter", "scatter_block_end(m, ps, blk, bs, b)", 0),
    ("end: bone local pose", "bone_local_pose_block(m, blk, bs, b, h.parent, h.world_rotation, h.lossy_scale)", 0),
    ("end: write-back", "write_transforms_block(m, blk, bs, b, h.local_position, h.local_rotation)", 0),
]


@numba.njit
def begin_lanes(m, ps, prm, ts, cs, tt, h, fi, blk, bs, b):
    """``frame.begin_frame_block``'s per-lane part (scalar): prelude, C.2 center, C.4, G.2."""
    lanes = blk.block_lane_base[b]
    for i in range(blk.block_width[b]):
        t = blk.lane_team[lanes + i]
        since_last_step = begin_frame_prelude_team(m, ps, prm, ts, tt, h, t)
        begin_lane_team(m, prm, ts, cs, tt, h, fi, bs, lanes + i, t, since_last_step)


def _wrapper(body: str):
    source = (
        "def f(m, ps, prm, ts, cs, tt, h, fi, blk, bs):\n"
        "    m, ps, prm, ts, cs, tt, h, blk, bs = (borrow(m), borrow(ps), borrow(prm), borrow(ts), borrow(cs),\n"
        "                                          borrow(tt), borrow(h), borrow(blk), borrow(bs))\n"
        "    for b in range(blk.block_width.shape[0]):\n"
        f"        {body}\n")
    namespace = dict(globals())
    exec(source, namespace)  # noqa: S102 (the stage calls above)
    return numba.njit(namespace["f"])


@numba.njit
def _gather_all(m, ps, ts, cs, tt, blk, bs):
    m, ps, ts, cs, tt, blk, bs = borrow(m), borrow(ps), borrow(ts), borrow(cs), borrow(tt), borrow(blk), borrow(bs)
    for b in range(blk.block_width.shape[0]):
        gather_block_full(m, ps, blk, bs, b)
        load_lanes(blk, bs, ts, tt, cs, b)


def describe_blocks(table) -> list[str]:
    """One line per block: its lanes, particles and teams."""
    return [f"block {b}: {int(table.block_width[b])} lanes x {int(table.block_particle_count[b])} particles "
            f"(teams {table.lane_team[table.block_lane_base[b]:table.block_lane_base[b] + table.block_width[b]].tolist()})"
            for b in range(len(table.block_width))]


def main(argv=None) -> int:
    from magica_py.config import load_scene
    from magica_py.runtime.player import Player
    from magica_py.solver.system import ClothSystem

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="crowd")
    ap.add_argument("--instances", type=int, default=None, help="rigs.0.instances.count override")
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--repeats", type=int, default=15)
    args = ap.parse_args(argv)
    sets = [f"rigs.0.instances.count={args.instances}"] if args.instances else []
    scene = load_scene(ROOT / "configs" / f"{args.scene}.yaml", overrides=sets)
    player = Player.for_scene(scene)
    system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings, batched=False).attach(player)
    player.run(args.frames)
    blk, bs = form_blocks(system)
    print("\n".join(describe_blocks(blk)) or "no blocks")
    if not len(blk.block_width):
        return 0
    m, ps, prm, ts, cs, tt, h = system.kernel_tables()
    kb, kbs = as_kernel_table(blk), as_kernel_table(bs)
    s = system.time_settings
    power = s.simulation_power
    fi = FrameInputs(1 / 60, 1 / 60, 0.02, 0, float(s.global_time_scale), float(s.simulation_delta_time),
                     int(s.max_steps_per_frame), int(s.timing_code), 90.0 / s.frequency, float(power[1]),
                     float(power[2]), float(power[3]), 1)
    _gather_all(m, ps, ts, cs, tt, kb, kbs)
    n = int(sum(int(blk.block_width[b]) * int(blk.block_particle_count[b]) for b in range(len(blk.block_width))))
    step = 0.0
    frame = 0.0
    print(f"{'stage':24s} ns/particle  (one call over {n} block particles)")
    for name, body, per_step in STAGES:
        fn = _wrapper(body)
        fn(m, ps, prm, ts, cs, tt, h, fi, kb, kbs)
        best = 1e9
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            fn(m, ps, prm, ts, cs, tt, h, fi, kb, kbs)
            best = min(best, time.perf_counter() - t0)
        ns = best * 1e9 / n
        step += ns * per_step
        frame += ns if per_step == 0 else 0.0
        print(f"{name:24s} {ns:8.1f}")
    print(f"{'one step':24s} {step:8.1f}\n{'per-frame block stages':24s} {frame:8.1f}")
    from bench_stages import stage_profile

    print("per-team frame stages (ns/particle, all teams):")
    total = 0.0
    for kind, name, sec in stage_profile(system):
        if kind == "frame":
            ns = sec * 1e9 / int(system.model.team_particle_count.sum())
            total += ns
            print(f"  {name:28s} {ns:8.1f}")
    print(f"  {'frame stages':28s} {total:8.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
