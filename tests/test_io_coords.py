"""glTF/BVH right-handed → Unity left-handed conversion (magica_py.io.coords)."""
import json
from pathlib import Path

import numpy as np
import pytest

from magica_py.io import coords
from magica_py.io.gltf import load_gltf
from magica_py.io.quat import qaxis_angle, qnormalize, qto_matrix
from magica_py.scene.hierarchy import TransformHierarchy

DATA = Path(__file__).parents[1].parent / "shared" / "data"
needs_data = pytest.mark.skipif(not DATA.is_dir(), reason=f"shared test data folder {DATA} is absent")


def _write_gltf(path: Path, nodes, roots):
    path.write_text(json.dumps({"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": roots}], "nodes": nodes}))
    return path


def test_known_point_lands_mirrored_in_x(tmp_path):
    # glTF: parent at (1, 2, 3) turned +90 deg about +Y (right-handed: +Z goes to +X),
    # child one unit along the parent's +Z: world (2, 2, 3). Unity mirrors X: (-2, 2, 3).
    s = np.sqrt(0.5)
    f = _write_gltf(tmp_path / "p.gltf", [
        {"name": "parent", "translation": [1, 2, 3], "rotation": [0, s, 0, s], "children": [1]},
        {"name": "child", "translation": [0, 0, 1]},
    ], [0])
    h = TransformHierarchy(load_gltf(f).bones)
    assert np.allclose(h.world_position[h.index("child")], [-2.0, 2.0, 3.0], atol=1e-12)
    assert np.allclose(h.local_rotation[h.index("parent")], [0.0, -s, 0.0, s], atol=1e-12)


def test_vrm0_mirror_z_puts_the_known_point_at_minus_z(tmp_path):
    f = _write_gltf(tmp_path / "p.gltf", [{"name": "a", "translation": [1, 2, 3], "children": [1]},
                                          {"name": "b", "translation": [0, 0, -1]}], [0])
    h = TransformHierarchy(load_gltf(f, mirror_axis="z").bones)
    assert np.allclose(h.world_position[h.index("b")], [1.0, 2.0, -2.0])


@pytest.mark.parametrize("axis", ["x", "z"])
def test_quaternion_rule_equals_matrix_conjugation_by_the_mirror(axis):
    rng = np.random.default_rng(3)
    q = qnormalize(rng.normal(size=(50, 4)))
    m = np.diag([-1.0, 1.0, 1.0]) if axis == "x" else np.diag([1.0, 1.0, -1.0])
    expected = m @ qto_matrix(q) @ m
    assert np.allclose(qto_matrix(coords.rotation_to_unity(q, axis)), expected, atol=1e-12)
    a = np.eye(4)
    a[:3, :3] = qto_matrix(q[0]) * 2.0
    a[:3, 3] = [1, 2, 3]
    conv = coords.matrix_to_unity(a, axis)
    assert np.allclose(conv[:3, :3], m @ a[:3, :3] @ m) and np.allclose(conv[:3, 3], m @ a[:3, 3])


@pytest.mark.parametrize("axis", ["x", "z"])
def test_converting_every_local_pose_converts_the_world_poses(tmp_path, axis):
    rng = np.random.default_rng(7)
    nodes = []
    for i in range(6):
        nodes.append({"name": f"n{i}", "translation": list(rng.normal(size=3)),
                      "rotation": list(qnormalize(rng.normal(size=4))), "scale": [1.5, 1.5, 1.5],
                      **({"children": [i + 1]} if i < 5 else {})})
    f = _write_gltf(tmp_path / "chain.gltf", nodes, [0])
    h = TransformHierarchy(load_gltf(f, mirror_axis=axis).bones)
    # independent right-handed forward kinematics in the file's axes, then the mirror
    world = np.eye(4)
    for i, n in enumerate(nodes):
        local = np.eye(4)
        local[:3, :3] = qto_matrix(np.array(n["rotation"])) * 1.5
        local[:3, 3] = n["translation"]
        world = world @ local
        assert np.allclose(h.local_to_world[h.index(f"n{i}")], coords.matrix_to_unity(world, axis), atol=1e-9)


def test_axis_angle_helper_turns_x_to_y_about_z():
    q = qaxis_angle([0.0, 0.0, 1.0], np.pi / 2)
    assert np.allclose(qto_matrix(q) @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])


@needs_data
def test_vrm0_avatar_faces_plus_z_with_its_left_at_minus_x():
    from magica_py.io.vrm import load_vrm
    with pytest.warns(UserWarning):
        avatar = load_vrm(DATA / "vrm" / "Godette_vrm_v4.vrm")
    h = TransformHierarchy(avatar.bones)
    foot, toes = h.world_position[h.index("foot.l_Armature")], h.world_position[h.index("toes.l_Armature")]
    assert foot[0] < -0.1                      # Unity: a character facing +Z has its left at -X
    assert toes[2] - foot[2] > 0.05            # toes point forward (+Z)
    hand = h.world_position[h.index(avatar.humanoid["leftHand"])]
    assert hand[0] < -0.3
