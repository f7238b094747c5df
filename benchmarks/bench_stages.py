"""Stage profile of the solver (issue 4 "Speed"): each stage kernel run alone over every team.

Imported by ``bench_solver.py --stages``. After the scene has run its warm-up frames, each
stage of one step (and the per-frame stages) is called for every team in one numba call,
repeated, min of the repeats (machine load spreads over all stages because the repeats are
interleaved). Stages mutate the state, so the figures are costs on a realistic state, not a
simulation. A
stage whose kernel signature no longer matches is reported as ``n/a``.
"""
from __future__ import annotations

import time

import numba

from magica_py.solver.center import center_and_inertia_team, reset_or_shift_team, skin_team
from magica_py.solver.colliders import collider_end_step_team, collider_frame_team, collider_step_team
from magica_py.solver.constraints.angle import angle_team
from magica_py.solver.constraints.bending import apply_accumulated, bending_team
from magica_py.solver.constraints.collision import edge_collision_team, point_collision_team
from magica_py.solver.constraints.distance import distance_team
from magica_py.solver.constraints.motion import motion_team
from magica_py.solver.constraints.tether import tether_team
from magica_py.solver.display import display_team
from magica_py.solver.guards import check_team
from magica_py.solver.rotations import line_rotations_team, triangle_rotations_team
from magica_py.solver.step import end_step_team, predict_team, step_basic_pose_team, team_step_update
from magica_py.solver.writeback import transform_data_team, write_transforms_team

DT = 1.0 / 90.0


@numba.njit
def _team_update(m, ps, prm, ts, cs, h, live):
    for t in live:
        team_step_update(m, ts, prm, 1.0, t, DT)


@numba.njit
def _colliders_step(m, ps, prm, ts, cs, h, live):
    for t in live:
        collider_step_team(cs, ts, t, 1.0)
        collider_end_step_team(cs, ts, t)


@numba.njit
def _predict(m, ps, prm, ts, cs, h, live):
    for t in live:
        predict_team(m, ps, prm, ts, t, 1.0, DT, 1.0, 1.0)


@numba.njit
def _basic_pose(m, ps, prm, ts, cs, h, live):
    for t in live:
        step_basic_pose_team(m, ps, prm, ts, t)


@numba.njit
def _tether(m, ps, prm, ts, cs, h, live):
    for t in live:
        tether_team(m, ps, prm, t, 0.7, 1.0)


@numba.njit
def _distance_x2(m, ps, prm, ts, cs, h, live):
    for t in live:
        distance_team(m, ps, prm, ts, t, 1.0, 1.0, 0.3)
        distance_team(m, ps, prm, ts, t, 1.0, 1.0, 0.3)


@numba.njit
def _angle(m, ps, prm, ts, cs, h, live):
    for t in live:
        angle_team(m, ps, prm, ts, t, 1.0, 1.0, 0.9, prm.restoration_attenuation[t])


@numba.njit
def _bending(m, ps, prm, ts, cs, h, live):
    for t in live:
        if m.team_bend_count[t] > 0 or m.team_volume_count[t] > 0:
            bending_team(m, ps, prm, ts, t, 1.0, 1.0)
            apply_accumulated(m, ps, t, True)


@numba.njit
def _collision(m, ps, prm, ts, cs, h, live):
    for t in live:
        if ts.collider_count[t] > 0:
            if prm.collision_mode[t] == 1:
                point_collision_team(m, ps, prm, ts, cs, t)
            elif prm.collision_mode[t] == 2:
                edge_collision_team(m, ps, prm, ts, cs, t)


@numba.njit
def _motion(m, ps, prm, ts, cs, h, live):
    for t in live:
        motion_team(m, ps, prm, t, 0.95)


@numba.njit
def _end_step(m, ps, prm, ts, cs, h, live):
    for t in live:
        end_step_team(m, ps, prm, ts, t, DT, 1.0)


@numba.njit
def _skin(m, ps, prm, ts, cs, h, live):
    for t in live:
        skin_team(m, ps, h.local_to_world, t)


@numba.njit
def _center(m, ps, prm, ts, cs, h, live):
    for t in live:
        center_and_inertia_team(m, ps, prm, ts, t, h.world_position, h.world_rotation, h.lossy_scale,
                                1.0 / 60.0, 1.0, 0, True, DT)
        reset_or_shift_team(m, ps, ts, t)
        collider_frame_team(cs, ts, t, h.world_position, h.world_rotation, h.lossy_scale)


@numba.njit
def _guards_display(m, ps, prm, ts, cs, h, live):
    for t in live:
        check_team(m, ps, ts, t)
        display_team(m, ps, prm, ts, t, DT, 1.0, 1.0 - DT, 1.0 - DT, False, None)


@numba.njit
def _line_rotations(m, ps, prm, ts, cs, h, live):
    for t in live:
        line_rotations_team(m, ps, prm, ts, t)


@numba.njit
def _triangle_rotations(m, ps, prm, ts, cs, h, live):
    for t in live:
        triangle_rotations_team(m, ps, t)


@numba.njit
def _write_back(m, ps, prm, ts, cs, h, live):
    for t in live:
        if transform_data_team(m, ps, t):
            write_transforms_team(m, ps, t, h.parent, h.world_rotation, h.lossy_scale,
                                  h.local_position, h.local_rotation)


STEP_STAGES = [("team update (C.3)", _team_update), ("colliders (G.3)", _colliders_step),
               ("predict (D.1)", _predict), ("basic pose (D.2)", _basic_pose), ("tether (D.3)", _tether),
               ("distance x2 (D.4)", _distance_x2), ("angle (D.5/D.6)", _angle),
               ("bending (D.7)", _bending), ("collision (D.8)", _collision), ("motion (D.9)", _motion),
               ("end of step (D.10)", _end_step)]
FRAME_STAGES = [("skinning (C.1)", _skin), ("center/shift (C.2-C.5, G.2)", _center),
                ("guards + display (E.1)", _guards_display), ("line rotations (E.2)", _line_rotations),
                ("triangle rotations (E.3)", _triangle_rotations), ("write-back (E.4)", _write_back)]


def stage_profile(system, repeats: int = 7, calls: int = 10) -> list[tuple[str, str, float]]:
    """``[(kind, stage, seconds per call over all teams)]`` (kind: "step" or "frame")."""
    m, ps, prm, ts, cs, _tt, h = system.kernel_tables()
    live = system.model.live_teams
    stages = [("step", n, f) for n, f in STEP_STAGES] + [("frame", n, f) for n, f in FRAME_STAGES]
    best = {}
    for kind, name, fn in stages:
        try:
            fn(m, ps, prm, ts, cs, h, live)
        except numba.core.errors.TypingError:
            best[name] = float("nan")
    for _ in range(repeats):
        for kind, name, fn in stages:
            if name in best and best[name] != best[name]:
                continue
            t0 = time.perf_counter()
            for _ in range(calls):
                fn(m, ps, prm, ts, cs, h, live)
            best[name] = min(best.get(name, 1e9), (time.perf_counter() - t0) / calls)
    return [(kind, name, best[name]) for kind, name, _fn in stages]
