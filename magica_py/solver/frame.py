"""The LATE_UPDATE frame of every block in one numba call (docs/solver.md §A.3, §D.0 order).

One recipe for every scene: scale suspension and distance culling, the runtime's team time
(§A.4); then per block its begin of frame (skinning, center, inertia, reset or shift,
collider frame: §C, §G.2) and its steps (each: §A.6 time, §C.3 team update, §G.3 colliders,
§D.1-§D.10) and, right after them, its end of frame (guards, display §E.1, rotations
§E.2/§E.3, transform data and write-back §E.4, §A.7), while the block's rows are still in the
cache. Within a team everything runs in particle order (Gauss-Seidel, §D.0), the block's teams
side by side (``solver/lanes.py``). Blocks are independent: the frame reads the hierarchy's
world arrays (the pose propagated before LATE_UPDATE) and the write-back writes only its local
arrays, which no block reads, so a block written back before another's begin changes nothing
that block sees (MagicaCloth2 reads every cloth's transforms before it writes any: docs/solver.md
§A.3). The serial kernel (``simulate_frame``) and a frame on several threads
(``begin_parallel_frame``, then ``simulate_worker`` on each Python thread of the system's pool
with the blocks dealt to it, then ``end_parallel_frame``) call the same per-block functions and
give the same bits.

**Lanes that do not run.** A block runs every stage for all its lanes. A lane whose team is
not simulated this frame (disabled, culled, scale-suspended: ``ACTIVE`` 0) or that runs
fewer steps than its neighbours (another time scale, a reset clock) keeps its state: its
columns are copied aside before the block's frame (or step) and written back after it
(``save_lane`` / ``restore_lane``), and the stages that write outside the tables (the
write-back, the guards' events) skip it. A free lane (no team) is computed and ignored.

**The frame's arrays.** The kernels take them in one StructRef ``F`` (``frame_call.FrameArrays``:
the ``Tables`` fields, the team clocks as ``tt_*``, the hierarchy as ``h_*``) and pass ``F`` down
the recipe; each recipe function binds the arrays it uses to locals at its top. numba counts a
reference per array each time a namedtuple of arrays is copied into a function, and one for the
StructRef (docs/architecture.md, *Calling the frame kernel*).

**Only the stages a scene uses are compiled.** The optional stages are switched by plain
arguments (``StageSwitches``: ``None`` or ``1``); numba removes an ``if switch is not None``
branch whose argument is ``None`` before it types the callee, so a scene whose cloths use no
angle constraint neither compiles nor calls ``angle_block``. Each combination is its own
compiled (and disk-cached) signature. Within a compiled stage, the block's parameters still
decide at run time (a switch is on when any block may need the stage), so every switch on
(``MAGICA_STAGES=all``, ``jit.stage_policy``) gives the same bits.
"""
from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels.cache_lines import read_lines
from magica_py.kernels.math3d import q_angle, v_length, v_sub
from magica_py.runtime.team_time import (
    TeamTimeState, team_time_begin_step_team, team_time_end_frame, team_time_frame_update,
)
from magica_py.solver import blocks as bk
from magica_py.solver import state as st
from magica_py.solver.attenuations import step_attenuations
from magica_py.solver.center import (
    center_and_inertia_lane, distance_culling_lane, end_frame_block, reset_or_shift_block, skin_block,
    scale_ratio_of, snap_lane_to_base_pose, team_world_poses, world_pose_rows,
)
from magica_py.solver.colliders import (
    collider_end_frame_block, collider_end_step_block, collider_frame_block, collider_step_block,
)
from magica_py.solver.contact_speed import contact_speed_block
from magica_py.solver.constraints.angle import angle_block
from magica_py.solver.constraints.bending import bending_block
from magica_py.solver.constraints.collision import edge_collision_block, point_collision_block
from magica_py.solver.constraints.distance import distance_block
from magica_py.solver.constraints.motion import motion_block
from magica_py.solver.constraints.tether import tether_block
from magica_py.solver.display import display_block, display_fraction, record_display_state_block
from magica_py.solver.guards import check_block, lane_guard_code, reset_lane_to_base
from magica_py.solver.lanes import LANES, get1, get3, put1
from magica_py.solver.parameters import (
    PRM_COLLISION_LAST, PRM_COLLISION_MODE, PRM_CONTACT_SPEED_LIMIT, PRM_INEXTENSIBILITY, PRM_QUALITY,
    PRM_TELEPORT_DISTANCE, PRM_TELEPORT_ROTATION, PRM_TIME_BASED_SMOOTHING,
)
from magica_py.solver.quality import drift_applies, drift_begin_block, drift_end_block, quality_end_of_step_block
from magica_py.solver.quality_display import display_constraints_block
from magica_py.solver.rotations import line_rotations_block, triangle_rotations_block
from magica_py.solver.step import end_step_block, predict_block, step_basic_pose_block, team_step_block
from magica_py.solver.writeback import transform_block, write_transforms_block
from magica_py.wind.force import wind_block

TimeArrays = namedtuple("TimeArrays", TeamTimeState.FIELDS)
# the solver's tables as the frame kernel takes them (``system.ClothSystem.tables``):
# state (PS, TS, CS, TRS triangle and EDS edge scratch), per-lane model (PM, TM, LM link, TRM
# triangle, BM bend, VM volume), parameters P (one row per block) and PP (its depth curves at
# each particle: ``blocks.PARTICLE_PARAMETERS``), block ints BI and topology,
# per-lane hierarchy nodes (PT particles, TI teams, CT collider slots), the live block ids
# (int64: a block id goes on to every stage and row helper; one signature, docs/tech-notes.md §7)
Tables = namedtuple("Tables", [
    "PS", "TS", "CS", "TRS", "EDS", "PM", "PP", "TM", "LM", "TRM", "BM", "VM", "P", "BI", "topology", "PT", "TI", "CT",
    "blocks"])
