"""The LATE_UPDATE frame of every team in one numba call (docs/solver.md §A.3, §D.0 order).

One recipe for every scene: scale suspension and distance culling, the runtime's team time
(§A.4); then per team its begin of frame (skinning, center, inertia, reset or shift, collider
frame: §C, §G.2) and its steps (each: §A.6 time, §C.3 team update, §G.3 colliders,
§D.1-§D.10); then per team its end of frame (guards, display §E.1, rotations §E.2/§E.3,
transform data and write-back §E.4, §A.7). Within a team everything runs in particle order
(Gauss-Seidel, §D.0). Teams are independent until the write-back, so the serial kernel
(``simulate_frame``) and the parallel one (``simulate_frame_parallel``, teams dealt to
threads) call the same per-team functions and give the same bits.

**Only the stages a scene uses are compiled.** The optional stages are switched by plain
arguments (``StageSwitches``: ``None`` or ``1``); numba removes an ``if switch is not None``
branch whose argument is ``None`` before it types the callee, so a scene whose cloths use no
angle constraint neither compiles nor calls ``angle_team``. Each combination is its own
compiled (and disk-cached) signature. Within a compiled stage, the per-team parameters still
decide at run time (a switch is on when any team may need the stage).
"""
from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
from numba import prange

from magica_py.jit import kernel
from magica_py.kernels.math3d import load3, load4, q_angle, v_length, v_sub
from reference_solver.runtime.team_time import TeamTimeState, team_time_begin_step_team, team_time_end_frame, \
    team_time_frame_update
from reference_solver.solver.attenuations import step_attenuations
from reference_solver.solver.center import (
    center_and_inertia_team, distance_culling_team, end_frame_team, reset_or_shift_team, skin_team,
    snap_particles_to_base_pose,
)
from reference_solver.solver.colliders import (
    collider_end_frame_team, collider_end_step_team, collider_frame_team, collider_step_team,
)
from reference_solver.solver.constraints.angle import angle_team
from reference_solver.solver.constraints.bending import apply_accumulated, bending_team
from reference_solver.solver.constraints.collision import edge_collision_team, point_collision_team
from reference_solver.solver.constraints.distance import distance_team
from reference_solver.solver.constraints.motion import motion_team
from reference_solver.solver.constraints.tether import tether_team
from reference_solver.solver.display import display_team, record_display_state_team
from reference_solver.solver.guards import check_team, reset_team_to_base
from reference_solver.solver.quality import drift_applies, drift_begin_team, drift_end_team, quality_end_of_step
from reference_solver.solver.quality_display import display_constraints_team
from reference_solver.solver.rotations import line_rotations_team, triangle_rotations_team
from reference_solver.solver.step import end_step_team, predict_team, step_basic_pose_team, team_step_update
from reference_solver.solver.writeback import transform_data_team, write_transforms_team
from reference_solver.wind.force import wind_team

TimeArrays = namedtuple("TimeArrays", TeamTimeState.FIELDS)
HierarchyArrays = namedtuple("HierarchyArrays", [
    "parent", "local_position", "local_rotation", "world_position", "world_rotation",
    "lossy_scale", "local_to_world",
    # the world pose at build (copies taken by ``hierarchy_arrays`` when the system is built),
    # read once by quality mode's build-time reset (``build_reset_team``)
    "build_world_position", "build_world_rotation", "build_lossy_scale", "build_local_to_world",
    "build_pose_pending",   # (1,) uint8: 1 until the first frame has run
    "ramp_from_build"])     # (n,) uint8 per team id (< n): 1 while its last reset was the build
# frame inputs: Unity time of the frame and the global simulation settings
FrameInputs = namedtuple("FrameInputs", [
    "delta_time", "unscaled_delta_time", "fixed_delta_time", "fixed_update_count",
    "global_time_scale", "dt", "max_steps", "timing", "frequency_ratio",
    "power_y", "power_z", "power_w",
    "threads"])   # threads the parallel kernel deals its work to (numba.get_num_threads() at the call)
