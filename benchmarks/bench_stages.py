"""Stage profile of the solver (issue 4 "Speed"): each stage driver run alone over every block.

    python benchmarks/bench_stages.py [--scenes tail_orbit crowd ...] [--frames 30] [--repeats 7]
                                      [--set cloths.0.parameters.solver.mode=quality ...]

Imported by ``bench_solver.py --stages``. After the scene has run its warm-up frames, each
stage of one step (and the per-frame stages) is called for every live block of the scene
(``ClothSystem.tables``: the lane form, ``solver/lanes.py``) in one numba call: the block
drivers (``*_block``) as ``frame.run_step`` / ``block_frame_steps`` / ``block_frame_end`` call
them, the lane drivers (``*_lane``) for every lane that holds a team. Each is repeated, min of
the repeats (machine load spreads over all stages because the repeats are interleaved). Stages
mutate the state, so the figures are costs on a realistic state, not a simulation. A stage
the scene does not use (its ``StageSwitches`` entry is None: not compiled by the frame) is
reported as ``-``; a stage whose driver signature no longer matches as ``n/a``.
"""
from __future__ import annotations

import argparse
import math
import pathlib
import sys
import time

import numba

from magica_py.solver import blocks as bk
from magica_py.solver.attenuations import step_attenuations
from magica_py.solver.center import center_and_inertia_lane, reset_or_shift_block, skin_block, team_world_poses
from magica_py.solver.colliders import collider_end_step_block, collider_frame_block, collider_step_block
from magica_py.solver.constraints.angle import angle_block
from magica_py.solver.constraints.bending import bending_block
from magica_py.solver.constraints.collision import edge_collision_block, point_collision_block
from magica_py.solver.constraints.distance import distance_block
from magica_py.solver.constraints.motion import motion_block
from magica_py.solver.constraints.tether import tether_block
from magica_py.solver.display import display_block
from magica_py.solver.guards import check_block
from magica_py.solver.parameters import (PRM_COLLISION_LAST, PRM_COLLISION_MODE, PRM_CONTACT_SPEED_LIMIT,
                                         PRM_FTL_DAMPING, PRM_INEXTENSIBILITY, PRM_QUALITY,
                                         PRM_TIME_BASED_SMOOTHING)
from magica_py.solver.contact_speed import contact_speed_block
from magica_py.solver.display import record_display_state_block
from magica_py.solver.quality import (INEXT_FTL_EDGES, drift_applies, drift_begin_block, drift_end_block,
                                      drift_in_block, has_cross_links, inextensibility_passes,
                                      quality_end_of_step_block)
from magica_py.solver.quality_display import display_constraints_block
from magica_py.solver.rotations import line_rotations_block, triangle_rotations_block
from magica_py.solver.step import end_step_block, predict_block, step_basic_pose_block, team_step_block
from magica_py.solver.writeback import transform_block, write_transforms_block
from magica_py.wind.force import wind_block

ROOT = pathlib.Path(__file__).resolve().parent.parent
DT = 1.0 / 90.0
RATIO = 1.0      # 90 Hz: frequency ratio 90 / f and the power terms are 1
POWER = 1.0
JIT = {"cache": True, "error_model": "numpy"}


@numba.njit(**JIT)
def _team_update(T, h, q, zones, calls):
    for _call in range(calls):
        for i in range(T.blocks.shape[0]):
            b = T.blocks[i]
            team_step_block(T.TS, T.TM, T.P, b, bk.lane_width(T.BI, b), DT)


@numba.njit(**JIT)
def _colliders_step(T, h, q, zones, calls):
    for _call in range(calls):
        for i in range(T.blocks.shape[0]):
            b = T.blocks[i]
            collider_step_block(T.CS, T.TS, T.BI, T.topology, b)
            collider_end_step_block(T.CS, T.BI, b)


@numba.njit(**JIT)
def _predict(T, h, q, zones, calls):
    for _call in range(calls):
        for i in range(T.blocks.shape[0]):
            predict_block(T.PS, T.PM, T.PP, T.TS, T.P, T.BI, T.topology, T.blocks[i], DT, RATIO, POWER)


@numba.njit(**JIT)
def _wind(T, h, q, zones, calls):
    for _call in range(calls):
        for i in range(T.blocks.shape[0]):
            wind_block(T.PS, T.PM, T.TS, T.TI, T.P, T.BI, T.topology, T.blocks[i], DT, zones)


@numba.njit(**JIT)
def _basic_pose(T, h, q, zones, calls):
    for _call in range(calls):
        for i in range(T.blocks.shape[0]):
            step_basic_pose_block(T.PS, T.PM, T.TS, T.TM, T.P, T.BI, T.topology, T.blocks[i])


