"""Teams at runtime (issue 3 item 7) in the lane form: lanes and blocks taken and freed without
disturbing other teams (``blocks.BlockLayout``), the frame kernel visiting only the blocks in
use, removed cloths' bones left alone; a ``set_parameter`` that moves a team to another block
carries its state bit for bit; a lane that is disabled or runs at another time scale than its
block's other lanes. Where a frozen oracle exists the runs are compared with the per-team
solver of ``tests/reference_solver`` bit for bit."""
from __future__ import annotations

import pathlib

import numpy as np
import pytest

from magica_py.config import load_scene
from magica_py.runtime.player import Player
from magica_py.solver import state as st
from magica_py.solver.blocks import LANES, BlockLayout
from magica_py.solver.system import ClothSystem

ROOT = pathlib.Path(__file__).resolve().parent.parent


def _walk():
    """The walking character: hair (line) and skirt (mesh), independent teams."""
    scene = load_scene(ROOT / "configs" / "character_walk.yaml")
    player = Player.for_scene(scene)
    system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings).attach(player)
    return scene, player, system


def _crowd(reference: bool = False, count: int = 3):
    """``count`` instances of the crowd's character (hair#i, skirt#i): the hairs share a block,
    the skirts another. ``reference``: the per-team solver of tests/reference_solver instead."""
    scene = load_scene(ROOT / "configs" / "crowd.yaml", [f"rigs[0].instances.count={count}"])
    player = Player.for_scene(scene)
    if reference:
        from reference_solver.solver.system import ClothSystem as System
    else:
        System = ClothSystem
    system = System(scene.hierarchy, scene.cloths, scene.colliders, scene.settings).attach(player)
    return scene, player, system


def _team(system, name):
    return system.team_names.index(name)


def _same_as_reference(frame, scene, system, ref_scene, ref):
    for t in ref.live_teams:
        # the particles' state (positions() of a team that did not run reports its bones)
        assert system.read_particles(t, "position").tobytes() == ref.positions(t).tobytes(), (frame, ref.team_names[t])
    for name in ("local_position", "local_rotation", "world_position", "world_rotation"):
        assert getattr(scene.hierarchy, name).tobytes() == getattr(ref_scene.hierarchy, name).tobytes(), (frame, name)


def _team_state(system, team) -> dict:
    """Every particle and team field of a team, and its collider slots' state (copies)."""
    out = {f"particle.{f}": system.read_particles(team, f) for f in st.PARTICLE.fields}
    out.update({f"team.{f}": np.atleast_1d(system.read_team(team, f)) for f in st.TEAM.fields})
    m = system.model
    s, n = int(m.team_collider_start[team]), int(m.team_collider_count[team])
    out.update({f"collider.{f}": getattr(system.collider_state, f)[s:s + n] for f in st.COLLIDER.fields})
    return out


def _assert_same_state(a: dict, b: dict, what):
    assert a.keys() == b.keys()
    for k in a:
        assert a[k].tobytes() == b[k].tobytes(), (what, k)


def test_layout_of_the_walk_models_reuses_a_freed_lane_and_leaves_other_columns_bit_identical():
    scene, _player, system = _walk()
    models = list(system.models)                               # hair, skirt
    layout = BlockLayout()
    ids = [layout.add(m) for m in models + models]             # 4 teams: 2 blocks of 2 lanes
    assert [layout.place(t) for t in ids] == [(0, 0), (1, 0), (0, 1), (1, 1)]
    pm = layout.particle_model.copy()
    layout.remove(ids[1])
    assert layout.live_teams == [0, 2, 3] and layout.blocks[1] is not None
    g = layout.slots(3)["particle"]
    for t in (0, 2, 3):                                        # other lanes' columns untouched
        b, lane = layout.place(t)
        rows = layout.slots(t)["particle"]
        assert np.array_equal(layout.particle_model[rows, lane::LANES], pm[rows, lane::LANES])
    new = layout.add(models[1])
    assert new == 4 and layout.place(new) == (1, 0)            # ids are not reused, the lane is
    assert np.array_equal(layout.particle_model[g], pm[g])     # the same columns again, bit for bit