# The frame inputs travel into the kernel as one float64 array in FrameInputs' field order
# (``frame_input_values``; typing a namedtuple argument costs ~6-9 us per call, an array
# 0.2 us) and the kernel rebuilds the namedtuple (``frame_inputs``); every value is a float64
# or a small integer, so the round trip is exact.
FRAME_INPUT_COUNT = len(FrameInputs._fields)
# The optional stages (None: not compiled, not called; 1: compiled, run where a team asks):
# angle (D.5/D.6), bending (D.7 dihedral and volume), point and edge collision (D.8),
# motion (D.9), quality (quality mode's build reset, end-of-step passes and display collision),
# lines (E.2 line rotations), triangles (E.3 triangle rotations), wind (the wind's share of
# D.1, ``wind.force.wind_team``: a scene with wind zones or a cloth with moving wind).
# ``system.stage_switches`` derives them from the live teams.
StageSwitches = namedtuple("StageSwitches", [
    "angle", "bending", "point_collision", "edge_collision", "motion", "quality", "lines", "triangles", "wind"])
# the per-thread work table of the parallel kernel: team_worker (teams,) int32, worker_load
# (threads,) int64 particle-steps (written by ``assign_workers`` each frame)
WorkerTable = namedtuple("WorkerTable", ["team_worker", "worker_load"])


def frame_input_values() -> np.ndarray:
    """The array ``simulate_frame`` takes its frame inputs in: (13,) float64, FrameInputs' field
    order (the system refills it every frame)."""
    return np.zeros(FRAME_INPUT_COUNT)


@kernel
def frame_inputs(values):
    """The ``FrameInputs`` of a frame from its (13,) float64 values (counts and codes back to
    integers)."""
    return FrameInputs(values[0], values[1], values[2], int(values[3]), values[4], values[5], int(values[6]),
                       int(values[7]), values[8], values[9], values[10], values[11], int(values[12]))


def time_arrays(state: TeamTimeState) -> TimeArrays:
    return TimeArrays(*(getattr(state, name) for name in TeamTimeState.FIELDS))


def hierarchy_arrays(h) -> HierarchyArrays:
    """The hierarchy's arrays for the frame kernel, with a snapshot of its current world pose
    as the build pose (the system calls this once, right after building its cloths)."""
    return HierarchyArrays(h.parent, h.local_position, h.local_rotation, h.world_position,
                           h.world_rotation, h.lossy_scale, h.local_to_world,
                           h.world_position.copy(), h.world_rotation.copy(), h.lossy_scale.copy(),
                           h.local_to_world.copy(), np.ones(1, dtype=np.uint8),
                           np.zeros(max(h.parent.shape[0], 1), dtype=np.uint8))


def worker_table(team_capacity: int, threads: int) -> WorkerTable:
    return WorkerTable(np.full(max(team_capacity, 1), -1, dtype=np.int32), np.zeros(max(threads, 1), dtype=np.int64))


@kernel
def prepare_teams(m, ts, prm, tt, h):
    """Scale suspension (A.4) and distance culling (H.1) before the team time runs."""
    for i in range(m.live_teams.shape[0]):
        t = m.live_teams[i]
        if ts.enabled[t] == 0:
            tt.active[t] = False
            ts.active[t] = 0
            continue
        tt.active[t] = True
        comp = m.team_component_transform[t]
        smin = min(abs(h.lossy_scale[comp, 0]), min(abs(h.lossy_scale[comp, 1]), abs(h.lossy_scale[comp, 2])))
        negative = h.lossy_scale[comp, 0] < 0.0 or h.lossy_scale[comp, 1] < 0.0 or h.lossy_scale[comp, 2] < 0.0
        # a tiny scale suspends the team (A.4); so does a negative one: the negative-scale
        # teleport of H.7 is not modelled (negative scale is rejected at build)
        ts.scale_suspended[t] = 1 if (smin < 1e-6 or negative) else 0
        culled = distance_culling_team(prm, ts, t, h.world_position, comp)
        if (1 if culled else 0) != ts.culled[t]:
            ts.reset[t] = 1  # any visibility change forces a reset (H.1)
        ts.culled[t] = 1 if culled else 0
        suspended = ts.scale_suspended[t] != 0 or culled
        tt.suspended[t] = suspended
        ts.active[t] = 0 if suspended else 1


