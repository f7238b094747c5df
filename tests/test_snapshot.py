"""Capturing and restoring the simulation state (runtime/snapshot.py) is exact: the frames
after a restore give the bits the frames after the capture gave, and a fork restored into a
second player built from the same scene continues the same run."""
import hashlib
import pathlib

import numpy as np
import pytest

from magica_py.config import load_scene
from magica_py.runtime.player import Player
from magica_py.runtime.snapshot import SnapshotError
from magica_py.solver.system import ClothSystem

ROOT = pathlib.Path(__file__).resolve().parents[1]


def make_player(name: str):
    scene = load_scene(ROOT / "configs" / f"{name}.yaml")
    player = Player.for_scene(scene)
    system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings).attach(player)
    return player, system


def state_hash(player, system) -> str:
    h = player.scene.hierarchy
    digest = hashlib.sha256()
    for a in (system.particles.position, system.particles.velocity, h.local_position, h.local_rotation,
              h.world_position, h.world_rotation):
        digest.update(np.ascontiguousarray(a).tobytes())
    digest.update(repr((player.frame, player.time_manager.time, player.time_manager.time_scale)).encode())
    return digest.hexdigest()


# hitches_and_events: the capture (frame 100, ~1.9 s) comes before a teleport (2 s), a slow
# motion (3-3.25 s) and a parameter change (3.75 s), so the restore has to undo all three
@pytest.mark.parametrize("name, before, after", [
    ("tail_orbit", 20, 30), ("character_walk", 15, 20), ("hitches_and_events", 100, 140), ("crowd", 4, 4)])
def test_frames_after_a_restore_repeat_the_frames_after_the_capture(name, before, after):
    player, system = make_player(name)
    player.run(before)
    snapshot = player.capture()
    player.run(after)
    first = state_hash(player, system)
    player.restore(snapshot)
    assert player.frame == before
    player.run(after)
    assert state_hash(player, system) == first


def test_capturing_changes_nothing():
    plain, plain_system = make_player("tail_orbit")
    plain.run(40)
    captured, captured_system = make_player("tail_orbit")
    captured.run(15)
    captured.capture()
    captured.run(25)
    assert state_hash(captured, captured_system) == state_hash(plain, plain_system)


def test_a_snapshot_restored_into_a_second_player_continues_the_same_run():
    reference, reference_system = make_player("hitches_and_events")
    reference.run(60)
    snapshot = reference.capture()
    reference.run(50)
    fork, fork_system = make_player("hitches_and_events")   # a fresh player at frame 0
    fork.restore(snapshot)
    fork.run(50)
    assert state_hash(fork, fork_system) == state_hash(reference, reference_system)


def test_a_restore_undoes_runtime_parameter_changes():
    player, system = make_player("tail_orbit")
    player.run(10)
    snapshot = player.capture()
    damping = system.parameters.damping_curve.copy()
    system.set_parameter(system.team_names[0], "damping", 0.9)
    assert not np.array_equal(system.parameters.damping_curve, damping)
    player.restore(snapshot)
    assert np.array_equal(system.parameters.damping_curve, damping)


def test_restoring_after_a_cloth_was_added_is_refused_with_the_reason():
    player, system = make_player("tail_orbit")
    player.run(5)
    snapshot = player.capture()
    system.add_cloth(system.specs[0])
    with pytest.raises(SnapshotError, match="cloths added or removed"):
        player.restore(snapshot)


def test_a_snapshot_reports_its_size():
    player, _system = make_player("tail_orbit")
    player.run(3)
    snapshot = player.capture()
    assert snapshot.frame == 3 and snapshot.time > 0.0
    assert 0 < snapshot.nbytes < 10_000_000
