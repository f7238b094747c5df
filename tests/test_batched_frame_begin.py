"""The begin of frame in block form (``frame.begin_frame_block``, ``batched/frame_begin``: C.1
skinning into the block rows, C.2 sums lanes innermost, per-lane C.2/C.4/G.2, the history
gathered through the C.5 shift, a Reset lane snapped) gives exactly the bits of the per-team
``frame.begin_frame_team`` followed by the plain gather: block rows against team rows, the
team rows the block begin writes too, every TeamState and ColliderState value, on mid-motion
frames, the first frame (every lane resets), a teleport in Reset and in Keep mode, and a lane
that does not shift beside lanes that do. (A block that does not run leaves its teams to
``begin_frame_team``: tests/test_batched_frame.py's fallback tests.)"""
import numba
import numpy as np
import pytest

from batched_harness import block_rows, block_tables, crowd_system, restore, snapshot
from magica_py.solver.batch_tables import borrow
from magica_py.solver.batched.frame_begin import SHIFT_KEEP, SHIFT_MOVE, SHIFT_RESET
from magica_py.solver.frame import (
    FrameInputs, _time_frame_update, as_kernel_table, begin_frame_block, begin_frame_team, prepare_teams,
)

# what the steps read from the block after the begin of frame, and the per-team begin leaves in
# the team rows (position / rotation: C.1; the history: C.5; the rest: the plain gather)
BEGIN_FIELDS = ("position", "rotation", "old_position", "old_rotation", "old_pos", "velocity", "disp_pos",
                "collision_normal", "friction", "static_friction")
# what a Reset also writes (C.5 snap), compared for lanes that reset
SNAP_FIELDS = ("next_pos", "base_pos", "base_rot", "velocity_pos", "real_velocity")


def _frame_inputs(system):
    s = system.time_settings
    power = s.simulation_power
    return FrameInputs(1 / 60, 1 / 60, 0.02, 0, float(s.global_time_scale),
                       float(s.simulation_delta_time), int(s.max_steps_per_frame), int(s.timing_code),
                       90.0 / s.frequency, float(power[1]), float(power[2]), float(power[3]), 1)


@numba.njit
def _prepare(m, ps, prm, ts, cs, tt, h, fi):
    m, ps, prm, ts, cs, tt, h = borrow(m), borrow(ps), borrow(prm), borrow(ts), borrow(cs), borrow(tt), borrow(h)
    prepare_teams(m, ts, prm, tt, h)
    _time_frame_update(tt, fi)


@numba.njit
def _team_begin(m, ps, prm, ts, cs, tt, h, fi, teams):
    m, ps, prm, ts, cs, tt, h = borrow(m), borrow(ps), borrow(prm), borrow(ts), borrow(cs), borrow(tt), borrow(h)
    for t in teams:
        begin_frame_team(m, ps, prm, ts, cs, tt, h, fi, t)


@numba.njit
def _block_begin(m, ps, prm, ts, cs, tt, h, fi, blk, bs):
    m, ps, prm, ts, cs, tt, h = borrow(m), borrow(ps), borrow(prm), borrow(ts), borrow(cs), borrow(tt), borrow(h)
    blk, bs = borrow(blk), borrow(bs)
    for b in range(blk.block_width.shape[0]):
        begin_frame_block(m, ps, prm, ts, cs, tt, h, fi, blk, bs, b)


def _compare_begin(system, edit=None):
    """Per-team begin then block begin from the same state (after the frame's team time and
    ``edit(system)``); asserts the bits and returns (block table, block state)."""
    blk, bs = block_tables(system)
    tables = system.kernel_tables()
    fi = _frame_inputs(system)
    _prepare(*tables, fi)
    if edit is not None:
        edit(system, blk)
    h = system._hierarchy
    before = snapshot(system)
    ramp_before = h.ramp_from_build.copy()
    _team_begin(*tables, fi, blk.lane_team.copy())
    expected = snapshot(system)
    ramp_expected = h.ramp_from_build.copy()
    restore(system, before)
    h.ramp_from_build[...] = ramp_before
    _block_begin(*tables, fi, as_kernel_table(blk), as_kernel_table(bs))
    m = system.model
    rows = np.concatenate([np.arange(m.team_particle_start[t], m.team_particle_start[t] + m.team_particle_count[t])
                           for t in blk.lane_team])
    for name in BEGIN_FIELDS:
        got = block_rows(system, blk, bs, name)[rows]
        want = expected[f"ps.{name}"][rows]
        assert np.array_equal(got, want), f"{name}: {int((got != want).sum())} values differ"
    resets = [int(t) for t in blk.lane_team if expected["ts.reset"][t] != 0]
    for t in resets:
        r = np.arange(m.team_particle_start[t], m.team_particle_start[t] + m.team_particle_count[t])
        for name in SNAP_FIELDS:
            assert np.array_equal(block_rows(system, blk, bs, name)[r], expected[f"ps.{name}"][r]), name
    for key, want in expected.items():
        if not key.startswith("ps."):
            got = getattr({"ts": system.teams, "cs": system.collider_state}[key[:2]], key[3:])
            same = (got == want) | (np.isnan(got) & np.isnan(want))
            assert same.all(), f"{key} differs"
    assert np.array_equal(h.ramp_from_build, ramp_expected)
    # team rows: the begin leaves them as they were (a Reset lane too): the block holds the
    # frame until the scatters after the steps
    for name in system.particles._fields:
        want = before[f"ps.{name}"]
        if want.shape[:1] != system.particles.position.shape[:1]:
            continue   # not a per-particle field
        got = getattr(system.particles, name)
        assert np.array_equal(got, want), f"team rows of {name}: {int((got != want).sum())} values differ"
    return blk, bs, expected


