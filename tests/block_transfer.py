"""Copies between the team rows and a block's rows that only the tests and ``bench_blocks`` use.

The frame fills a block through its begin of frame in block form (``frame.begin_frame_block``)
and the block step's lane-form C.3 / G.3, and empties it through
``solver/batched/transfer.scatter_block*``. The stage tests (``batched_harness``) and
``benchmarks/bench_blocks.py`` instead start a block stage from any mid-step state of the
team rows, and compare the step-internal fields too:

* ``gather_block`` / ``gather_block_full``: the particle fields the block takes as is (collision
  normal, friction, static friction) / every field of the block state, scratch included;
* ``scatter_block_full``: every field the steps write, step-internal ones included;
* ``gather_block_end``: what the end stages in block form read besides the gathered state;
* ``load_lanes``: a step's team values (after C.3) and collider slots (after G.3) of every
  lane, from the team rows.

Copies only (docs/solver.md sections): values are moved, never recomputed.
"""
from __future__ import annotations

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels.rows import flat
from magica_py.solver.batched.transfer import _out, in3, in4


@kernel
def _in(dst, src, k, r, n):
    for c in range(n):
        dst[c, k] = src[r, c]


@kernel
def _copy_in(dst, src, k, r, n):
    """dst[:n, k] = flat src[r * n : r * n + n] (unsigned indices)."""
    base = r * np.uint64(n)
    for c in range(n):
        dst[c, k] = src[base + np.uint64(c)]


@kernel
def gather_block(m, ps, blk, bs, b):
    """The particle state the block takes as is from the team rows: collision normal, friction
    and static friction. The rest of what the steps read comes from the begin of frame in
    block form (``frame.begin_frame_block``: the skinned pose computed in the block, the
    history gathered through the C.5 shift, ``frame_begin.gather_shift_block``, which also
    makes these copies in its pass: the frame does not call this; ``gather_block_full``,
    the stage tests and ``bench_blocks`` do)."""
    width = blk.block_width[b]
    base = blk.block_row_base[b]
    lanes = blk.block_lane_base[b]
    count = blk.block_particle_count[b]
    # arrays as locals and flat team rows (through the tables every pointer is reloaded after
    # each store: the copy ran 3x slower)
    normal, friction, static_friction = flat(ps.collision_normal), ps.friction, ps.static_friction
    b_normal, b_friction, b_static_friction = bs.collision_normal, bs.friction, bs.static_friction
    starts, lane_team = m.team_particle_start, blk.lane_team
    # particle outer, lane inner: the block rows are written in order
    for p in range(count):
        for i in range(width):
            r = np.uint64(starts[lane_team[lanes + i]] + p)
            k = np.uint64(base + p * width + i)
            _copy_in(b_normal, normal, k, r, 3)
            b_friction[k] = friction[r]
            b_static_friction[k] = static_friction[r]


@kernel
def gather_block_full(m, ps, blk, bs, b):
    """Every particle field of ``PARTICLE_BLOCK_FIELDS`` (the stage tests start a block stage
    from a mid-step state: next_pos, velocity_pos, step basic pose, scratch)."""
    gather_block(m, ps, blk, bs, b)
    width = blk.block_width[b]
    base = blk.block_row_base[b]
    lanes = blk.block_lane_base[b]
    count = blk.block_particle_count[b]
    for i in range(width):
        start = m.team_particle_start[blk.lane_team[lanes + i]]
        for p in range(count):
            r = start + p
            k = base + p * width + i
            _in(bs.position, ps.position, k, r, 3)
            _in(bs.rotation, ps.rotation, k, r, 4)
            _in(bs.old_position, ps.old_position, k, r, 3)
            _in(bs.old_rotation, ps.old_rotation, k, r, 4)
            _in(bs.old_pos, ps.old_pos, k, r, 3)
            _in(bs.velocity, ps.velocity, k, r, 3)
            _in(bs.disp_pos, ps.disp_pos, k, r, 3)
            _in(bs.next_pos, ps.next_pos, k, r, 3)
            _in(bs.velocity_pos, ps.velocity_pos, k, r, 3)
            _in(bs.real_velocity, ps.real_velocity, k, r, 3)
            _in(bs.base_pos, ps.base_pos, k, r, 3)
            _in(bs.base_rot, ps.base_rot, k, r, 4)
            _in(bs.step_basic_pos, ps.step_basic_pos, k, r, 3)
            _in(bs.step_basic_rot, ps.step_basic_rot, k, r, 4)
            bs.angle_length[k] = ps.angle_length[r]
            _in(bs.angle_local_pos, ps.angle_local_pos, k, r, 3)
            _in(bs.angle_local_rot, ps.angle_local_rot, k, r, 4)
            _in(bs.angle_rest_vector, ps.angle_rest_vector, k, r, 3)
            bs.angle_inverse_mass[k] = ps.angle_inverse_mass[r]
            bs.angle_rest_length[k] = ps.angle_rest_length[r]
            _in(bs.angle_rest_direction, ps.angle_rest_direction, k, r, 3)
            _in(bs.angle_rotation, ps.angle_rotation, k, r, 4)
            _in(bs.accum_vector, ps.accum_vector, k, r, 3)
            bs.accum_count[k] = ps.accum_count[r]
            bs.bend_inverse_mass[k] = ps.bend_inverse_mass[r]
            bs.accum_friction[k] = ps.accum_friction[r]
            _in(bs.accum_normal, ps.accum_normal, k, r, 3)


