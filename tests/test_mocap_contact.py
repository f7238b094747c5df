"""The mocap suite's contact readings (issue 16: "no particle faster than the body part it
touches plus 2 m/s"): a pair "within one radius" of a body part is near it, not necessarily in
contact; the strict readings count a pair only when the sphere touches the collider (gap at
most ``TOUCH_TOLERANCE`` of its radius) or D.8 pushed the particle in that step.

Oracles: the geometry of a straight flight past a sphere (no contact, yet the near reading
reports an ejection beyond 2 m/s), and, in a solver run, D.8's push predicted from the
particles' rest positions and the sphere's poses before and after each step.
"""
from __future__ import annotations

import math
import pathlib

import numpy as np
import pytest
import yaml

from magica_py.bench import metrics as M
from magica_py.bench import mocap_suite as S
from magica_py.bench.variants import Variant, prepare


def sphere_shapes(radius, centre=(0.0, 0.0, 0.0)):
    from types import SimpleNamespace

    return SimpleNamespace(shape=np.array([0]), position=np.array([centre], float), start=np.array([centre], float),
                           end=np.array([centre], float), radius=np.array([radius]), end_radius=np.array([radius]),
                           normal=np.zeros((1, 3)), suspended=np.array([False]))


def test_a_strand_flying_straight_past_a_still_sphere_is_near_it_but_not_in_contact():
    """A particle (r 2 cm) in straight flight at 4 m/s along a line tangent to the shell of a
    still 10 cm sphere (the shell: R + r = 12 cm). Where its gap is g, its outward speed is
    |v| s / (R + r + g), s = sqrt((R + r + g)^2 - (R + r)^2): 2.06 m/s at g = r, beyond the
    2 m/s bound, with no contact force at all. The near reading (within one radius) counts it;
    the contact reading does not, until the gap is within 5 % of the radius."""
    R, r, speed = 0.10, 0.02, 4.0
    shell = R + r
    s = np.linspace(0.0, 0.09, 91)                        # m along the line past the tangent point
    x = np.stack([s, np.full_like(s, shell), np.zeros_like(s)], axis=1)
    v = np.tile([speed, 0.0, 0.0], (s.size, 1))
    pairs = (np.arange(s.size), np.zeros(s.size, dtype=np.int64))
    depth, normal = M.pair_contacts(x, np.full(s.size, r), pairs, sphere_shapes(R))
    gap = -depth
    _, _, outward = M.ejection_speeds(v, np.zeros_like(v), normal)
    expected = speed * s / np.hypot(shell, s)
    assert np.allclose(outward, expected)
    near, touching = S.contact_pairs(depth, np.full(s.size, r), np.zeros(s.size, dtype=bool))
    at_one_radius = int(np.argmin(np.abs(gap - r)))
    assert near[:at_one_radius].all() and outward[near].max() > 2.0     # the near reading: "ejected"
    assert math.isclose(speed * math.sqrt((shell + r) ** 2 - shell ** 2) / (shell + r), 2.06, abs_tol=0.005)
    assert (touching == (gap <= S.TOUCH_TOLERANCE * r)).all()
    assert outward[touching].max() < 0.35 * speed                        # in contact: grazing, barely leaving


def test_a_pushed_particle_is_in_contact_wherever_the_later_passes_left_it_within_one_radius():
    depth = np.array([-0.4, -0.4, -0.01, -1.5]) * 0.02
    near, touching = S.contact_pairs(depth, np.full(4, 0.02), np.array([True, False, False, True]))
    assert near.tolist() == [True, True, True, False]
    assert touching.tolist() == [True, False, True, False]


def test_d8s_push_mark_is_the_friction_keep_exactly():
    """D.8 sets a pushed particle's friction to 1 and D.10 multiplies it by the keep (0.6 at
    90 Hz): exactly 0.6 after a push; 0.6 (1 - d/r) after a step near but outside (d > 0);
    0.36 one step after a push."""
    keep = np.full(4, 0.6)
    friction = np.array([1.0 * 0.6, (1.0 - 0.3) * 0.6, 0.6 * 0.6, (1.0 - 1e-6) * 0.6])
    assert S.pushed_by_collision(friction, keep).tolist() == [True, False, False, False]


SPEED = 1.0              # m/s, the sphere
SPHERE_RADIUS = 0.05


