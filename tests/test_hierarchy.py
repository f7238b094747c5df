"""Transform hierarchy (magica_py/scene/hierarchy.py) against independent numpy 4x4 matrices."""
from __future__ import annotations

import math

import numpy as np
import pytest

from magica_py.kernels.math3d import q_from_euler_degrees
from magica_py.scene.hierarchy import BoneSpec, HierarchyError, TransformHierarchy


# ----------------------------------------------------------------------------- numpy oracle
def rodrigues(axis, angle):
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) * math.cos(angle) + math.sin(angle) * kx + (1 - math.cos(angle)) * np.outer(k, k)


def quat_of(axis, angle):
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    return tuple(np.append(k * math.sin(angle / 2), math.cos(angle / 2)))


def axis_angle_of_quat(q):
    q = np.asarray(q, float)
    angle = 2 * math.acos(np.clip(q[3], -1, 1))
    s = math.sqrt(max(1 - q[3] ** 2, 0.0))
    axis = q[:3] / s if s > 1e-12 else np.array([1.0, 0.0, 0.0])
    return axis, angle


def rot_matrix(q):
    axis, angle = axis_angle_of_quat(q)
    return rodrigues(axis, angle)


def trs(p, q, s):
    m = np.eye(4)
    m[:3, :3] = rot_matrix(q) @ np.diag(s)
    m[:3, 3] = p
    return m


def oracle(bones):
    """World matrices and world rotation matrices by name, by explicit recursion."""
    by_name = {b.name: b for b in bones}
    world, world_rot = {}, {}

    def solve(name):
        if name in world:
            return
        b = by_name[name]
        local = trs(b.position, b.rotation, b.scale)
        if b.parent is None:
            world[name], world_rot[name] = local, rot_matrix(b.rotation)
        else:
            solve(b.parent)
            world[name] = world[b.parent] @ local
            world_rot[name] = world_rot[b.parent] @ rot_matrix(b.rotation)

    for b in bones:
        solve(b.name)
    return world, world_rot


def random_bones(rng, n, nonuniform=True):
    names = [f"n{i}" for i in range(n)]
    bones = []
    for i in range(n):
        parent = None if i == 0 or rng.random() < 0.1 else names[int(rng.integers(0, i))]
        axis = rng.normal(size=3)
        scale = tuple(rng.uniform(0.5, 2.0, size=3)) if nonuniform else (1.0, 1.0, 1.0)
        bones.append(BoneSpec(names[i], parent, tuple(rng.normal(size=3)),
                              quat_of(axis, rng.uniform(-math.pi, math.pi)), scale))
    order = rng.permutation(n)  # children may come before their parents in the input
    return [bones[i] for i in order]


def check_against_oracle(h, bones, atol):
    world, world_rot = oracle(bones)
    for name, m in world.items():
        i = h.index(name)
        np.testing.assert_allclose(h.local_to_world[i], m, atol=atol, err_msg=name)
        np.testing.assert_allclose(h.world_position[i], m[:3, 3], atol=atol, err_msg=name)
        np.testing.assert_allclose(rot_matrix(h.world_rotation[i]), world_rot[name], atol=atol,
                                   err_msg=name)
        lossy = np.diag(world_rot[name].T @ m[:3, :3])
        np.testing.assert_allclose(h.lossy_scale[i], lossy, atol=atol, err_msg=name)


# ----------------------------------------------------------------------------- tests
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_hierarchies_with_nonuniform_scale_match_numpy_matrices(seed):
    rng = np.random.default_rng(seed)
    bones = random_bones(rng, 60)
    h = TransformHierarchy(bones)
    check_against_oracle(h, bones, atol=1e-9)


def test_parents_come_before_children_and_names_map_to_indices():
    rng = np.random.default_rng(5)
    bones = random_bones(rng, 40)
    h = TransformHierarchy(bones)
    for i in range(h.count):
        assert h.parent[i] < i
        assert h.index(h.names[i]) == i
    by_name = {b.name: b for b in bones}
    for i, name in enumerate(h.names):
        parent = by_name[name].parent
        assert (h.parent[i] == -1) if parent is None else (h.names[h.parent[i]] == parent)


def test_deep_chain_of_200_nodes_matches_numpy():
    rng = np.random.default_rng(7)
    bones = [BoneSpec("b0", None, (0.0, 0.0, 0.0))]
    for i in range(1, 200):
        bones.append(BoneSpec(f"b{i}", f"b{i - 1}", (0.0, 0.05, 0.0),
                              quat_of(rng.normal(size=3), rng.uniform(-0.2, 0.2)),
                              tuple(rng.uniform(0.98, 1.02, size=3))))
    h = TransformHierarchy(bones)
    check_against_oracle(h, bones, atol=1e-9)
    # an unscaled, straight chain ends exactly 199 * 0.05 above the root
    h2 = TransformHierarchy([BoneSpec("b0", None)] + [BoneSpec(f"b{i}", f"b{i - 1}", (0, 0.05, 0))
                                                        for i in range(1, 200)])
    np.testing.assert_allclose(h2.world_position[-1], (0, 199 * 0.05, 0), atol=1e-12)


def test_propagate_after_editing_local_poses():
    rng = np.random.default_rng(9)
    bones = random_bones(rng, 30)
    h = TransformHierarchy(bones)
    edited = []
    for b in bones:
        i = h.index(b.name)
        q = quat_of(rng.normal(size=3), rng.uniform(-3, 3))
        p = tuple(rng.normal(size=3))
        h.local_rotation[i] = q
        h.local_position[i] = p
        edited.append(BoneSpec(b.name, b.parent, p, q, b.scale))
    h.propagate()
    check_against_oracle(h, edited, atol=1e-9)


