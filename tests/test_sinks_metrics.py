"""Sink metrics: numba kernels against a slow numpy twin and hand-computed cases."""
from __future__ import annotations

import numpy as np
import pytest

from magica_py.build.proxy import DISABLE_COLLISION, FIXED, INVALID_MOTION, MOVE
from magica_py.sinks.base import ClothTopology
from magica_py.sinks.metrics import FrameMetrics


def cloth(n, colliders, attribute=None, radius=0.02):
    edges = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1).astype(np.int32)
    return ClothTopology(name=f"c{n}", attribute=np.full(n, 2, np.uint8) if attribute is None else attribute,
                         radius=np.full(n, radius), parent=np.arange(-1, n - 1, dtype=np.int32), edges=edges,
                         triangles=np.zeros((0, 3), np.int32), rest_length=np.full(n - 1, 0.1),
                         transform_index=np.arange(n, dtype=np.int32), colliders=np.asarray(colliders, np.int32))


# colliders 0 sphere, 1 capsule, 2 plane; one of each kind -> slot 0 of its kind
KIND, SLOT = np.array([0, 1, 2]), np.array([0, 0, 0])


def shapes(b, rng):
    return {"sphere_center": rng.normal(size=(b, 1, 3)), "sphere_radius": rng.uniform(0.1, 0.5, (b, 1)),
            "capsule_start": rng.normal(size=(b, 1, 3)), "capsule_end": rng.normal(size=(b, 1, 3)),
            "capsule_start_radius": rng.uniform(0.1, 0.3, (b, 1)), "capsule_end_radius": rng.uniform(0.1, 0.3, (b, 1)),
            "plane_point": rng.normal(size=(b, 1, 3)) * 0.1,
            "plane_normal": np.tile([[0.0, 1.0, 0.0]], (b, 1, 1))}


def numpy_twin(cloths, x, sh, dt, previous):
    """Straightforward numpy: every pair, every edge, every particle."""
    b = x.shape[0]
    offsets = np.cumsum([0] + [c.particle_count for c in cloths])
    stretch, pen, speed = np.zeros(b), np.zeros(b), np.zeros(b)
    for f in range(b):
        prev = previous if f == 0 else x[f - 1]
        speed[f] = np.linalg.norm(x[f] - prev, axis=1).max() / dt[f] if dt[f] > 0 else 0.0
        for ci, c in enumerate(cloths):
            o = offsets[ci]
            for (i, j), r in zip(c.edges, c.rest_length):
                stretch[f] = max(stretch[f], abs(np.linalg.norm(x[f, o + i] - x[f, o + j]) / r - 1))
            for p in range(c.particle_count):
                if not (c.attribute[p] & MOVE) or (c.attribute[p] & DISABLE_COLLISION):   # as D.8
                    continue
                q, r = x[f, o + p], c.radius[p]
                for col in c.colliders:
                    if col == 0:
                        d = sh["sphere_radius"][f, 0] + r - np.linalg.norm(q - sh["sphere_center"][f, 0])
                    elif col == 1:
                        a, e = sh["capsule_start"][f, 0], sh["capsule_end"][f, 0]
                        t = np.clip(np.dot(q - a, e - a) / np.dot(e - a, e - a), 0, 1)
                        rr_ = sh["capsule_start_radius"][f, 0] * (1 - t) + sh["capsule_end_radius"][f, 0] * t
                        d = rr_ + r - np.linalg.norm(q - (a + (e - a) * t))
                    else:
                        d = r - np.dot(q - sh["plane_point"][f, 0], sh["plane_normal"][f, 0])
                    pen[f] = max(pen[f], d)
    return stretch, pen, speed