HierarchyArrays = namedtuple("HierarchyArrays", [
    "parent", "local_position", "local_rotation", "world_position", "world_rotation",
    "lossy_scale", "local_to_world",
    # the world pose at build (copies taken by ``hierarchy_arrays`` when the system is built),
    # read once by quality mode's build-time reset (``build_reset_lane``)
    "build_world_position", "build_world_rotation", "build_lossy_scale", "build_local_to_world",
    "build_pose_pending"])   # (1,) uint8: 1 until the first frame has run
# frame inputs: Unity time of the frame and the global simulation settings
FrameInputs = namedtuple("FrameInputs", [
    "delta_time", "unscaled_delta_time", "fixed_delta_time", "fixed_update_count",
    "global_time_scale", "dt", "max_steps", "timing", "frequency_ratio",
    "power_y", "power_z", "power_w",
    "threads"])   # threads a parallel frame deals its blocks to (the system's thread count)
# The frame inputs travel into the kernel as one float64 array in FrameInputs' field order
# (``frame_input_values``; typing a namedtuple argument costs ~6-9 us per call, an array
# 0.2 us) and the kernel rebuilds the namedtuple (``frame_inputs``); every value is a float64
# or a small integer, so the round trip is exact.
FRAME_INPUT_COUNT = len(FrameInputs._fields)
# The optional stages (None: not compiled, not called; 1: compiled, run where a block asks):
# angle (D.5/D.6), bending (D.7 dihedral and volume), point and edge collision (D.8),
# motion (D.9), quality (quality mode's build reset, end-of-step passes and display collision),
# lines (E.2 line rotations), triangles (E.3 triangle rotations), wind (the wind's share of
# D.1, ``wind.force.wind_block``: a scene with wind zones or a cloth with moving wind),
# colliders (§G.2/§G.3, the colliders' frame and step poses: a team with a collider; a scene
# without any neither compiles nor runs them). ``system.stage_switches`` derives them from the
# live blocks.
StageSwitches = namedtuple("StageSwitches", [
    "angle", "bending", "point_collision", "edge_collision", "motion", "quality", "lines", "triangles", "wind",
    "colliders"])
# the per-thread work table of a parallel frame: block_worker (blocks,) int32, worker_load
# (threads,) int64 particle-steps (both written by ``assign_workers`` each frame), worker_share
# (threads,) float64 the fraction of a frame's load each thread gets (written by the system
# after each frame from the threads' measured speeds, ``solver/balance.py``; equal at first)
WorkerTable = namedtuple("WorkerTable", ["block_worker", "worker_load", "worker_share"])


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
                           h.local_to_world.copy(), np.ones(1, dtype=np.uint8))


def worker_table(block_capacity: int, threads: int) -> WorkerTable:
    threads = max(threads, 1)
    return WorkerTable(np.full(max(block_capacity, 1), -1, dtype=np.int32), np.zeros(threads, dtype=np.int64),
                       np.full(threads, 1.0 / threads))


# rows of the tables a lane's save copies (module constants: the kernels read them as constants)
PS_ROWS = st.PARTICLE.rows
TS_ROWS = st.TEAM.rows
CS_ROWS = st.COLLIDER.rows


def lane_save_area(max_particles: int, max_colliders: int, threads: int) -> np.ndarray:
    """Scratch of ``save_lane``: per thread, every lane of one block's particle, team and
    collider items (``LANES`` lanes of ``max_particles`` particle slots and ``max_colliders``
    collider slots), and one value more at the end (``warm_block``'s sum)."""
    width = LANES * (max_particles * PS_ROWS + TS_ROWS + max_colliders * CS_ROWS)
    return np.zeros((max(threads, 1), width + 1))


# ``warm_block`` reads a block's rows ahead only where its lanes are mostly used and the
# particle state is larger than a core's L2 cache (1 MiB on the CPUs measured: AMD Zen 4, and
# about that on current Intel cores): a smaller state stays cached from one frame to the next,
# and a block of one team would read 16 lanes to use one (docs/BENCHMARKS.md, session 14).
WARM_MIN_LANES = LANES // 2
WARM_MIN_STATE_VALUES = (1 << 20) // 8


@kernel
def _warm_rows(a, i0, i1):
    """``read_lines`` over rows ``i0:i1`` of the C-contiguous 2-D table ``a``."""
    return read_lines(a.reshape(-1), i0 * a.shape[1], i1 * a.shape[1])


@kernel(inline="always")
def _warm_particle_rows(PS, g0, g1, first, end):
    """``read_lines`` over rows ``first:end`` of each particle slot ``g0:g1`` of ``PS``."""
    flat = PS.reshape(-1)
    width = PS.shape[1]
    acc = 0.0
    for g in range(g0, g1):
        acc += read_lines(flat, g * width + first * LANES, g * width + end * LANES)
    return acc