@kernel
def run_step(m, ps, prm, ts, cs, tt, t, fi, angle, bending, point_collision, edge_collision, motion, quality, wind):
    """One simulation step of team t (§D.0 order) at frame interpolation fi."""
    dt = fi.dt
    ratio = fi.frequency_ratio
    frac = tt.frame_interpolation[t]
    tether_attenuation, distance_attenuation, limit_attenuation, restoration_attenuation, motion_attenuation = \
        step_attenuations(prm, t, ratio)
    team_step_update(m, ts, prm, frac, t, dt)
    collider_step_team(cs, ts, t, frac)
    predict_team(m, ps, prm, ts, t, frac, dt, ratio, fi.power_z)
    if wind is not None:
        if ts.wind_zone_count[t] > 0 or prm.wind_moving_wind[t] > 0.01:  # wind's share of D.1's force sum
            wind_team(m, ps, prm, ts, t, dt)
    step_basic_pose_team(m, ps, prm, ts, t)
    tether_team(m, ps, prm, t, tether_attenuation, ratio)
    distance_team(m, ps, prm, ts, t, ratio, fi.power_y, distance_attenuation)
    drift = False
    if angle is not None:
        drift = quality is not None and drift_applies(prm, t)
        if drift:   # quality mode: the angle pass's kept-out share, a drift the passes do not see
            drift_begin_team(m, ps, t)
        angle_team(m, ps, prm, ts, t, ratio, fi.power_w, limit_attenuation, restoration_attenuation)
        if drift:
            drift_end_team(m, ps, t)
    if bending is not None:
        if m.team_bend_count[t] > 0 or m.team_volume_count[t] > 0:
            bending_team(m, ps, prm, ts, t, ratio, fi.power_y)
            apply_accumulated(m, ps, t, True)
    if ts.collider_count[t] > 0:
        if point_collision is not None:
            if prm.collision_mode[t] == 1:
                point_collision_team(m, ps, prm, ts, cs, t)
        if edge_collision is not None:
            if prm.collision_mode[t] == 2:
                edge_collision_team(m, ps, prm, ts, cs, t)
    distance_team(m, ps, prm, ts, t, ratio, fi.power_y, distance_attenuation)
    if motion is not None:
        motion_team(m, ps, prm, t, motion_attenuation)
    if quality is not None:
        if prm.inextensibility[t] != 0 or prm.collision_last[t] != 0:  # quality mode (§D.0)
            quality_end_of_step(m, ps, prm, ts, cs, t, ratio, fi.power_y, distance_attenuation, drift)
    end_step_team(m, ps, prm, ts, t, dt, ratio)
    if quality is not None:
        if prm.time_based_smoothing[t] != 0:   # quality display: keep this step's state (display.py)
            record_display_state_team(m, ps, ts, t)
    collider_end_step_team(cs, ts, t)


