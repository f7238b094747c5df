"""The read-ahead of a block's rows before its frame (``frame.warm_block``): it reads every
cache line of the block's items that the frame's stages read (of the particle state: the rows
every scene carries and those of the optional stages compiled) and writes nothing but its sum
into the thread's save area, and it leaves alone the scenes whose state stays cached (a small
state, a block of one team)."""
from __future__ import annotations

import pathlib

import numpy as np
import pytest

from magica_py.config import load_scene
from magica_py.runtime.player import Player
from magica_py.solver import blocks as bk
from magica_py.solver import state as st
from magica_py.solver.frame import WARM_MIN_LANES, WARM_MIN_STATE_VALUES, warm_block
from magica_py.solver.lanes import LANES
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


def _particle_rows_sum(PS, g0, g1, first, end):
    """The oracle of the particle state's spans: rows ``first:end`` of each slot, in slot order."""
    acc = 0.0
    for g in range(g0, g1):
        acc += _line_sum(PS[g].reshape(-1, LANES), first, end)
    return acc


# (angle, bending, edge collision, quality) switches and the particle rows read with them
SWITCHED_SPANS = [
    ((None, None, None, None), []),                                       # the light scene's stages
    ((1, None, None, None), [st.ANGLE_ROWS]),
    ((None, 1, None, None), [st.BENDING_EDGE_ROWS]),
    ((None, None, 1, None), [st.BENDING_EDGE_ROWS]),
    ((1, 1, 1, 1), [st.BENDING_EDGE_ROWS, st.ANGLE_ROWS, st.QUALITY_ROWS]),
]


@pytest.mark.parametrize("switches, spans", SWITCHED_SPANS)
def test_a_wide_block_of_a_large_state_is_read_line_by_line_and_nothing_but_the_sum_is_written(switches, spans):
    system = _system("light_chains")   # 1,000 chains: 63 blocks of 16 lanes, 19 MB of particle state
    T = system.tables
    assert T.PS.size >= WARM_MIN_STATE_VALUES
    rng = np.random.default_rng(7)
    for table in (T.PS, T.PM, T.PP, T.TS, T.CS):   # values that make every line count in the sum
        table[:] = rng.uniform(-1.0, 1.0, table.shape)
    before = {name: getattr(T, name).copy() for name in T._fields}
    area = np.zeros(64)
    b = int(T.blocks[5])
    assert T.BI[b, bk.BI_LANES_USED] >= WARM_MIN_LANES
    warm_block(T, b, area, *switches)
    g0, n = int(T.BI[b, bk.BI_G0]), int(T.BI[b, bk.BI_N])
    c0, nc = int(T.BI[b, bk.BI_COLLIDER0]), int(T.BI[b, bk.BI_COLLIDERS])
    expected = _particle_rows_sum(T.PS, g0, g0 + n, 0, st.CARRIED_ROWS)
    for first, end in spans:
        expected += _particle_rows_sum(T.PS, g0, g0 + n, first, end)
    expected += _line_sum(T.PM, g0, g0 + n) + _line_sum(T.PP, g0, g0 + n)
    expected += _line_sum(T.TS, b, b + 1) + _line_sum(T.CS, c0, c0 + nc)
    assert n == 16 and nc == 1
    assert area[-1] == expected
    assert not np.any(area[:-1])
    for name in T._fields:
        np.testing.assert_array_equal(getattr(T, name), before[name], err_msg=name)


def test_the_particle_rows_read_ahead_are_every_row_but_the_scratch_when_every_stage_is_compiled():
    """The spans cover the particle state's fields (each row once) except the stages' scratch,
    which every stage writes before it reads; the rows every scene carries come first."""
    spans = [(0, st.CARRIED_ROWS), st.BENDING_EDGE_ROWS, st.ANGLE_ROWS, st.QUALITY_ROWS]
    rows = sorted(r for first, end in spans for r in range(first, end))
    scratch = st.STAGE_SCRATCH // LANES
    assert rows == [r for r in range(st.PARTICLE.rows) if not scratch <= r < scratch + st.PARTICLE.size("stage_scratch")]
    for name in ("position", "next_pos", "velocity", "transform_rotation"):
        assert st.PARTICLE.column(name) // LANES < st.CARRIED_ROWS


def test_small_states_and_one_team_blocks_are_not_read_ahead():
    tail = _system("tail_orbit")             # one cloth: a block of one lane, 8 particle slots
    area = np.zeros(8)
    warm_block(tail.tables, int(tail.tables.blocks[0]), area, None, None, None, None)
    assert not np.any(area)
    crowd = _system("crowd")                 # 16-lane blocks, but what of a state below the bound?
    T = crowd.tables
    b = int(T.blocks[0])
    assert T.BI[b, bk.BI_LANES_USED] >= WARM_MIN_LANES and T.PS.size >= WARM_MIN_STATE_VALUES
    small = T._replace(PS=T.PS[:WARM_MIN_STATE_VALUES // T.PS.shape[1] - 1])
    warm_block(small, b, area, 1, 1, None, None)
    assert not np.any(area)
    warm_block(T, b, area, 1, 1, None, None)  # the crowd's own state is read ahead
    assert area[-1] != 0.0
