"""Quality mode's contact speed limit (issue 16 item 2, docs/quality-mode.md *Contact speed*):
a particle within the contact range of a collider at the end of a step keeps at most
``solver.contact_speed_limit`` of velocity relative to the body point under it.

Oracles: hand-computed values of the per-element maths, and a scene in which a strand sweeps
over a still ball at the particle speed limit: with the limit, no particle in the contact
range moves faster than the limit relative to the ball after any step; without it (the same
scene, the limit off), they do - the case exercises what it claims to.
"""
import math
import pathlib

import numpy as np
import pytest
import yaml

from magica_py.bench.mocap_suite import solver_body_velocity
from magica_py.bench.variants import Variant, prepare
from magica_py.solver.contact_speed import body_point_velocity, contact_velocity

LIMIT = 2.0
BALL_RADIUS = 0.08


def close(a, b):
    return np.allclose(np.asarray(a), np.asarray(b), rtol=0.0, atol=1e-12)


def test_the_velocity_relative_to_a_still_body_is_clamped_to_the_limit():
    assert close(contact_velocity((4.0, 0.0, 0.0), (0.0, 0.0, 0.0), 1.0, 2.0, -1.0), (2.0, 0.0, 0.0))
    assert close(contact_velocity((1.5, 0.0, 0.0), (0.0, 0.0, 0.0), 1.0, 2.0, -1.0), (1.5, 0.0, 0.0))


def test_the_clamp_is_relative_to_a_moving_body_and_follows_the_stabilisation_weight():
    # body at 1 m/s along x, particle at 4: 1 + 2
    assert close(contact_velocity((4.0, 0.0, 0.0), (1.0, 0.0, 0.0), 1.0, 2.0, -1.0), (3.0, 0.0, 0.0))
    # carried velocity already x 0.5 (4 m/s -> 2): 0.5 x (1 + 2)
    assert close(contact_velocity((2.0, 0.0, 0.0), (1.0, 0.0, 0.0), 0.5, 2.0, -1.0), (1.5, 0.0, 0.0))
    # the weight 0 right after a reset keeps the particle still
    assert close(contact_velocity((0.0, 0.0, 0.0), (3.0, 0.0, 0.0), 0.0, 2.0, -1.0), (0.0, 0.0, 0.0))


def test_the_particle_speed_limit_holds_after_the_clamp():
    # body at 6 m/s along y, particle at 4 along x: relative (4, -6) clamped to 2, then |v| <= 4
    v = contact_velocity((4.0, 0.0, 0.0), (0.0, 6.0, 0.0), 1.0, 2.0, 4.0)
    rel = np.array([4.0, -6.0, 0.0]) * (2.0 / math.sqrt(52.0))
    expected = np.array([0.0, 6.0, 0.0]) + rel
    expected *= 4.0 / np.linalg.norm(expected)
    assert close(v, expected)


def test_the_body_point_velocity_includes_the_rotation():
    # a body turning 0.1 rad about z around the origin in dt: the point (1, 0, 0) came from
    # (cos 0.1, -sin 0.1, 0)
    a, dt = 0.1, 0.01
    now_rot = (0.0, 0.0, math.sin(a / 2), math.cos(a / 2))
    v = body_point_velocity((0.0, 0.0, 0.0), now_rot, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), (1.0, 0.0, 0.0), dt)
    assert close(v, ((1.0 - math.cos(a)) / dt, math.sin(a) / dt, 0.0))
    # and a translation
    v = body_point_velocity((0.0, 0.1, 0.0), (0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0),
                            (5.0, 5.0, 5.0), dt)
    assert close(v, (0.0, 10.0, 0.0))


def sweep_scene(folder: pathlib.Path) -> str:
    """A 6-bone strand hanging 0.3 m from a root that crosses 1 m along x in 0.2 s and stops;
    a still ball (radius 8 cm) under the root's path, in the strand's way."""
    doc = {
        "version": 1,
        "scene": {"name": "strand_over_ball", "fps": 90, "duration": 1.0, "simulation_frequency": 90,
                  "max_steps_per_frame": 3},
        "rigs": [{"name": "r", "bones": [{"name": "root", "position": [-0.5, 1.0, 0.0]}],
                  "parts": [{"chain": {"name": "strand", "parent": "root", "bones": 6, "length": 0.3,
                                       "direction": [0, -1, 0]}}]}],
        "animation": [{"target": "root", "keyframes": {"keys": [
            {"time": 0.0, "position": [-0.5, 1.0, 0.0]},
            {"time": 0.2, "position": [0.5, 1.0, 0.0]}]}}],
        "colliders": [{"name": "ball", "position": [0.0, 0.85, 0.0], "sphere": {"radius": BALL_RADIUS}}],
        "cloths": [{"name": "strand", "root_bones": ["strand_0"], "connection": "line", "colliders": ["ball"],
                    "collision_mode": "point"}],
    }
    path = folder / "strand_over_ball.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return str(path)


def fastest_relative_in_range(path, parameters):
    """The fastest velocity (m/s) relative to the ball's body point, in the solver's frame, of
    the moving particles within the contact range (sphere within one radius of the ball's
    surface) after each step (one step per frame)."""
    p = prepare(Variant("sweep", path, parameters=parameters))
    system = p.system
    ps, cs = system.particles, system.collider_state
    moving = (np.asarray(system.model.attribute) & 0x02) != 0
    dt = 1.0 / float(system.time_settings.frequency)
    fastest = 0.0
    for _ in range(p.frames):
        p.player.step()
        x = ps.old_pos[moving]
        r = float(system.parameters.radius_curve[0, 0]) * float(system.teams.scale_ratio[0])
        gap = np.linalg.norm(x - cs.start_new[0], axis=1) - cs.radius_start[0] - r
        near = gap <= r
        if near.any():
            slots = np.zeros(int(near.sum()), dtype=np.int64)
            vb = solver_body_velocity(system, slots, x[near], dt)
            fastest = max(fastest, float(np.linalg.norm(ps.velocity[moving][near] - vb, axis=1).max()))
    return fastest


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    return sweep_scene(tmp_path_factory.mktemp("contact_speed"))


def test_without_the_limit_the_strand_slides_over_the_ball_faster_than_the_limit(sweep):
    fastest = fastest_relative_in_range(sweep, {"solver.mode": "quality", "solver.contact_speed_limit": False})
    assert fastest > LIMIT + 0.5


def test_with_the_limit_no_particle_in_contact_range_is_faster_than_it_relative_to_the_ball(sweep):
    fastest = fastest_relative_in_range(sweep, {"solver.mode": "quality", "solver.contact_speed_limit": LIMIT})
    assert 0.5 < fastest <= LIMIT + 1e-9


def test_faithful_mode_ignores_the_contact_speed_limit(sweep):
    """MagicaCloth2's behaviour stays: the parameter means nothing in faithful mode."""
    fastest = fastest_relative_in_range(sweep, {"solver.contact_speed_limit": LIMIT})
    assert fastest > LIMIT + 0.5
