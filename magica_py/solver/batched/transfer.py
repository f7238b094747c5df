"""Moving state between the team rows (``ParticleState``, ``TeamState``, ``ColliderState``)
and a block's lane-innermost arrays (``BlockState``). The begin of frame in block form
(``frame_begin``) fills a block (the skinned pose, the history gathered through the
docs/solver.md §C.5 shift, the plain copies); this module empties it:

* ``scatter_block``: after the steps, the state the rest of the frame reads back (the
  step-internal fields stay in the block);
* ``scatter_block_end``: the results of the end stages in block form (``frame_end``), and
  ``scatter_block_end_inputs`` their inputs, when the block's end of frame runs per team;
* ``in3/in4/out3/out4``: one team or slot row to or from one lane column (the lane-form C.3 /
  G.3 copy-in and copy-out); ``bload*`` / ``bstore*``: one block row.

The copies into a block that only the tests and ``benchmarks/bench_blocks.py`` need are in
``tests/block_transfer.py``. Copies only: values are moved, never recomputed, so they cannot
change bits.
"""
from __future__ import annotations

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels.rows import flat


@kernel
def _out(dst, src, r, k, n):
    for c in range(n):
        dst[r, c] = src[c, k]


@kernel
def _copy_out(dst, src, r, k, n):
    base = r * np.uint64(n)
    for c in range(n):
        dst[base + np.uint64(c)] = src[c, k]


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
    old_rotation, disp_pos) to the team rows: the begin of frame in block form skins and shifts
    the history in the block rows only (``frame_begin``), so the per-team end stages see this
    frame's pose through this copy."""
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