def moving_sphere_scene(folder: pathlib.Path) -> str:
    """A 6-bone chain hanging 0.3 m from a fixed root, no gravity (it stays still until
    touched), and a 5 cm sphere moving along +Z at 1 m/s towards its lower half; 90 fps at
    90 Hz: one step per frame."""
    doc = {
        "version": 1,
        "scene": {"name": "sphere_into_chain", "fps": 90, "duration": 0.3, "simulation_frequency": 90,
                  "max_steps_per_frame": 3, "gravity": [0, -1, 0]},
        "rigs": [{"name": "r", "bones": [{"name": "root", "position": [0, 1.0, 0]},
                                         {"name": "ball", "position": [0, 0.8, -0.15]}],
                  "parts": [{"chain": {"name": "chain", "parent": "root", "bones": 6, "length": 0.3,
                                       "direction": [0, -1, 0]}}]}],
        "animation": [{"target": "ball", "keyframes": {"keys": [
            {"time": 0.0, "position": [0, 0.8, -0.15]}, {"time": 0.3, "position": [0, 0.8, -0.15 + 0.3 * SPEED]}]}}],
        "colliders": [{"name": "ball_col", "transform": "ball", "sphere": {"radius": SPHERE_RADIUS}}],
        "cloths": [{"name": "chain", "root_bones": ["chain_0"], "connection": "line", "colliders": ["ball_col"],
                    "collision_mode": "point", "parameters": {"gravity": 0.0}}],
    }
    path = folder / "sphere_into_chain.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return str(path)


@pytest.mark.parametrize("mode", ["quality", "faithful"])
def test_the_push_mark_flags_exactly_the_particles_d8_pushed(tmp_path, mode):
    """Until the first push the chain is still, so D.8 sees each particle at its rest place x:
    it pushes it in a step when x is inside the moving sphere's shell by D.8's moving plane
    (normal n from the sphere's previous centre, surface at its current one:
    (x - c_new).n < R + r). The mark must flag exactly those, step by step, up to and
    including the first step that pushes."""
    p = prepare(Variant("sphere", moving_sphere_scene(tmp_path), parameters={"solver.mode": mode}))
    system = p.system
    ps, cs = system.particles, system.collider_state
    moving = (np.asarray(system.model.attribute) & 0x02) != 0
    team = np.asarray(system.model.particle_team, dtype=np.int64)
    keep = S.friction_keep(system)[team]
    r = M.particle_radius(system.model, system.parameters)
    pushed_any = grazed = False
    c_old = None                       # the sphere's centre at the previous step (first step: its own)
    for _ in range(p.frames):
        x = np.array(ps.old_pos, copy=True)
        p.player.step()
        c_new = np.array(cs.start_new[0], copy=True)
        c_old = c_new if c_old is None else c_old
        n = (x - c_old) / np.linalg.norm(x - c_old, axis=1)[:, None]
        expected = moving & (np.einsum("ij,ij->i", x - c_new, n) < cs.radius_start[0] + r)
        mark = S.pushed_by_collision(np.asarray(ps.friction), keep) & moving
        assert mark.tolist() == expected.tolist()
        grazed |= bool((moving & (np.asarray(ps.friction) > 0.0) & ~mark).any())   # near, friction, no push
        if expected.any():
            pushed_any = True
            break
        c_old = c_new
    assert pushed_any                                   # the sphere reaches the chain within the run
    assert grazed                                       # and came within range of one before pushing it


def test_the_body_velocity_is_read_in_the_solvers_frame_from_the_last_steps_collider_motion():
    """``solver_body_velocity``: the collider slot's previous-step pose (``start_old``, the
    inverse ``inverse_old_rot``) to its pose of the step (``start_new``, ``now_rot``), the frame
    of ``particles.velocity``; hand values for a translation and a turn about z."""
    from types import SimpleNamespace

    a, dt = 0.1, 0.01
    inverse_turn_back = (0.0, 0.0, math.sin(a / 2), math.cos(a / 2))   # the inverse of a turn by -a about z
    cs = SimpleNamespace(start_old=np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]),
                         start_new=np.array([[0.0, 0.01, 0.0], [0.0, 0.0, 0.0]]),
                         inverse_old_rot=np.array([[0.0, 0.0, 0.0, 1.0], inverse_turn_back]),
                         now_rot=np.array([[0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 1.0]]))
    system = SimpleNamespace(collider_state=cs)
    points = np.array([[3.0, 4.0, 5.0], [1.0, 0.0, 0.0]])
    v = S.solver_body_velocity(system, np.array([0, 1]), points, dt)
    # slot 0 moved 1 cm along y; slot 1 turned from -a to 0: the point (1, 0, 0) came from
    # (cos a, -sin a, 0)
    assert np.allclose(v[0], (0.0, 1.0, 0.0), atol=1e-12)
    assert np.allclose(v[1], ((1.0 - math.cos(a)) / dt, math.sin(a) / dt, 0.0), atol=1e-12)
