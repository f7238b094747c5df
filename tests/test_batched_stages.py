"""Each block stage (``solver/batched``) gives exactly the bits of its per-team stage, from
the same mid-motion crowd state (``batched_harness``)."""
import numba
import numpy as np
import pytest

from batched_harness import block_tables, compare_stage, crowd_system
from magica_py.solver.batch_tables import borrow
from magica_py.solver.step import predict_block, predict_team

DT = 1.0 / 90.0
MOVE = 0x02


@pytest.fixture(scope="module")
def crowd():
    return crowd_system(instances=6, frames=25)


@numba.njit
def _predict_teams(m, ps, prm, ts, cs, tt, teams):
    m, ps, prm, ts = borrow(m), borrow(ps), borrow(prm), borrow(ts)
    for t in teams:
        predict_team(m, ps, prm, ts, t, tt.frame_interpolation[t], DT, 0.5, 1.0)


@numba.njit
def _predict_blocks(m, ps, prm, ts, cs, tt, blk, bs, blocks):
    m, prm, blk, bs = borrow(m), borrow(prm), borrow(blk), borrow(bs)
    for b in blocks:
        predict_block(m, bs, prm, blk, b, DT, 0.5, 1.0)


def test_predict_block_is_bit_identical_to_predict_team(crowd):
    compare_stage(crowd, _predict_teams, _predict_blocks,
             ["base_pos", "base_rot", "step_basic_pos", "step_basic_rot", "next_pos", "velocity_pos", "velocity"])


def test_predict_block_matches_with_a_mid_frame_interpolation(crowd):
    tt = crowd.time_state
    saved = tt.frame_interpolation.copy()
    tt.frame_interpolation[:] = 0.37
    try:
        compare_stage(crowd, _predict_teams, _predict_blocks, ["base_pos", "base_rot", "next_pos", "velocity"])
    finally:
        tt.frame_interpolation[:] = saved


PREDICT_FIELDS = ["base_pos", "base_rot", "step_basic_pos", "step_basic_rot", "next_pos", "velocity_pos", "velocity"]


def _predict_kinds(system, blk):
    """(Fixed, Move without the depth-inertia mix, Move with it) particles of the block lanes,
    the way predict_team decides them."""
    m, prm = system.model, system.parameters
    team_of = np.repeat(np.arange(len(m.team_particle_count)), m.team_particle_count)
    in_block = np.isin(team_of, blk.lane_team)
    move = (np.asarray(m.attribute) & MOVE) != 0
    k = prm.depth_inertia[team_of] * (1.0 - np.asarray(m.depth) ** 2)
    return in_block & ~move, in_block & move & (k == 0.0), in_block & move & (k != 0.0)


@pytest.mark.parametrize("depth_inertia", ["preset", 0.0])
@pytest.mark.parametrize("interpolation", ["last step", "per lane", "mid step"])
def test_predict_block_is_bit_identical_on_every_lane_loop_variant(crowd, interpolation, depth_inertia):
    """predict_block's lane loops, one per (every lane at its frame's last step or not, Fixed /
    Move without / Move with the depth-inertia mix): frame interpolation 1 in every lane, 1 in
    every other lane and 0.37 elsewhere (the block is not at its last step, yet those lanes take
    the frame's rotation), 0.37 everywhere; depth inertia of the presets (the mix everywhere
    but at the tips) or off."""
    tt, prm = crowd.time_state, crowd.parameters
    saved_t, saved_di = tt.frame_interpolation.copy(), prm.depth_inertia.copy()
    try:
        blk, _bs = block_tables(crowd)
        if interpolation == "last step":
            tt.frame_interpolation[blk.lane_team] = 1.0
        elif interpolation == "per lane":
            tt.frame_interpolation[blk.lane_team] = 0.37
            tt.frame_interpolation[blk.lane_team[::2]] = 1.0
        else:
            tt.frame_interpolation[blk.lane_team] = 0.37
        if depth_inertia != "preset":
            prm.depth_inertia[:] = depth_inertia
        fixed, shifted, mixed = _predict_kinds(crowd, blk)
        assert fixed.sum() > 0 and shifted.sum() > 0
        assert (mixed.sum() > 100) if depth_inertia == "preset" else (mixed.sum() == 0)
        # the animated rotation moved since the last frame: the slerp matters
        ps = crowd.particles
        assert (np.abs(ps.rotation - ps.old_rotation).max(axis=1) > 1e-6).sum() > 100
        compare_stage(crowd, _predict_teams, _predict_blocks, PREDICT_FIELDS)
    finally:
        tt.frame_interpolation[:] = saved_t
        prm.depth_inertia[:] = saved_di