def test_removing_and_readding_a_cloth_leaves_the_other_team_bit_identical():
    ref_scene, ref_player, ref = _walk()
    scene, player, system = _walk()
    hair, skirt = _team(system, "hair"), _team(system, "skirt")
    spec = system.specs[skirt]
    readded = None
    for frame in range(90):
        if frame == 20:
            system.remove_cloth(skirt)
        if frame == 50:
            readded = system.add_cloth(spec)
        ref_player.step()
        player.step()
        got = system.read_particles(hair, "position")
        assert np.array_equal(got, ref.read_particles(hair, "position")), f"hair differs at frame {frame}"
    hair_nodes = system.models[hair].transform_index
    assert np.array_equal(scene.hierarchy.world_position[hair_nodes], ref_scene.hierarchy.world_position[hair_nodes])
    assert readded == 2 and system.live_teams == [hair, readded]
    # the re-added skirt simulates: finite, moved away from its base pose
    pos = system.read_particles(readded, "position")
    base = system.read_particles(readded, "base_pos_buffer")
    assert np.isfinite(pos).all()
    assert np.abs(pos - base).max() > 1e-3


def test_removed_cloth_bones_are_neither_restored_nor_written_and_its_rows_stay_free():
    scene, player, system = _walk()
    skirt = _team(system, "skirt")
    player.run(10)
    b, lane, g = system.team_slots(skirt)
    freed_rows = system.PS[g].copy()
    nodes = np.asarray(system.models[skirt].transform_index)
    moving = nodes[(np.asarray(system.models[skirt].attribute) & 0x02) != 0]
    system.remove_cloth(skirt)
    assert system.layout.blocks[b] is None and b not in system.tables.blocks   # its block (one lane) is freed
    assert any(s <= g[0] and g[-1] < s + n for s, n in system.layout.allocators["particle"].free)
    assert not np.isin(nodes, player.restored_bones).any()
    assert np.isin(system.models[_team(system, "hair")].transform_index, player.restored_bones).all()
    marker = np.array([0.0, 0.0, np.sin(0.3), np.cos(0.3)])
    scene.hierarchy.local_rotation[moving] = marker
    player.run(5)
    # neither RESTORE (rest pose) nor the write-back (simulated pose) touched them
    assert np.array_equal(scene.hierarchy.local_rotation[moving], np.tile(marker, (len(moving), 1)))
    # the kernel never visited the freed rows: they hold what they held, bit for bit
    assert system.PS[g].tobytes() == freed_rows.tobytes()
    assert system.model.live_teams.tolist() == [_team(system, "hair")]
    assert system.model.team_particle_count[skirt] == 0


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
    with pytest.raises(KeyError, match="no cloth team"):
        system.read_particles(skirt, "position")
    system.set_parameter("hair", "damping", 0.1)   # the other team still is


def test_added_cloth_with_colliders_takes_a_lane_of_its_kind_with_its_own_collider_columns():
    scene, player, system = _walk()
    skirt = _team(system, "skirt")
    spec = system.specs[skirt]
    b, lane = system.layout.place(skirt)
    skirt_colliders = system.CS[system.layout.slots(skirt)["collider"], lane::LANES].copy()
    new = system.add_cloth(spec)
    # the same model, parameters and colliders: the skirt's block, the next lane
    assert system.layout.place(new) == (b, lane + 1)
    m = system.model
    n = int(m.team_collider_count[new])
    assert n == len(spec.colliders) > 0
    slots = system.layout.slots(new)["collider"]
    assert len(slots) == n
    assert system.CS[slots, lane::LANES].tobytes() == skirt_colliders.tobytes()   # the skirt's columns untouched
    cs = system.collider_state
    s0, s1 = int(m.team_collider_start[skirt]), int(m.team_collider_start[new])
    assert np.array_equal(cs.local_center[s1:s1 + n], cs.local_center[s0:s0 + n])
    assert np.array_equal(cs.size[s1:s1 + n], cs.size[s0:s0 + n]) and np.abs(cs.size[s1:s1 + n]).max() > 0
    player.run(30)
    a = system.read_particles(skirt, "position")
    c = system.read_particles(new, "position")
    # two identical skirts on the same bones with the same colliders move identically
    assert np.array_equal(a, c)
    assert np.abs(a - system.read_particles(skirt, "base_pos_buffer")).max() > 1e-3


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
    pos = system.read_particles(team, "position")
    assert np.isfinite(pos).all()
    assert np.abs(pos - system.read_particles(team, "base_pos_buffer")).max() > 1e-3   # it swings
    system.remove_cloth(team)
    player.run(2)
    assert system.live_teams == [] and player.restored_bones.size == 0
    assert system.tables.blocks.size == 0