@kernel
def build_reset_team(m, ps, prm, ts, h, t):
    """Quality mode: the Reset of a team built with the system happens at the build (t = 0),
    not at its first frame (docs/quality-mode.md, *start-up*). The particles snap to the
    build-time pose with zero velocity, and the center, frame and component histories take
    the build-time component pose; the first frame then integrates from there like any other
    frame. MagicaCloth2 resets on the first frame (C.5, H.2), i.e. at t = 1/fps: each frame
    rate would start from a different state, which a lightly damped chain carries for ~1 s."""
    skin_team(m, ps, h.build_local_to_world, t)
    center_and_inertia_team(m, ps, prm, ts, t, h.build_world_position, h.build_world_rotation,
                            h.build_lossy_scale, 0.0, 1.0, 0, False, 0.0, 0.0)
    snap_particles_to_base_pose(ps, m.team_particle_start[t], m.team_particle_start[t] + m.team_particle_count[t])
    for c in range(3):
        ts.old_component_pos[t, c] = ts.component_pos[t, c]
        ts.old_component_scale[t, c] = ts.component_scale[t, c]
    for c in range(4):
        ts.old_component_rot[t, c] = ts.component_rot[t, c]
    ts.reset[t] = 0  # the first frame is an ordinary frame (time_reset keeps the ramp at 0)


@kernel
def first_frame_continues_build_pose(m, prm, h, t):
    """True when the component's first-frame pose is within the teleport thresholds of its
    build pose (whatever the teleport mode): the animation then starts from the build pose
    and the build can be the reset instant. A scene whose rest pose is not the animation's
    pose at t = 0 (a jump at the first frame) keeps MagicaCloth2's first-frame reset."""
    comp = m.team_component_transform[t]
    init_len = v_length(load3(m.team_init_scale, t))
    ratio = v_length(load3(h.lossy_scale, comp)) / init_len if init_len > 0.0 else 1.0
    jump = v_length(v_sub(load3(h.world_position, comp), load3(h.build_world_position, comp)))
    turn = math.degrees(q_angle(load4(h.build_world_rotation, comp), load4(h.world_rotation, comp)))
    return jump < prm.teleport_distance[t] * ratio and turn < prm.teleport_rotation[t]


@kernel
def begin_frame_prelude_team(m, ps, prm, ts, tt, h, t, quality):
    """The team-level start of team t's frame: running flag, quality mode's first-frame build
    reset. Returns the team time since the last step (``center_and_inertia_team``)."""
    ts.running[t] = 1 if tt.running[t] else 0
    tracked = t < h.ramp_from_build.shape[0]
    if ts.reset[t] != 0 and tracked:
        h.ramp_from_build[t] = 0
    if (quality is not None and prm.quality[t] != 0 and h.build_pose_pending[0] != 0 and ts.reset[t] != 0 and ts.time_reset[t] != 0
            and first_frame_continues_build_pose(m, prm, h, t)):
        build_reset_team(m, ps, prm, ts, h, t)
        if tracked:
            h.ramp_from_build[t] = 1
    # the stabilisation ramp in continuous time when it started at the build (t = 0, on the
    # step grid); after a first-frame reset the per-step ramp is kept (docs/quality-mode.md)
    since_last_step = 0.0
    if tracked and h.ramp_from_build[t] != 0:
        since_last_step = tt.old_time[t] - tt.now_update_time[t]
    return since_last_step


@kernel
def begin_frame_team(m, ps, prm, ts, cs, tt, h, fi, t, quality):
    """Per-frame stages of team t before the steps (C.1, C.2/C.4, C.5, G.2)."""
    since_last_step = begin_frame_prelude_team(m, ps, prm, ts, tt, h, t, quality)
    skin_team(m, ps, h.local_to_world, t)
    center_and_inertia_team(m, ps, prm, ts, t, h.world_position, h.world_rotation, h.lossy_scale,
                            tt.frame_delta_time[t], tt.now_time_scale[t], tt.skip_count[t],
                            tt.running[t], fi.dt, since_last_step)
    reset_or_shift_team(m, ps, ts, t)
    collider_frame_team(cs, ts, t, h.world_position, h.world_rotation, h.lossy_scale)