@kernel(inline="always")
def warm_block(F, b, area, angle, bending, edge_collision, quality):
    """Read every cache line of block b's particle state, model and depth curves, team and
    collider items (``F``: the frame's ``FrameArrays``, or ``Tables``: the same field names)
    in address order before its frame, when ``WARM_*`` says it pays. The stages
    touch a particle's rows scattered over its 19 KB item, one particle after another, so each
    first touch of a row would wait for memory on its own; read in sequence, the hardware
    prefetcher streams the block into the cache (the light scene's kernel 10-20 % faster, the
    crowd's likewise). Of the particle state only the rows the frame's stages read are
    fetched: the rows every scene carries (``st.CARRIED_ROWS``) and those of the optional
    stages compiled (``angle``, ``bending``, ``edge_collision``, ``quality``: the frame's
    stage switches, None where no team uses it); the stages' scratch rows are written before
    they are read, so they are not fetched (the light scene's kernel 3-5 % faster than reading
    every row, 151 a slot then: docs/BENCHMARKS.md, session 30). The sum goes to the thread's save area
    (its last value, never read), so that the reads are kept; nothing else is written."""
    if F.BI[b, bk.BI_LANES_USED] < WARM_MIN_LANES or F.PS.shape[0] * F.PS.shape[1] < WARM_MIN_STATE_VALUES:
        return
    g0 = np.int64(F.BI[b, bk.BI_G0])
    g1 = g0 + F.BI[b, bk.BI_N]
    c0 = np.int64(F.BI[b, bk.BI_COLLIDER0])
    acc = _warm_particle_rows(F.PS, g0, g1, 0, st.CARRIED_ROWS)
    if bending is not None or edge_collision is not None:
        acc += _warm_particle_rows(F.PS, g0, g1, st.BENDING_EDGE_ROWS[0], st.BENDING_EDGE_ROWS[1])
    if angle is not None:
        acc += _warm_particle_rows(F.PS, g0, g1, st.ANGLE_ROWS[0], st.ANGLE_ROWS[1])
    if quality is not None:
        acc += _warm_particle_rows(F.PS, g0, g1, st.QUALITY_ROWS[0], st.QUALITY_ROWS[1])
    acc += _warm_rows(F.PM, g0, g1) + _warm_rows(F.PP, g0, g1)
    acc += _warm_rows(F.TS, b, b + 1) + _warm_rows(F.CS, c0, c0 + F.BI[b, bk.BI_COLLIDERS])
    area[area.shape[0] - 1] = acc


# ----------------------------------------------------------------------------- lanes that do not run
@kernel(forceinline=False)
def save_lane(PS, TS, CS, BI, b, l, area):
    """Copy lane l's columns of block b's particle, team and collider items into its part of
    ``area`` (one thread's row; lane l's part starts at ``l`` times a lane's size)."""
    n = BI[b, bk.BI_N]
    g0 = BI[b, bk.BI_G0]
    c0 = BI[b, bk.BI_COLLIDER0]
    at = l * (n * PS_ROWS + TS_ROWS + BI[b, bk.BI_COLLIDERS] * CS_ROWS)
    for g in range(g0, g0 + n):
        for r in range(PS_ROWS):
            area[at] = PS[g, r * LANES + l]
            at += 1
    for r in range(TS_ROWS):
        area[at] = TS[b, r * LANES + l]
        at += 1
    for k in range(c0, c0 + BI[b, bk.BI_COLLIDERS]):
        for r in range(CS_ROWS):
            area[at] = CS[k, r * LANES + l]
            at += 1


@kernel(forceinline=False)
def restore_lane(PS, TS, CS, BI, b, l, area):
    """Write lane l's columns of block b back from ``area`` (``save_lane``)."""
    n = BI[b, bk.BI_N]
    g0 = BI[b, bk.BI_G0]
    c0 = BI[b, bk.BI_COLLIDER0]
    at = l * (n * PS_ROWS + TS_ROWS + BI[b, bk.BI_COLLIDERS] * CS_ROWS)
    for g in range(g0, g0 + n):
        for r in range(PS_ROWS):
            PS[g, r * LANES + l] = area[at]
            at += 1
    for r in range(TS_ROWS):
        TS[b, r * LANES + l] = area[at]
        at += 1
    for k in range(c0, c0 + BI[b, bk.BI_COLLIDERS]):
        for r in range(CS_ROWS):
            CS[k, r * LANES + l] = area[at]
            at += 1


# ----------------------------------------------------------------------------- team level
@kernel(inline="always")
def prepare_lanes(F):
    """Scale suspension (A.4) and distance culling (H.1) of every lane, before the team time."""
    tt_active, tt_suspended, h_lossy_scale = F.tt_active, F.tt_suspended, F.h_lossy_scale
    h_world_position = F.h_world_position
    TS, TI, P, BI, blocks = F.TS, F.TI, F.P, F.BI, F.blocks
    for i in range(blocks.shape[0]):
        b = blocks[i]
        for l in range(bk.lane_width(BI, b)):
            t = TI[b, bk.TI_TEAM + l]
            if t < 0:
                continue
            if get1(TS, b, st.ENABLED, l) == 0.0:
                tt_active[t] = False
                put1(TS, b, st.ACTIVE, l, 0.0)
                continue
            tt_active[t] = True
            comp = TI[b, bk.TI_COMPONENT + l]
            sx, sy, sz = h_lossy_scale[comp, 0], h_lossy_scale[comp, 1], h_lossy_scale[comp, 2]
            smin = min(abs(sx), min(abs(sy), abs(sz)))
            negative = sx < 0.0 or sy < 0.0 or sz < 0.0
            # a tiny scale suspends the team (A.4); so does a negative one: the negative-scale
            # teleport of H.7 is not modelled (negative scale is rejected at build)
            put1(TS, b, st.SCALE_SUSPENDED, l, 1.0 if (smin < 1e-6 or negative) else 0.0)
            culled = distance_culling_lane(TS, TI, P, b, l, h_world_position)
            if (1.0 if culled else 0.0) != get1(TS, b, st.CULLED, l):
                put1(TS, b, st.RESET, l, 1.0)  # any visibility change forces a reset (H.1)
            put1(TS, b, st.CULLED, l, 1.0 if culled else 0.0)
            suspended = get1(TS, b, st.SCALE_SUSPENDED, l) != 0.0 or culled
            tt_suspended[t] = suspended
            put1(TS, b, st.ACTIVE, l, 0.0 if suspended else 1.0)