@kernel
def scatter_block_full(m, ps, blk, bs, b):
    """Every field the steps write, step-internal ones included (the stage tests compare them)."""
    width = blk.block_width[b]
    base = blk.block_row_base[b]
    lanes = blk.block_lane_base[b]
    count = blk.block_particle_count[b]
    for i in range(width):
        start = m.team_particle_start[blk.lane_team[lanes + i]]
        for p in range(count):
            r = start + p
            k = base + p * width + i
            _out(ps.next_pos, bs.next_pos, r, k, 3)
            _out(ps.old_pos, bs.old_pos, r, k, 3)
            _out(ps.velocity_pos, bs.velocity_pos, r, k, 3)
            _out(ps.velocity, bs.velocity, r, k, 3)
            _out(ps.real_velocity, bs.real_velocity, r, k, 3)
            _out(ps.base_pos, bs.base_pos, r, k, 3)
            _out(ps.base_rot, bs.base_rot, r, k, 4)
            _out(ps.collision_normal, bs.collision_normal, r, k, 3)
            _out(ps.step_basic_pos, bs.step_basic_pos, r, k, 3)
            _out(ps.step_basic_rot, bs.step_basic_rot, r, k, 4)
            ps.friction[r] = bs.friction[k]
            ps.static_friction[r] = bs.static_friction[k]


@kernel
def gather_block_end(m, ps, blk, bs, b):
    """What the end stages in block form (``batched/frame_end``) read that ``gather_block``
    does not copy: the display position (E.1; C.5 shifts it at the begin of the frame)."""
    width = blk.block_width[b]
    base = blk.block_row_base[b]
    lanes = blk.block_lane_base[b]
    disp_pos, b_disp_pos = flat(ps.disp_pos), bs.disp_pos
    starts, lane_team = m.team_particle_start, blk.lane_team
    for p in range(blk.block_particle_count[b]):
        for i in range(width):
            r = np.uint64(starts[lane_team[lanes + i]] + p)
            k = np.uint64(base + p * width + i)
            _copy_in(b_disp_pos, disp_pos, k, r, 3)


@kernel
def load_lanes(blk, bs, ts, tt, cs, b):
    """This step's team values (after C.3) and collider slots (after G.3) of every lane, from the
    team rows. The block step no longer calls it (``team_step.team_step_block`` and
    ``colliders.collider_step_block`` fill these lane arrays as they compute them); the stage
    tests (``tests/batched_harness``) and ``benchmarks/bench_blocks`` load lanes with it."""
    width = blk.block_width[b]
    lanes = blk.block_lane_base[b]
    colliders = blk.block_collider_count[b]
    cbase = blk.block_collider_base[b]
    for i in range(width):
        L = lanes + i
        t = blk.lane_team[L]
        bs.lane_frame_interpolation[L] = tt.frame_interpolation[t]
        in3(bs.lane_old_world_pos, L, ts.old_world_pos, t)
        in3(bs.lane_now_world_pos, L, ts.now_world_pos, t)
        in3(bs.lane_inertia_vector, L, ts.inertia_vector, t)
        in4(bs.lane_inertia_rotation, L, ts.inertia_rotation, t)
        in3(bs.lane_step_vector, L, ts.step_vector, t)
        in4(bs.lane_step_rotation, L, ts.step_rotation, t)
        bs.lane_velocity_weight[L] = ts.velocity_weight[t]
        bs.lane_gravity_ratio[L] = ts.gravity_ratio[t]
        bs.lane_gravity_dot[L] = ts.gravity_dot[t]
        bs.lane_scale_ratio[L] = ts.scale_ratio[t]
        bs.lane_external_force_mode[L] = ts.external_force_mode[t]
        in3(bs.lane_external_force, L, ts.external_force, t)
        bs.lane_angular_velocity[L] = ts.angular_velocity[t]
        in3(bs.lane_rotation_axis, L, ts.rotation_axis, t)
        start = ts.collider_start[t]
        for j in range(colliders):
            s = start + j
            k = cbase + j * width + i
            bs.col_shape[k] = cs.shape[s]
            bs.col_scale_suspend[k] = cs.scale_suspend[s]
            in3(bs.col_start_old, k, cs.start_old, s)
            in3(bs.col_end_old, k, cs.end_old, s)
            in3(bs.col_start_new, k, cs.start_new, s)
            in3(bs.col_end_new, k, cs.end_new, s)
            bs.col_radius_start[k] = cs.radius_start[s]
            bs.col_radius_end[k] = cs.radius_end[s]
            in3(bs.col_plane_normal, k, cs.plane_normal, s)
            in4(bs.col_inverse_old_rot, k, cs.inverse_old_rot, s)
            in4(bs.col_now_rot, k, cs.now_rot, s)
            in3(bs.col_aabb_min, k, cs.aabb_min, s)
            in3(bs.col_aabb_max, k, cs.aabb_max, s)