@numba.njit(**JIT)
def _tether(T, h, q, zones, calls):
    for _call in range(calls):
        for i in range(T.blocks.shape[0]):
            b = T.blocks[i]
            tether, _distance, _limit, _restoration, _motion = step_attenuations(T.P, b, RATIO)
            tether_block(T.PS, T.P, T.BI, T.topology, b, tether, RATIO)


@numba.njit(**JIT)
def _distance_x2(T, h, q, zones, calls):
    for _call in range(calls):
        for i in range(T.blocks.shape[0]):
            b = T.blocks[i]
            _tether, distance, _limit, _restoration, _motion = step_attenuations(T.P, b, RATIO)
            distance_block(T.PS, T.PM, T.PP, T.TS, T.TM, T.LM, T.P, T.BI, T.topology, b, RATIO, POWER, distance)
            distance_block(T.PS, T.PM, T.PP, T.TS, T.TM, T.LM, T.P, T.BI, T.topology, b, RATIO, POWER, distance)


@numba.njit(**JIT)
def _angle(T, h, q, zones, calls):
    for _call in range(calls):
        for i in range(T.blocks.shape[0]):
            b = T.blocks[i]
            _tether, _distance, limit, restoration, _motion = step_attenuations(T.P, b, RATIO)
            angle_block(T.PS, T.PP, T.TS, T.P, T.BI, T.topology, b, RATIO, POWER, limit, restoration)


@numba.njit(**JIT)
def _bending(T, h, q, zones, calls):
    for _call in range(calls):
        for i in range(T.blocks.shape[0]):
            b = T.blocks[i]
            if T.BI[b, bk.BI_BENDS] > 0 or T.BI[b, bk.BI_VOLUMES] > 0:
                bending_block(T.PS, T.PM, T.TS, T.BM, T.VM, T.P, T.BI, T.topology, b, RATIO, POWER)


@numba.njit(**JIT)
def _collision(T, h, q, zones, calls):
    for _call in range(calls):
        for i in range(T.blocks.shape[0]):
            b = T.blocks[i]
            if T.BI[b, bk.BI_COLLIDERS] > 0:
                if T.P[b, PRM_COLLISION_MODE] == 1.0:
                    point_collision_block(T.PS, T.PP, T.TS, T.CS, T.BI, T.topology, b)
                elif T.P[b, PRM_COLLISION_MODE] == 2.0:
                    edge_collision_block(T.PS, T.PP, T.TS, T.CS, T.BI, T.topology, b)


@numba.njit(**JIT)
def _motion(T, h, q, zones, calls):
    for _call in range(calls):
        for i in range(T.blocks.shape[0]):
            b = T.blocks[i]
            _tether, _distance, _limit, _restoration, motion = step_attenuations(T.P, b, RATIO)
            motion_block(T.PS, T.PP, T.TS, T.P, T.BI, T.topology, b, motion)


@numba.njit(**JIT)
def _quality(T, h, q, zones, calls):
    for _call in range(calls):
        for i in range(T.blocks.shape[0]):
            b = T.blocks[i]
            if T.P[b, PRM_INEXTENSIBILITY] != 0.0 or T.P[b, PRM_COLLISION_LAST] != 0.0:
                _tether, distance, _limit, _restoration, _motion = step_attenuations(T.P, b, RATIO)
                quality_end_of_step_block(T.PS, T.PM, T.PP, T.TS, T.TM, T.CS, T.LM, T.EDS, T.P, T.BI, T.topology, b,
                                          RATIO, POWER, distance, False)


@numba.njit(**JIT)
def _quality_passes_only(T, h, q, zones, calls):
    for _call in range(calls):
        for i in range(T.blocks.shape[0]):
            b = T.blocks[i]
            mode = int(T.P[b, PRM_INEXTENSIBILITY])
            if mode != 0:
                _tether, distance, _limit, _restoration, _motion = step_attenuations(T.P, b, RATIO)
                mesh = mode == INEXT_FTL_EDGES and has_cross_links(T.BI, T.topology, b)
                inextensibility_passes(T.PS, T.PM, T.PP, T.TS, T.TM, T.LM, T.EDS, T.P, T.BI, T.topology, b, RATIO,
                                       POWER, distance, mode, mesh, T.P[b, PRM_FTL_DAMPING])


@numba.njit(**JIT)
def _quality_drift(T, h, q, zones, calls):
    for _call in range(calls):
        for i in range(T.blocks.shape[0]):
            b = T.blocks[i]
            if drift_applies(T.P, b):
                mode = int(T.P[b, PRM_INEXTENSIBILITY])
                _tether, distance, _limit, _restoration, _motion = step_attenuations(T.P, b, RATIO)
                mesh = mode == INEXT_FTL_EDGES and has_cross_links(T.BI, T.topology, b)
                drift_begin_block(T.PS, T.BI, b)
                drift_end_block(T.PS, T.BI, T.topology, b)
                drift_in_block(T.PS, T.PM, T.PP, T.TS, T.TM, T.LM, T.EDS, T.P, T.BI, T.topology, b, RATIO, POWER,
                               distance, mode, mesh)


