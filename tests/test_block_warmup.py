"""The read-ahead of a block's rows before its frame (``frame.warm_block``): it reads every
cache line of the block's items and writes nothing but its sum into the thread's save area,
and it leaves alone the scenes whose state stays cached (a small state, a block of one team)."""
from __future__ import annotations

import pathlib

import numpy as np

from magica_py.config import load_scene
from magica_py.runtime.player import Player
from magica_py.solver import blocks as bk
from magica_py.solver.frame import WARM_MIN_LANES, WARM_MIN_STATE_VALUES, warm_block
from magica_py.solver.system import ClothSystem

CONFIGS = pathlib.Path(__file__).resolve().parent.parent / "configs"


def _system(name):
    scene = load_scene(CONFIGS / f"{name}.yaml")
    return ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings).attach(Player.for_scene(scene))


def _line_sum(table, i0, i1):
    """The oracle: rows i0:i1 as one flat span, every 8th value (one per 64-byte line) from its
    start and then its last value, summed in the kernel's order with Python floats."""
    flat = table.reshape(-1)
    lo, hi = i0 * table.shape[1], i1 * table.shape[1]
    acc = 0.0
    for k in range(lo, hi, 8):
        acc += float(flat[k])
    if hi > lo:
        acc += float(flat[hi - 1])
    return acc


def test_a_wide_block_of_a_large_state_is_read_line_by_line_and_nothing_but_the_sum_is_written():
    system = _system("light_chains")   # 1,000 chains: 63 blocks of 16 lanes, 25 MB of particle state
    T = system.tables
    assert T.PS.size >= WARM_MIN_STATE_VALUES
    rng = np.random.default_rng(7)
    for table in (T.PS, T.PM, T.PP, T.TS, T.CS):   # values that make every line count in the sum
        table[:] = rng.uniform(-1.0, 1.0, table.shape)
    before = {name: getattr(T, name).copy() for name in T._fields}
    area = np.zeros(64)
    b = int(T.blocks[5])
    assert T.BI[b, bk.BI_LANES_USED] >= WARM_MIN_LANES
    warm_block(T, b, area)
    g0, n = int(T.BI[b, bk.BI_G0]), int(T.BI[b, bk.BI_N])
    c0, nc = int(T.BI[b, bk.BI_COLLIDER0]), int(T.BI[b, bk.BI_COLLIDERS])
    expected = _line_sum(T.PS, g0, g0 + n) + _line_sum(T.PM, g0, g0 + n) + _line_sum(T.PP, g0, g0 + n)
    expected += _line_sum(T.TS, b, b + 1) + _line_sum(T.CS, c0, c0 + nc)
    assert n == 16 and nc == 1
    assert area[-1] == expected
    assert not np.any(area[:-1])
    for name in T._fields:
        np.testing.assert_array_equal(getattr(T, name), before[name], err_msg=name)


def test_small_states_and_one_team_blocks_are_not_read_ahead():
    tail = _system("tail_orbit")             # one cloth: a block of one lane, 8 particle slots
    area = np.zeros(8)
    warm_block(tail.tables, int(tail.tables.blocks[0]), area)
    assert not np.any(area)
    crowd = _system("crowd")                 # 16-lane blocks, but what of a state below the bound?
    T = crowd.tables
    b = int(T.blocks[0])
    assert T.BI[b, bk.BI_LANES_USED] >= WARM_MIN_LANES and T.PS.size >= WARM_MIN_STATE_VALUES
    small = T._replace(PS=T.PS[:WARM_MIN_STATE_VALUES // T.PS.shape[1] - 1])
    warm_block(small, b, area)
    assert not np.any(area)
    warm_block(T, b, area)                   # the crowd's own state is read ahead
    assert area[-1] != 0.0
