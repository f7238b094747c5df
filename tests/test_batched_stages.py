"""Each block stage (``solver/batched``) gives exactly the bits of its per-team stage, from
the same mid-motion crowd state (``batched_harness``)."""
import numba
import pytest

from batched_harness import compare_stage, crowd_system
from magica_py.solver.batch_tables import borrow
from magica_py.solver.step import predict_block, predict_team

DT = 1.0 / 90.0


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
