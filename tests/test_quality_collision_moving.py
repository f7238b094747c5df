"""Collision that neither traps nor throws (issue 16 item 2, docs/quality-mode.md): in quality
mode a capsule moving at 4 m/s through a hanging chain leaves no particle inside it at the end
of any step, and the particles it pushes - including those it starts the step inside - move
no faster than the capsule plus a small margin.

The scene: a 10-bone chain hanging 0.5 m from a fixed root (no gravity: the capsule is the
only thing that moves it), a horizontal capsule (radius 5 cm, 0.4 m long, across the chain)
moving along +Z at 4 m/s at the chain's middle height; one step per frame (90 fps, 90 Hz) so
that after every frame the state and the collider work data are those of the last step.
"""
import pathlib

import numpy as np
import pytest
import yaml

from magica_py.bench.variants import Variant, prepare

SPEED = 4.0            # m/s, the capsule
CAPSULE_RADIUS = 0.05
MARGIN = 0.5           # m/s above the capsule's speed


def scene(folder: pathlib.Path, start_z: float) -> str:
    travel = 0.6
    doc = {
        "version": 1,
        "scene": {"name": "capsule_through_chain", "fps": 90, "duration": 0.4, "simulation_frequency": 90,
                  "max_steps_per_frame": 3, "gravity": [0, -1, 0]},
        "rigs": [{"name": "r", "bones": [{"name": "root", "position": [0, 1.0, 0]},
                                         {"name": "bar", "position": [0, 0.72, start_z]}],
                  "parts": [{"chain": {"name": "chain", "parent": "root", "bones": 10, "length": 0.5,
                                       "direction": [0, -1, 0]}}]}],
        "animation": [{"target": "bar", "keyframes": {"keys": [
            {"time": 0.0, "position": [0, 0.72, start_z]},
            {"time": travel / SPEED, "position": [0, 0.72, start_z + travel]}]}}],
        "colliders": [{"name": "bar_col", "transform": "bar",
                       "capsule": {"radius": CAPSULE_RADIUS, "end_radius": CAPSULE_RADIUS, "length": 0.4,
                                   "direction": "x", "aligned_on_center": True}}],
        "cloths": [{"name": "chain", "root_bones": ["chain_0"], "connection": "line", "colliders": ["bar_col"],
                    "collision_mode": "point", "parameters": {"gravity": 0.0}}],
    }
    path = folder / f"capsule_through_chain_{start_z:+.2f}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return str(path)


def capsule_depth(x, a, b, radius):
    """Depth (m, > 0 inside) of points x (N, 3) inside the capsule segment ab + radius."""
    ab = b - a
    t = np.clip(((x - a) @ ab) / max(float(ab @ ab), 1e-30), 0.0, 1.0)
    return radius - np.linalg.norm(x - (a + t[:, None] * ab), axis=1)


def run(path, parameters):
    """Per frame: deepest particle sphere inside the capsule at the end of the step (m), and
    the fastest particle near the capsule (m/s)."""
    p = prepare(Variant("capsule", path, parameters=parameters))
    system = p.system
    m = system.model
    ps, cs = system.particles, system.collider_state
    moving = (np.asarray(m.attribute) & 0x02) != 0
    r = float(system.parameters.radius_curve[0, 0])
    depth, speed, started_inside = [], [], []
    for _ in range(p.frames):
        before = capsule_depth(ps.old_pos[moving], cs.start_new[0], cs.end_new[0], cs.radius_start[0] + r)
        p.player.step()
        d = capsule_depth(ps.old_pos[moving], cs.start_new[0], cs.end_new[0], cs.radius_start[0] + r)
        depth.append(float(d.max()))
        near = d > -2.0 * r
        v = np.linalg.norm(ps.velocity[moving], axis=1)
        speed.append(float(v[near].max(initial=0.0)))
        started_inside.append(int((before > 1e-4).sum()))
    return np.array(depth), np.array(speed), np.array(started_inside), r


@pytest.mark.parametrize("start_z", [-0.15, -0.02])
def test_a_moving_capsule_leaves_no_particle_inside_and_throws_none(tmp_path, start_z):
    """start_z -0.15: the capsule reaches the chain within the run; -0.02: it starts around
    the chain (particles start the first step inside it)."""
    depth, speed, started_inside, r = run(scene(tmp_path, start_z), {"solver.mode": "quality"})
    if start_z > -0.1:
        assert started_inside[0] > 0               # the case is what it says
    assert depth.max() <= 1e-6                     # no particle sphere inside at any step's end
    assert speed.max() <= SPEED + MARGIN


def test_the_faithful_solver_traps_the_particles_the_capsule_starts_around(tmp_path):
    """The oracle's other side: MagicaCloth2's D.8 alone leaves particles inside the capsule
    (why quality mode handles the collider's motion in the step)."""
    depth, _speed, _inside, r = run(scene(tmp_path, -0.02), {})
    assert depth.max() > 0.1 * r
