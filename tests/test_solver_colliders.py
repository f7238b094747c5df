"""Collider collision (docs/solver.md §D.8, §G): penetration bounds in point mode, edge mode catching a
thin capsule that point mode misses, and the collider work data against the numpy oracle
``ColliderSet.world_shapes``."""
from __future__ import annotations

import math

import numpy as np
import pytest

from magica_py.scene.hierarchy import BoneSpec
from solver_scenes import chain_system, params, run

PARTICLE_RADIUS = 0.02  # default radius curve


def swing_onto(shape, where, mode="point", frames=180, rotation=(0.0, 0.0, 0.0, 1.0), **param_overrides):
    """A horizontal 5-bone tail (0.5 m, root at y=1) swinging down onto one collider at 90 fps,
    returning the end-of-step positions of every step."""
    extra = [BoneSpec("col", None, tuple(where), rotation)]
    spec = {"name": "col", "transform": "col", **shape}
    s, h = chain_system(bones=5, length=0.5, direction=(0.0, 0.0, -1.0), extra_bones=extra,
                        collider_specs=[spec], collision_mode=mode,
                        parameters=params(**param_overrides))
    traj = []
    for _ in range(frames):
        run(s, 1, dt=1.0 / 90.0)            # exactly one step per frame
        traj.append(s.particles.old_pos.copy())
    return s, h, np.array(traj)


def capsule_distance(x, start, end, r_start, r_end):
    """Signed distance of points x (..., 3) to a tapered capsule's surface (numpy oracle)."""
    ab = end - start
    t = np.clip(((x - start) @ ab) / (ab @ ab), 0.0, 1.0)
    closest = start + t[..., None] * ab
    return np.linalg.norm(x - closest, axis=-1) - (r_start + (r_end - r_start) * t)


def test_point_mode_keeps_particles_out_of_a_sphere():
    center = np.array([0.0, 0.72, -0.3])
    _, _, traj = swing_onto({"sphere": {"radius": 0.1}}, center)
    depth = 0.1 + PARTICLE_RADIUS - np.linalg.norm(traj[:, 1:] - center, axis=2)
    assert depth.max() <= 0.1 * PARTICLE_RADIUS          # measured 7.8 %
    # the sphere was in the way: without collision the tail passes through it
    _, _, free = swing_onto({"sphere": {"radius": 0.1}}, center, mode="none")
    assert np.linalg.norm(free[:, 1:] - center, axis=2).min() < 0.05


def test_point_mode_keeps_particles_above_a_plane():
    _, _, traj = swing_onto({"plane": {}}, (0.0, 0.8, 0.0))
    depth = 0.8 + PARTICLE_RADIUS - traj[:, 1:, 1]
    assert depth.max() <= 0.1 * PARTICLE_RADIUS          # measured 0.5 %
    assert traj[-1, 4, 1] == pytest.approx(0.8 + PARTICLE_RADIUS, abs=2e-3)   # resting on it


def test_point_mode_keeps_particles_out_of_a_tapered_capsule():
    s, h, traj = swing_onto({"capsule": {"radius": 0.05, "end_radius": 0.03, "length": 0.6,
                                         "direction": "x"}}, (0.0, 0.75, -0.3))
    ws = s.colliders.world_shapes(h)
    d = capsule_distance(traj[:, 1:], ws.start[0], ws.end[0], ws.radius[0], ws.end_radius[0])
    assert (PARTICLE_RADIUS - d).max() <= 0.1 * PARTICLE_RADIUS


def test_collider_work_data_matches_the_numpy_world_shapes():
    # a rotated, scaled, start-aligned, reversed capsule: kernel endpoints == oracle endpoints
    q = (0.0, math.sin(0.3), 0.0, math.cos(0.3))
    extra = [BoneSpec("col", None, (0.1, 0.5, -0.2), q, scale=(1.5, 1.5, 1.5))]
    spec = {"name": "col", "transform": "col", "center": (0.01, 0.02, 0.03),
            "capsule": {"radius": 0.04, "end_radius": 0.02, "length": 0.3, "direction": "z",
                        "reverse": True, "aligned_on_center": False}}
    s, h = chain_system(bones=3, length=0.3, extra_bones=extra, collider_specs=[spec],
                        collision_mode="point")
    run(s, 2)
    ws = s.colliders.world_shapes(h)
    cs = s.collider_state
    np.testing.assert_allclose(cs.start_new[0], ws.start[0], atol=1e-12)
    np.testing.assert_allclose(cs.end_new[0], ws.end[0], atol=1e-12)
    assert cs.radius_start[0] == pytest.approx(ws.radius[0])
    assert cs.radius_end[0] == pytest.approx(ws.end_radius[0])


def test_edge_mode_catches_a_thin_capsule_that_point_mode_misses():
    # a 5 mm capsule along X, on the arc swept by the middle of the edge between particles
    # 2 (0.25 m from the root) and 3 (0.375 m): the particles pass 6 cm away from it
    a = math.radians(40.0)
    rr = 0.3125
    where = (0.0, 1.0 - rr * math.sin(a), -rr * math.cos(a))
    shape = {"capsule": {"radius": 0.005, "length": 0.6, "direction": "x"}}
    s_point, h, point = swing_onto(shape, where, mode="point", frames=270)
    s_edge, _, edge = swing_onto(shape, where, mode="edge", frames=270)
    ws = s_edge.colliders.world_shapes(h)

    def segment_clearance(traj):
        # closest approach of the 2-3 edge to the capsule axis at the end of every step
        a2, a3 = traj[:, 2], traj[:, 3]
        best = np.full(len(traj), np.inf)
        for u in np.linspace(0.0, 1.0, 41):
            p = a2 + (a3 - a2) * u
            best = np.minimum(best, capsule_distance(p, ws.start[0], ws.end[0], 0.005, 0.005))
        return best

    # point mode: the edge passes through the capsule (the tail ends up hanging below it)
    assert segment_clearance(point).min() < 0.0
    assert point[-1, 4, 1] < where[1] - 0.1
    # edge mode: the edge never crosses the capsule and the tail drapes over it
    assert segment_clearance(edge).min() > -0.1 * PARTICLE_RADIUS
    assert edge[-1, 3, 2] < where[2] and edge[-1, 2, 1] > where[1] - 0.1


def test_edge_mode_friction_is_quantised_to_zero_or_one_as_in_magicacloth2():
    # The fixed-point max of §0.2 casts to an integer before scaling, so an edge records
    # friction 1 when a collider pushed it and 0 otherwise (Appendix 2.5); D.10 then decays it
    # by 0.6 per step: every friction value is 0 or a power of 0.6.
    a = math.radians(40.0)
    rr = 0.3125
    where = (0.0, 1.0 - rr * math.sin(a), -rr * math.cos(a))
    s, h = chain_system(bones=5, length=0.5, direction=(0.0, 0.0, -1.0),
                        extra_bones=[BoneSpec("col", None, where)],
                        collider_specs=[{"name": "col", "transform": "col",
                                         "capsule": {"radius": 0.005, "length": 0.6, "direction": "x"}}],
                        collision_mode="edge")
    seen = set()
    for _ in range(200):
        run(s, 1, dt=1.0 / 90.0)
        for f in s.particles.friction:
            if f > 0.0:
                k = math.log(f) / math.log(0.6)
                assert abs(k - round(k)) < 1e-9
                seen.add(round(k))
    assert 1 in seen                     # contact happened (friction 1 then x0.6)
