"""Test harness of the batched steps: one stage run per team and in block form from the same
state, compared bit for bit (``solver/batched``).

Usage (see tests/test_batched_stages.py)::

    system = crowd_system(instances=6, frames=25)       # a realistic mid-motion state
    before = snapshot(system)
    run_team_stage(system, my_team_wrapper)             # the per-team stage on every block team
    team_result = snapshot(system)
    restore(system, before)
    run_block_stage(system, my_block_wrapper)           # gather, lanes, block stage, scatter
    assert_same_rows(system, team_result, fields)

A wrapper is an ``@njit`` function ``(m, ps, prm, ts, cs, tt, teams)`` for the per-team stage
(``teams``: int32 array of team ids) and ``(m, ps, prm, ts, cs, tt, blk, bs, blocks)`` for the
block stage; the harness gathers before and scatters after the block wrapper, with the
per-step lane values loaded (``block_transfer.load_lanes``). The gather is the *full* one (every
field of the block state, scratch included), so a stage can start from a mid-step state.
Only the fields ``scatter_block_full`` writes back are compared by ``assert_same_rows``; compare
others with ``block_rows``.
"""
from __future__ import annotations

import pathlib

import numba
import numpy as np

from magica_py.solver.batch_tables import borrow
from magica_py.solver.batched.blocks import form_blocks
from block_transfer import gather_block_full, load_lanes, scatter_block_full
from magica_py.solver.frame import as_kernel_table

ROOT = pathlib.Path(__file__).resolve().parents[1]


def crowd_system(instances: int = 6, frames: int = 25, overrides: dict | None = None, config: str = "crowd"):
    """``configs/<config>.yaml`` with fewer instances, run ``frames`` frames per team (no blocks)."""
    from magica_py.config import load_scene
    from magica_py.runtime.player import Player
    from magica_py.solver.system import ClothSystem

    sets = {"rigs.0.instances.count": instances}
    sets.update(overrides or {})
    scene = load_scene(ROOT / "configs" / f"{config}.yaml", overrides=[f"{k}={v}" for k, v in sets.items()])
    player = Player.for_scene(scene)
    # per team: with blocks, the step-internal fields of block teams (next_pos, base and step
    # basic pose, ...) stay in the block state and their team rows would be stale
    system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings, batched=False).attach(player)
    player.run(frames)
    system._player_for_tests = player
    return system


def snapshot(system) -> dict:
    """Copies of every array of the particle, team and collider tables."""
    out = {}
    for prefix, table in (("ps", system.particles), ("ts", system.teams), ("cs", system.collider_state)):
        for name in table._fields:
            out[f"{prefix}.{name}"] = getattr(table, name).copy()
    return out


def restore(system, snap: dict) -> None:
    for prefix, table in (("ps", system.particles), ("ts", system.teams), ("cs", system.collider_state)):
        for name in table._fields:
            getattr(table, name)[...] = snap[f"{prefix}.{name}"]


@numba.njit
def _gather_all(m, ps, ts, cs, tt, blk, bs):
    m, ps, ts, cs, tt, blk, bs = borrow(m), borrow(ps), borrow(ts), borrow(cs), borrow(tt), borrow(blk), borrow(bs)
    for b in range(blk.block_width.shape[0]):
        gather_block_full(m, ps, blk, bs, b)
        load_lanes(blk, bs, ts, tt, cs, b)


@numba.njit
def _scatter_all(m, ps, blk, bs):
    m, ps, blk, bs = borrow(m), borrow(ps), borrow(blk), borrow(bs)
    for b in range(blk.block_width.shape[0]):
        scatter_block_full(m, ps, blk, bs, b)


def block_tables(system):
    blk, bs = form_blocks(system)
    assert len(blk.block_width) > 0, "no block formed"
    return blk, bs


def run_team_stage(system, wrapper, blk) -> None:
    m, ps, prm, ts, cs, tt, _h = system.kernel_tables()
    wrapper(m, ps, prm, ts, cs, tt, blk.lane_team.copy())


def run_block_stage(system, wrapper, blk, bs) -> None:
    m, ps, prm, ts, cs, tt, _h = system.kernel_tables()
    kb, kbs = as_kernel_table(blk), as_kernel_table(bs)
    _gather_all(m, ps, ts, cs, tt, kb, kbs)
    wrapper(m, ps, prm, ts, cs, tt, kb, kbs, np.arange(len(blk.block_width), dtype=np.int32))
    _scatter_all(m, ps, kb, kbs)


def block_rows(system, blk, bs, name: str) -> np.ndarray:
    """A block-state particle field back in team-row order ((n,) or (n, c) like ParticleState;
    rows of teams outside blocks are NaN)."""
    ref = getattr(system.particles, name)
    out = np.full(ref.shape, np.nan)
    arr = getattr(bs, name)
    m = system.model
    for b in range(len(blk.block_width)):
        w = int(blk.block_width[b])
        for i in range(w):
            t = int(blk.lane_team[blk.block_lane_base[b] + i])
            start = int(m.team_particle_start[t])
            for p in range(int(blk.block_particle_count[b])):
                k = int(blk.block_row_base[b]) + p * w + i
                out[start + p] = arr[..., k]
    return out


def assert_same_rows(system, blk, expected: dict, fields) -> None:
    """``system.particles`` equals ``expected`` (a snapshot) bit for bit on every block team's rows."""
    m = system.model
    rows = np.concatenate([np.arange(m.team_particle_start[t], m.team_particle_start[t] + m.team_particle_count[t])
                           for t in blk.lane_team])
    for name in fields:
        got = getattr(system.particles, name)[rows]
        want = expected[f"ps.{name}"][rows]
        same = (got == want) | (np.isnan(got) & np.isnan(want))
        assert same.all(), f"{name}: {int((~same).sum())} values differ, max {np.nanmax(np.abs(got - want))}"


def compare_stage(system, team_wrapper, block_wrapper, fields) -> None:
    """Run the per-team and the block stage from the same state; the scattered ``fields``
    must be equal bit for bit. The system's state is left as it was."""
    blk, bs = block_tables(system)
    before = snapshot(system)
    run_team_stage(system, team_wrapper, blk)
    expected = snapshot(system)
    restore(system, before)
    run_block_stage(system, block_wrapper, blk, bs)
    try:
        assert_same_rows(system, blk, expected, fields)
    finally:
        restore(system, before)


def stage_timing(system, team_wrapper, block_wrapper, repeats: int = 20) -> tuple[float, float]:
    """(per-team, block) ns per particle of one stage call over every block team (min of
    ``repeats``; the block figure excludes gather/scatter). The state is left as it was."""
    import time

    blk, bs = block_tables(system)
    before = snapshot(system)
    m, ps, prm, ts, cs, tt, _h = system.kernel_tables()
    kb, kbs = as_kernel_table(blk), as_kernel_table(bs)
    _gather_all(m, ps, ts, cs, tt, kb, kbs)
    teams = blk.lane_team.copy()
    blocks = np.arange(len(blk.block_width), dtype=np.int32)
    n = int(system.model.team_particle_count[teams].sum())
    out = []
    for fn, args in ((team_wrapper, (m, ps, prm, ts, cs, tt, teams)),
                     (block_wrapper, (m, ps, prm, ts, cs, tt, kb, kbs, blocks))):
        fn(*args)
        best = 1e9
        for _ in range(repeats):
            t0 = time.perf_counter()
            fn(*args)
            best = min(best, time.perf_counter() - t0)
        out.append(best * 1e9 / n)
    restore(system, before)
    return out[0], out[1]