@kernel
def first_frame_continues_build_pose(F, b, l):
    """True when lane l's component's first-frame pose is within the teleport thresholds of
    its build pose (whatever the teleport mode): the animation then starts from the build pose
    and the build can be the reset instant. A scene whose rest pose is not the animation's
    pose at t = 0 (a jump at the first frame) keeps MagicaCloth2's first-frame reset."""
    comp = np.int64(F.TI[b, bk.TI_COMPONENT + l])
    now_pos, now_rot, now_scale = world_pose_rows(F.h_world_position, F.h_world_rotation, F.h_lossy_scale, comp)
    build_pos, build_rot, _scale = world_pose_rows(F.h_build_world_position, F.h_build_world_rotation,
                                                   F.h_build_lossy_scale, comp)
    ratio = scale_ratio_of(now_scale, v_length(get3(F.TM, b, bk.INIT_SCALE, l)))
    jump = v_length(v_sub(now_pos, build_pos))
    turn = math.degrees(q_angle(build_rot, now_rot))
    return jump < F.P[b, PRM_TELEPORT_DISTANCE] * ratio and turn < F.P[b, PRM_TELEPORT_ROTATION]


@kernel(forceinline=False)
def build_reset_lane(F, b, l):
    """Quality mode: the Reset of a team built with the system happens at the build (t = 0),
    not at its first frame (docs/quality-mode.md, *start-up*). The particles snap to the
    build-time pose with zero velocity, and the center, frame and component histories take
    the build-time component pose; the first frame then integrates from there like any other
    frame. MagicaCloth2 resets on the first frame (C.5, H.2), i.e. at t = 1/fps: each frame
    rate would start from a different state, which a lightly damped chain carries for ~1 s."""
    PS, TS = F.PS, F.TS
    skin_block(PS, F.PM, F.BI, F.PT, F.h_build_local_to_world, b, l, l + 1)
    component, anchor = team_world_poses(F.TI, b, l, F.h_build_world_position, F.h_build_world_rotation,
                                         F.h_build_lossy_scale)
    center_and_inertia_lane(F, b, l, component, anchor, 0.0, 1.0, 0, False, 0.0, 0.0)
    g0 = F.BI[b, bk.BI_G0]
    for g in range(g0, g0 + F.BI[b, bk.BI_N]):
        snap_lane_to_base_pose(PS, g, l)
    for c in range(3):
        TS[b, st.OLD_COMPONENT_POS + c * LANES + l] = TS[b, st.COMPONENT_POS + c * LANES + l]
        TS[b, st.OLD_COMPONENT_SCALE + c * LANES + l] = TS[b, st.COMPONENT_SCALE + c * LANES + l]
    for c in range(4):
        TS[b, st.OLD_COMPONENT_ROT + c * LANES + l] = TS[b, st.COMPONENT_ROT + c * LANES + l]
    put1(TS, b, st.RESET, l, 0.0)  # the first frame is an ordinary frame (time_reset keeps the ramp at 0)


@kernel(forceinline=False)
def begin_frame_prelude_block(F, b, w, quality):
    """The team-level start of the frame of every active lane of block b (its first ``w``
    lanes): running flag, quality mode's first-frame build reset, and the team time since the
    last step (``DISPLAY_T``, kept until ``center_and_inertia_lane`` reads it)."""
    TS = F.TS
    for l in range(w):
        t = lane_team(F.TI, b, l)
        if t < 0 or get1(TS, b, st.ACTIVE, l) == 0.0:
            continue
        put1(TS, b, st.RUNNING, l, 1.0 if F.tt_running[t] else 0.0)
        if get1(TS, b, st.RESET, l) != 0.0:
            put1(TS, b, st.RAMP_FROM_BUILD, l, 0.0)
        if (quality is not None and F.P[b, PRM_QUALITY] != 0.0 and F.h_build_pose_pending[0] != 0
                and get1(TS, b, st.RESET, l) != 0.0 and get1(TS, b, st.TIME_RESET, l) != 0.0
                and first_frame_continues_build_pose(F, b, l)):
            build_reset_lane(F, b, l)
            put1(TS, b, st.RAMP_FROM_BUILD, l, 1.0)
        # the stabilisation ramp in continuous time when it started at the build (t = 0, on the
        # step grid); after a first-frame reset the per-step ramp is kept (docs/quality-mode.md)
        since_last_step = 0.0
        if get1(TS, b, st.RAMP_FROM_BUILD, l) != 0.0:
            since_last_step = F.tt_old_time[t] - F.tt_now_update_time[t]
        put1(TS, b, st.DISPLAY_T, l, since_last_step)


@kernel
def lane_team(TI, b, l):
    return TI[b, bk.TI_TEAM + l]


@kernel
def busiest_lane_steps(TI, update_count, b, w):
    """The steps this frame of block b's busiest lane (``update_count``: the team clocks')."""
    steps = 0
    for l in range(w):
        t = lane_team(TI, b, l)
        if t >= 0:
            steps = max(steps, update_count[t])
    return steps


