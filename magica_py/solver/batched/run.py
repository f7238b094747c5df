"""The block step: ``run_step`` of ``solver/frame.py`` for every lane of a block at once.

The per-team parts of a step run for all lanes at once too (docs/solver.md §C.3 ``team_step.team_step_block``,
G.3 ``colliders.collider_step_block``: copy-in, lane loop, copy-out, the collider end of step
folded into the copy-out); the particle stages run in block form, in ``run_step``'s order with the same
arguments (``attenuations.step_attenuations`` of the exemplar's parameter row, equal in every
lane by formation).
"""
from __future__ import annotations

from magica_py.jit import kernel
from magica_py.solver.colliders import collider_step_block
from magica_py.solver.attenuations import step_attenuations
from magica_py.solver.constraints.angle import angle_block
from magica_py.solver.constraints.bending import apply_accumulated_block, bending_block
from magica_py.solver.constraints.collision import point_collision_block
from magica_py.solver.constraints.distance import distance_block
from magica_py.solver.constraints.motion import motion_block
from magica_py.solver.constraints.tether import tether_block
from magica_py.solver.step import end_step_block, predict_block, step_basic_pose_block
from magica_py.solver.team_step import team_step_block


@kernel
def decide_blocks(m, ts, tt, blk):
    """``blk.block_run``: 1 for a block whose lanes all run this frame with the same number
    of steps (after the team time); its teams then skip the per-team step path."""
    for b in range(blk.block_width.shape[0]):
        lanes = blk.block_lane_base[b]
        first = blk.lane_team[lanes]
        count = tt.update_count[first]
        run = count > 0
        for i in range(blk.block_width[b]):
            t = blk.lane_team[lanes + i]
            if ts.active[t] == 0 or tt.update_count[t] != count:
                run = False
        blk.block_run[b] = 1 if run else 0


@kernel
def team_runs_alone(blk, t):
    """True when team t's steps run per team this frame (no block, or its block does not run)."""
    b = blk.team_block[t]
    return b < 0 or blk.block_run[b] == 0


@kernel
def run_block_step(m, prm, ts, cs, tt, blk, bs, b, fi):
    """One simulation step of every lane of block b (``frame.run_step`` in block form)."""
    dt = fi.dt
    ratio = fi.frequency_ratio
    ex = blk.block_exemplar[b]
    tether_attenuation, distance_attenuation, limit_attenuation, restoration_attenuation, motion_attenuation = \
        step_attenuations(prm, ex, ratio)
    # C.3 and G.3 of every lane, lanes innermost; they fill the lane arrays (load_lanes' values)
    team_step_block(m, prm, ts, tt, blk, bs, b, dt)
    if blk.block_collider_count[b] > 0:
        collider_step_block(cs, ts, blk, bs, b)
    predict_block(m, bs, prm, blk, b, dt, ratio, fi.power_z)
    step_basic_pose_block(m, bs, prm, blk, b)
    tether_block(m, bs, prm, blk, b, tether_attenuation)
    distance_block(m, bs, prm, blk, b, ratio, fi.power_y, distance_attenuation)
    angle_block(m, bs, prm, blk, b, ratio, fi.power_w, limit_attenuation, restoration_attenuation)
    if m.team_bend_count[ex] > 0 or m.team_volume_count[ex] > 0:
        bending_block(m, bs, prm, blk, b, ratio, fi.power_y)
        apply_accumulated_block(m, bs, blk, b, True)
    if blk.block_collider_count[b] > 0 and prm.collision_mode[ex] == 1:
        point_collision_block(m, bs, prm, blk, b)
    distance_block(m, bs, prm, blk, b, ratio, fi.power_y, distance_attenuation)
    motion_block(m, bs, prm, blk, b, motion_attenuation)
    end_step_block(m, bs, prm, blk, b, dt, ratio)
    # the colliders' end of step (old pose = now pose) is done by collider_step_block's copy-out
