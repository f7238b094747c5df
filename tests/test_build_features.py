"""What gets built for which parameters ("model only what a scene needs"), curve tables, frames,
read-only arrays and ``describe``."""
from __future__ import annotations

import math

import numpy as np
import pytest

from magica_py.build import build_cloth, describe
from magica_py.build.proxy import FLIP_NORMAL
from magica_py.kernels.math3d import q_mul, rot_from_normal_tangent
from magica_py.params import resolve_parameters
from magica_py.scene import rigs
from magica_py.scene.hierarchy import BoneSpec, TransformHierarchy
from test_build_rigs import SQUARE, Spec, chain_rig, skirt_spec, strands_rig


def ring(strands, radius=0.2):
    return [(radius * math.sin(a), 0.0, radius * math.cos(a))
            for a in np.linspace(0.0, 2.0 * math.pi, strands, endpoint=False)]


def test_line_mode_skips_bending_and_volume_and_builds_no_pairs():
    h = chain_rig()
    m = build_cloth(h, Spec("tail", (h.index("c0"),)))
    assert m.features["bending"] is False and m.features["volume"] is False
    assert m.skipped["bending"] == "no triangles (line mode or no mesh)"
    assert m.bend_vertices.shape == (0, 4) and m.volume_vertices.shape == (0, 4)
    assert m.features["distance"] and m.features["tether"] and m.features["lines"]
    assert not m.features["triangles"]


def test_bending_stiffness_zero_skips_bending_data_in_mesh_modes():
    h = strands_rig(SQUARE)
    params = resolve_parameters(None, {"triangle_bending": {"stiffness": 0.0}})
    m = build_cloth(h, skirt_spec(h, "sequential_loop_mesh", parameters=params))
    assert m.skipped["bending"] == "triangle_bending.stiffness is 0"
    assert len(m.bend_vertices) == 0
    m2 = build_cloth(h, skirt_spec(h, "sequential_loop_mesh"))
    assert m2.features["bending"] and len(m2.bend_vertices) == 20


def test_bending_pairs_of_a_flat_quad_strip_are_flat_and_volume_needs_a_fold():
    h = strands_rig([(0.1 * k, 0.0, 0.0) for k in range(3)])
    m = build_cloth(h, skirt_spec(h, "sequential_non_loop_mesh", strands=3))
    assert len(m.bend_vertices) > 0
    np.testing.assert_allclose(m.bend_rest_angle, 0.0, atol=1e-7)
    assert m.features["volume"] is False and "90" in m.skipped["volume"]
    # square tube: the 90° folds between faces register volume pairs with |V0| > 0
    h = strands_rig(SQUARE)
    m = build_cloth(h, skirt_spec(h, "sequential_loop_mesh"))
    assert len(m.volume_vertices) == 8
    folded = np.degrees(m.bend_rest_angle) > 45
    np.testing.assert_allclose(np.degrees(m.bend_rest_angle[folded]), 90.0, atol=1e-6)
    assert (np.abs(m.volume_rest) > 0).all()
    # rest volume: 1000/6 * |det| of the four world points (one of the tetrahedra by hand)
    v = m.volume_vertices[0]
    P = m.local_position  # component at the origin, identity: world = cloth-local
    hand = 1000.0 / 6.0 * np.dot(np.cross(P[v[1]] - P[v[0]], P[v[2]] - P[v[0]]), P[v[3]] - P[v[0]])
    assert m.volume_rest[0] == pytest.approx(hand, rel=1e-12)


