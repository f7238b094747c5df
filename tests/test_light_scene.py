"""configs/light_chains.yaml is the chain model of ../shared/peers-bench (README.md, common.py):
chain k's root on C + R (cos(wt + phi_k), 0, sin(wt + phi_k)) relative to its spot, 16 bones
0.05 m apart hanging along -Y, one fixed 0.2 m sphere at (0.8, 1.3, 0), distance and collider
only. The peers' formula is written out here so the test needs nothing outside the repository."""
from __future__ import annotations

import math
import pathlib
from types import SimpleNamespace

import numpy as np
import pytest

from magica_py.config import load_scene

CONFIG = pathlib.Path(__file__).resolve().parents[1] / "configs" / "light_chains.yaml"
K = 1000
CENTER = np.array([0.0, 1.5, 0.0])
RADIUS = 0.5
OMEGA = 2.0 * math.pi


@pytest.fixture(scope="module")
def scene():
    return load_scene(CONFIG)


def peers_root(t, k):
    phi = 2.0 * math.pi * k / K
    return CENTER + RADIUS * np.array([math.cos(OMEGA * t + phi), 0.0, math.sin(OMEGA * t + phi)])


def test_scene_has_the_peers_sizes(scene):
    h = scene.hierarchy
    assert len(scene.cloths) == K and h.count == 18 * K
    assert scene.settings.simulation_frequency == 90
    bones = [h.index(f"chain_{d}#7") for d in range(16)]
    offsets = np.diff(h.world_position[bones], axis=0)
    np.testing.assert_allclose(offsets, np.tile([0.0, -0.05, 0.0], (15, 1)), atol=1e-12)


@pytest.mark.parametrize("t", [0.0, 0.1, 0.37, 1.9])
def test_every_root_flies_the_peers_circle_with_its_phase(scene, t):
    h = scene.hierarchy
    scene.animation.apply(h, SimpleNamespace(time=SimpleNamespace(time=t), events=[]))
    h.propagate()
    for k in (0, 1, 250, 613, 999):
        spot = h.world_position[h.index(f"spot#{k}")]
        root = h.world_position[h.index(f"chain_0#{k}")]
        np.testing.assert_allclose(root - spot, peers_root(t, k), atol=1e-12)


def test_each_chain_collides_with_its_own_fixed_sphere(scene):
    h = scene.hierarchy
    shapes = scene.colliders.world_shapes(h)
    for k in (0, 42, 999):
        cloth = scene.cloths[k]
        (c,) = cloth.colliders
        spot = h.world_position[h.index(f"spot#{k}")]
        np.testing.assert_allclose(shapes.position[c] - spot, [0.8, 1.3, 0.0], atol=1e-12)
        assert shapes.radius[c] == pytest.approx(0.2)
        assert scene.colliders.transform[c] == h.index(f"spot#{k}")   # does not orbit


def test_only_distance_and_the_collider_are_asked_for(scene):
    cloth = scene.cloths[0]
    p = cloth.parameters
    assert cloth.connection_mode == "line" and cloth.collision_mode == "point"
    assert p["angle_restoration.use"] is False and p["angle_limit.use"] is False
    assert p["motion.use_max_distance"] is False and p["motion.use_backstop"] is False
    assert p["gravity"] == pytest.approx(9.81)
    assert p["collider_collision.friction"] == 0.0
