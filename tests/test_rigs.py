"""Rig generators: geometry by hand, names, bone frames, placement and instancing."""
import fnmatch
import math

import numpy as np
import pytest

from magica_py.kernels.math3d import q_rotate
from magica_py.scene.hierarchy import BoneSpec, TransformHierarchy
from magica_py.scene.rigs import (
    chain,
    fan,
    instance_name,
    instance_offsets,
    instance_rig,
    part_bones,
    rig_bones,
    sheet,
    skirt,
)


def build(bones, parent_position=(0.0, 1.0, 0.0)):
    return TransformHierarchy([BoneSpec("hips", None, parent_position)] + bones)


def world(h, name):
    return h.world_position[h.index(name)]


def axis_of(h, name, local_axis):
    return np.asarray(q_rotate(tuple(h.world_rotation[h.index(name)]), local_axis))


# ----------------------------------------------------------------------------- chain
def test_straight_chain_positions_follow_direction_with_equal_segments():
    h = build(chain("tail", "hips", bones=5, length=0.8, direction=(0, 0, -2),
                    position=(0.0, 0.1, 0.0)))
    expected = [(0.0, 1.1, -0.2 * k) for k in range(5)]
    got = [world(h, f"tail_{k}") for k in range(5)]
    np.testing.assert_allclose(got, expected, atol=1e-12)


def test_chain_names_and_parents_form_one_strand():
    bones = chain("tail", "hips", bones=3, length=0.2)
    assert [b.name for b in bones] == ["tail_0", "tail_1", "tail_2"]
    assert [b.parent for b in bones] == ["hips", "tail_0", "tail_1"]


def test_chain_bone_y_points_to_child_and_z_is_orthogonal():
    h = build(chain("tail", "hips", bones=6, length=0.5, direction=(1, -1, 0.3), curl=17))
    for k in range(5):
        seg = world(h, f"tail_{k + 1}") - world(h, f"tail_{k}")
        y = axis_of(h, f"tail_{k}", (0.0, 1.0, 0.0))
        np.testing.assert_allclose(seg / np.linalg.norm(seg), y, atol=1e-12)
        assert abs(np.dot(y, axis_of(h, f"tail_{k}", (0.0, 0.0, 1.0)))) < 1e-12
        assert np.linalg.norm(seg) == pytest.approx(0.1, abs=1e-12)


def test_horizontal_chain_curls_upward_by_curl_per_bone():
    # curl 90 per bone on a tail pointing back: back, up, forward, down (a square of side 0.1)
    h = build(chain("tail", "hips", bones=5, length=0.4, direction=(0, 0, -1), curl=90))
    expected = [(0, 1, 0), (0, 1, -0.1), (0, 1.1, -0.1), (0, 1.1, 0), (0, 1, 0)]
    np.testing.assert_allclose([world(h, f"tail_{k}") for k in range(5)], expected, atol=1e-12)


def test_chain_curl_angle_between_segments_equals_curl():
    h = build(chain("tail", "hips", bones=4, length=0.3, direction=(0, -1, 0), curl=25))
    s0 = world(h, "tail_1") - world(h, "tail_0")
    s1 = world(h, "tail_2") - world(h, "tail_1")
    angle = math.degrees(math.acos(np.dot(s0, s1) / np.linalg.norm(s0) / np.linalg.norm(s1)))
    assert angle == pytest.approx(25.0, abs=1e-9)
    # a vertical (hanging) chain curls backward (-Z)
    assert s1[2] < 0.0


def test_chain_curl_axis_overrides_the_bend_plane():
    h = build(chain("tail", "hips", bones=2, length=0.1, direction=(0, -1, 0), curl=90,
                    curl_axis=(0, 0, 1)))
    # X = +Z, Y = -Y -> Z = X x Y = (0,0,1) x (0,-1,0) = (1, 0, 0): bends toward +X
    np.testing.assert_allclose(axis_of(h, "tail_1", (0.0, 1.0, 0.0)), (1, 0, 0), atol=1e-12)


def test_single_bone_chain_and_bad_arguments():
    assert len(chain("a", None, bones=1, length=0.0)) == 1
    with pytest.raises(ValueError, match="non-zero vector"):
        chain("a", None, bones=3, length=1.0, direction=(0, 0, 0))
    with pytest.raises(ValueError, match="bones >= 1"):
        chain("a", None, bones=0, length=1.0)


