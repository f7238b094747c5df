"""Block and lane arrays of the batched steps (see ``solver/batched/__init__``).

``BlockTable`` (read-only between formations, except ``block_run`` written each frame):

* per block ``b``: ``block_width`` lanes (teams), ``block_exemplar`` (a team of the block: its
  model rows give the shared topology; local index = model row - its team_particle_start),
  ``block_particle_count`` P, ``block_row_base`` (first row in the block state: particle p of
  lane i is row ``block_row_base + p * width + i``), ``block_lane_base`` (first lane in the
  lane arrays), ``block_shared_base`` (first row of the ``shared_*`` arrays: one row per
  particle, values equal in every lane), ``block_collider_count`` C and ``block_collider_base`` (collider j of lane i
  is lane-collider row ``block_collider_base + j * width + i``), ``block_run`` (1: the block
  runs its steps this frame; written by the frame kernel);
* per lane ``L``: ``lane_team``;
* per team: ``team_block`` (-1: not in a block).

``BlockState``: particle fields mirror ``ParticleState`` (same names, units and meaning) but
component-major, ``(3, rows)`` / ``(4, rows)`` / ``(rows,)``, so that a loop over the lanes of
one particle reads contiguous memory. Lane fields (``lane_*``) hold the team values of the
current step (written at each step by the lane form of docs/solver.md §C.3, ``team_step.team_step_block``, which
also copies them back to ``TeamState``; ``transfer.load_lanes`` copies them from the team rows
for the stage tests);
collider fields (``col_*``) hold each lane's collider slots at this step (``ColliderState``).
"""
from __future__ import annotations

from collections import namedtuple

import numpy as np

from magica_py.solver.fields import F64, I32, U8, make_soa

I64 = np.int64

BLOCK_WIDTH = 64   # lanes per block at most (one step per particle, lane streams on: 24-28 lanes 148 ns, 48-52 lanes 140 ns)

BLOCK_FIELDS = [
    ("block_width", "block", (), I32, "lanes (teams) in the block"),
    ("block_exemplar", "block", (), I32, "team whose model rows give the block's topology"),
    ("block_particle_count", "block", (), I32, "particles per lane"),
    ("block_row_base", "block", (), I32, "first block-state row; row = base + p * width + lane"),
    ("block_lane_base", "block", (), I32, "first lane-array index of the block"),
    ("block_shared_base", "block", (), I32, "first shared row (per particle, same in every lane): base + p"),
    ("block_collider_count", "block", (), I32, "collider slots per lane"),
    ("block_collider_base", "block", (), I32, "first lane-collider row; row = base + j * width + lane"),
    ("block_run", "block", (), U8, "1: runs its steps in block form this frame (frame kernel)"),
    ("lane_team", "lane", (), I32, "team of each lane"),
    ("team_block", "team", (), I32, "block of each team id, -1 if none"),
    # thread assignment of the parallel frame kernel (``frame.assign_workers``, each frame)
    ("block_order", "block", (), I32, "blocks by decreasing size (particles x lanes): assignment order"),
    ("block_worker", "block", (), I32, "thread running the block's frame, -1: the block does not run"),
    ("team_worker", "team", (), I32, "thread running the team's frame, -1: its running block does"),
    ("worker_load", "worker", (), I64, "particle-steps assigned to each thread this frame"),
    # end of frame in block form (``batched/frame_end``)
    ("block_triangle_base", "block", (), I32, "first block triangle row; row = base + tri * width + lane"),
    ("block_end", "block", (), U8, "1: this frame's guards and E.1-E.4 ran in block form (frame kernel)"),
]
BlockTable = make_soa("BlockTable", BLOCK_FIELDS)