@kernel
def team_frame_steps(m, ps, prm, ts, cs, tt, h, fi, t, angle, bending, point_collision, edge_collision, motion,
                     quality, wind):
    """Team t's frame up to the write-back: its begin of frame and its steps (each advancing
    its own clock, §A.6; the clock of a suspended but enabled team advances too)."""
    if ts.active[t] != 0:
        begin_frame_team(m, ps, prm, ts, cs, tt, h, fi, t, quality)
    for step in range(tt.update_count[t]):
        _begin_step_team(tt, fi, step, t)
        if ts.active[t] != 0 and tt.step_running[t]:
            run_step(m, ps, prm, ts, cs, tt, t, fi, angle, bending, point_collision, edge_collision, motion, quality,
                     wind)


@kernel
def team_frame_end(m, ps, prm, ts, cs, tt, h, fi, t, quality, lines, triangles):
    """Per-frame stages of team t after the steps: guards, E.1-E.4, A.7."""
    if ts.active[t] == 0:
        return
    code = check_team(m, ps, ts, t)
    if code != 0:
        reset_team_to_base(m, ps, ts, t)
        ts.guard_code[t] = code
        if t < h.ramp_from_build.shape[0]:
            h.ramp_from_build[t] = 0
    display_team(m, ps, prm, ts, t, fi.dt, tt.time[t], tt.old_time[t], tt.now_update_time[t],
                 tt.running[t], quality)
    if quality is not None:
        if prm.time_based_smoothing[t] != 0:
            display_constraints_team(m, ps, prm, ts, cs, t, fi.dt)  # quality mode (§E.1)
    if lines is not None:
        line_rotations_team(m, ps, prm, ts, t)
    if triangles is not None:
        triangle_rotations_team(m, ps, t)
    if transform_data_team(m, ps, t):
        write_transforms_team(m, ps, t, h.parent, h.world_rotation, h.lossy_scale,
                              h.local_position, h.local_rotation)
    else:
        reset_team_to_base(m, ps, ts, t)
        ts.guard_code[t] = 1
    end_frame_team(ts, t, tt.running[t])
    collider_end_frame_team(cs, ts, t, tt.running[t])


@kernel
def _time_frame_update(tt, fi):
    team_time_frame_update(
        tt.active, tt.suspended, tt.update_mode, tt.team_time_scale, tt.time, tt.old_time,
        tt.now_update_time, tt.old_update_time, tt.frame_update_time, tt.frame_old_time,
        tt.update_count, tt.skip_count, tt.frame_delta_time, tt.now_time_scale, tt.frame_add,
        tt.running, fi.delta_time, fi.unscaled_delta_time, fi.fixed_delta_time,
        fi.fixed_update_count, fi.global_time_scale, fi.dt, fi.max_steps, fi.timing)


@kernel
def _frame_close(tt, h, fi):
    team_time_end_frame(tt.active, tt.running, tt.step_running, tt.skip_count, tt.time, tt.old_time,
                        tt.now_update_time, tt.old_update_time, tt.frame_update_time,
                        tt.frame_old_time, fi.timing)
    h.build_pose_pending[0] = 0  # teams added or reset later reset at their first frame


@kernel
def frame_counts(m, ts, tt):
    """What the frame did, for the caller's metrics and events: (most steps of a team,
    particle-steps, teams with a guard code). Integers: the same on every CPU."""
    most_steps = np.int64(0)
    particle_steps = np.int64(0)
    guarded = 0
    for t in range(tt.update_count.shape[0]):
        c = np.int64(tt.update_count[t])
        most_steps = max(most_steps, c)
        particle_steps += c * np.int64(m.team_particle_count[t])
        if ts.guard_code[t] != 0:
            guarded += 1
    return most_steps, particle_steps, guarded


@kernel
def _begin_step_team(tt, fi, step, t):
    team_time_begin_step_team(step, t, tt.active, tt.update_count, tt.time, tt.now_update_time,
                              tt.frame_old_time, tt.frame_interpolation, tt.step_running, fi.dt, fi.timing)