# ----------------------------------------------------------------------------- fan
def test_fan_spreads_strands_evenly_over_the_spread_angle():
    h = build(fan("hair", "hips", strands=5, bones=3, length=0.2, spread=120, tilt=0,
                  radius=0.08))
    centre = np.array([0.0, 1.0, 0.0])
    azimuths = []
    for s in range(5):
        root = world(h, f"hair_{s}_0") - centre
        assert np.linalg.norm(root) == pytest.approx(0.08, abs=1e-12)
        assert root[1] == pytest.approx(0.0, abs=1e-12)
        azimuths.append(math.degrees(math.atan2(root[0], -root[2])))  # from -Z (the back)
    # about the -Y axis from -Z: -60 .. +60 in 30 degree steps (sign by the right-hand rule)
    np.testing.assert_allclose(sorted(azimuths), [-60, -30, 0, 30, 60], atol=1e-9)
    assert azimuths[2] == pytest.approx(0.0, abs=1e-9)


def test_fan_strands_tilt_outward_by_tilt():
    h = build(fan("hair", "hips", strands=3, bones=2, length=0.1, spread=90, tilt=30,
                  radius=0.05))
    for s in range(3):
        root = world(h, f"hair_{s}_0")
        outward = root - np.array([0.0, 1.0, 0.0])
        outward /= np.linalg.norm(outward)
        d = world(h, f"hair_{s}_1") - root
        d /= np.linalg.norm(d)
        np.testing.assert_allclose(d, math.cos(math.radians(30)) * np.array([0, -1, 0])
                                   + math.sin(math.radians(30)) * outward, atol=1e-12)


def test_fan_with_full_spread_does_not_duplicate_the_seam():
    h = build(fan("hair", "hips", strands=4, bones=1, length=0.0, spread=360, tilt=0, radius=1))
    roots = np.array([world(h, f"hair_{s}_0") for s in range(4)])
    d = np.linalg.norm(roots[:, None] - roots[None], axis=-1)
    assert d[~np.eye(4, dtype=bool)].min() == pytest.approx(math.sqrt(2), abs=1e-12)


# ----------------------------------------------------------------------------- skirt
def test_skirt_ring_radius_flare_angle_and_strand_lengths():
    h = build(skirt("skirt", "hips", strands=12, bones=4, radius=0.15, length=0.4, flare=20))
    centre = np.array([0.0, 1.0, 0.0])
    for s in range(12):
        root = world(h, f"skirt_{s}_0")
        radial = root - centre
        assert radial[1] == pytest.approx(0.0, abs=1e-12)
        assert np.linalg.norm(radial) == pytest.approx(0.15, abs=1e-12)
        tip = world(h, f"skirt_{s}_3")
        d = tip - root
        assert np.linalg.norm(d) == pytest.approx(0.4, abs=1e-12)
        # angle from straight down, leaning outward in the radial plane
        angle = math.degrees(math.acos(-d[1] / np.linalg.norm(d)))
        assert angle == pytest.approx(20.0, abs=1e-9)
        assert np.dot(d, radial) > 0.0
        assert abs(np.dot(np.cross(radial, (0, 1, 0)), d)) < 1e-12
    # strand 0 at the front (+Z), strands 30 degrees apart
    np.testing.assert_allclose(world(h, "skirt_0_0"), (0, 1, 0.15), atol=1e-12)
    a0 = world(h, "skirt_0_0") - centre
    a1 = world(h, "skirt_1_0") - centre
    assert math.degrees(math.acos(np.dot(a0, a1) / 0.15 ** 2)) == pytest.approx(30.0, abs=1e-9)


def test_skirt_bone_frames_point_along_the_strand_and_outward():
    h = build(skirt("skirt", "hips", strands=6, bones=3, radius=0.2, length=0.3, flare=40))
    for s in range(6):
        radial = world(h, f"skirt_{s}_0") - np.array([0.0, 1.0, 0.0])
        z = axis_of(h, f"skirt_{s}_0", (0.0, 0.0, 1.0))
        assert np.dot(z, radial) > 0.0
        x = axis_of(h, f"skirt_{s}_0", (1.0, 0.0, 0.0))
        assert abs(np.dot(x, radial)) < 1e-12  # curl axis is tangent to the ring


def test_skirt_root_glob_selects_exactly_the_strand_roots():
    bones = skirt("skirt", "hips", strands=12, bones=4, radius=0.15, length=0.4, flare=20)
    assert len(bones) == 48
    roots = fnmatch.filter([b.name for b in bones], "skirt_*_0")
    assert roots == [f"skirt_{s}_0" for s in range(12)]
    assert all(b.parent == "hips" for b in bones if b.name in roots)
    h = build(bones)
    # every strand's other bones are descendants of its root
    for s in range(12):
        sub = {h.names[i] for i in h.descendants(h.index(f"skirt_{s}_0"))}
        assert sub == {f"skirt_{s}_{k}" for k in range(4)}


