"""The LATE_UPDATE frame of every team in one numba call (docs/solver.md §A.3, §D.0 order).

``simulate_frame`` runs, for all teams: scale suspension and distance culling, the runtime's
team time (§A.4), skinning / center / inertia / reset-or-shift / collider frame (§C, §G.2),
the steps (each: §A.6 time, §C.3 team update, §G.3 colliders, §D.1-§D.10), then guards,
display (§E.1), rotations (§E.2/§E.3), transform data and write-back (§E.4) and the end of
frame (§A.7). Within a team everything runs in particle order (Gauss-Seidel, §D.0).
"""
from __future__ import annotations

from collections import namedtuple

import math

import numpy as np
from numba import prange, types
from numba.core.extending import overload
from numba.experimental import structref

from magica_py.jit import kernel
from magica_py.kernels.math3d import load3, load4, q_angle, v_length, v_sub
from magica_py.solver.attenuations import step_attenuations
from magica_py.solver.batch_tables import borrow
from magica_py.solver.batched.run import decide_blocks, run_block_step, team_runs_alone
from magica_py.solver.batched.frame_begin import (
    SHIFT_RESET, begin_lane_team, center_sums_block, gather_shift_block, lane_starts_block, skin_block,
    snap_lane_block, touch_bones_block, touch_history_block,
)
from magica_py.solver.batched.frame_end import end_frame_block, write_transforms_block
from magica_py.solver.batched.transfer import scatter_block, scatter_block_end, scatter_block_end_inputs
from magica_py.runtime.team_time import (
    TeamTimeState, team_time_begin_step, team_time_begin_step_team, team_time_end_frame,
    team_time_frame_update,
)
from magica_py.solver.center import (
    center_and_inertia_team, distance_culling_team, end_frame_team, reset_or_shift_team, skin_team,
    snap_particles_to_base_pose,
)
from magica_py.solver.colliders import (
    collider_end_frame_team, collider_end_step_team, collider_frame_team, collider_step_team,
)
from magica_py.solver.constraints.angle import angle_team
from magica_py.solver.constraints.bending import apply_accumulated, bending_team
from magica_py.solver.constraints.collision import edge_collision_team, point_collision_team
from magica_py.solver.constraints.distance import distance_team
from magica_py.solver.constraints.motion import motion_team
from magica_py.solver.constraints.tether import tether_team
from magica_py.solver.display import display_team
from magica_py.solver.guards import check_team, reset_team_to_base
from magica_py.solver.quality import (
    display_constraints_team, quality_end_of_step,
)
from magica_py.solver.rotations import line_rotations_team, triangle_rotations_team
from magica_py.solver.step import end_step_team, predict_team, step_basic_pose_team, team_step_update
from magica_py.solver.writeback import transform_data_team, write_transforms_team

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
def run_step(m, ps, prm, ts, cs, tt, t, fi):
    """One simulation step of team t (§D.0 order) at frame interpolation fi."""
    dt = fi.dt
    ratio = fi.frequency_ratio
    frac = tt.frame_interpolation[t]
    tether_attenuation, distance_attenuation, limit_attenuation, restoration_attenuation, motion_attenuation = \
        step_attenuations(prm, t, ratio)
    team_step_update(m, ts, prm, frac, t, dt)
    collider_step_team(cs, ts, t, frac)
    predict_team(m, ps, prm, ts, t, frac, dt, ratio, fi.power_z)
    step_basic_pose_team(m, ps, prm, ts, t)
    tether_team(m, ps, prm, t, tether_attenuation)
    distance_team(m, ps, prm, ts, t, ratio, fi.power_y, distance_attenuation)
    angle_team(m, ps, prm, ts, t, ratio, fi.power_w, limit_attenuation, restoration_attenuation)
    if m.team_bend_count[t] > 0 or m.team_volume_count[t] > 0:
        bending_team(m, ps, prm, ts, t, ratio, fi.power_y)
        apply_accumulated(m, ps, t, True)
    if ts.collider_count[t] > 0:
        if prm.collision_mode[t] == 1:
            point_collision_team(m, ps, prm, ts, cs, t)
        elif prm.collision_mode[t] == 2:
            edge_collision_team(m, ps, prm, ts, cs, t)
    distance_team(m, ps, prm, ts, t, ratio, fi.power_y, distance_attenuation)
    motion_team(m, ps, prm, t, motion_attenuation)
    if prm.inextensibility[t] != 0 or prm.collision_last[t] != 0:  # quality mode (§D.0)
        quality_end_of_step(m, ps, prm, ts, cs, t, ratio, fi.power_y, distance_attenuation)
    end_step_team(m, ps, prm, ts, t, dt, ratio)
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
def begin_frame_prelude_team(m, ps, prm, ts, tt, h, t):
    """The team-level start of team t's frame: running flag, quality mode's first-frame build
    reset. Returns the team time since the last step (``center_and_inertia_team``)."""
    ts.running[t] = 1 if tt.running[t] else 0
    tracked = t < h.ramp_from_build.shape[0]
    if ts.reset[t] != 0 and tracked:
        h.ramp_from_build[t] = 0
    if (prm.quality[t] != 0 and h.build_pose_pending[0] != 0 and ts.reset[t] != 0 and ts.time_reset[t] != 0
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
def begin_frame_team(m, ps, prm, ts, cs, tt, h, fi, t):
    """Per-frame stages of team t before the steps (C.1, C.2/C.4, C.5, G.2)."""
    since_last_step = begin_frame_prelude_team(m, ps, prm, ts, tt, h, t)
    skin_team(m, ps, h.local_to_world, t)
    center_and_inertia_team(m, ps, prm, ts, t, h.world_position, h.world_rotation, h.lossy_scale,
                            tt.frame_delta_time[t], tt.now_time_scale[t], tt.skip_count[t],
                            tt.running[t], fi.dt, since_last_step)
    reset_or_shift_team(m, ps, ts, t)
    collider_frame_team(cs, ts, t, h.world_position, h.world_rotation, h.lossy_scale)


@kernel
def begin_frame_block(m, ps, prm, ts, cs, tt, h, fi, blk, bs, b):
    """``begin_frame_team`` for every lane of running block b and the gather, with the particle
    work on the block rows, lanes innermost (``batched/frame_begin``): per lane the prelude,
    C.1 skinning into the block, C.2 sums, then per lane the team-level stages (center, C.4,
    G.2), then the history gathered through the C.5 shift (with the plain copies of
    ``gather_block``), and a Reset lane snapped. The same bits."""
    lanes = blk.block_lane_base[b]
    # the prelude first, as in begin_frame_team (a build reset skins and snaps the team rows
    # with the build pose before this frame's skinning)
    for i in range(blk.block_width[b]):
        t = blk.lane_team[lanes + i]
        bs.lane_since_last_step[lanes + i] = begin_frame_prelude_team(m, ps, prm, ts, tt, h, t)
    lane_starts_block(m, blk, bs, b)
    touch_bones_block(m, h.local_to_world, blk, bs, b)   # cold bone matrices, in lane order
    skin_block(m, h.local_to_world, blk, bs, b)
    center_sums_block(m, blk, bs, b)
    for i in range(blk.block_width[b]):
        begin_lane_team(m, prm, ts, cs, tt, h, fi, bs, lanes + i, blk.lane_team[lanes + i],
                        bs.lane_since_last_step[lanes + i])
    touch_history_block(ps, blk, bs, b)   # cold team rows, in lane order
    gather_shift_block(m, ps, blk, bs, b)   # with gather_block's copies
    for i in range(blk.block_width[b]):
        if bs.lane_shift_mode[lanes + i] == SHIFT_RESET:
            snap_lane_block(blk, bs, b, i)


@kernel
def end_frame_stages_team(m, ps, prm, ts, cs, tt, h, fi, t):
    """Per-frame stages of team t after the steps: guards, E.1-E.4, A.7."""
    code = check_team(m, ps, ts, t)
    if code != 0:
        reset_team_to_base(m, ps, ts, t)
        ts.guard_code[t] = code
        if t < h.ramp_from_build.shape[0]:
            h.ramp_from_build[t] = 0
    display_team(m, ps, prm, ts, t, fi.dt, tt.time[t], tt.old_time[t], tt.now_update_time[t],
                 tt.running[t])
    if prm.time_based_smoothing[t] != 0:
        display_constraints_team(m, ps, prm, ts, cs, t, fi.dt)  # quality mode (§E.1)
    line_rotations_team(m, ps, prm, ts, t)
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
def end_frame_lane(m, ps, ts, cs, tt, h, bs, t, lane):
    """``end_frame_stages_team`` of a lane's team after its block ran the guards and E.1-E.4
    (``batched/frame_end``, results scattered) and the write-back of its finite lanes
    (``frame_end.write_transforms_block``): the guard's reset when a bone value is not
    finite, then A.7."""
    if bs.lane_transform_ok[lane] == 0:
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
def _max_update_count(m, ts, tt):
    max_count = 0
    for i in range(m.live_teams.shape[0]):
        t = m.live_teams[i]
        if ts.active[t] != 0 and tt.update_count[t] > max_count:
            max_count = tt.update_count[t]
    return max_count


@kernel
def _frame_begin(m, ps, prm, ts, cs, tt, h, fi):
    prepare_teams(m, ts, prm, tt, h)
    _time_frame_update(tt, fi)
    for i in range(m.live_teams.shape[0]):
        t = m.live_teams[i]
        if ts.active[t] != 0:
            begin_frame_team(m, ps, prm, ts, cs, tt, h, fi, t)


@kernel
def _frame_end(m, ps, prm, ts, cs, tt, h, fi):
    for i in range(m.live_teams.shape[0]):
        t = m.live_teams[i]
        if ts.active[t] != 0:
            end_frame_stages_team(m, ps, prm, ts, cs, tt, h, fi, t)
    _frame_close(tt, h, fi)


@kernel
def _frame_close(tt, h, fi):
    team_time_end_frame(tt.active, tt.running, tt.step_running, tt.skip_count, tt.time, tt.old_time,
                        tt.now_update_time, tt.old_update_time, tt.frame_update_time,
                        tt.frame_old_time, fi.timing)
    h.build_pose_pending[0] = 0  # teams added or reset later reset at their first frame


@kernel
def _begin_step(tt, fi, step):
    team_time_begin_step(step, tt.active, tt.update_count, tt.time, tt.now_update_time,
                         tt.frame_old_time, tt.frame_interpolation, tt.step_running, fi.dt, fi.timing)


@kernel
def simulate_frame(m, ps, prm, ts, cs, tt, h, blk, bs, fi):
    """The whole cloth frame for every team, one team after another (see the module
    docstring). ``blk``/``bs`` are not read: scenes without blocks do not compile the block
    path (``simulate_frame_blocks``)."""
    m, ps, prm, ts, cs, tt, h = (borrow(m), borrow(ps), borrow(prm), borrow(ts), borrow(cs),
                                 borrow(tt), borrow(h))  # no refcounting inside (batch_tables.py)
    _frame_begin(m, ps, prm, ts, cs, tt, h, fi)
    for step in range(_max_update_count(m, ts, tt)):
        _begin_step(tt, fi, step)
        for i in range(m.live_teams.shape[0]):
            t = m.live_teams[i]
            if ts.active[t] != 0 and tt.step_running[t]:
                run_step(m, ps, prm, ts, cs, tt, t, fi)
    _frame_end(m, ps, prm, ts, cs, tt, h, fi)


@kernel
def simulate_frame_blocks(m, ps, prm, ts, cs, tt, h, blk, bs, fi):
    """``simulate_frame`` with the teams of a running block (``solver/batched``) stepping side
    by side: the same bits (tests/test_batched_frame.py). Everything runs as the parallel
    kernel's one worker (``_worker_steps``, ``_worker_end``)."""
    m, ps, prm, ts, cs, tt, h, blk, bs = (borrow(m), borrow(ps), borrow(prm), borrow(ts), borrow(cs),
                                          borrow(tt), borrow(h), borrow(blk), borrow(bs))  # batch_tables.py
    prepare_teams(m, ts, prm, tt, h)
    _time_frame_update(tt, fi)
    decide_blocks(m, ts, tt, blk)
    assign_workers(m, ts, tt, blk, 1)
    _worker_steps(m, ps, prm, ts, cs, tt, h, blk, bs, fi, 0)
    _worker_end(m, ps, prm, ts, cs, tt, h, blk, bs, fi, 0)
    _frame_close(tt, h, fi)


@kernel(parallel=True)
def simulate_frame_parallel(m, ps, prm, ts, cs, tt, h, blk, bs, fi):
    """``simulate_frame_blocks`` over threads (opt-in: ``ClothSystem(parallel=True)``; also
    for scenes without blocks, whose teams all take the per-team path).

    Work units (a running block with all its lanes, or a team stepping alone) are dealt to
    the threads each frame (``assign_workers``: greedy, largest first); each thread then runs
    the whole frame of its units up to the write-back (begin, gather, every step, scatter) in
    one parallel region, and their end-of-frame stages in a second. Two thread launches per
    frame, and a balance that does not depend on team order. Units are independent and each
    runs in its own order, so the results are bit-identical to the serial kernels
    (element-wise, no reductions). The barrier between the regions keeps the serial order
    of begin-of-frame reads (transforms) before any write-back."""
    m, ps, prm, ts, cs, tt, h, blk, bs = (borrow(m), borrow(ps), borrow(prm), borrow(ts), borrow(cs),
                                          borrow(tt), borrow(h), borrow(blk), borrow(bs))  # batch_tables.py
    prepare_teams(m, ts, prm, tt, h)
    _time_frame_update(tt, fi)
    decide_blocks(m, ts, tt, blk)
    workers = max(1, min(fi.threads, blk.worker_load.shape[0]))
    assign_workers(m, ts, tt, blk, workers)
    for w in prange(workers):
        _worker_steps(m, ps, prm, ts, cs, tt, h, blk, bs, fi, w)
    for w in prange(workers):
        _worker_end(m, ps, prm, ts, cs, tt, h, blk, bs, fi, w)
    _frame_close(tt, h, fi)


@kernel
def _unit_cost(particles, steps):
    """Work of a unit in particle-steps, the frame stages counted as about one step."""
    return np.int64(particles) * np.int64(steps + 1)


@kernel
def _least_loaded(blk, workers):
    best = 0
    for w in range(1, workers):
        if blk.worker_load[w] < blk.worker_load[best]:
            best = w
    return best


@kernel
def assign_workers(m, ts, tt, blk, workers):
    """``blk.block_worker`` / ``blk.team_worker`` for this frame: running blocks (largest
    first), then the teams outside them, each to the least loaded of ``workers`` threads."""
    for w in range(workers):
        blk.worker_load[w] = 0
    for j in range(blk.block_width.shape[0]):
        b = blk.block_order[j]
        if blk.block_run[b] == 0:
            blk.block_worker[b] = -1
            continue
        w = _least_loaded(blk, workers)
        blk.block_worker[b] = w
        first = blk.lane_team[blk.block_lane_base[b]]
        blk.worker_load[w] += _unit_cost(blk.block_width[b] * blk.block_particle_count[b], tt.update_count[first])
    for i in range(m.live_teams.shape[0]):
        t = m.live_teams[i]
        if not team_runs_alone(blk, t):
            blk.team_worker[t] = -1
            continue
        w = _least_loaded(blk, workers)
        blk.team_worker[t] = w
        if ts.active[t] != 0:
            blk.worker_load[w] += _unit_cost(m.team_particle_count[t], tt.update_count[t])


@kernel
def _begin_step_team(tt, fi, step, t):
    team_time_begin_step_team(step, t, tt.active, tt.update_count, tt.time, tt.now_update_time,
                              tt.frame_old_time, tt.frame_interpolation, tt.step_running, fi.dt, fi.timing)


@kernel
def _worker_steps(m, ps, prm, ts, cs, tt, h, blk, bs, fi, w):
    """Thread w's units up to the write-back: begin of frame, the steps (each team advancing
    its own clock, A.6), and for a block the gather before them, then the guards and E.1-E.4 in
    block form (``batched/frame_end``; the write-back itself waits for the barrier) and the
    scatter."""
    for b in range(blk.block_width.shape[0]):
        if blk.block_worker[b] != w:
            continue
        lanes = blk.block_lane_base[b]
        width = blk.block_width[b]
        # the begin of frame and the gather (disp_pos included: the end stages read it)
        begin_frame_block(m, ps, prm, ts, cs, tt, h, fi, blk, bs, b)
        for step in range(tt.update_count[blk.lane_team[lanes]]):
            for i in range(width):
                _begin_step_team(tt, fi, step, blk.lane_team[lanes + i])
            run_block_step(m, prm, ts, cs, tt, blk, bs, b, fi)
        # guards and E.1-E.4 in block form (the write-back waits for the barrier), unless
        # the block's end of frame takes the per-team path this frame
        end_in_block = end_frame_block(m, ps, prm, ts, tt, h, blk, bs, b, fi)
        blk.block_end[b] = 1 if end_in_block else 0
        scatter_block(m, ps, blk, bs, b)
        if end_in_block:
            scatter_block_end(m, ps, blk, bs, b)
        else:
            scatter_block_end_inputs(m, ps, blk, bs, b)
    for i in range(m.live_teams.shape[0]):
        t = m.live_teams[i]
        if blk.team_worker[t] != w:
            continue
        if ts.active[t] != 0:
            begin_frame_team(m, ps, prm, ts, cs, tt, h, fi, t)
        # the clock of a suspended (but enabled) team advances too, as in simulate_frame
        for step in range(tt.update_count[t]):
            _begin_step_team(tt, fi, step, t)
            if ts.active[t] != 0 and tt.step_running[t]:
                run_step(m, ps, prm, ts, cs, tt, t, fi)


@kernel
def _worker_end(m, ps, prm, ts, cs, tt, h, blk, bs, fi, w):
    """Thread w's end-of-frame stages (guards, E.1-E.4, A.7) of the teams of its units: for
    a block whose guards and E.1-E.4 ran in block form, the rest (``end_frame_lane``)."""
    for b in range(blk.block_width.shape[0]):
        if blk.block_worker[b] != w:
            continue
        lanes = blk.block_lane_base[b]
        if blk.block_end[b] != 0:
            write_transforms_block(m, blk, bs, b, h.local_position, h.local_rotation)
        for i in range(blk.block_width[b]):
            if blk.block_end[b] != 0:
                end_frame_lane(m, ps, ts, cs, tt, h, bs, blk.lane_team[lanes + i], lanes + i)
            else:
                end_frame_stages_team(m, ps, prm, ts, cs, tt, h, fi, blk.lane_team[lanes + i])
    for i in range(m.live_teams.shape[0]):
        t = m.live_teams[i]
        if blk.team_worker[t] == w and ts.active[t] != 0:
            end_frame_stages_team(m, ps, prm, ts, cs, tt, h, fi, t)


# ----------------------------------------------------------------------------- kernel tables
# A namedtuple of arrays passed to a compiled function that LLVM does not inline is passed
# by value: ~60 array structs per table, ~12 us per call for five tables (measured), paid by
# every stage call. The kernels therefore receive each table as a numba StructRef with the
# same field names (one pointer; attribute access is unchanged), sharing the numpy arrays.
@structref.register
class TableStructType(types.StructRef):
    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class TableStruct(structref.StructRefProxy):
    """A solver table (namedtuple of arrays) as one numba object; see ``as_kernel_table``."""


structref.define_boxing(TableStructType, TableStruct)


def _to_struct(table):  # typed by the overload below, never run in Python
    raise NotImplementedError


@overload(_to_struct)
def _to_struct_overload(table):
    if not isinstance(table, types.BaseNamedTuple):
        return None
    names = tuple(table.fields)
    struct_type = TableStructType(list(zip(names, table.types)))
    # field-by-field stores, generated from the field names (compiled inside the cached caller)
    source = "def impl(table):\n    s = structref.new(struct_type)\n"
    source += "".join(f"    s.{name} = table.{name}\n" for name in names)
    source += "    return s\n"
    namespace = {"structref": structref, "struct_type": struct_type}
    exec(source, namespace)  # noqa: S102 (trusted, generated from field names)
    return namespace["impl"]


@kernel
def as_kernel_table(table):
    """The StructRef twin of a solver table (shares its arrays)."""
    return _to_struct(table)