@numba.njit(**JIT)
def _contact_speed(T, h, q, zones, calls):
    for _call in range(calls):
        for i in range(T.blocks.shape[0]):
            b = T.blocks[i]
            if (T.P[b, PRM_CONTACT_SPEED_LIMIT] >= 0.0 and T.BI[b, bk.BI_COLLIDERS] > 0
                    and T.P[b, PRM_COLLISION_MODE] != 0.0):
                contact_speed_block(T.PS, T.PP, T.TS, T.CS, T.P, T.BI, T.topology, b, DT)


@numba.njit(**JIT)
def _record_display(T, h, q, zones, calls):
    for _call in range(calls):
        for i in range(T.blocks.shape[0]):
            b = T.blocks[i]
            if T.P[b, PRM_TIME_BASED_SMOOTHING] != 0.0:
                record_display_state_block(T.PS, T.TS, T.BI, T.topology, b)


@numba.njit(**JIT)
def _display_constraints(T, h, q, zones, calls):
    for _call in range(calls):
        for i in range(T.blocks.shape[0]):
            b = T.blocks[i]
            if T.P[b, PRM_QUALITY] != 0.0:
                display_constraints_block(T.PS, T.PP, T.TS, T.CS, T.EDS, T.P, T.BI, T.topology, b, DT)


@numba.njit(**JIT)
def _end_step(T, h, q, zones, calls):
    for _call in range(calls):
        for i in range(T.blocks.shape[0]):
            end_step_block(T.PS, T.PM, T.TS, T.P, T.BI, T.topology, T.blocks[i], DT, RATIO)


@numba.njit(**JIT)
def _skin(T, h, q, zones, calls):
    for _call in range(calls):
        for i in range(T.blocks.shape[0]):
            b = T.blocks[i]
            skin_block(T.PS, T.PM, T.BI, T.PT, h.local_to_world, b, 0, bk.lane_width(T.BI, b))


@numba.njit(**JIT)
def _center(T, h, q, zones, calls):
    for _call in range(calls):
        for i in range(T.blocks.shape[0]):
            b = T.blocks[i]
            w = bk.lane_width(T.BI, b)
            for l in range(w):
                if T.TI[b, bk.TI_TEAM + l] >= 0:
                    component, anchor = team_world_poses(T.TI, b, l, h.world_position, h.world_rotation, h.lossy_scale)
                    center_and_inertia_lane(T, b, l, component, anchor, 1.0 / 60.0, 1.0, 0, True, DT, 0.0)
            reset_or_shift_block(T.PS, T.TS, T.BI, b)
            collider_frame_block(T.CS, T.TS, T.TI, T.BI, T.CT, b, w, h.world_position, h.world_rotation, h.lossy_scale)


@numba.njit(**JIT)
def _guards_display(T, h, q, zones, calls):
    for _call in range(calls):
        for i in range(T.blocks.shape[0]):
            b = T.blocks[i]
            check_block(T.PS, T.TS, T.BI, b)
            display_block(T.PS, T.TS, T.P, T.BI, T.topology, b, DT, q)


@numba.njit(**JIT)
def _line_rotations(T, h, q, zones, calls):
    for _call in range(calls):
        for i in range(T.blocks.shape[0]):
            line_rotations_block(T.PS, T.PM, T.TS, T.P, T.BI, T.topology, T.blocks[i])


@numba.njit(**JIT)
def _triangle_rotations(T, h, q, zones, calls):
    for _call in range(calls):
        for i in range(T.blocks.shape[0]):
            triangle_rotations_block(T.PS, T.TRS, T.TRM, T.BI, T.topology, T.blocks[i])


@numba.njit(**JIT)
def _write_back(T, h, q, zones, calls):
    for _call in range(calls):
        for i in range(T.blocks.shape[0]):
            b = T.blocks[i]
            transform_block(T.PS, T.PM, T.TS, T.BI, T.PT, T.topology, b, h.parent, h.world_rotation, h.lossy_scale)
            write_transforms_block(T.PS, T.TS, T.TI, T.BI, T.PT, T.topology, b, bk.lane_width(T.BI, b),
                                   h.local_position, h.local_rotation)