@kernel(forceinline=False, inline="always")
def run_step(F, b, fi, angle, bending, point_collision, edge_collision, motion, quality, wind, wind_zones,
             colliders):
    """One simulation step of block b (§D.0 order): every lane at its own frame
    interpolation (``FRAME_INTERPOLATION``). ``F``: the frame's ``FrameArrays``, or the
    solver's ``Tables`` (a step reads table fields only)."""
    PS, TS, CS, PM, PP, TM, P, BI, topology = F.PS, F.TS, F.CS, F.PM, F.PP, F.TM, F.P, F.BI, F.topology
    dt = fi.dt
    ratio = fi.frequency_ratio
    tether_attenuation, distance_attenuation, limit_attenuation, restoration_attenuation, motion_attenuation = \
        step_attenuations(P, b, ratio)
    team_step_block(TS, TM, P, b, bk.lane_width(BI, b), dt)
    if colliders is not None:
        collider_step_block(CS, TS, BI, topology, b)
    predict_block(PS, PM, PP, TS, P, BI, topology, b, dt, ratio, fi.power_z)
    if wind is not None:
        wind_block(PS, PM, TS, F.TI, P, BI, topology, b, dt, wind_zones)
    step_basic_pose_block(PS, PM, TS, TM, P, BI, topology, b)
    tether_block(PS, P, BI, topology, b, tether_attenuation, ratio)
    distance_block(PS, PM, PP, TS, TM, F.LM, P, BI, topology, b, ratio, fi.power_y,
                   distance_attenuation)
    drift = False
    if angle is not None:
        drift = quality is not None and drift_applies(P, b)
        if drift:   # quality mode: the angle pass's kept-out share, a drift the passes do not see
            drift_begin_block(PS, BI, b)
        angle_block(PS, PP, TS, P, BI, topology, b, ratio, fi.power_w, limit_attenuation,
                    restoration_attenuation)
        if drift:
            drift_end_block(PS, BI, topology, b)
    if bending is not None:
        if BI[b, bk.BI_BENDS] > 0 or BI[b, bk.BI_VOLUMES] > 0:
            bending_block(PS, PM, TS, F.BM, F.VM, P, BI, topology, b, ratio, fi.power_y)
    if BI[b, bk.BI_COLLIDERS] > 0:
        if point_collision is not None:
            if P[b, PRM_COLLISION_MODE] == 1.0:
                point_collision_block(PS, PP, TS, CS, BI, topology, b)
        if edge_collision is not None:
            if P[b, PRM_COLLISION_MODE] == 2.0:
                edge_collision_block(PS, PP, TS, CS, BI, topology, b)
    distance_block(PS, PM, PP, TS, TM, F.LM, P, BI, topology, b, ratio, fi.power_y,
                   distance_attenuation)
    if motion is not None:
        motion_block(PS, PP, TS, P, BI, topology, b, motion_attenuation)
    if quality is not None:
        if P[b, PRM_INEXTENSIBILITY] != 0.0 or P[b, PRM_COLLISION_LAST] != 0.0:  # quality mode (§D.0)
            quality_end_of_step_block(PS, PM, PP, TS, TM, CS, F.LM, F.EDS, P, BI, topology, b,
                                      ratio, fi.power_y, distance_attenuation, drift)
    end_step_block(PS, PM, TS, P, BI, topology, b, dt, ratio)
    if quality is not None:
        if (P[b, PRM_CONTACT_SPEED_LIMIT] >= 0.0 and BI[b, bk.BI_COLLIDERS] > 0
                and P[b, PRM_COLLISION_MODE] != 0.0):
            contact_speed_block(PS, PP, TS, CS, P, BI, topology, b, dt)   # quality mode: after D.10
        if P[b, PRM_TIME_BASED_SMOOTHING] != 0.0:   # quality display: keep this step's state (display.py)
            record_display_state_block(PS, TS, BI, topology, b)
    if colliders is not None:
        collider_end_step_block(CS, BI, b)


@kernel(forceinline=False)
def frozen_lanes(TS, TI, b, w):
    """Does block b have a team that is not simulated this frame (``ACTIVE`` 0)?"""
    for l in range(w):
        if lane_team(TI, b, l) >= 0 and get1(TS, b, st.ACTIVE, l) == 0.0:
            return True
    return False


@kernel(forceinline=False)
def save_frozen(PS, TS, CS, TI, BI, b, w, area):
    for l in range(w):
        if lane_team(TI, b, l) >= 0 and get1(TS, b, st.ACTIVE, l) == 0.0:
            save_lane(PS, TS, CS, BI, b, l, area)


@kernel(forceinline=False)
def restore_frozen(PS, TS, CS, TI, BI, b, w, area):
    for l in range(w):
        if lane_team(TI, b, l) >= 0 and get1(TS, b, st.ACTIVE, l) == 0.0:
            restore_lane(PS, TS, CS, BI, b, l, area)


