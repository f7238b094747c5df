"""Each block stage (``solver/batched``) gives exactly the bits of its per-team stage, from
the same mid-motion crowd state (``batched_harness``)."""
import numba
import pytest

from batched_harness import (
    assert_same_rows, block_tables, crowd_system, restore, run_block_stage, run_team_stage, snapshot,
)
from magica_py.solver.batch_tables import borrow
from magica_py.solver.step import predict_block, predict_team

DT = 1.0 / 90.0


@pytest.fixture(scope="module")
def crowd():
    return crowd_system(instances=6, frames=25)


def _compare(system, team_wrapper, block_wrapper, fields):
    blk, bs = block_tables(system)
    before = snapshot(system)
    run_team_stage(system, team_wrapper, blk)
    expected = snapshot(system)
    restore(system, before)
    run_block_stage(system, block_wrapper, blk, bs)
    after_block = snapshot(system)
    restore(system, before)
    restore(system, after_block)
    assert_same_rows(system, blk, expected, fields)
    restore(system, before)


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
    _compare(crowd, _predict_teams, _predict_blocks,
             ["base_pos", "base_rot", "step_basic_pos", "step_basic_rot", "next_pos", "velocity_pos", "velocity"])


def test_predict_block_matches_with_a_mid_frame_interpolation(crowd):
    tt = crowd.time_state
    saved = tt.frame_interpolation.copy()
    tt.frame_interpolation[:] = 0.37
    try:
        _compare(crowd, _predict_teams, _predict_blocks, ["base_pos", "base_rot", "next_pos", "velocity"])
    finally:
        tt.frame_interpolation[:] = saved