def test_set_world_pose_round_trips_under_nonuniform_parent_scale():
    rng = np.random.default_rng(11)
    bones = random_bones(rng, 25)
    h = TransformHierarchy(bones)
    for i in range(h.count):
        target_p = rng.normal(size=3)
        target_q = quat_of(rng.normal(size=3), rng.uniform(-3, 3))
        h.set_world_pose(i, target_p, target_q)
        np.testing.assert_allclose(h.world_position[i], target_p, atol=1e-9)
        np.testing.assert_allclose(rot_matrix(h.world_rotation[i]), rot_matrix(target_q), atol=1e-9)
    # position only keeps the world rotation
    before = h.world_rotation[3].copy()
    h.set_world_pose(3, position=(1.0, 2.0, 3.0))
    np.testing.assert_allclose(h.world_position[3], (1, 2, 3), atol=1e-9)
    np.testing.assert_allclose(rot_matrix(h.world_rotation[3]), rot_matrix(before), atol=1e-9)


def test_transform_point_inverse_and_direction():
    rng = np.random.default_rng(13)
    bones = random_bones(rng, 20)
    h = TransformHierarchy(bones)
    world, world_rot = oracle(bones)
    for b in bones:
        i = h.index(b.name)
        p, d = rng.normal(size=3), rng.normal(size=3)
        expected = world[b.name] @ np.append(p, 1.0)
        np.testing.assert_allclose(h.transform_point(i, p), expected[:3], atol=1e-9)
        np.testing.assert_allclose(h.inverse_transform_point(i, expected[:3]), p, atol=1e-8)
        np.testing.assert_allclose(h.transform_direction(i, d), world_rot[b.name] @ d, atol=1e-9)
        np.testing.assert_allclose(h.inverse_transform_direction(i, d), world_rot[b.name].T @ d,
                                   atol=1e-9)


def test_lossy_scale_of_a_rotated_nonuniform_parent():
    # parent scaled (2, 1, 1), child rotated 90 degrees about Z: the child's X axis lies along the
    # parent's Y axis, so its lossy scale is (1, 2, 1) times its own scale
    h = TransformHierarchy([
        BoneSpec("parent", None, (0, 0, 0), (0, 0, 0, 1), (2.0, 1.0, 1.0)),
        BoneSpec("child", "parent", (1, 0, 0), quat_of((0, 0, 1), math.pi / 2), (1.0, 3.0, 1.0)),
    ])
    np.testing.assert_allclose(h.lossy_scale[1], (1.0, 6.0, 1.0), atol=1e-12)
    np.testing.assert_allclose(h.world_position[1], (2.0, 0.0, 0.0), atol=1e-12)


def test_unity_euler_convention():
    q = q_from_euler_degrees(0.0, 90.0, 0.0)
    h = TransformHierarchy([BoneSpec("a", None, (0, 0, 0), q)])
    np.testing.assert_allclose(h.transform_direction(0, (1, 0, 0)), (0, 0, -1), atol=1e-15)
    np.testing.assert_allclose(h.transform_point(0, (0, 0, 1)), (1, 0, 0), atol=1e-15)


def test_restore_rest_pose_puts_back_only_the_listed_bones():
    h = TransformHierarchy([BoneSpec("a"), BoneSpec("b", "a", (0, 1, 0)), BoneSpec("c", "b", (0, 1, 0))])
    h.local_position[1:] = (5.0, 5.0, 5.0)
    h.local_rotation[1:] = quat_of((1, 0, 0), 0.5)
    h.restore_rest_pose(np.array([1], dtype=np.int32))
    np.testing.assert_array_equal(h.local_position[1], (0, 1, 0))
    np.testing.assert_array_equal(h.local_rotation[1], (0, 0, 0, 1))
    np.testing.assert_array_equal(h.local_position[2], (5, 5, 5))


def test_zero_rotation_is_rejected_with_a_clear_error():
    # a zero quaternion must never silently become NaN in the world pose
    with pytest.raises(HierarchyError, match="'a': rotation .* is not a valid quaternion"):
        TransformHierarchy([BoneSpec("a", None, (0, 0, 0), (0.0, 0.0, 0.0, 0.0))])


@pytest.mark.parametrize("bones, message", [
    ([BoneSpec("a"), BoneSpec("a")], "duplicate transform name 'a'"),
    ([BoneSpec("a"), BoneSpec("b", "ghost")], "parent 'ghost' does not exist"),
    ([BoneSpec("r"), BoneSpec("a", "b"), BoneSpec("b", "a")], r"cycle through \['a', 'b'\]"),
    ([BoneSpec("a", "a")], r"cycle through \['a'\]"),
])
def test_bad_hierarchies_raise_clear_errors(bones, message):
    with pytest.raises(HierarchyError, match=message):
        TransformHierarchy(bones)


def test_children_and_descendants_follow_sibling_order():
    h = TransformHierarchy([BoneSpec("r"), BoneSpec("x", "r"), BoneSpec("y", "r"),
                            BoneSpec("x1", "x"), BoneSpec("y1", "y")])
    assert [h.names[c] for c in h.children[h.index("r")]] == ["x", "y"]
    assert [h.names[i] for i in h.descendants(h.index("r"))] == ["r", "x", "x1", "y", "y1"]
    with pytest.raises(KeyError, match="no transform named 'z'"):
        h.index("z")
