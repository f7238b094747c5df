"""Bad rigs get a clear ``BuildError`` naming the cloth and the bones, or a documented handling
that never produces a NaN (issue 3)."""
from __future__ import annotations

import numpy as np
import pytest

import magica_py.build as build
from magica_py.build import BuildError, build_cloth
from magica_py.build.proxy import MOVE, ZERO_DISTANCE
from magica_py.scene.hierarchy import BoneSpec, TransformHierarchy
from test_build_rigs import SQUARE, Spec, chain_rig, skirt_spec, strands_rig


def _float_arrays(model):
    for name in ("local_position", "local_normal", "local_tangent", "bind_rotation",
                 "vertex_to_transform_rotation", "skin_bind_pose", "baseline_local_position",
                 "baseline_local_rotation", "depth", "distance_rest", "bend_rest_angle", "volume_rest",
                 "root_length", "vertex_uv", "triangle_uv"):
        yield name, getattr(model, name)


def test_missing_root_bone_names_the_cloth_and_the_list_entry():
    h = chain_rig()
    with pytest.raises(BuildError, match=r"cloth 'tail': root_bones\[1\] = 99 is not a transform"):
        build_cloth(h, Spec("tail", (h.index("c0"), 99)))
    with pytest.raises(BuildError, match=r"root_bones is empty"):
        build_cloth(h, Spec("tail", ()))


def test_duplicate_root_bone_is_rejected():
    h = chain_rig()
    with pytest.raises(BuildError, match=r"root bone 'c0' is listed twice \(root_bones\[0\] and root_bones\[1\]\)"):
        build_cloth(h, Spec("tail", (h.index("c0"), h.index("c0"))))


def test_bone_reached_from_two_roots_is_rejected():
    h = chain_rig()
    with pytest.raises(BuildError, match=r"root bone 'c1' lies below root bone 'c0'"):
        build_cloth(h, Spec("tail", (h.index("c0"), h.index("c1"))))


def test_root_without_children_is_rejected():
    h = chain_rig()
    with pytest.raises(BuildError, match=r"root bone 'c2' has no child bones"):
        build_cloth(h, Spec("tail", (h.index("c2"),)))


def test_unknown_connection_mode_and_bone_attribute_are_rejected():
    h = chain_rig()
    with pytest.raises(BuildError, match=r"connection_mode 'mesh'"):
        build_cloth(h, Spec("tail", (h.index("c0"),), "mesh"))
    with pytest.raises(BuildError, match=r"bone_attributes names transform 0"):
        build_cloth(h, Spec("tail", (h.index("c0"),), bone_attributes={h.index("body"): "fixed"}))
    with pytest.raises(BuildError, match=r"bone_attributes\[2\] = 'frozen'"):
        build_cloth(h, Spec("tail", (h.index("c0"),), bone_attributes={h.index("c1"): "frozen"}))


@pytest.mark.parametrize("offset", [(0.0, -1e300, 0.0), (0.0, 2e9, 0.0), (float("nan"), 0.0, 0.0)])
def test_a_bone_too_far_from_the_origin_is_refused_before_its_squares_overflow(offset):
    """A bone beyond POSITION_LIMIT (or at a non-finite place) is a BuildError naming it and
    where it is, not numpy overflow warnings and NaN depths that crash a sink later."""
    h = TransformHierarchy([BoneSpec("body", None, (0.0, 1.0, 0.0)), BoneSpec("c0", "body", (0.0, 0.0, 0.0)),
                            BoneSpec("c1", "c0", (0.0, -0.1, 0.0)), BoneSpec("c2", "c1", offset)])
    with np.errstate(all="raise"):   # refused before any arithmetic on the huge values
        with pytest.raises(BuildError, match=r"cloth 'tail': bone 'c2' is at .* m: expected finite positions "
                                             r"within 1e\+09 m of the origin"):
            build_cloth(h, Spec("tail", (h.index("c0"),)), cache=None)


def test_a_bone_at_the_position_limit_still_builds():
    h = chain_rig()
    far = TransformHierarchy([BoneSpec("body", None, (0.0, 1.0, 0.0)), BoneSpec("c0", "body", (9.9e8, 0.0, 0.0)),
                              BoneSpec("c1", "c0", (0.0, -0.1, 0.0)), BoneSpec("c2", "c1", (0.0, -0.1, 0.0))])
    model = build_cloth(far, Spec("tail", (far.index("c0"),)), cache=None)
    assert all(np.all(np.isfinite(a)) for _, a in _float_arrays(model))
    assert model.particle_count == build_cloth(h, Spec("tail", (h.index("c0"),)), cache=None).particle_count


