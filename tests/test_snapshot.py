"""Capturing and restoring the simulation state (runtime/snapshot.py) is exact: the frames
after a restore give the bits the frames after the capture gave, and a fork restored into a
second player built from the same scene continues the same run. Snapshots are taken team by
team (``ClothSystem.capture_state``), so they restore into a system whose teams are grouped
into blocks otherwise (a team moved by a parameter change, a candidate with other
parameters)."""
import hashlib
import pathlib

import numpy as np
import pytest

from magica_py.config import load_scene
from magica_py.runtime.player import Player
from magica_py.runtime.snapshot import SnapshotError
from magica_py.solver.system import ClothSystem

ROOT = pathlib.Path(__file__).resolve().parents[1]


def make_player(name: str, overrides=()):
    scene = load_scene(ROOT / "configs" / f"{name}.yaml", list(overrides))
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


def prepared(parameters=None, frequency=None):
    from magica_py.bench.variants import Variant, prepare, resolve_scene_path

    return prepare(Variant("t", resolve_scene_path("tail_orbit"), parameters=dict(parameters or {}),
                           frequency=frequency))


def test_a_model_keeping_restore_takes_the_state_and_keeps_the_candidates_parameters():
    reference = prepared({"solver.rate_mode": "frequency_consistent"})
    reference.player.run(12)
    snapshot = reference.player.capture()
    candidate = prepared({"solver.mode": "quality"})
    candidate.player.run(5)
    own_parameters = {n: getattr(candidate.system.parameters, n).copy()
                      for n in candidate.system.parameters._fields}
    candidate.player.restore(snapshot, keep_model=True)
    assert candidate.player.frame == 12
    assert np.array_equal(candidate.system.particles.position, reference.system.particles.position)
    assert np.array_equal(candidate.system.particles.velocity, reference.system.particles.velocity)
    assert np.array_equal(candidate.scene.hierarchy.world_position, reference.scene.hierarchy.world_position)
    for name, value in own_parameters.items():
        assert np.array_equal(getattr(candidate.system.parameters, name), value), name
    assert candidate.system.parameters.quality[0] == 1 and reference.system.parameters.quality[0] == 0
    # and a full restore takes the reference's parameters too
    candidate.player.restore(snapshot)
    assert candidate.system.parameters.quality[0] == 0


def test_a_candidate_at_another_frequency_continues_on_the_snapshots_clock():
    """A 1440 Hz snapshot at t = 0.2 s (60 fps, frame 12) restored into a 90 Hz candidate: its
    team clock is the reference's (its last step at 0.2 s), so it runs the steps a native
    90 Hz run takes from a frame on its own step grid (frame 12: 0.2 s = 18 steps): 1, 2, 1, 2."""
    def steps(p, frames):
        return [p.player.step().metrics["cloth.simulation_steps"] for _ in range(frames)]

    native = prepared(frequency=90)
    native.player.run(12)
    expected = steps(native, 6)
    reference = prepared(frequency=1440)
    reference.player.run(12)
    assert reference.system._time.now_update_time[0] == pytest.approx(0.2, abs=1e-12)
    snapshot = reference.player.capture()
    candidate = prepared(frequency=90)
    candidate.player.restore(snapshot, keep_model=True)
    assert candidate.system.time_settings.frequency == 90
    assert steps(candidate, 6) == expected == [1, 2, 1, 2, 1, 2]


def test_a_snapshot_survives_pickling_into_another_process():
    """Batch workers (Dask) receive snapshots pickled: the copy restores the same state."""
    import pickle

    player, system = make_player("character_walk")
    player.run(6)
    snapshot = pickle.loads(pickle.dumps(player.capture()))
    player.run(4)
    first = state_hash(player, system)
    player.restore(snapshot)
    player.run(4)
    assert state_hash(player, system) == first


THREE = ["rigs[0].instances.count=3"]   # the crowd's character three times: hair#0-2, skirt#0-2


def test_a_restore_after_a_team_moved_to_another_block_moves_it_back_and_repeats_the_frames():
    player, system = make_player("crowd", THREE)
    hair = system.teams_of("hair#1")[0]
    home = system.layout.place(hair)
    player.run(8)
    snapshot = player.capture()
    player.run(10)
    first = state_hash(player, system)
    player.restore(snapshot)
    system.set_parameter("hair#1", "damping", 0.3)
    assert system.layout.place(hair)[0] != home[0]            # a block of its own
    player.run(5)
    player.restore(snapshot)
    assert system.layout.place(hair) == home                  # back beside the other hairs
    player.run(10)
    assert state_hash(player, system) == first


def test_a_model_keeping_restore_into_a_system_grouped_otherwise_continues_each_team_bit_for_bit():
    """The reference runs hair#1 with another damping (a block of its own); the candidate
    keeps the scene's parameters (the three hairs in one block). After the restore every team
    holds the reference's state bit for bit; teams are independent, so every team whose
    parameters are the same in both then repeats the reference's frames bit for bit."""
    from magica_py.solver import state as st

    reference, ref_system = make_player("crowd", THREE)
    ref_system.set_parameter("hair#1", "damping", 0.3)
    reference.run(12)
    snapshot = reference.capture()
    candidate, system = make_player("crowd", THREE)
    candidate.run(3)
    hairs = [system.teams_of(f"hair#{i}")[0] for i in range(3)]
    assert len({system.layout.place(t)[0] for t in hairs}) == 1
    assert len({ref_system.layout.place(t)[0] for t in hairs}) == 2
    own_damping = system.parameters.damping_curve.copy()
    candidate.restore(snapshot, keep_model=True)
    assert candidate.frame == 12
    assert np.array_equal(system.parameters.damping_curve, own_damping)
    assert len({system.layout.place(t)[0] for t in hairs}) == 1   # its own grouping kept
    for t in ref_system.live_teams:
        for field in st.PARTICLE.fields:
            assert system.read_particles(t, field).tobytes() == ref_system.read_particles(t, field).tobytes(), \
                (system.team_names[t], field)
        for field in st.TEAM.fields:
            assert np.atleast_1d(system.read_team(t, field)).tobytes() == \
                np.atleast_1d(ref_system.read_team(t, field)).tobytes(), (system.team_names[t], field)
    same = [t for t in ref_system.live_teams if t != hairs[1]]
    h, ref_h = candidate.scene.hierarchy, reference.scene.hierarchy
    nodes = np.concatenate([system.models[t].transform_index for t in same])
    differed = False
    for frame in range(10):
        candidate.step()
        reference.step()
        for t in same:
            assert system.positions(t).tobytes() == ref_system.positions(t).tobytes(), (frame, system.team_names[t])
        assert h.world_position[nodes].tobytes() == ref_h.world_position[nodes].tobytes(), frame
        differed |= system.positions(hairs[1]).tobytes() != ref_system.positions(hairs[1]).tobytes()
    assert differed                                              # hair#1 runs its own damping
