"""ColliderSet construction and world shapes (docs/solver.md §G.2, §G.3) against hand-computed values."""
import numpy as np
import pytest

from magica_py.kernels.math3d import q_from_euler_degrees
from magica_py.scene.colliders import (
    CAPSULE,
    PLANE,
    SPHERE,
    ColliderSet,
    static_transform_bone,
    static_transform_name,
)
from magica_py.scene.hierarchy import BoneSpec, TransformHierarchy


def one(collider, position=(1.0, 2.0, 3.0), euler=(0.0, 0.0, 0.0), scale=(1.0, 1.0, 1.0)):
    """A hierarchy with a single node 'bone' and the collider attached to it."""
    h = TransformHierarchy([BoneSpec("bone", None, position, tuple(q_from_euler_degrees(*euler)),
                                     scale)])
    cs = ColliderSet.from_specs([dict(collider, name="c", transform="bone")], h)
    return cs, cs.world_shapes(h)


CAPSULE_Y = {"capsule": {"radius": 0.06, "end_radius": 0.05, "length": 0.4, "direction": "y"}}


# ----------------------------------------------------------------------------- spheres
def test_sphere_center_is_rotated_then_scaled_and_radius_uses_x_scale():
    _, w = one({"center": [0.1, 0, 0], "sphere": {"radius": 0.1}}, euler=(0, 90, 0),
               scale=(2, 2, 2))
    # Euler(0,90,0) * (0.1,0,0) = (0,0,-0.1); times 2
    np.testing.assert_allclose(w.position[0], (1, 2, 2.8), atol=1e-12)
    np.testing.assert_allclose(w.start[0], w.position[0])
    assert w.radius[0] == pytest.approx(0.2)


def test_non_uniform_scale_multiplies_in_world_axes_after_rotation():
    # the §G.2 approximation: (R center) * |S|, not R (center * S)
    _, w = one({"center": [0.1, 0, 0], "sphere": {"radius": 0.1}}, euler=(0, 90, 0),
               scale=(2, 3, 4))
    np.testing.assert_allclose(w.position[0], (1, 2, 3 - 0.4), atol=1e-12)
    assert w.radius[0] == pytest.approx(0.2)


def test_negative_scale_mirrors_the_center_offset_sign():
    _, w = one({"center": [0.1, 0.2, 0], "sphere": {"radius": 0.1}}, scale=(-2, 1, 1))
    # center * sign(S) = (-0.1, 0.2, 0); rotated (identity) then * |S| = (-0.2, 0.2, 0)
    np.testing.assert_allclose(w.position[0], (0.8, 2.2, 3), atol=1e-12)


# ----------------------------------------------------------------------------- capsules
def test_capsule_aligned_on_center_endpoints_inset_by_the_radii():
    _, w = one(CAPSULE_Y)
    # a = L/2 - rs = 0.14 toward +Y (start), b = L/2 - re = 0.15 toward -Y (end)
    np.testing.assert_allclose(w.start[0], (1, 2.14, 3), atol=1e-12)
    np.testing.assert_allclose(w.end[0], (1, 1.85, 3), atol=1e-12)
    assert (w.radius[0], w.end_radius[0]) == pytest.approx((0.06, 0.05))
    np.testing.assert_allclose(w.axis[0], (0, 1, 0), atol=1e-12)


def test_capsule_reverse_swaps_the_axis():
    _, w = one({"capsule": dict(CAPSULE_Y["capsule"], reverse=True)})
    np.testing.assert_allclose(w.start[0], (1, 1.86, 3), atol=1e-12)
    np.testing.assert_allclose(w.end[0], (1, 2.15, 3), atol=1e-12)


def test_capsule_start_aligned_starts_at_the_transform():
    _, w = one({"capsule": dict(CAPSULE_Y["capsule"], aligned_on_center=False)})
    # a = 0, b = L - rs - re = 0.29 toward -axis (Appendix 3 item 10)
    np.testing.assert_allclose(w.start[0], (1, 2, 3), atol=1e-12)
    np.testing.assert_allclose(w.end[0], (1, 2 - 0.29, 3), atol=1e-12)


def test_capsule_scaled_and_rotated_uses_the_axis_scale():
    # direction x; Euler(0,0,90) turns +X into +Y; scale 2 on X scales radii and length
    _, w = one({"center": [0, 0.1, 0], "capsule": {"radius": 0.05, "length": 0.3,
                                                   "direction": "x"}},
               euler=(0, 0, 90), scale=(2, 1, 1))
    # center (0,0.1,0) rotated -> (-0.1, 0, 0), times |S| (world axes) -> (-0.2, 0, 0)
    np.testing.assert_allclose(w.position[0], (0.8, 2, 3), atol=1e-12)
    assert w.radius[0] == pytest.approx(0.1) and w.end_radius[0] == pytest.approx(0.1)
    # L = 0.6, a = b = 0.3 - 0.1 = 0.2 along world +Y
    np.testing.assert_allclose(w.start[0], (0.8, 2.2, 3), atol=1e-12)
    np.testing.assert_allclose(w.end[0], (0.8, 1.8, 3), atol=1e-12)


def test_capsule_negative_axis_scale_flips_the_axis():
    _, w = one(CAPSULE_Y, scale=(1, -2, 1))
    # axis -Y, k = 2: a = 0.4 - 0.12 = 0.28 toward -Y, b = 0.4 - 0.10 = 0.30 toward +Y
    np.testing.assert_allclose(w.start[0], (1, 2 - 0.28, 3), atol=1e-12)
    np.testing.assert_allclose(w.end[0], (1, 2.30, 3), atol=1e-12)