@kernel(forceinline=False, inline="always")
def block_frame_steps(F, b, fi, area, angle, bending, point_collision, edge_collision, motion, quality,
                      wind, wind_zones, colliders):
    """Block b's frame up to the write-back: its lanes' begin of frame and the steps (each
    lane advancing its own clock, §A.6; the clock of a suspended but enabled team advances
    too). Lanes that do not run keep their state (module docstring)."""
    tt_active, tt_frame_delta_time = F.tt_active, F.tt_frame_delta_time
    tt_frame_interpolation, tt_frame_old_time = F.tt_frame_interpolation, F.tt_frame_old_time
    tt_now_time_scale, tt_now_update_time = F.tt_now_time_scale, F.tt_now_update_time
    tt_running, tt_skip_count, tt_step_running = F.tt_running, F.tt_skip_count, F.tt_step_running
    tt_time, tt_update_count, h_local_to_world = F.tt_time, F.tt_update_count, F.h_local_to_world
    h_lossy_scale, h_world_position, h_world_rotation = F.h_lossy_scale, F.h_world_position, F.h_world_rotation
    PS, TS, CS, PM, TI, BI, PT = F.PS, F.TS, F.CS, F.PM, F.TI, F.BI, F.PT
    warm_block(F, b, area, angle, bending, edge_collision, quality)
    w = bk.lane_width(BI, b)
    frozen = frozen_lanes(TS, TI, b, w)
    if frozen:
        save_frozen(PS, TS, CS, TI, BI, b, w, area)
    begin_frame_prelude_block(F, b, w, quality)
    skin_block(PS, PM, BI, PT, h_local_to_world, b, 0, w)
    for l in range(w):
        t = lane_team(TI, b, l)
        if t >= 0 and get1(TS, b, st.ACTIVE, l) != 0.0:
            component, anchor = team_world_poses(TI, b, l, h_world_position, h_world_rotation, h_lossy_scale)
            center_and_inertia_lane(F, b, l, component, anchor, tt_frame_delta_time[t], tt_now_time_scale[t],
                                    tt_skip_count[t], tt_running[t], fi.dt, get1(TS, b, st.DISPLAY_T, l))
    reset_or_shift_block(PS, TS, BI, b)
    if colliders is not None:
        collider_frame_block(CS, TS, TI, BI, F.CT, b, w, h_world_position, h_world_rotation, h_lossy_scale)
    if frozen:
        restore_frozen(PS, TS, CS, TI, BI, b, w, area)
    for step in range(busiest_lane_steps(TI, tt_update_count, b, w)):
        runs = 0
        idle = 0
        for l in range(w):
            t = lane_team(TI, b, l)
            if t < 0:
                continue
            team_time_begin_step_team(step, t, tt_active, tt_update_count, tt_time, tt_now_update_time,
                                      tt_frame_old_time, tt_frame_interpolation, tt_step_running, fi.dt,
                                      fi.timing)
            put1(TS, b, st.FRAME_INTERPOLATION, l, tt_frame_interpolation[t])
            if get1(TS, b, st.ACTIVE, l) != 0.0 and tt_step_running[t]:
                runs += 1
            else:
                idle += 1
        if runs == 0:
            continue
        if idle > 0:
            for l in range(w):
                t = lane_team(TI, b, l)
                if t >= 0 and not (get1(TS, b, st.ACTIVE, l) != 0.0 and tt_step_running[t]):
                    save_lane(PS, TS, CS, BI, b, l, area)
        run_step(F, b, fi, angle, bending, point_collision, edge_collision, motion, quality, wind, wind_zones,
                 colliders)
        if idle > 0:
            for l in range(w):
                t = lane_team(TI, b, l)
                if t >= 0 and not (get1(TS, b, st.ACTIVE, l) != 0.0 and tt_step_running[t]):
                    restore_lane(PS, TS, CS, BI, b, l, area)


@kernel(forceinline=False, inline="always")
def block_frame_end(F, b, fi, area, quality, lines, triangles, colliders):
    """Block b's stages after the steps: guards, E.1-E.4 and A.7 of every active lane (the
    frame's team clocks read per lane); lanes that are not simulated keep their state."""
    tt_now_update_time, tt_old_time, tt_running = F.tt_now_update_time, F.tt_old_time, F.tt_running
    tt_time, h_local_position, h_local_rotation = F.tt_time, F.h_local_position, F.h_local_rotation
    h_lossy_scale, h_parent, h_world_rotation = F.h_lossy_scale, F.h_parent, F.h_world_rotation
    PS, TS, CS, PM, TI, P, BI, PT, topology = F.PS, F.TS, F.CS, F.PM, F.TI, F.P, F.BI, F.PT, F.topology
    w = bk.lane_width(BI, b)
    dt = fi.dt
    frozen = frozen_lanes(TS, TI, b, w)
    if frozen:
        save_frozen(PS, TS, CS, TI, BI, b, w, area)
    check_block(PS, TS, BI, b)
    for l in range(w):
        t = lane_team(TI, b, l)
        if t < 0 or get1(TS, b, st.ACTIVE, l) == 0.0:
            continue
        code = lane_guard_code(TS, b, l)
        if code != 0:
            reset_lane_to_base(PS, TS, BI, b, l)
            put1(TS, b, st.GUARD_CODE, l, float(code))
            put1(TS, b, st.RAMP_FROM_BUILD, l, 0.0)
        put1(TS, b, st.DISPLAY_T, l, display_fraction(dt, tt_time[t], tt_old_time[t], tt_now_update_time[t]))
        alpha = min(max(tt_time[t] - tt_now_update_time[t], 0.0), dt) / dt if dt > 0.0 else 0.0
        put1(TS, b, st.DISPLAY_ALPHA, l, alpha)
    display_block(PS, TS, P, BI, topology, b, dt, quality)
    if quality is not None:
        if P[b, PRM_TIME_BASED_SMOOTHING] != 0.0:
            display_constraints_block(PS, F.PP, TS, CS, F.EDS, P, BI, topology, b, dt)  # quality (§E.1)
    if lines is not None:
        line_rotations_block(PS, PM, TS, P, BI, topology, b)
    if triangles is not None:
        triangle_rotations_block(PS, F.TRS, F.TRM, BI, topology, b)
    transform_block(PS, PM, TS, BI, PT, topology, b, h_parent, h_world_rotation, h_lossy_scale)
    write_transforms_block(PS, TS, TI, BI, PT, topology, b, w, h_local_position, h_local_rotation)
    for l in range(w):   # a lane whose transform data is not finite is reset and reported
        t = lane_team(TI, b, l)
        if t >= 0 and get1(TS, b, st.ACTIVE, l) != 0.0 and get1(TS, b, st.TRANSFORM_OK, l) == 0.0:
            reset_lane_to_base(PS, TS, BI, b, l)
            put1(TS, b, st.GUARD_CODE, l, 1.0)
    end_frame_block(TS, TI, b, w, tt_running)
    if colliders is not None:
        collider_end_frame_block(CS, TS, TI, BI, b, w, tt_running)
    if frozen:
        restore_frozen(PS, TS, CS, TI, BI, b, w, area)