def test_motion_angle_and_collision_features_follow_the_parameters():
    h = chain_rig()
    root = (h.index("c0"),)
    m = build_cloth(h, Spec("tail", root, collision_mode="none"))
    assert m.skipped["motion"] == "motion.use_max_distance and motion.use_backstop are off"
    assert m.features["angle_restoration"] and not m.features["angle_limit"]
    assert m.skipped["collision_point"] == "collision_mode is none"
    params = resolve_parameters(None, {"motion": {"use_max_distance": True},
                                       "angle_restoration": {"use": False}, "angle_limit": {"use": True}})
    m = build_cloth(h, Spec("tail", root, parameters=params, colliders=(0, 2), collision_mode="point"))
    assert m.features["motion"] and m.features["angle_limit"]
    assert m.skipped["angle_restoration"] == "angle_restoration.use is off"
    assert m.features["collision_point"] and m.collision_mode == "point"
    assert m.collider_index.tolist() == [0, 2] and m.collider_slot_capacity == 8
    m = build_cloth(h, Spec("tail", root, colliders=(1,), collision_mode="edge"))
    assert m.features["collision_edge"] and not m.features["collision_point"]
    m = build_cloth(h, Spec("tail", root, colliders=(), collision_mode="point"))
    assert m.skipped["collision_point"] == "no colliders" and m.collider_index.shape == (0,)
    params = resolve_parameters(None, {"motion": {"use_backstop": True}})
    assert build_cloth(h, Spec("tail", root, parameters=params)).features["motion"]


def test_curve_tables_are_the_parameters_16_samples():
    h = chain_rig()
    params = resolve_parameters(None, {"radius": 0.05})
    m = build_cloth(h, Spec("tail", (h.index("c0"),), parameters=params))
    np.testing.assert_array_equal(m.curves["radius"], np.full(16, 0.05))
    np.testing.assert_array_equal(m.curves["angle_restoration.stiffness"],
                                  params["angle_restoration.stiffness"].samples)
    # plain mapping without the keys: reference defaults (docs/solver.md §F.1)
    d = build_cloth(h, Spec("tail", (h.index("c0"),))).curves
    np.testing.assert_allclose(d["angle_limit.limit_angle"], 60.0 * np.arange(16) / 15)
    np.testing.assert_allclose(d["angle_restoration.stiffness"], 0.2 * (1.0 - 0.8 * np.arange(16) / 15))
    np.testing.assert_allclose(d["damping"], 0.05)
    assert all(not a.flags.writeable for a in d.values())


def test_every_model_array_is_read_only():
    h = strands_rig(SQUARE)
    m = build_cloth(h, skirt_spec(h, "sequential_loop_mesh"))
    arrays = [v for v in vars(m).values() if isinstance(v, np.ndarray)]
    assert len(arrays) > 50
    assert all(not a.flags.writeable for a in arrays)
    with pytest.raises(ValueError):
        m.local_position[0, 0] = 1.0
    with pytest.raises(TypeError):
        m.features["bending"] = False


def test_mesh_vertex_frames_are_orthonormal_and_bind_rotation_inverts_them():
    h = TransformHierarchy([BoneSpec("hips")] + rigs.skirt("sk", "hips", strands=12, bones=4))
    m = build_cloth(h, Spec("sk", tuple(h.index(f"sk_{s}_0") for s in range(12)), "sequential_loop_mesh"))
    n, t = m.local_normal, m.local_tangent
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(t, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose((n * t).sum(axis=1), 0.0, atol=1e-12)
    for i in range(m.particle_count):
        q = q_mul(tuple(m.bind_rotation[i]), rot_from_normal_tangent(tuple(n[i]), tuple(t[i])))
        assert abs(abs(q[3]) - 1.0) < 1e-12
    # the flood fill gives the whole ring one orientation (fold 30° < 80°), and the
    # closed/open vote turns it outward; vertex normals follow
    p = m.local_position
    tri = m.triangles
    normal = np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]])
    radial = p[tri].mean(axis=1) * [1, 0, 1]
    assert ((normal * radial).sum(axis=1) > 0).all()
    assert ((n * p * [1, 0, 1]).sum(axis=1) > 0).all()
    # each shared edge is walked in opposite directions by its two triangles (consistent winding)
    directed = {(int(a), int(b)) for t3 in tri for a, b in ((t3[0], t3[1]), (t3[1], t3[2]), (t3[2], t3[0]))}
    assert len(directed) == 3 * len(tri)
    assert not (m.vertex_triangle_flip & FLIP_NORMAL).any()