# (label, driver wrapper, the StageSwitches entry that compiles it in the frame or None: always)
STEP_STAGES = [("team update (C.3)", _team_update, None), ("colliders (G.3)", _colliders_step, "colliders"),
               ("predict (D.1)", _predict, None), ("wind (D.1)", _wind, "wind"),
               ("basic pose (D.2)", _basic_pose, None), ("tether (D.3)", _tether, None),
               ("distance x2 (D.4)", _distance_x2, None), ("angle (D.5/D.6)", _angle, "angle"),
               ("bending (D.7)", _bending, "bending"), ("collision (D.8)", _collision, "collision"),
               ("motion (D.9)", _motion, "motion"), ("quality passes", _quality, "quality"),
               ("  of which inextensibility", _quality_passes_only, "quality"),
               ("quality drift", _quality_drift, "quality"),
               ("end of step (D.10)", _end_step, None),
               ("quality contact speed", _contact_speed, "quality"),
               ("quality display record", _record_display, "quality")]
FRAME_STAGES = [("skinning (C.1)", _skin, None), ("center/shift (C.2-C.5, G.2)", _center, None),
                ("guards + display (E.1)", _guards_display, None),
                ("line rotations (E.2)", _line_rotations, "lines"),
                ("triangle rotations (E.3)", _triangle_rotations, "triangles"),
                ("quality display (E.1)", _display_constraints, "quality"),
                ("write-back (E.4)", _write_back, None)]


def _used(system, switch) -> bool:
    if switch is None:
        return True
    s = system.stages
    if switch == "collision":
        return s.point_collision is not None or s.edge_collision is not None
    return getattr(s, switch) is not None


def stage_profile(system, repeats: int = 7, calls: int = 10) -> list[tuple[str, str, float]]:
    """``[(kind, stage, seconds per call over all blocks)]`` (kind: "step" or "frame"); nan for a
    stage the scene does not use, inf for one whose driver no longer types."""
    # the frame's arrays (``frame_call.FrameArrays``: every table under its ``Tables`` name), as
    # the frame passes them: C.2/C.4 (``center_and_inertia_lane``) takes them as one object
    T, h = system._frame_arrays(), system._hierarchy
    q, zones = system.stages.quality, system._wind_zones()
    stages = [("step", n, f, s) for n, f, s in STEP_STAGES] + [("frame", n, f, s) for n, f, s in FRAME_STAGES]
    best = {}
    for _kind, name, fn, switch in stages:
        if not _used(system, switch):
            best[name] = math.nan
            continue
        try:
            fn(T, h, q, zones, 1)
        except numba.core.errors.TypingError:
            best[name] = math.inf
    for _ in range(repeats):
        for _kind, name, fn, _switch in stages:
            if name in best and not math.isfinite(best[name]):   # not used, or does not type
                continue
            t0 = time.perf_counter()
            fn(T, h, q, zones, calls)   # the calls in one numba call: no per-call argument typing
            best[name] = min(best.get(name, 1e9), (time.perf_counter() - t0) / calls)
    return [(kind, name, best[name]) for kind, name, _fn, _switch in stages]


def format_profile(profile, particles: int) -> list[str]:
    """Lines of a stage profile: us per call and ns per particle ("-": stage not used, "n/a":
    the driver no longer types)."""
    lines = []
    for kind, stage, sec in profile:
        if math.isnan(sec):
            value = f"{'-':>9s}     {'-':>7s}"
        elif math.isinf(sec):
            value = f"{'n/a':>9s}     {'n/a':>7s}"
        else:
            value = f"{sec * 1e6:9.1f} us  {sec * 1e9 / max(particles, 1):7.1f} ns/particle"
        lines.append(f"{kind:5s} {stage:28s} {value}")
    return lines


def main(argv=None) -> int:
    from magica_py.config import load_scene
    from magica_py.runtime.player import Player
    from magica_py.solver.system import ClothSystem

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=["tail_orbit", "character_walk", "crowd"])
    ap.add_argument("--frames", type=int, default=30, help="warm-up frames before the profile")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--calls", type=int, default=10)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="scene override, as magica-py run --set (e.g. cloths.0.parameters.solver.mode=quality)")
    args = ap.parse_args(argv)
    for name in args.scenes:
        scene = load_scene(ROOT / "configs" / f"{name}.yaml", overrides=list(args.set))
        player = Player.for_scene(scene)
        system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings,
                             wind=getattr(scene, "wind", ())).attach(player)
        player.run(args.frames)
        particles = int(system.model.team_particle_count.sum())
        blocks = len(system.tables.blocks)
        print(f"== {name}: {len(system.live_teams)} teams in {blocks} blocks, {particles} particles "
              f"(each stage alone over every block, min of {args.repeats} x {args.calls} calls)")
        for line in format_profile(stage_profile(system, args.repeats, args.calls), particles):
            print("   " + line)
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    raise SystemExit(main())