@kernel(inline="always")
def _time_frame_update(F, fi):
    team_time_frame_update(
        F.tt_active, F.tt_suspended, F.tt_update_mode, F.tt_team_time_scale, F.tt_time, F.tt_old_time,
        F.tt_now_update_time, F.tt_old_update_time, F.tt_frame_update_time, F.tt_frame_old_time,
        F.tt_update_count, F.tt_skip_count, F.tt_frame_delta_time, F.tt_now_time_scale, F.tt_frame_add,
        F.tt_running, fi.delta_time, fi.unscaled_delta_time, fi.fixed_delta_time,
        fi.fixed_update_count, fi.global_time_scale, fi.dt, fi.max_steps, fi.timing)


@kernel(forceinline=False)
def _frame_close(F, fi):
    team_time_end_frame(F.tt_active, F.tt_running, F.tt_step_running, F.tt_skip_count, F.tt_time, F.tt_old_time,
                        F.tt_now_update_time, F.tt_old_update_time, F.tt_frame_update_time,
                        F.tt_frame_old_time, fi.timing)
    F.h_build_pose_pending[0] = 0  # teams added or reset later reset at their first frame


@kernel(forceinline=False)
def frame_counts(F):
    """What the frame did, for the caller's metrics and events: (most steps of a team,
    particle-steps, lanes with a guard code). Integers: the same on every CPU."""
    most_steps = np.int64(0)
    particle_steps = np.int64(0)
    guarded = 0
    for i in range(F.blocks.shape[0]):
        b = F.blocks[i]
        n = np.int64(F.BI[b, bk.BI_N])
        for l in range(bk.lane_width(F.BI, b)):
            t = F.TI[b, bk.TI_TEAM + l]
            if t < 0:
                continue
            c = np.int64(F.tt_update_count[t])
            most_steps = max(most_steps, c)
            particle_steps += c * n
            if get1(F.TS, b, st.GUARD_CODE, l) != 0.0:
                guarded += 1
    return most_steps, particle_steps, guarded


@kernel(forceinline=False)
def simulate_frame(F, frame_values, area, wind_zones, angle, bending, point_collision, edge_collision, motion,
                   quality, lines, triangles, wind, colliders):
    """The whole cloth frame, one block after another (see the module docstring): each
    block's begin, steps and end. ``F``: the frame's arrays (``frame_call.FrameArrays``:
    ``Tables``, ``TimeArrays`` (``tt_*``), ``HierarchyArrays`` (``h_*``) in one StructRef);
    ``frame_values``: the frame inputs (``frame_input_values``); ``area``: ``lane_save_area``.
    Returns ``frame_counts``. The system calls it directly (one compiled function between
    Python and the stages: a wrapper kernel around it would optimise and emit every stage's
    code once more on the first run)."""
    fi = frame_inputs(frame_values)
    prepare_lanes(F)
    _time_frame_update(F, fi)
    for i in range(F.blocks.shape[0]):
        block_frame_steps(F, F.blocks[i], fi, area[0], angle, bending, point_collision, edge_collision,
                          motion, quality, wind, wind_zones, colliders)
        block_frame_end(F, F.blocks[i], fi, area[0], quality, lines, triangles, colliders)
    _frame_close(F, fi)
    return frame_counts(F)


@kernel(forceinline=False)
def begin_parallel_frame(F, frame_values, block_worker, worker_load, worker_share):
    """A frame on several threads, before the threads: ``simulate_frame``'s scale suspension,
    culling and team clocks, then the blocks dealt to the threads (``assign_workers``,
    ``WorkerTable``). Returns the number of threads that get blocks. The system then runs
    ``simulate_worker`` on each thread (Python threads: the kernels release the GIL) and
    ``end_parallel_frame``; blocks are independent and each runs in its own order, so the
    results are the serial kernel's bits."""
    fi = frame_inputs(frame_values)
    prepare_lanes(F)
    _time_frame_update(F, fi)
    workers = max(1, min(fi.threads, worker_load.shape[0]))
    assign_workers(F, WorkerTable(block_worker, worker_load, worker_share), workers)
    return workers


@kernel(forceinline=False)
def simulate_worker(F, frame_values, area, wind_zones, block_worker, worker, angle, bending, point_collision,
                    edge_collision, motion, quality, lines, triangles, wind, colliders):
    """Thread ``worker``'s share of a parallel frame: the begin, steps and end of each block
    ``assign_workers`` dealt to it (``block_worker``), with its own row of the save area."""
    fi = frame_inputs(frame_values)
    for i in range(F.blocks.shape[0]):
        b = F.blocks[i]
        if block_worker[b] == worker:
            block_frame_steps(F, b, fi, area[worker], angle, bending, point_collision, edge_collision,
                              motion, quality, wind, wind_zones, colliders)
            block_frame_end(F, b, fi, area[worker], quality, lines, triangles, colliders)


@kernel(forceinline=False)
def end_parallel_frame(F, frame_values):
    """A frame on several threads, after the threads: ``simulate_frame``'s close of frame
    (§A.7) and its counts (``frame_counts``)."""
    fi = frame_inputs(frame_values)
    _frame_close(F, fi)
    return frame_counts(F)