# (name, components (0: scalar), dtype, gathered at frame start, scattered at frame end);
# next_pos, velocity_pos, base and step basic pose are step-internal (D.1 rewrites them).
# The begin of frame in block form (``frame.begin_frame_block``) computes position and rotation
# (C.1 skinning, not gathered) and gathers old_position, old_rotation, old_pos, velocity and
# disp_pos through the C.5 shift (``frame_begin.gather_shift_block``); it also stores position,
# rotation, old_position, old_rotation and disp_pos in the team rows (the per-team end-of-frame
# stages read them there; the steps do not change them), so they are not scattered.
PARTICLE_BLOCK_FIELDS = [
    ("position", 3, F64, False, False),
    ("rotation", 4, F64, False, False),
    ("old_position", 3, F64, True, False),
    ("old_rotation", 4, F64, True, False),
    ("next_pos", 3, F64, False, False),
    ("old_pos", 3, F64, True, True),
    ("velocity_pos", 3, F64, False, False),
    ("velocity", 3, F64, True, True),
    ("disp_pos", 3, F64, True, False),
    # model data: ``center.bind_point`` of the vertex's local position (w = 1), normal and
    # tangent (w = 0), the constant half of C.1 (written when the blocks are formed,
    # ``frame_begin.bind_rows_block``; read by ``frame_begin.skin_block``)
    ("skin_bound_position", 4, F64, False, False),
    ("skin_bound_normal", 4, F64, False, False),
    ("skin_bound_tangent", 4, F64, False, False),
    ("real_velocity", 3, F64, False, True),
    ("base_pos", 3, F64, False, False),
    ("base_rot", 4, F64, False, False),
    ("friction", 0, F64, True, True),
    ("static_friction", 0, F64, True, True),
    ("collision_normal", 3, F64, True, True),
    ("step_basic_pos", 3, F64, False, False),
    ("step_basic_rot", 4, F64, False, False),
    # stage scratch (each stage leaves it as it found it, as in ParticleState)
    ("angle_length", 0, F64, False, False),
    ("angle_local_pos", 3, F64, False, False),
    ("angle_local_rot", 4, F64, False, False),
    ("angle_rest_vector", 3, F64, False, False),
    ("angle_inverse_mass", 0, F64, False, False),
    ("angle_rest_length", 0, F64, False, False),
    ("angle_rest_direction", 3, F64, False, False),
    ("angle_rotation", 4, F64, False, False),
    ("accum_vector", 3, F64, False, False),
    ("accum_count", 0, I32, False, False),
    ("bend_inverse_mass", 0, F64, False, False),
    ("distance_inverse_mass", 0, F64, False, False),
    ("accum_friction", 0, F64, False, False),
    ("accum_normal", 3, F64, False, False),
    # end of frame (``batched/frame_end``): E.1 reads and writes disp_pos (gathered above, with
    # the C.5 shift); base_pos/rot_buffer: this frame's animated pose kept by
    # E.1 for E.2 (base_rot_buffer is E.2's only: not scattered); transform_rotation: E.4's
    # bone rotation (transform_position is position, scattered from it)
    ("base_pos_buffer", 3, F64, False, True),
    ("base_rot_buffer", 4, F64, False, False),
    ("transform_rotation", 4, F64, False, False),
    # E.4's local pose of each bone under its parent (the write-back copies it through the
    # transform indices after the barrier): m for the position, xyzw
    ("bone_local_position", 3, F64, False, False),
    ("bone_local_rotation", 4, F64, False, False),
]
# E.3 scratch per triangle of each lane (row = block_triangle_base + tri * width + lane)
TRIANGLE_BLOCK_FIELDS = [
    ("triangle_normal", 3, F64, "unit or 0; display normal of the triangle (E.3, per frame)"),
    ("triangle_tangent", 3, F64, "unit or 0; display uv tangent of the triangle (E.3, per frame)"),
]
# per-particle values that are the same in every lane (parameters x depth): one row per particle
SHARED_PARTICLE_FIELDS = [
    ("shared_damping", 0, F64, "D.1 damping factor saturate(1 - step_rate(damping(depth)))"),
    ("shared_angle_limit", 0, F64, "rad; D.5 limit angle at the particle's depth"),
    ("shared_angle_limit_cos", 0, F64, "cos of shared_angle_limit"),
    ("shared_restoration_k", 0, F64, "D.6 stiffness of this step before the per-lane gravity factor"),
]
# TeamState / team-time values of the current step, one per lane
LANE_FIELDS = [
    ("frame_interpolation", 0, F64), ("old_world_pos", 3, F64), ("now_world_pos", 3, F64),
    ("inertia_vector", 3, F64), ("inertia_rotation", 4, F64), ("step_vector", 3, F64),
    ("step_rotation", 4, F64), ("velocity_weight", 0, F64), ("gravity_ratio", 0, F64),
    ("gravity_dot", 0, F64), ("scale_ratio", 0, F64), ("external_force_mode", 0, I32),
    ("external_force", 3, F64), ("angular_velocity", 0, F64), ("rotation_axis", 3, F64),
    # C.3 in lane form (``solver/team_step.team_step_block``): its other inputs and results
    ("now_world_rot", 4, F64), ("old_frame_world_pos", 3, F64), ("frame_world_pos", 3, F64),
    ("old_frame_world_rot", 4, F64), ("frame_world_rot", 4, F64), ("old_frame_world_scale", 3, F64),
    ("frame_world_scale", 3, F64), ("distance_weight", 0, F64), ("step_move_inertia_ratio", 0, F64),
    ("step_rotation_inertia_ratio", 0, F64), ("blend_weight", 0, F64),
    # begin of frame in block form (``batched/frame_begin``), written once per frame:
    # first model row of the lane's team (team_particle_start), by ``lane_starts_block`` (and
    # the end's lane prelude: the write-back's transform indices)
    ("particle_start", 0, I64),
    # s; team time from the last step to the frame's start (``frame.begin_frame_prelude_team``)
    ("since_last_step", 0, F64),
    # sink of the cache warm-up reads of ``frame_begin.touch_*_block`` (never read)
    ("touch", 0, F64),
    # C.2 sums over the center-fixed vertices (m; unit axes summed), by ``center_sums_block``
    ("center_position_sum", 3, F64), ("center_normal_sum", 3, F64), ("center_tangent_sum", 3, F64),
    # C.5 of the lane (``begin_lane_team``): SHIFT_KEEP / SHIFT_MOVE / SHIFT_RESET, and the
    # shift's pivot (m, the previous component position), vector (m) and rotation
    ("shift_mode", 0, I32), ("shift_pivot", 3, F64), ("shift_vector", 3, F64), ("shift_rotation", 4, F64),
    # end of frame in block form (``batched/frame_end``), written by its lane prelude from the
    # team rows (blend_weight above is the last step's; a frame may have no step of its own)
    ("guard_limit_sq", 0, F64),     # (m/s)^2; guards' speed bound
    ("display_t", 0, F64),          # E.1 frame interpolation fraction
    ("end_blend_weight", 0, F64),   # TeamState.blend_weight at the end of the frame
    ("end_running", 0, U8),         # 1: the team ran this frame (E.1 keeps the old pose)
    ("transform_ok", 0, U8),        # E.4: 1 when every bone value of the lane is finite
    ("line_ctv", 3, F64),           # E.2 sum of the children's rest vectors of the current entry (m)
    ("line_cv", 3, F64),            # E.2 sum of the children's simulated vectors (m)
    ("vertex_ns", 3, F64),          # E.3 sum of the current vertex's triangle normals
    ("vertex_ts", 3, F64),          # E.3 sum of its triangle tangents
]
# ColliderState values of each lane's collider slots at the current step
COLLIDER_FIELDS = [
    ("shape", 0, I32), ("scale_suspend", 0, U8), ("start_old", 3, F64), ("end_old", 3, F64),
    ("start_new", 3, F64), ("end_new", 3, F64), ("radius_start", 0, F64), ("radius_end", 0, F64),
    ("plane_normal", 3, F64), ("inverse_old_rot", 4, F64), ("now_rot", 4, F64),
    ("aabb_min", 3, F64), ("aabb_max", 3, F64),
    # G.3 in lane form (``colliders.collider_step_block``): its other inputs and results
    ("old_frame_pos", 3, F64), ("frame_pos", 3, F64), ("old_frame_rot", 4, F64), ("frame_rot", 4, F64),
    ("old_pos", 3, F64), ("old_rot", 4, F64), ("now_pos", 3, F64),
    ("axis_scale", 0, F64),
]

