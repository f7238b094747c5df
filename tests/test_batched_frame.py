"""The frame with blocks (``solver/batched``) gives exactly the bits of the frame without:
positions, velocities and the written bone poses, serial and parallel, through parameter
changes (a team leaves its block), culling and time-scale differences (a block falls back to
per-team steps for a frame), and teams added and removed at runtime."""
import pathlib

import numpy as np
import pytest

from magica_py.config import load_scene
from magica_py.runtime.player import Player
from magica_py.solver.system import ClothSystem

ROOT = pathlib.Path(__file__).resolve().parents[1]


def _crowd(instances=6, sets=()):
    return load_scene(ROOT / "configs" / "crowd.yaml",
                      overrides=[f"rigs.0.instances.count={instances}", *sets])


def _run(batched, frames=60, parallel=False, instances=6, events=None, sets=()):
    scene = _crowd(instances, sets)
    player = Player.for_scene(scene)
    system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings,
                         parallel=parallel, batched=batched).attach(player)
    for frame in range(frames):
        if events and frame in events:
            events[frame](system)
        player.step()
    h = scene.hierarchy
    return system, (system.particles.position.copy(), system.particles.velocity.copy(),
                    system.particles.old_pos.copy(), h.local_position.copy(), h.local_rotation.copy())


def _assert_identical(a, b):
    for x, y in zip(a, b):
        assert x.shape == y.shape
        assert np.array_equal(x, y), f"{int((x != y).sum())} values differ, max {np.abs(x - y).max()}"


def test_the_crowd_forms_blocks_of_hair_and_skirt_lanes():
    system, _ = _run(True, frames=1)
    blk = system.block_table
    assert len(blk.block_width) == 2 and sorted(blk.block_particle_count.tolist()) == [30, 48]
    assert blk.block_width.tolist() == [6, 6]
    assert (blk.team_block[:12] >= 0).all()
    off, _ = _run(False, frames=1)
    assert len(off.block_table.block_width) == 0


def test_blocks_reproduce_the_per_team_frame_bit_for_bit():
    _, with_blocks = _run(True)
    _, without = _run(False)
    _assert_identical(with_blocks, without)


def test_blocks_in_parallel_reproduce_the_serial_frame_bit_for_bit():
    _, parallel = _run(True, parallel=True)
    _, serial = _run(False)
    _assert_identical(parallel, serial)


def test_a_parameter_change_on_one_instance_takes_it_out_of_its_block_with_the_same_bits():
    def change(system):
        system.set_parameter("hair#2", "damping", 0.4)
    events = {20: change}
    system, with_blocks = _run(True, events=events)
    _, without = _run(False, events=events)
    _assert_identical(with_blocks, without)
    hair2 = system.teams_of("hair#2")[0]
    assert system.block_table.team_block[hair2] == -1
    assert sum(system.block_table.block_width) == 11


def test_a_block_falls_back_to_per_team_steps_when_a_lane_is_disabled_or_slowed():
    def disable(system):
        system.set_enabled("skirt#1", False)

    def enable(system):
        system.set_enabled("skirt#1", True)

    def slow(system):
        system.set_time_scale("hair#3", 0.5)
    events = {10: disable, 20: enable, 30: slow}
    _, with_blocks = _run(True, events=events)
    _, without = _run(False, events=events)
    _assert_identical(with_blocks, without)


def test_teams_removed_and_added_at_runtime_keep_the_bits():
    def remove(system):
        system.remove_cloth(system.teams_of("hair#1")[0])

    def add(system):
        system.add_cloth(system.specs[system.teams_of("hair#0")[0]])
    events = {15: remove, 30: add}
    system, with_blocks = _run(True, events=events)
    _, without = _run(False, events=events)
    _assert_identical(with_blocks, without)
    assert system.block_table.lane_team.size >= 10


@pytest.mark.parametrize("sets", [("scene.fps=144",), ("scene.fps=30",)])
def test_blocks_keep_the_bits_at_other_frame_rates(sets):
    _, with_blocks = _run(True, frames=40, sets=sets)
    _, without = _run(False, frames=40, sets=sets)
    _assert_identical(with_blocks, without)


def test_the_parallel_frame_deals_every_unit_to_one_thread_by_load():
    """``frame.assign_workers``: each running block and each team outside one goes to one
    thread; the loads add up to the frame's work and the largest is within one unit of even."""
    from magica_py.solver.frame import assign_workers

    # one hair instance culled by a time-scale difference: its block falls back, 12 lone teams
    system, _ = _run(True, frames=2, instances=12)
    blk, m, ts, tt = system.block_table, system.model, system.teams, system._time
    tt.update_count[:] = 2
    blk.block_run[:] = 1
    blk.block_run[0] = 0
    assign_workers.py_func(m, ts, tt, blk, 2)
    assert blk.block_worker[0] == -1 and set(blk.block_worker[1:].tolist()) <= {0, 1}
    live = [int(t) for t in m.live_teams]
    alone = [t for t in live if blk.team_block[t] < 0 or blk.block_run[blk.team_block[t]] == 0]
    assert sorted(t for t in live if blk.team_worker[t] >= 0) == sorted(alone)
    costs = [int(blk.block_width[b] * blk.block_particle_count[b]) * 3 for b in range(1, len(blk.block_width))]
    costs += [int(m.team_particle_count[t]) * 3 for t in alone]
    assert int(blk.worker_load[:2].sum()) == sum(costs)
    assert abs(int(blk.worker_load[0]) - int(blk.worker_load[1])) <= max(costs)


def test_block_widths_are_multiples_of_the_vector_width_where_the_count_allows():
    from magica_py.solver.batched.blocks import LANE_ALIGN, block_widths
    from magica_py.solver.batched.state import BLOCK_WIDTH

    assert block_widths(100) == [52, 48]
    assert block_widths(2) == [2] and block_widths(64) == [64]
    for n in range(2, 400):
        widths = block_widths(n)
        assert sum(widths) == n and max(widths) <= BLOCK_WIDTH
        assert len(widths) == -(-n // BLOCK_WIDTH)
        assert all(w % LANE_ALIGN == 0 for w in widths[:-1])
        assert widths[-1] % LANE_ALIGN == n % LANE_ALIGN