@kernel(forceinline=False)
def assign_workers(F, wt, workers):
    """``wt.block_worker`` for this frame: the live blocks cut into ``workers`` runs of
    consecutive blocks, run w holding about ``wt.worker_share[w]`` of the frame's load (a
    block's load: its particles times the lanes it uses times the steps of its busiest lane,
    plus one for the frame stages); a block goes to the run its middle falls in, so that no
    run is more than half a block off its share. Consecutive blocks on one thread keep each
    thread's writes (particle and team rows, team clocks, the bones written back) in one
    region of memory, away from the other threads'."""
    total = np.int64(0)
    for i in range(F.blocks.shape[0]):
        total += block_load(F, F.blocks[i])
    shares = 0.0
    for w in range(workers):
        wt.worker_load[w] = 0
        shares += wt.worker_share[w]
    # run w ends at ``edge`` (in load units, doubled so that a block's middle is an integer)
    scale = 2.0 * total / shares if shares > 0.0 else 0.0
    w = 0
    edge = wt.worker_share[0] * scale
    done = np.int64(0)
    for i in range(F.blocks.shape[0]):
        b = F.blocks[i]
        load = block_load(F, b)
        while w < workers - 1 and 2 * done + load >= edge:
            w += 1
            edge += wt.worker_share[w] * scale
        wt.block_worker[b] = w
        wt.worker_load[w] += load
        done += load


@kernel
def block_load(F, b):
    steps = busiest_lane_steps(F.TI, F.tt_update_count, b, bk.lane_width(F.BI, b))
    return np.int64(F.BI[b, bk.BI_N]) * np.int64(F.BI[b, bk.BI_LANES_USED]) * np.int64(steps + 1)


@kernel(inline="always")
def typed_only(n):
    """False for every n. The ``compile_*`` functions below call the stages under
    ``if typed_only(...)``: numba types (and so compiles into its cache) every callee of a branch
    it cannot decide, while LLVM folds ``n * 0 != 0`` to false in the function's own module
    and drops the calls, and with them the callees' code that numba links into the
    ``compile_*`` function's module, before that module is optimised and turned into machine
    code (3.4 s less of the tail's first run: docs/tech-notes.md §7). Inlined at numba's level
    (``inline="always"``), so that the constant
    is in the caller's own module when LLVM optimises it; a module-level constant instead
    would be pruned before typing, and the callees would not be compiled at all."""
    return n * 0 != 0


@kernel(forceinline=False)
def compile_end_stages(F, frame_values, area, quality, lines, triangles, colliders):
    """The end-of-frame stages (``block_frame_end``) typed and compiled with exactly the frame
    kernels' argument types, never run (see ``typed_only``): on a first run the system's process
    compiles them while a forked helper compiles the step's stages (``compile_step_stages``,
    ``solver/compile_helper.py``)."""
    fi = frame_inputs(frame_values)
    if typed_only(F.blocks.shape[0]):
        block_frame_end(F, F.blocks[0], fi, area[0], quality, lines, triangles, colliders)


@kernel(forceinline=False)
def compile_step_stages(F, frame_values, wind_zones, angle, bending, point_collision, edge_collision, motion,
                        quality, wind, colliders):
    """The step's stages (``run_step``) typed and compiled with exactly the frame kernels'
    argument types, never run (see ``typed_only``): a first run's forked helper compiles them
    into numba's cache (``solver/compile_helper.py``)."""
    fi = frame_inputs(frame_values)
    if typed_only(F.blocks.shape[0]):
        run_step(F, F.blocks[0], fi, angle, bending, point_collision, edge_collision, motion, quality, wind,
                 wind_zones, colliders)


@kernel(forceinline=False)
def compile_late_stages(F, frame_values, colliders):
    """The functions the frame kernel's typing reaches last (the close of frame and the end of
    the begin of frame), typed in the reverse of that order with exactly the frame kernels'
    argument types, never run (see ``typed_only``): a first run's helper compiles them after
    the step's stages (``solver/compile_helper.py``), while the system's process is still
    working forward through the begin of frame, so that the two meet in between."""
    fi = frame_inputs(frame_values)
    if typed_only(F.blocks.shape[0]):
        frame_counts(F)
        _frame_close(F, fi)
        b = F.blocks[0]
        w = bk.lane_width(F.BI, b)
        for step in range(busiest_lane_steps(F.TI, F.tt_update_count, b, w)):
            for l in range(w):
                t = lane_team(F.TI, b, l)
                team_time_begin_step_team(step, t, F.tt_active, F.tt_update_count, F.tt_time,
                                          F.tt_now_update_time, F.tt_frame_old_time, F.tt_frame_interpolation,
                                          F.tt_step_running, fi.dt, fi.timing)
        if colliders is not None:
            collider_frame_block(F.CS, F.TS, F.TI, F.BI, F.CT, b, w, F.h_world_position, F.h_world_rotation,
                                 F.h_lossy_scale)
        reset_or_shift_block(F.PS, F.TS, F.BI, b)
        for l in range(w):
            t = lane_team(F.TI, b, l)
            component, anchor = team_world_poses(F.TI, b, l, F.h_world_position, F.h_world_rotation, F.h_lossy_scale)
            center_and_inertia_lane(F, b, l, component, anchor, F.tt_frame_delta_time[t], F.tt_now_time_scale[t],
                                    F.tt_skip_count[t], F.tt_running[t], fi.dt, get1(F.TS, b, st.DISPLAY_T, l))