@kernel
def simulate_frame(tables, frame_values, angle, bending, point_collision, edge_collision, motion, quality, lines,
                   triangles, wind):
    """The whole cloth frame, one team after another (see the module docstring): every team's
    begin and steps, then every team's end (all reads of this frame's transforms come before
    any write-back). ``tables``: ``tables.SolverTables``; ``frame_values``: the frame inputs
    (``frame_input_values``). Returns ``frame_counts``."""
    fi = frame_inputs(frame_values)
    m, ps, prm, ts, cs, tt, h = (tables.model, tables.particles, tables.parameters, tables.teams,
                                 tables.colliders, tables.time, tables.hierarchy)
    prepare_teams(m, ts, prm, tt, h)
    _time_frame_update(tt, fi)
    for i in range(m.live_teams.shape[0]):
        team_frame_steps(m, ps, prm, ts, cs, tt, h, fi, m.live_teams[i], angle, bending, point_collision,
                         edge_collision, motion, quality, wind)
    for i in range(m.live_teams.shape[0]):
        team_frame_end(m, ps, prm, ts, cs, tt, h, fi, m.live_teams[i], quality, lines, triangles)
    _frame_close(tt, h, fi)
    return frame_counts(m, ts, tt)


@kernel(parallel=True)
def simulate_frame_parallel(tables, frame_values, wt, angle, bending, point_collision, edge_collision, motion,
                            quality, lines, triangles, wind):
    """``simulate_frame`` with the teams dealt to ``fi.threads`` threads (``scene.threads``,
    ``system.choose_threads``). ``assign_workers`` deals the teams each frame (greedy,
    largest first); each thread runs its teams' begin and steps in one parallel region and
    their ends in a second: two thread launches per frame. Teams are independent and each
    runs in its own order, so the results are the serial kernel's bits."""
    fi = frame_inputs(frame_values)
    m, ps, prm, ts, cs, tt, h = (tables.model, tables.particles, tables.parameters, tables.teams,
                                 tables.colliders, tables.time, tables.hierarchy)
    prepare_teams(m, ts, prm, tt, h)
    _time_frame_update(tt, fi)
    workers = max(1, min(fi.threads, wt.worker_load.shape[0]))
    assign_workers(m, ts, tt, wt, workers)
    # each region rebuilds the frame inputs from the array: a namedtuple made in the kernel
    # cannot enter a prange body (numba's parfor lowering looks its class up by name)
    for w in prange(workers):
        fw = frame_inputs(frame_values)
        for i in range(m.live_teams.shape[0]):
            t = m.live_teams[i]
            if wt.team_worker[t] == w:
                team_frame_steps(m, ps, prm, ts, cs, tt, h, fw, t, angle, bending, point_collision,
                                 edge_collision, motion, quality, wind)
    for w in prange(workers):
        fw = frame_inputs(frame_values)
        for i in range(m.live_teams.shape[0]):
            t = m.live_teams[i]
            if wt.team_worker[t] == w:
                team_frame_end(m, ps, prm, ts, cs, tt, h, fw, t, quality, lines, triangles)
    _frame_close(tt, h, fi)
    return frame_counts(m, ts, tt)


@kernel
def _unit_cost(particles, steps):
    """Work of a unit in particle-steps, the frame stages counted as about one step."""
    return np.int64(particles) * np.int64(steps + 1)


@kernel
def _least_loaded(wt, workers):
    best = 0
    for w in range(1, workers):
        if wt.worker_load[w] < wt.worker_load[best]:
            best = w
    return best


@kernel
def assign_workers(m, ts, tt, wt, workers):
    """``wt.team_worker`` for this frame: the live teams in order, each to the least loaded of
    ``workers`` threads (ties to the lower thread). Suspended teams cost nothing but still go
    to a thread (their clocks advance)."""
    for w in range(workers):
        wt.worker_load[w] = 0
    for i in range(m.live_teams.shape[0]):
        t = m.live_teams[i]
        w = _least_loaded(wt, workers)
        wt.team_worker[t] = w
        if ts.active[t] != 0:
            wt.worker_load[w] += _unit_cost(m.team_particle_count[t], tt.update_count[t])