# ----------------------------------------------------------------------------- sheet
def test_sheet_strands_are_parallel_and_evenly_spaced_across_the_width():
    h = build(sheet("cape", "hips", strands=5, bones=3, length=0.6, width=0.4,
                    position=(0.0, 0.2, -0.1)))
    for s in range(5):
        np.testing.assert_allclose(world(h, f"cape_{s}_0"), (-0.2 + 0.1 * s, 1.2, -0.1), atol=1e-12)
        np.testing.assert_allclose(world(h, f"cape_{s}_2"), (-0.2 + 0.1 * s, 0.6, -0.1), atol=1e-12)
        # +Z = across x direction = X x (-Y) = -Z: away from the body for a cape on the back
        np.testing.assert_allclose(axis_of(h, f"cape_{s}_1", (0.0, 0.0, 1.0)), (0, 0, -1), atol=1e-12)
    with pytest.raises(ValueError, match="parallel"):
        sheet("cape", "hips", 2, 2, 0.1, 0.1, direction=(1, 0, 0), across=(2, 0, 0))


def test_part_bones_dispatches_on_the_single_key():
    bones = part_bones({"chain": {"name": "tail", "parent": "hips", "bones": 8, "length": 0.8,
                                  "direction": [0, 0, -1], "curl": 5}})
    assert len(bones) == 8 and bones[-1].name == "tail_7"
    with pytest.raises(ValueError, match="unknown rig part"):
        part_bones({"braid": {}})


# ----------------------------------------------------------------------------- rigs and crowds
def test_rig_placement_rotates_and_moves_the_roots():
    rig = {"name": "c", "position": [1, 0, 0], "euler": [0, 90, 0],
           "bones": [{"name": "hips", "position": [0, 1, 0]},
                     {"name": "head", "parent": "hips", "position": [0, 0.6, 0.1]}]}
    h = TransformHierarchy(rig_bones(rig))
    np.testing.assert_allclose(world(h, "hips"), (1, 1, 0), atol=1e-12)
    # Euler(0,90,0) turns +Z into +X
    np.testing.assert_allclose(world(h, "head"), (1.1, 1.6, 0), atol=1e-12)


def test_instance_offsets_fill_a_grid_row_by_row():
    off = instance_offsets(5, [1.5, 0, 0], columns=2)
    np.testing.assert_allclose(off, [[0, 0, 0], [1.5, 0, 0], [0, 0, 1.5], [1.5, 0, 1.5],
                                     [0, 0, 3]], atol=1e-12)
    np.testing.assert_allclose(instance_offsets(3, [1, 0, 0], 2, row_spacing=[0, 0, -4])[2],
                               (0, 0, -4))
    np.testing.assert_allclose(instance_offsets(3, [0, 0, 2]), [[0, 0, 0], [0, 0, 2], [0, 0, 4]])


def test_instance_rig_names_parents_and_root_offsets():
    rig = {"name": "c",
           "bones": [{"name": "hips", "position": [0, 1, 0]}],
           "parts": [{"skirt": {"name": "skirt", "parent": "hips", "strands": 3, "bones": 2,
                                "radius": 0.1, "length": 0.2, "flare": 10}}],
           "instances": {"count": 100, "spacing": [1.5, 0, 0], "columns": 10}}
    bones = rig_bones(rig)
    assert len(bones) == 100 * 7
    h = TransformHierarchy(bones)
    assert h.parent[h.index("skirt_2_1#57")] == h.index("skirt_2_0#57")
    assert h.parent[h.index("skirt_2_0#57")] == h.index(instance_name("hips", 57))
    np.testing.assert_allclose(world(h, "hips#57"), (7 * 1.5, 1, 5 * 1.5), atol=1e-12)
    local = world(h, "skirt_1_1#57") - world(h, "hips#57")
    np.testing.assert_allclose(local, world(h, "skirt_1_1#0") - world(h, "hips#0"), atol=1e-12)
    assert fnmatch.filter(h.names, instance_name("skirt_*_0", 3)) == [
        "skirt_0_0#3", "skirt_1_0#3", "skirt_2_0#3"]


def test_instance_rig_keeps_outside_parents():
    bones = instance_rig(chain("tail", "stage", bones=2, length=0.1), 2, [1, 0, 0])
    assert [b.parent for b in bones] == ["stage", "tail_0#0", "stage", "tail_0#1"]
