"""Teams at runtime (issue 3 item 7): chunks allocated and freed without disturbing other
teams, the frame kernel visiting only the teams in use, removed cloths' bones left alone."""
from __future__ import annotations

import pathlib

import numpy as np
import pytest

from magica_py.config import load_scene
from magica_py.runtime.player import Player
from magica_py.solver.layout import ChunkAllocator, SolverLayout
from magica_py.solver.system import ClothSystem

ROOT = pathlib.Path(__file__).resolve().parent.parent


def _walk():
    """The walking character: hair (line) and skirt (mesh), independent teams."""
    scene = load_scene(ROOT / "configs" / "character_walk.yaml")
    player = Player.for_scene(scene)
    system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings).attach(player)
    return scene, player, system


def _team(system, name):
    return system.team_names.index(name)


def test_chunk_allocator_reuses_freed_space_first_and_coalesces():
    a = ChunkAllocator()
    assert [a.allocate(n) for n in (5, 3, 4)] == [0, 5, 8]
    assert a.capacity == 12
    a.release(5, 3)
    assert a.allocate(2) == 5           # first fit inside the hole
    assert a.allocate(2) == 12          # the 1-row rest of the hole is too small: grow
    assert a.free == [[7, 1]]
    a.release(0, 5)
    a.release(5, 2)                     # 0..8 coalesce into one block
    assert a.free == [[0, 8]]
    assert a.used == 14 - 8
    with pytest.raises(ValueError, match="already free"):
        a.release(6, 1)


def test_layout_chunks_never_overlap_and_other_teams_rows_stay_bit_identical():
    scene, _player, system = _walk()
    models = [m for m in system.models]
    layout = SolverLayout()
    ids = [layout.add(m) for m in models + models]          # 4 teams
    before = layout.model()
    layout.remove(ids[1])
    after_remove = layout.model()
    assert after_remove.live_teams.tolist() == [0, 2, 3]
    assert after_remove.team_particle_count[1] == 0
    new = layout.add(models[1])
    after = layout.model()
    assert new == 4                                          # ids are not reused
    # the freed particle chunk of team 1 is reused by the same-sized model
    assert after.team_particle_start[4] == before.team_particle_start[1]
    owner = np.asarray(after.particle_team)
    for t in (0, 2, 3, 4):
        s, n = int(after.team_particle_start[t]), int(after.team_particle_count[t])
        assert (owner[s:s + n] == t).all()                   # no overlap: each row has one owner
        for name in ("transform_index", "parent", "local_position", "depth", "distance_start"):
            assert np.array_equal(getattr(after, name)[s:s + n], getattr(before, name)[
                int(before.team_particle_start[t if t != 4 else 1]):][:n])
    # re-added team 1 became team 4 with exactly the old global data (same chunks)
    for name in ("baseline_data", "distance_target", "triangles"):
        assert np.array_equal(getattr(after, name), getattr(before, name))


def test_removing_and_readding_a_cloth_leaves_the_other_team_bit_identical():
    ref_scene, ref_player, ref = _walk()
    scene, player, system = _walk()
    hair, skirt = _team(system, "hair"), _team(system, "skirt")
    h_ref = ref.team_particles(hair)
    spec = system.specs[skirt]
    readded = None
    for frame in range(90):
        if frame == 20:
            system.remove_cloth(skirt)
        if frame == 50:
            readded = system.add_cloth(spec)
        ref_player.step()
        player.step()
        got = system.particles.position[system.team_particles(hair)]
        assert np.array_equal(got, ref.particles.position[h_ref]), f"hair differs at frame {frame}"
    hair_nodes = system.models[hair].transform_index
    assert np.array_equal(scene.hierarchy.world_position[hair_nodes], ref_scene.hierarchy.world_position[hair_nodes])
    assert readded == 2 and system.live_teams == [hair, readded]
    # the re-added skirt simulates: finite, moved away from its base pose, stretch sane
    pos = system.particles.position[system.team_particles(readded)]
    base = system.particles.base_pos_buffer[system.team_particles(readded)]
    assert np.isfinite(pos).all()
    assert np.abs(pos - base).max() > 1e-3


def test_removed_cloth_bones_are_neither_restored_nor_written_and_its_rows_stay_free():
    scene, player, system = _walk()
    skirt = _team(system, "skirt")
    player.run(10)
    sl = system.team_particles(skirt)
    nodes = np.asarray(system.models[skirt].transform_index)
    moving = nodes[(np.asarray(system.models[skirt].attribute) & 0x02) != 0]
    system.remove_cloth(skirt)
    assert not np.isin(nodes, player.restored_bones).any()
    assert np.isin(system.models[_team(system, "hair")].transform_index, player.restored_bones).all()
    marker = np.array([0.0, 0.0, np.sin(0.3), np.cos(0.3)])
    scene.hierarchy.local_rotation[moving] = marker
    player.run(5)
    # neither RESTORE (rest pose) nor the write-back (simulated pose) touched them
    assert np.array_equal(scene.hierarchy.local_rotation[moving], np.tile(marker, (len(moving), 1)))
    # the kernel never visited the freed rows: they keep their fresh (zero) values
    assert not system.particles.position[sl].any()
    assert not system.particles.velocity[sl].any()
    assert system.model.live_teams.tolist() == [_team(system, "hair")]


def test_removed_team_is_not_addressable():
    _scene, _player, system = _walk()
    skirt = _team(system, "skirt")
    system.remove_cloth(skirt)
    with pytest.raises(KeyError, match="no cloth team"):
        system.remove_cloth(skirt)
    with pytest.raises(KeyError):
        system.set_parameter(skirt, "damping", 0.1)
    with pytest.raises(KeyError, match="no cloth named"):
        system.teams_of("skirt")
    system.set_parameter("hair", "damping", 0.1)   # the other team still is


def test_added_cloth_with_colliders_gets_its_own_slots():
    scene, player, system = _walk()
    skirt = _team(system, "skirt")
    spec = system.specs[skirt]
    slots_before = system.collider_state.team.copy()
    new = system.add_cloth(spec)
    s, n = int(system.teams.collider_start[new]), int(system.teams.collider_count[new])
    assert n == len(spec.colliders) > 0
    assert (system.collider_state.team[s:s + n] == new).all()
    assert np.array_equal(system.collider_state.team[:len(slots_before)], slots_before)
    player.run(30)
    a = system.particles.position[system.team_particles(skirt)]
    b = system.particles.position[system.team_particles(new)]
    # two identical skirts on the same bones with the same colliders move identically
    assert np.array_equal(a, b)


def test_a_system_started_empty_takes_a_cloth_at_runtime_and_gives_it_back():
    scene = load_scene(ROOT / "configs" / "character_walk.yaml")
    player = Player.for_scene(scene)
    system = ClothSystem(scene.hierarchy, [], scene.colliders, scene.settings).attach(player)
    player.run(3)
    assert system.live_teams == [] and player.restored_bones.size == 0
    team = system.add_cloth(scene.cloths[_skirt_index(scene)])
    assert team == 0 and system.model.team_particle_count.tolist() == [48]
    assert player.restored_bones.size > 0
    player.run(20)
    sl = system.team_particles(team)
    pos = system.particles.position[sl]
    assert np.isfinite(pos).all()
    assert np.abs(pos - system.particles.base_pos_buffer[sl]).max() > 1e-3   # it swings
    system.remove_cloth(team)
    player.run(2)
    assert system.live_teams == [] and player.restored_bones.size == 0


def _skirt_index(scene):
    return [c.name for c in scene.cloths].index("skirt")
