"""The threads' shares of a parallel frame (solver/balance.py) and how the blocks follow them
(frame.assign_workers): hand-worked shares and a slow reference of the dealing rule. That the
bits do not depend on the shares: tests/test_solver_frame.py."""
from __future__ import annotations

import numpy as np
import pytest

from magica_py.solver.balance import FLOOR, SMOOTHING, WorkerBalance
from solver_scenes import run, three_tails


def test_shares_are_in_proportion_to_the_threads_speeds():
    share = np.full(2, 0.5)
    WorkerBalance(2).update([2.0, 1.0], np.array([100, 100]), 2, share)
    # 0.02 and 0.01 s per unit: speeds 50 and 100
    assert share == pytest.approx([1 / 3, 2 / 3], rel=1e-12)


def test_one_frames_measure_moves_the_running_rate_by_the_smoothing_weight():
    balance = WorkerBalance(2)
    share = np.full(2, 0.5)
    balance.update([2.0, 1.0], np.array([100, 100]), 2, share)
    balance.update([1.0, 1.0], np.array([100, 100]), 2, share)
    rate0 = 0.02 + SMOOTHING * (0.01 - 0.02)
    assert balance.rate == pytest.approx([rate0, 0.01], rel=1e-12)
    assert share[0] == pytest.approx((1 / rate0) / (1 / rate0 + 100.0), rel=1e-12)


def test_a_stalled_thread_keeps_the_floor_share_and_the_shares_sum_to_one():
    share = np.full(3, 1 / 3)
    WorkerBalance(3).update([100.0, 1.0, 1.0], np.array([10, 10, 10]), 3, share)
    assert share[0] == pytest.approx(FLOOR / 3, rel=1e-12)
    assert share[1] == pytest.approx(share[2], rel=1e-12)
    assert share.sum() == pytest.approx(1.0, rel=1e-12)


def test_shares_wait_until_every_thread_is_measured_and_one_thread_is_left_alone():
    balance = WorkerBalance(2)
    share = np.full(2, 0.5)
    balance.update([1.0, 0.0], np.array([100, 0]), 2, share)
    assert list(share) == [0.5, 0.5]
    single = np.ones(1)
    WorkerBalance(1).update([1.0], np.array([10]), 1, single)
    assert list(single) == [1.0]


def test_a_thread_without_blocks_drifts_back_towards_the_others_rate():
    balance = WorkerBalance(2)
    share = np.full(2, 0.5)
    balance.update([10.0, 1.0], np.array([100, 100]), 2, share)   # rates 0.1 and 0.01
    balance.update([0.0, 1.0], np.array([0, 100]), 2, share)
    assert balance.rate[0] == pytest.approx(0.1 + SMOOTHING * (0.01 - 0.1), rel=1e-12)


def _deal(loads, shares):
    """The dealing rule written out: block k goes to the first run whose end (its share's
    part of the total, summed) lies beyond the block's middle; the last run takes the rest."""
    total = sum(loads)
    ends = np.cumsum(shares) / sum(shares) * total
    out, done = [], 0
    for load in loads:
        middle = done + load / 2
        out.append(next((w for w, end in enumerate(ends[:-1]) if middle < end), len(shares) - 1))
        done += load
    return out


@pytest.mark.parametrize("shares", [(0.5, 0.5), (0.9, 0.1), (0.1, 0.9), (0.3, 0.4, 0.3)])
def test_blocks_are_dealt_in_runs_by_the_middle_of_each_block(shares):
    from magica_py.solver.frame import WorkerTable, assign_workers, block_load

    s, _h = three_tails(False)
    run(s, 3)
    F = s._frame_arrays()
    blocks = s.tables.blocks
    loads = [int(block_load(F, b)) for b in blocks]
    table = WorkerTable(np.full(blocks.max() + 1, -1, dtype=np.int32), np.zeros(len(shares), dtype=np.int64),
                        np.array(shares, dtype=np.float64))
    assign_workers(F, table, len(shares))
    expected = _deal(loads, shares)
    assert [int(table.block_worker[b]) for b in blocks] == expected
    for w in range(len(shares)):
        assert table.worker_load[w] == sum(load for load, e in zip(loads, expected) if e == w)