def test_short_capsule_collapses_to_a_sphere_without_crossing():
    _, w = one({"capsule": {"radius": 0.1, "length": 0.1, "direction": "z"}})
    np.testing.assert_allclose(w.start[0], w.end[0], atol=1e-12)


# ----------------------------------------------------------------------------- planes
def test_plane_normal_is_rotated_local_up_with_the_sign_of_y_scale():
    _, w = one({"plane": {}}, euler=(90, 0, 0))
    np.testing.assert_allclose(w.normal[0], (0, 0, 1), atol=1e-12)
    np.testing.assert_allclose(w.position[0], (1, 2, 3))
    _, w = one({"plane": {}}, scale=(1, -1, 1))
    np.testing.assert_allclose(w.normal[0], (0, -1, 0), atol=1e-12)


def test_zero_scale_suspends_the_collider():
    _, w = one({"sphere": {"radius": 0.1}}, scale=(0, 1, 1))
    assert bool(w.suspended[0])
    assert w.radius[0] == pytest.approx(0.1 * 1e-6)
    _, w = one({"sphere": {"radius": 0.1}})
    assert not w.suspended[0]


def test_world_shapes_follow_a_rotated_scaled_parent():
    h = TransformHierarchy([
        BoneSpec("root", None, (0, 0, 0), tuple(q_from_euler_degrees(0, 90, 0)), (2, 2, 2)),
        BoneSpec("leg", "root", (0.5, 0, 0)),
    ])
    cs = ColliderSet.from_specs([{"name": "c", "transform": "leg", "center": [0, 0, 0.1],
                                  "capsule": {"radius": 0.05, "length": 0.3,
                                              "direction": "z", "aligned_on_center": False}}], h)
    w = cs.world_shapes(h)
    # leg at R(0.5,0,0)*2 = (0,0,-1); center R(0,0,0.1)*2 = (0.2,0,0)
    np.testing.assert_allclose(w.position[0], (0.2, 0, -1), atol=1e-12)
    # axis local +Z -> world +X, k = 2: L = 0.6, rs = re = 0.1, end at 0.4 toward -X
    np.testing.assert_allclose(w.end[0], (-0.2, 0, -1), atol=1e-12)


# ----------------------------------------------------------------------------- construction
def test_from_specs_fills_the_soa_and_subset_keeps_order():
    specs = [
        {"name": "head_col", "transform": "head", "center": [0, 0.05, 0], "sphere": {"radius": 0.1}},
        {"name": "thigh_l", "transform": "leg", "capsule": {"radius": 0.06, "end_radius": 0.05,
                                                            "length": 0.4, "direction": "z",
                                                            "reverse": True,
                                                            "aligned_on_center": False}},
        {"name": "ground", "position": [0, -1, 0], "plane": {}},
    ]
    bones = [BoneSpec("hips", None, (0, 1, 0)), BoneSpec("head", "hips", (0, 0.6, 0)),
             BoneSpec("leg", "hips", (0.1, 0, 0)), static_transform_bone(specs[2])]
    h = TransformHierarchy(bones)
    cs = ColliderSet.from_specs(specs, h)
    assert cs.count == 3 and cs.names == ("head_col", "thigh_l", "ground")
    assert cs.shape.tolist() == [SPHERE, CAPSULE, PLANE]
    assert cs.transform.tolist() == [h.index("head"), h.index("leg"),
                                     h.index(static_transform_name("ground"))]
    assert cs.direction[1] == 2 and cs.reverse_direction[1] and not cs.aligned_on_center[1]
    assert cs.end_radius.tolist() == [0.1, 0.05, 0.0]
    assert not cs.radius.flags.writeable
    w = cs.world_shapes(h)
    np.testing.assert_allclose(w.position[2], (0, -1, 0))
    np.testing.assert_allclose(w.position[0], (0, 1.65, 0))
    sub = cs.subset([2, 0])
    assert sub.names == ("ground", "head_col") and sub.shape.tolist() == [PLANE, SPHERE]
    assert cs.index("thigh_l") == 1
    # explicit static-transform hook
    cs2 = ColliderSet.from_specs([specs[2]], h, static_transforms={"ground": h.index("hips")})
    assert cs2.transform[0] == h.index("hips")


def test_capsule_defaults_follow_magica_menu_defaults():
    cs, _ = one({"capsule": {"radius": 0.05, "length": 0.3}})
    assert cs.end_radius[0] == 0.05 and cs.direction[0] == 1
    assert not cs.reverse_direction[0] and cs.aligned_on_center[0]


@pytest.mark.parametrize("spec, message", [
    ({"sphere": {"radius": -0.1}}, r"colliders\[0\]\.sphere\.radius: expected a number >= 0"),
    ({"capsule": {"radius": 0.1, "length": 0.3, "direction": "w"}}, r"direction: expected x, y or z"),
    ({"sphere": {"radius": 0.1}, "plane": {}}, "exactly one of"),
])
def test_bad_collider_entries_name_the_path(spec, message):
    h = TransformHierarchy([BoneSpec("bone")])
    with pytest.raises(ValueError, match=message):
        ColliderSet.from_specs([dict(spec, name="c", transform="bone")], h)
    with pytest.raises(ValueError, match=r"no transform named 'nope'"):
        ColliderSet.from_specs([{"name": "c", "transform": "nope", "plane": {}}], h)


def test_empty_set():
    cs = ColliderSet.empty()
    assert cs.count == 0
    assert cs.world_shapes(TransformHierarchy([BoneSpec("a")])).position.shape == (0, 3)
