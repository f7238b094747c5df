"""Lanes that do not run keep their state (solver/frame.py, *Lanes that do not run*).

The teams of a block run every stage side by side; a team that is disabled, culled or runs
fewer steps than its neighbours (its own time scale, a reset clock) is saved before and put
back after. Each case runs a block of instanced teams with the lane form and, frame by frame,
the same scene with the frozen per-team reference (``tests/reference_solver``): every team's
particles and every bone must be the same bits, and a frozen team's particles must not move.
"""
from __future__ import annotations

import numpy as np
import pytest

from magica_py.config import load_scene_text
from magica_py.runtime.player import Player
from magica_py.solver.system import ClothSystem
from reference_solver.solver.system import ClothSystem as ReferenceSystem

SCENE = """
version: 1
scene: {name: lanes, fps: 60, duration: 1.0, simulation_frequency: 90}
rigs:
  - name: r
    bones:
      - {name: spot}
      - {name: root, parent: spot, position: [0, 1, 0]}
    parts:
      - chain: {name: c, parent: root, bones: 5, length: 0.4, direction: [0, -1, 0]}
    instances: {count: 5, spacing: [1.5, 0, 0], phase_offset: 0.1}
animation:
  - {target: root, orbit: {center: [0, 1, 0], radius: 0.3, period: 0.8, axis: [0, -1, 0]}}
cloths:
  - {name: tail, root_bones: [c_0], connection: line}
"""


def pair():
    systems = []
    for cls in (ClothSystem, ReferenceSystem):
        scene = load_scene_text(SCENE)
        player = Player.for_scene(scene)
        system = cls(scene.hierarchy, scene.cloths, scene.colliders, scene.settings, parallel=False).attach(player)
        systems.append((player, system, scene))
    return systems


def particle_state(system, team):
    """A team's particle positions as the solver holds them (``positions()`` of a team that did
    not run this frame reports its bones; the reference solver's is its state)."""
    read = getattr(system, "read_particles", None)
    return read(team, "position") if read is not None else system.positions(team)


def same_bits(systems):
    (_, a, sa), (_, b, sb) = systems
    for t in b.live_teams:
        # the particles' state (positions() of a team that did not run reports its bones)
        assert np.array_equal(particle_state(a, t), particle_state(b, t)), f"team {t}: particles differ"
    for name in ("local_position", "local_rotation", "world_position", "world_rotation"):
        assert np.array_equal(getattr(sa.hierarchy, name), getattr(sb.hierarchy, name)), name


def test_the_instances_share_one_block():
    (_, system, _), _ = pair()
    blocks = {system.layout.place(t)[0] for t in system.live_teams}
    assert len(blocks) == 1 and len(system.live_teams) == 5


@pytest.mark.parametrize("action", ["disable", "time_scale", "reset", "force"])
def test_a_lane_that_does_not_run_keeps_its_state_and_the_others_their_bits(action):
    systems = pair()
    frozen = None
    for frame in range(40):
        if frame == 10:
            for _player, system, _scene in systems:
                if action == "disable":
                    system.set_enabled(2, False)
                elif action == "time_scale":
                    system.set_time_scale(1, 0.37)
                elif action == "reset":
                    system.reset_cloth(3)
                else:
                    system.add_force(4, (1.0, 0.0, 0.0), 5.0)
        if frame == 25 and action == "disable":
            for _player, system, _scene in systems:
                system.set_enabled(2, True)
        for player, _system, _scene in systems:
            player.step()
        if action == "disable" and 11 <= frame < 25:
            now = particle_state(systems[0][1], 2)
            if frozen is not None:
                assert np.array_equal(now, frozen), "a disabled team's particles moved"
            frozen = now
        same_bits(systems)