def test_line_mode_vertex_to_transform_rotation_is_identity_for_rotated_bones():
    h = TransformHierarchy([BoneSpec("hips")] + rigs.chain("tail", "hips", bones=5, length=0.4,
                                                           direction=(0.0, 0.0, -1.0), curl=15.0))
    m = build_cloth(h, Spec("tail", (h.index("tail_0"),)))
    w = np.abs(m.vertex_to_transform_rotation[:, 3])
    np.testing.assert_allclose(w, 1.0, atol=1e-12)
    # rest rotation relative to the parent is the 15° curl of every bone after the first two
    angle = np.degrees(2 * np.arccos(np.clip(np.abs(m.baseline_local_rotation[2:, 3]), 0, 1)))
    np.testing.assert_allclose(angle, 15.0, atol=1e-9)


def test_describe_lists_counts_built_and_skipped_features():
    h = strands_rig(SQUARE)
    lines = describe(build_cloth(h, skirt_spec(h, "sequential_loop_mesh")))
    text = "\n".join(lines)
    assert lines[0] == "cloth 'skirt': 12 particles (4 fixed, 8 move, 0 invalid), mode sequential_loop_mesh, 4 roots"
    assert "28 edges, 0 lines, 16 triangles, 4 baselines, 4 center-fixed" in text
    assert "built   bending: 20 pairs" in text
    assert "skipped motion: motion.use_max_distance and motion.use_backstop are off" in text


def test_bone_attribute_overrides_make_invalid_and_extra_fixed_bones():
    h = chain_rig(bones=4)
    m = build_cloth(h, Spec("tail", (h.index("c0"),), bone_attributes={h.index("c1"): "fixed",
                                                                        h.index("c3"): "invalid"}))
    assert m.attribute.tolist() == [1, 1, 2, 0]
    assert m.root_index.tolist() == [-1, -1, 1, -1]
    # baseline starts at the fixed c1, the invalid tip is not followed
    assert m.baseline_data.tolist() == [1, 2]
    assert m.center_fixed.tolist() == [1, 3]  # c1 has a Move neighbour; c3 is not Move and touches c2


def test_cloth_local_pose_equals_the_world_to_local_transform_of_the_reference():
    # §B.2: localPos = W2L·P, localNormal = normalize(W2L·(R·up)); our chained pose must agree
    rng = np.random.default_rng(11)

    def q(v):
        v = np.asarray(v, dtype=float)
        return tuple(v / np.linalg.norm(v))

    bones = [BoneSpec("root", None, (0.3, 1.2, -0.4), q(rng.normal(size=4))),
             BoneSpec("body", "root", (0.1, 0.2, 0.3), q(rng.normal(size=4)), (1.5, 0.7, 1.1))]
    for s in range(3):
        parent = "body"
        for k in range(4):
            bones.append(BoneSpec(f"s{s}_{k}", parent, tuple(rng.normal(0, 0.1, 3)), q(rng.normal(size=4))))
            parent = f"s{s}_{k}"
    h = TransformHierarchy(bones)
    m = build_cloth(h, Spec("c", tuple(h.index(f"s{s}_0") for s in range(3))), cache=None)
    assert m.component_transform == h.index("body")
    w2l = m.init_render_world_to_local
    world = h.world_position[m.transform_index]
    np.testing.assert_allclose(m.local_position, world @ w2l[:3, :3].T + w2l[:3, 3], atol=1e-12)
    for i, t in enumerate(m.transform_index):
        up = h.transform_direction(t, (0, 1, 0))
        fw = h.transform_direction(t, (0, 0, 1))
        n = w2l[:3, :3] @ up
        f = w2l[:3, :3] @ fw
        np.testing.assert_allclose(m.local_normal[i], n / np.linalg.norm(n), atol=1e-12)
        np.testing.assert_allclose(m.local_tangent[i], f / np.linalg.norm(f), atol=1e-12)