def test_kernels_match_the_numpy_twin_on_random_batches():
    rng = np.random.default_rng(3)
    # the fixed particle and the one with DisableCollision are skipped; InvalidMotion collides (D.8)
    attribute = np.array([FIXED, MOVE, MOVE, MOVE | DISABLE_COLLISION, MOVE | INVALID_MOTION, MOVE], np.uint8)
    cloths = [cloth(6, [0, 1, 2], attribute), cloth(4, [1]), cloth(3, [])]
    metrics = FrameMetrics(cloths, KIND, SLOT)
    previous = None
    for batch in range(3):                                       # speed carries across batches
        x = rng.normal(size=(5, 13, 3)) * 0.4
        sh = shapes(5, rng)
        dt = np.array([1 / 60, 0.0, 1 / 30, 1 / 60, 0.5])
        got = metrics.compute(x, sh, dt)
        stretch, pen, speed = numpy_twin(cloths, x, sh, dt, x[0] if previous is None else previous)
        np.testing.assert_allclose(got["max_edge_stretch"], stretch, rtol=1e-12)
        np.testing.assert_allclose(got["max_penetration"], np.maximum(pen, 0), rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(got["max_speed"], speed, rtol=1e-12)
        assert got["max_speed"][1] == 0.0                        # delta time 0
        previous = x[-1]


def test_hand_computed_penetration_and_stretch():
    # one move particle 0.05 m from a sphere's centre of radius 0.1, particle radius 0.02: 0.07 deep
    c = cloth(2, [0], radius=0.02)
    metrics = FrameMetrics([c], KIND, SLOT)
    x = np.array([[[0.0, 1.0, 0.0], [0.0, 0.88, 0.0]]])          # edge 0.12 long, rest 0.1: stretch 0.2
    sh = {"sphere_center": np.array([[[0.0, 0.83, 0.0]]]), "sphere_radius": np.array([[0.1]])}
    got = metrics.compute(x, sh, np.array([1 / 60]))
    assert got["max_penetration"][0] == pytest.approx(0.07, abs=1e-12)
    assert got["max_edge_stretch"][0] == pytest.approx(0.2, abs=1e-12)
    assert got["max_speed"][0] == 0.0                             # first frame


def test_particles_outside_every_collider_report_zero_penetration():
    c = cloth(3, [0, 2])
    metrics = FrameMetrics([c], KIND, SLOT)
    x = np.array([[[5.0, 1.0, 0.0], [5.0, 2.0, 0.0], [5.0, 3.0, 0.0]]])
    sh = {"sphere_center": np.zeros((1, 1, 3)), "sphere_radius": np.full((1, 1), 0.1),
          "plane_point": np.zeros((1, 1, 3)), "plane_normal": np.array([[[0.0, 1.0, 0.0]]])}
    assert metrics.compute(x, sh, np.array([0.1]))["max_penetration"][0] == 0.0


def test_batched_collider_shapes_equal_the_per_frame_world_shapes():
    from magica_py.scene.colliders import ColliderSet
    from magica_py.scene.hierarchy import BoneSpec, TransformHierarchy
    from magica_py.sinks.shapes import ColliderBatch, collider_shapes

    h = TransformHierarchy([BoneSpec("a"), BoneSpec("b", "a", (0, 1, 0), scale=(1.5, 0.5, 2.0)), BoneSpec("c", "b")])
    colliders = ColliderSet.from_specs([
        {"name": "s", "transform": "b", "center": [0.1, 0, 0], "sphere": {"radius": 0.2}},
        {"name": "k", "transform": "c", "capsule": {"radius": 0.1, "end_radius": 0.05, "length": 0.5,
                                                    "direction": "z", "reverse": True, "aligned_on_center": False}},
        {"name": "p", "transform": "a", "plane": {}},
        {"name": "s2", "transform": "c", "sphere": {"radius": 0.3}}], h)
    batch = ColliderBatch(colliders)
    rng = np.random.default_rng(5)
    poses, expected = [], []
    for _ in range(4):
        q = rng.normal(size=(3, 4))
        h.local_rotation[:] = q / np.linalg.norm(q, axis=1, keepdims=True)
        h.local_position[:] = rng.normal(size=(3, 3))
        h.propagate()
        poses.append(batch.capture(h))
        expected.append(collider_shapes(colliders, h))
    got = batch.shapes(*(np.stack([p[i] for p in poses]) for i in range(3)))
    for f, want in enumerate(expected):
        for name, values in got.items():
            np.testing.assert_allclose(values[f], getattr(want, name), rtol=0, atol=1e-15)
    assert got["sphere_center"].shape == (4, 2, 3) and got["capsule_start"].shape == (4, 1, 3)