def _skirt_index(scene):
    return [c.name for c in scene.cloths].index("skirt")


def test_set_parameter_moves_a_team_to_a_block_of_its_kind_with_its_state_bit_for_bit():
    scene, player, system = _crowd()
    ref_scene, ref_player, ref = _crowd(reference=True)
    hairs = [_team(system, f"hair#{i}") for i in range(3)]
    assert [system.layout.place(t)[0] for t in hairs] == [0, 0, 0]
    for frame in range(15):
        player.step()
        ref_player.step()
    moved = hairs[1]
    home = system.layout.place(moved)
    before = _team_state(system, moved)
    others = {t: (system.layout.place(t), _team_state(system, t)) for t in system.live_teams if t != moved}
    system.set_parameter("hair#1", "damping", 0.3)
    ref.set_parameter("hair#1", "damping", 0.3)
    b, lane = system.layout.place(moved)
    assert b != home[0] and lane == 0 and system.layout.blocks[b].used == [0]   # a block of its own
    assert system.P[b].tobytes() != system.P[home[0]].tobytes()
    _assert_same_state(_team_state(system, moved), before, "moved team")
    for t, (place, state) in others.items():             # nobody else moved or changed
        assert system.layout.place(t) == place
        _assert_same_state(_team_state(system, t), state, system.team_names[t])
    for frame in range(15, 35):
        player.step()
        ref_player.step()
        _same_as_reference(frame, scene, system, ref_scene, ref)
    # back to the block's parameters: it rejoins its old block (the first free lane), and
    # the block it had alone is freed
    state = _team_state(system, moved)
    damping = system.team_parameters[hairs[0]].get("damping")
    system.set_parameter("hair#1", "damping", damping)
    ref.set_parameter("hair#1", "damping", damping)
    assert system.layout.place(moved) == home and system.layout.blocks[b] is None
    _assert_same_state(_team_state(system, moved), state, "moved back")
    for frame in range(35, 50):
        player.step()
        ref_player.step()
        _same_as_reference(frame, scene, system, ref_scene, ref)


def test_a_disabled_lane_keeps_its_state_while_its_block_runs_and_resets_when_enabled():
    scene, player, system = _crowd()
    ref_scene, ref_player, ref = _crowd(reference=True)
    skirt = _team(system, "skirt#1")
    for _ in range(10):
        player.step()
        ref_player.step()
    system.set_enabled("skirt#1", False)
    ref.set_enabled("skirt#1", False)
    player.step()
    ref_player.step()
    frozen = _team_state(system, skirt)
    for frame in range(11, 26):
        player.step()
        ref_player.step()
        _same_as_reference(frame, scene, system, ref_scene, ref)
        _assert_same_state(_team_state(system, skirt), frozen, f"disabled skirt, frame {frame}")
    neighbour = _team(system, "skirt#0")
    assert system.layout.place(neighbour)[0] == system.layout.place(skirt)[0]
    assert system.read_particles(neighbour, "position").tobytes() != frozen["particle.position"].tobytes()
    system.set_enabled("skirt#1", True)
    ref.set_enabled("skirt#1", True)
    assert system.read_team(skirt, "reset") == 1.0             # re-enabling resets (disable mode Reset)
    for frame in range(26, 46):
        player.step()
        ref_player.step()
        _same_as_reference(frame, scene, system, ref_scene, ref)


def test_a_lane_at_another_time_scale_runs_its_own_steps_within_its_block():
    scene, player, system = _crowd()
    ref_scene, ref_player, ref = _crowd(reference=True)
    slow, other = _team(system, "hair#2"), _team(system, "hair#0")
    assert system.layout.place(slow)[0] == system.layout.place(other)[0]
    system.set_time_scale("hair#2", 0.37)
    ref.set_time_scale("hair#2", 0.37)
    differed = 0
    for frame in range(40):
        player.step()
        ref_player.step()
        _same_as_reference(frame, scene, system, ref_scene, ref)
        differed += int(system.time_state.update_count[slow] != system.time_state.update_count[other])
    assert differed >= 10          # the block ran steps in which that lane sat out