def _full_snapshot(system):
    """``snapshot`` plus the team time and the hierarchy (the tests advance the one, edit the other)."""
    snap = snapshot(system)
    for prefix, table in (("tt", system._time), ("h", system._hierarchy)):
        for name in table._fields:
            snap[f"{prefix}.{name}"] = getattr(table, name).copy()
    return snap


def _full_restore(system, snap):
    restore(system, snap)
    for prefix, table in (("tt", system._time), ("h", system._hierarchy)):
        for name in table._fields:
            getattr(table, name)[...] = snap[f"{prefix}.{name}"]


@pytest.fixture(scope="module")
def mid_motion():
    system = crowd_system(instances=6, frames=25)
    snap = _full_snapshot(system)
    yield system, snap
    _full_restore(system, snap)


def test_block_begin_of_a_walking_crowd_matches_the_per_team_begin_bit_for_bit(mid_motion):
    system, snap = mid_motion
    _full_restore(system, snap)
    blk, bs, expected = _compare_begin(system)
    # the crowd walks: every lane shifts its history, none resets
    modes = bs.lane_shift_mode[:int(blk.block_width.sum())]
    assert (modes == SHIFT_MOVE).all()
    # and the shift moved something (a frame of walking at ~1.2 m/s, world inertia 1)
    moved = np.abs(block_rows(system, blk, bs, "old_position") - snap["ps.old_position"])
    assert np.nanmax(moved) > 1e-4


def test_the_first_frame_resets_every_lane_on_the_block_rows():
    system = crowd_system(instances=6, frames=0)
    blk, bs, expected = _compare_begin(system)
    lanes = int(blk.block_width.sum())
    assert (bs.lane_shift_mode[:lanes] == SHIFT_RESET).all()
    # snapped: the history is the skinned pose, the velocity zero
    assert np.array_equal(block_rows(system, blk, bs, "old_pos"), block_rows(system, blk, bs, "position"))
    assert np.nanmax(np.abs(block_rows(system, blk, bs, "velocity"))) == 0.0


def test_a_teleported_lane_resets_or_keeps_its_shape_with_the_per_team_bits(mid_motion):
    system, snap = mid_motion
    for mode in (1, 2):   # TELEPORT_RESET, TELEPORT_KEEP
        _full_restore(system, snap)
        prm = system.parameters
        saved = prm.teleport_mode.copy()

        def jump(system, blk):
            prm.teleport_mode[:] = mode   # every team (a block's parameter rows stay equal)
            t = int(blk.lane_team[blk.block_lane_base[0] + 1])
            comp = int(system.model.team_component_transform[t])
            system._hierarchy.world_position[comp] += (10.0, 0.0, 0.0)   # a 10 m jump of one lane

        try:
            blk, bs, expected = _compare_begin(system, jump)
        finally:
            prm.teleport_mode[:] = saved
        t = int(blk.lane_team[blk.block_lane_base[0] + 1])
        lanes = int(blk.block_width.sum())
        if mode == 1:
            assert expected["ts.reset"][t] == 1 and bs.lane_shift_mode[blk.block_lane_base[0] + 1] == SHIFT_RESET
            assert (bs.lane_shift_mode[:lanes] == SHIFT_RESET).sum() == 1
        else:
            assert expected["ts.keep_teleport"][t] == 1
            assert (bs.lane_shift_mode[:lanes] == SHIFT_MOVE).all()
    _full_restore(system, snap)


def test_a_lane_without_shift_keeps_its_history_as_gathered_beside_lanes_that_shift(mid_motion):
    system, snap = mid_motion
    _full_restore(system, snap)
    prm = system.parameters
    names = ("world_inertia", "movement_smoothing", "movement_speed_limit", "rotation_speed_limit")
    saved = {n: getattr(prm, n).copy() for n in names}
    still = {}

    def no_shift(system, blk):
        # one lane (after the blocks are formed): world inertia 1, no smoothing, no speed
        # limits, so that C.4 shifts nothing (inertia_shift stays 0)
        L = int(blk.block_lane_base[0] + 2)
        t = int(blk.lane_team[L])
        prm.world_inertia[t] = 1.0
        prm.movement_smoothing[t] = 0.0
        prm.movement_speed_limit[t] = -1.0
        prm.rotation_speed_limit[t] = -1.0
        still.update(lane=L, team=t)

    try:
        blk, bs, expected = _compare_begin(system, no_shift)
    finally:
        for n in names:
            getattr(prm, n)[:] = saved[n]
    lanes = int(blk.block_width.sum())
    modes = bs.lane_shift_mode[:lanes]
    assert modes[still["lane"]] == SHIFT_KEEP and (np.delete(modes, still["lane"]) == SHIFT_MOVE).all()
    t = still["team"]
    m = system.model
    rows = np.arange(m.team_particle_start[t], m.team_particle_start[t] + m.team_particle_count[t])
    for name in ("old_position", "old_pos", "velocity", "disp_pos", "old_rotation"):
        assert np.array_equal(block_rows(system, blk, bs, name)[rows], snap[f"ps.{name}"][rows]), name
    _full_restore(system, snap)