BlockState = namedtuple("BlockState",
                        [f[0] for f in PARTICLE_BLOCK_FIELDS] + [f[0] for f in SHARED_PARTICLE_FIELDS]
                        + ["lane_" + f[0] for f in LANE_FIELDS] + ["col_" + f[0] for f in COLLIDER_FIELDS]
                        + [f[0] for f in TRIANGLE_BLOCK_FIELDS],
                        module=__name__)


def _array(components: int, n: int, dtype, name: str) -> np.ndarray:
    a = np.zeros((components, n) if components else (n,), dtype=dtype)
    if components == 4 and ("rot" in name):
        a[3] = 1.0
    return a


def allocate_block_state(rows: int, shared_rows: int, lanes: int, collider_rows: int,
                         triangle_rows: int = 0) -> BlockState:
    """Zeroed block arrays (identity quaternions); at least one row each so that types are stable."""
    rows, shared_rows, lanes, collider_rows, triangle_rows = (
        max(1, x) for x in (rows, shared_rows, lanes, collider_rows, triangle_rows))
    arrays = [_array(c, rows, dt, n) for n, c, dt, _g, _s in PARTICLE_BLOCK_FIELDS]
    arrays += [_array(c, shared_rows, dt, n) for n, c, dt, _doc in SHARED_PARTICLE_FIELDS]
    arrays += [_array(c, lanes, dt, n) for n, c, dt in LANE_FIELDS]
    arrays += [_array(c, collider_rows, dt, n) for n, c, dt in COLLIDER_FIELDS]
    arrays += [_array(c, triangle_rows, dt, n) for n, c, dt, _doc in TRIANGLE_BLOCK_FIELDS]
    return BlockState(*arrays)


def worker_capacity() -> int:
    """Threads the parallel frame kernel can use (numba's pool size, fixed at import)."""
    import numba
    return max(1, int(numba.config.NUMBA_NUM_THREADS))