def test_zero_length_bone_gets_zero_distance_flag_and_a_zero_rest_link_without_nan():
    h = TransformHierarchy([
        BoneSpec("body"),
        BoneSpec("c0", "body", (0.0, 1.0, 0.0)),
        BoneSpec("c1", "c0", (0.0, -0.1, 0.0)),
        BoneSpec("c2", "c1", (0.0, 0.0, 0.0)),   # on top of its parent
        BoneSpec("c3", "c2", (0.0, -0.1, 0.0)),
    ])
    m = build_cloth(h, Spec("tail", (h.index("c0"),)))
    assert m.bone_names == ("c0", "c1", "c2", "c3")
    assert (m.attribute[2] & ZERO_DISTANCE) and not (m.attribute[3] & ZERO_DISTANCE)
    rest = dict(zip(zip(np.repeat(np.arange(4), m.distance_count).tolist(), m.distance_target.tolist()),
                    m.distance_rest.tolist()))
    assert rest[(2, 1)] == 0.0 and rest[(1, 2)] == 0.0
    assert rest[(3, 2)] == pytest.approx(0.1)
    np.testing.assert_allclose(m.depth, [0.0, 0.5, 0.5, 1.0])
    for name, a in _float_arrays(m):
        assert np.isfinite(a).all(), name


@pytest.mark.parametrize("mode", ["automatic_mesh", "sequential_loop_mesh"])
def test_coincident_strands_build_without_nan_or_degenerate_triangles(mode):
    # two strands share every position (the reference warns this breaks baselines)
    h = strands_rig([SQUARE[0], SQUARE[0], SQUARE[1], SQUARE[2]])
    m = build_cloth(h, skirt_spec(h, mode))
    for name, a in _float_arrays(m):
        assert np.isfinite(a).all(), name
    p = m.local_position
    t = m.triangles
    area = np.linalg.norm(np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]]), axis=1)
    assert (area > 1e-9).all()
    # every coincident pair that got linked is a zero-distance link
    src = np.repeat(np.arange(m.particle_count), m.distance_count)
    d = np.linalg.norm(p[src] - p[m.distance_target], axis=1)
    assert (m.distance_rest[d < 1e-8] == 0.0).all()
    assert np.count_nonzero(m.attribute & MOVE) == 8


def test_more_bones_than_the_reference_limit_is_rejected():
    bones = [BoneSpec("body"), BoneSpec("root", "body")]
    bones += [BoneSpec(f"b{k}", "root", (0.0, -0.01, 0.0)) for k in range(32767)]
    h = TransformHierarchy(bones)
    with pytest.raises(BuildError, match=r"32768 bones \(proxy vertices\) exceed the reference limit of 32767"):
        build_cloth(h, Spec("huge", (h.index("root"),)))


@pytest.mark.parametrize("what, limit", [("triangles", 15), ("edges", 27)])
def test_triangle_and_edge_limits_are_checked(monkeypatch, what, limit):
    # the 4 x 3 loop skirt has 16 triangles and 28 edges: lower the limit just below
    monkeypatch.setattr(build, "MAX_PROXY_COUNT", limit)
    h = strands_rig(SQUARE)
    if what == "edges":  # vertices (12) and triangles (16) pass, edges (28) fail
        monkeypatch.setattr(build, "MAX_PROXY_COUNT", 27)
    with pytest.raises(BuildError, match=rf"cloth 'skirt': \d+ {what} exceed the reference limit of {limit} "
                                         r"\(roots \['s0_0', 's1_0', 's2_0', 's3_0'\]\)"):
        build_cloth(h, skirt_spec(h, "sequential_loop_mesh"), cache=None)


def test_more_than_127_strands_on_one_level_is_rejected_in_mesh_modes():
    ring = [(np.sin(a), 0.0, np.cos(a)) for a in np.linspace(0, 2 * np.pi, 128, endpoint=False)]
    h = strands_rig(ring, bones=2)
    with pytest.raises(BuildError, match=r"128 bones share hierarchy level 0"):
        build_cloth(h, skirt_spec(h, "sequential_loop_mesh", strands=128))
    m = build_cloth(h, skirt_spec(h, "line", strands=128))  # line mode has no such limit
    assert m.particle_count == 256


def test_zero_scale_bone_is_rejected():
    h = TransformHierarchy([BoneSpec("body"), BoneSpec("c0", "body"),
                            BoneSpec("c1", "c0", (0, -0.1, 0), scale=(0.0, 1.0, 1.0))])
    with pytest.raises(BuildError, match=r"bones \['c1'\] have a zero scale"):
        build_cloth(h, Spec("tail", (h.index("c0"),)))
