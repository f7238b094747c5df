"""Moving state between the team rows (``ParticleState``, ``TeamState``, ``ColliderState``)
and a block's lane-innermost arrays (``BlockState``).

* ``gather_block``: at the start of a frame's steps, the particle fields the block takes as is
  from each lane's team rows (the begin of frame in block form, ``frame_begin``, computes the
  skinned pose and gathers the history through the docs/solver.md §C.5 shift);
* ``scatter_block``: after the steps, the state the rest of the frame reads back (the
  step-internal fields stay in the block; ``scatter_block_full`` copies those too, for tests);
* ``gather_block_end`` / ``scatter_block_end``: what the end stages in block form
  (``frame_end``) read besides the gathered state, and their results
  (``scatter_block_end_inputs``: their inputs, when the block's end of frame runs per team);
* ``load_lanes``: a step's team and collider values (after the per-team C.3 / G.3) from the
  team rows into the ``lane_*`` / ``col_*`` arrays, for the stage tests and ``bench_blocks``
  (the block step's lane-form C.3 / G.3 fill them as they compute them);
* ``in3/in4/out3/out4``: one team or slot row to or from one lane column.

Copies only: values are moved, never recomputed, so they cannot change bits.
"""
from __future__ import annotations

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels.rows import flat


@kernel
def block_row(blk, b, p, lane):
    """Row of particle p (team-local) of lane ``lane`` in the block state."""
    return blk.block_row_base[b] + p * blk.block_width[b] + lane


@kernel
def _in(dst, src, k, r, n):
    for c in range(n):
        dst[c, k] = src[r, c]


@kernel
def _out(dst, src, r, k, n):
    for c in range(n):
        dst[r, c] = src[c, k]


@kernel
def _copy_in(dst, src, k, r, n):
    """dst[:n, k] = flat src[r * n : r * n + n] (unsigned indices)."""
    base = r * np.uint64(n)
    for c in range(n):
        dst[c, k] = src[base + np.uint64(c)]


@kernel
def _copy_out(dst, src, r, k, n):
    base = r * np.uint64(n)
    for c in range(n):
        dst[base + np.uint64(c)] = src[c, k]


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
def scatter_block(m, ps, blk, bs, b):
    """The state the steps leave for the rest of the frame and the next one: old_pos, velocity,
    real_velocity, friction, static friction, collision normal. next_pos, velocity_pos,
    base_pos/rot and the step basic pose are step-internal (each step's D.1 writes them all
    before they are read) and stay in the block."""
    width = blk.block_width[b]
    base = blk.block_row_base[b]
    lanes = blk.block_lane_base[b]
    count = blk.block_particle_count[b]
    old_pos, velocity, real_velocity, normal = (flat(ps.old_pos), flat(ps.velocity), flat(ps.real_velocity),
                                                flat(ps.collision_normal))
    friction, static_friction = ps.friction, ps.static_friction
    b_old_pos, b_velocity, b_real_velocity, b_normal = bs.old_pos, bs.velocity, bs.real_velocity, bs.collision_normal
    b_friction, b_static_friction = bs.friction, bs.static_friction
    starts, lane_team = m.team_particle_start, blk.lane_team
    for p in range(count):
        for i in range(width):
            r = np.uint64(starts[lane_team[lanes + i]] + p)
            k = np.uint64(base + p * width + i)
            _copy_out(old_pos, b_old_pos, r, k, 3)
            _copy_out(velocity, b_velocity, r, k, 3)
            _copy_out(real_velocity, b_real_velocity, r, k, 3)
            _copy_out(normal, b_normal, r, k, 3)
            friction[r] = b_friction[k]
            static_friction[r] = b_static_friction[k]


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
def scatter_block_end(m, ps, blk, bs, b):
    """The results of the end stages in block form (``frame_end.end_frame_block``) that stay in
    the block rows, after ``scatter_block``: the displayed pose (position: the sinks read it;
    rotation) and the animated pose the sinks show (base_pos_buffer). E.1 writes the next
    frame's history (disp_pos, old_position, old_rotation) to the team rows itself; the bone
    pose (E.4) stays in the block (the write-back reads it there); E.2's base_rot_buffer and
    E.3's triangle frames are read within the block only: their team rows are not written."""
    width = blk.block_width[b]
    base = blk.block_row_base[b]
    lanes = blk.block_lane_base[b]
    count = blk.block_particle_count[b]
    position, rotation, base_pos_buffer = flat(ps.position), flat(ps.rotation), flat(ps.base_pos_buffer)
    b_position, b_rotation, b_base_pos_buffer = bs.position, bs.rotation, bs.base_pos_buffer
    starts, lane_team = m.team_particle_start, blk.lane_team
    for p in range(count):
        for i in range(width):
            r = np.uint64(starts[lane_team[lanes + i]] + p)
            k = np.uint64(base + p * width + i)
            _copy_out(position, b_position, r, k, 3)
            _copy_out(rotation, b_rotation, r, k, 4)
            _copy_out(base_pos_buffer, b_base_pos_buffer, r, k, 3)


@kernel
def scatter_block_end_inputs(m, ps, blk, bs, b):
    """A block whose end of frame takes the per-team path (``frame_end.end_frame_block``
    False): the block rows the per-team end stages read (position, rotation, old_position,
    old_rotation, disp_pos) to the team rows. Today these rows equal the team rows already
    (only the end stages write them); copied so that a begin of frame in block form can
    keep them in the block."""
    width = blk.block_width[b]
    base = blk.block_row_base[b]
    lanes = blk.block_lane_base[b]
    for p in range(blk.block_particle_count[b]):
        for i in range(width):
            r = m.team_particle_start[blk.lane_team[lanes + i]] + p
            k = base + p * width + i
            _out(ps.position, bs.position, r, k, 3)
            _out(ps.rotation, bs.rotation, r, k, 4)
            _out(ps.old_position, bs.old_position, r, k, 3)
            _out(ps.old_rotation, bs.old_rotation, r, k, 4)
            _out(ps.disp_pos, bs.disp_pos, r, k, 3)


@kernel
def in3(dst, k, src, s):
    """dst[:, k] = src[s] (a team or slot row into a lane / lane-collider column)."""
    dst[0, k] = src[s, 0]
    dst[1, k] = src[s, 1]
    dst[2, k] = src[s, 2]


@kernel
def in4(dst, k, src, s):
    dst[0, k] = src[s, 0]
    dst[1, k] = src[s, 1]
    dst[2, k] = src[s, 2]
    dst[3, k] = src[s, 3]


@kernel
def out3(dst, s, src, k):
    """dst[s] = src[:, k] (a lane / lane-collider column back into its team or slot row)."""
    dst[s, 0] = src[0, k]
    dst[s, 1] = src[1, k]
    dst[s, 2] = src[2, k]


@kernel
def out4(dst, s, src, k):
    dst[s, 0] = src[0, k]
    dst[s, 1] = src[1, k]
    dst[s, 2] = src[2, k]
    dst[s, 3] = src[3, k]


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


# ----------------------------------------------------------------------------- block access
@kernel
def bload3(a, k):
    return (a[0, k], a[1, k], a[2, k])


@kernel
def bstore3(a, k, v):
    a[0, k] = v[0]
    a[1, k] = v[1]
    a[2, k] = v[2]


@kernel
def bload4(a, k):
    return (a[0, k], a[1, k], a[2, k], a[3, k])


@kernel
def bstore4(a, k, q):
    a[0, k] = q[0]
    a[1, k] = q[1]
    a[2, k] = q[2]
    a[3, k] = q[3]
