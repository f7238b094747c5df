"""Hand-written expected build arrays for small rigs (issue 3): a 3-bone chain, a 2-strand fan
and a 4 x 3 skirt in the four connection modes.  Also home of the tiny helpers the other
build tests import (``Spec``, rig builders)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pytest

from magica_py.build import build_cloth
from magica_py.build.proxy import FIXED, MOVE, TRIANGLE
from magica_py.build.virtual_mesh import automatic_root_chain
from magica_py.scene.hierarchy import BoneSpec, TransformHierarchy


@dataclass(frozen=True)
class Spec:
    """Duck-typed stand-in for ``scene.ClothSpec``."""

    name: str
    root_bones: tuple
    connection_mode: str = "line"
    component: int | None = None
    parameters: dict = field(default_factory=dict)
    colliders: tuple = ()
    collision_mode: str = "point"
    bone_attributes: dict = field(default_factory=dict)


def chain_rig(bones=3, segment=0.1):
    out = [BoneSpec("body", None, (0.0, 1.0, 0.0))]
    parent = "body"
    for k in range(bones):
        out.append(BoneSpec(f"c{k}", parent, (0.0, 0.0, 0.0) if k == 0 else (0.0, -segment, 0.0)))
        parent = f"c{k}"
    return TransformHierarchy(out)


def strands_rig(root_positions, bones=3, segment=0.1, prefix="s", offsets=None):
    """Strands hanging along -Y from ``hips``; ``offsets[k]`` overrides the k-th child offset."""
    out = [BoneSpec("hips")]
    for s, p in enumerate(root_positions):
        parent = "hips"
        for k in range(bones):
            pos = tuple(p) if k == 0 else (offsets[k] if offsets else (0.0, -segment, 0.0))
            out.append(BoneSpec(f"{prefix}{s}_{k}", parent, pos))
            parent = f"{prefix}{s}_{k}"
    return TransformHierarchy(out)


SQUARE = [(0.0, 0.0, 0.2), (0.2, 0.0, 0.0), (0.0, 0.0, -0.2), (-0.2, 0.0, 0.0)]


def skirt_spec(h, mode, strands=4, **kw):
    return Spec("skirt", tuple(h.index(f"s{s}_0") for s in range(strands)), mode, **kw)


def tri_set(triangles):
    return {tuple(sorted(int(v) for v in t)) for t in triangles}


def csr_lists(start, count, data):
    return [data[s:s + c].tolist() for s, c in zip(start, count)]


# ----------------------------------------------------------------------------- 3-bone chain
def test_chain_of_three_bones_builds_the_hand_computed_arrays():
    h = chain_rig()
    m = build_cloth(h, Spec("tail", (h.index("c0"),)))
    assert m.bone_names == ("c0", "c1", "c2")
    assert m.transform_index.tolist() == [h.index("c0"), h.index("c1"), h.index("c2")]
    assert m.component_transform == h.index("body")
    assert m.attribute.tolist() == [FIXED, MOVE, MOVE]
    assert m.parent.tolist() == [-1, 0, 1]
    assert m.root_index.tolist() == [-1, 0, 0]
    np.testing.assert_allclose(m.depth, [0.0, 0.5, 1.0])
    np.testing.assert_allclose(m.local_position, [[0, 0, 0], [0, -0.1, 0], [0, -0.2, 0]], atol=1e-15)
    assert m.lines.tolist() == [[0, 1], [1, 2]]
    assert m.edges.tolist() == [[0, 1], [1, 2]]
    assert m.triangles.shape == (0, 3)
    assert csr_lists(m.neighbor_start, m.neighbor_count, m.neighbor_data) == [[1], [0, 2], [1]]
    assert csr_lists(m.child_start, m.child_count, m.child_data) == [[1], [2], []]
    assert m.baseline_flags.tolist() == [1]  # IncludeLine: no vertex has triangles
    assert m.baseline_start.tolist() == [0] and m.baseline_count.tolist() == [3]
    assert m.baseline_data.tolist() == [0, 1, 2]
    assert m.center_fixed.tolist() == [0]
    # bone axes are the world axes: rest pose relative to the parent is a plain offset
    np.testing.assert_allclose(m.baseline_local_position, [[0, 0, 0], [0, -0.1, 0], [0, -0.1, 0]], atol=1e-15)
    np.testing.assert_allclose(m.baseline_local_rotation, np.tile([0, 0, 0, 1.0], (3, 1)), atol=1e-15)
    np.testing.assert_allclose(m.bind_rotation, np.tile([0, 0, 0, 1.0], (3, 1)), atol=1e-15)
    np.testing.assert_allclose(m.vertex_to_transform_rotation, np.tile([0, 0, 0, 1.0], (3, 1)), atol=1e-15)
    # distance links: vertical both ways, rest +0.1
    assert csr_lists(m.distance_start, m.distance_count, m.distance_target) == [[1], [0, 2], [1]]
    np.testing.assert_allclose(m.distance_rest, [0.1, 0.1, 0.1, 0.1], rtol=1e-12)
    np.testing.assert_allclose(m.init_local_gravity_direction, [0, -1, 0])
    np.testing.assert_allclose(m.init_render_local_to_world[:3, 3], [0, 1, 0])


def test_chain_positions_are_in_the_scaled_and_rotated_component_space():
    # component turned 90° about +Y and scaled 2: cloth-local = inverse TRS of the component
    s = np.sqrt(0.5)
    h = TransformHierarchy([
        BoneSpec("body", None, (1.0, 2.0, 3.0), (0.0, s, 0.0, s), (2.0, 2.0, 2.0)),
        BoneSpec("c0", "body", (0.0, 0.0, 0.0)),
        BoneSpec("c1", "c0", (0.1, 0.0, 0.0)),  # local +X of body = world -Z, 0.2 m long in the world
    ])
    m = build_cloth(h, Spec("tail", (h.index("c0"),)))
    np.testing.assert_allclose(m.local_position, [[0, 0, 0], [0.1, 0, 0]], atol=1e-12)
    np.testing.assert_allclose(m.init_scale, [2, 2, 2])
    np.testing.assert_allclose(m.distance_rest, [0.1, 0.1], rtol=1e-12)
    # the skin bind pose takes each bone's cloth-local position to the bone origin
    for i in range(2):
        p = m.skin_bind_pose[i] @ np.append(m.local_position[i], 1.0)
        np.testing.assert_allclose(p, [0, 0, 0, 1], atol=1e-12)


# ----------------------------------------------------------------------------- 2-strand fan
def test_two_strand_fan_visits_the_last_root_first_and_keeps_root_order_for_baselines():
    h = strands_rig([(-0.1, 0.0, 0.0), (0.1, 0.0, 0.0)], prefix="f")
    m = build_cloth(h, Spec("hair", (h.index("f0_0"), h.index("f1_0"))))
    # LIFO traversal (docs/solver.md §B.1): the last root is collected first
    assert m.bone_names == ("f1_0", "f1_1", "f1_2", "f0_0", "f0_1", "f0_2")
    assert m.root_vertices.tolist() == [3, 0]
    assert m.lines.tolist() == [[0, 1], [1, 2], [3, 4], [4, 5]]
    assert m.parent.tolist() == [-1, 0, 1, -1, 3, 4]
    assert m.root_index.tolist() == [-1, 0, 0, -1, 3, 3]
    np.testing.assert_allclose(m.depth, [0, 0.5, 1, 0, 0.5, 1])
    # baselines follow the root list (f0 first), not the vertex order
    assert csr_lists(m.baseline_start, m.baseline_count, m.baseline_data) == [[3, 4, 5], [0, 1, 2]]
    assert m.center_fixed.tolist() == [0, 3]


def test_two_strand_fan_in_non_loop_mesh_mode_never_links_first_and_last_root_lines():
    # §B.3 step 4: without loop, root lines 0 and last never connect, so two strands stay lines
    h = strands_rig([(-0.1, 0.0, 0.0), (0.1, 0.0, 0.0)], prefix="f")
    m = build_cloth(h, Spec("hair", (h.index("f0_0"), h.index("f1_0")), "sequential_non_loop_mesh"))
    assert m.triangles.shape == (0, 3)
    assert m.lines.tolist() == [[0, 1], [1, 2], [3, 4], [4, 5]]


def test_two_strand_fan_in_loop_mesh_mode_becomes_a_strip_of_quads():
    h = strands_rig([(-0.1, 0.0, 0.0), (0.1, 0.0, 0.0)], prefix="f")
    m = build_cloth(h, Spec("hair", (h.index("f0_0"), h.index("f1_0")), "sequential_loop_mesh"))
    # vertices: f1 = 0,1,2 ; f0 = 3,4,5 -> quads (0,1,3,4) and (1,2,4,5), one diagonal each
    assert tri_set(m.triangles) == {(0, 1, 3), (1, 3, 4), (1, 2, 4), (2, 4, 5)}
    assert m.lines.shape == (0, 2)
    assert (m.attribute & TRIANGLE).all()
    assert m.baseline_flags.tolist() == [0, 0]  # every baseline vertex is in a triangle


# ----------------------------------------------------------------------------- 4 x 3 skirt
SKIRT_NAMES = ("s3_0", "s3_1", "s3_2", "s2_0", "s2_1", "s2_2", "s1_0", "s1_1", "s1_2", "s0_0", "s0_1", "s0_2")
# strand s0 -> vertices 9,10,11; s1 -> 6,7,8; s2 -> 3,4,5; s3 -> 0,1,2
NON_LOOP_TRIANGLES = {(0, 1, 3), (1, 3, 4), (1, 2, 4), (2, 4, 5),       # s3 | s2
                      (3, 4, 6), (4, 6, 7), (4, 5, 7), (5, 7, 8),       # s2 | s1
                      (6, 7, 9), (7, 9, 10), (7, 8, 10), (8, 10, 11)}   # s1 | s0
SEAM_TRIANGLES = {(0, 1, 9), (1, 9, 10), (1, 2, 10), (2, 10, 11)}       # s3 | s0 (loop only)


@pytest.mark.parametrize("mode", ["line", "automatic_mesh", "sequential_loop_mesh", "sequential_non_loop_mesh"])
def test_skirt_4x3_common_arrays_do_not_depend_on_the_connection_mode(mode):
    h = strands_rig(SQUARE)
    m = build_cloth(h, skirt_spec(h, mode))
    assert m.bone_names == SKIRT_NAMES
    assert m.root_vertices.tolist() == [9, 6, 3, 0]
    assert m.parent.tolist() == [-1, 0, 1, -1, 3, 4, -1, 6, 7, -1, 9, 10]
    assert m.root_index.tolist() == [-1, 0, 0, -1, 3, 3, -1, 6, 6, -1, 9, 9]
    np.testing.assert_allclose(m.depth, [0, 0.5, 1] * 4)
    assert csr_lists(m.baseline_start, m.baseline_count, m.baseline_data) == [
        [9, 10, 11], [6, 7, 8], [3, 4, 5], [0, 1, 2]]
    assert m.center_fixed.tolist() == [0, 3, 6, 9]


def test_skirt_4x3_line_mode_has_only_the_bone_lines():
    h = strands_rig(SQUARE)
    m = build_cloth(h, skirt_spec(h, "line"))
    assert m.lines.tolist() == [[0, 1], [1, 2], [3, 4], [4, 5], [6, 7], [7, 8], [9, 10], [10, 11]]
    assert m.triangles.shape == (0, 3)
    assert csr_lists(m.neighbor_start, m.neighbor_count, m.neighbor_data) == [
        [1], [0, 2], [1], [4], [3, 5], [4], [7], [6, 8], [7], [10], [9, 11], [10]]


def test_skirt_4x3_non_loop_mesh_keeps_one_diagonal_per_quad_and_leaves_the_seam_open():
    h = strands_rig(SQUARE)
    m = build_cloth(h, skirt_spec(h, "sequential_non_loop_mesh"))
    assert tri_set(m.triangles) == NON_LOOP_TRIANGLES
    assert m.lines.shape == (0, 2)
    # vertex 0 (s3 root): triangles first (0-1, 0-3 of triangle (0,1,3)), no seam link to 9
    nb = csr_lists(m.neighbor_start, m.neighbor_count, m.neighbor_data)
    assert nb[0] == [1, 3]
    assert nb[9] == [6, 7, 10]
    assert nb[4] == [1, 2, 3, 6, 5, 7]
    assert all(9 not in nb[v] for v in (0, 1, 2))


def test_skirt_4x3_loop_mesh_closes_the_seam_between_the_last_and_first_root():
    h = strands_rig(SQUARE)
    m = build_cloth(h, skirt_spec(h, "sequential_loop_mesh"))
    assert tri_set(m.triangles) == NON_LOOP_TRIANGLES | SEAM_TRIANGLES
    assert len(m.edges) == 28  # 8 vertical + 4 x 3 horizontal + 4 x 2 diagonals
    assert (m.attribute & TRIANGLE).all()


def test_skirt_4x3_automatic_mesh_chains_the_roots_and_also_links_the_square_diagonals():
    h = strands_rig(SQUARE)
    m = build_cloth(h, skirt_spec(h, "automatic_mesh"))
    # square: the diagonal (0.283 m x sqrt 2 = 0.4 m) is within 1.5 x the nearest distance,
    # so opposite strands link too and more triangles appear than in loop mode
    assert NON_LOOP_TRIANGLES | SEAM_TRIANGLES <= tri_set(m.triangles)
    assert len(m.triangles) == 24


def test_automatic_root_chain_reverses_when_the_next_root_is_too_far():
    pos = np.array([[0.25 * k, 0.0, 0.0] for k in range(4)])  # exact distances: ties are real ties
    # roots given as [2, 0, 3, 1] (hand-traced in §B.3 step 2): 2 -> 3 (tie with 1, 3 comes
    # first in the pool); 3 -> 1 is 0.5 >= 1.5 x 0.25 so the chain reverses to [3, 2]; then 1, 0
    chain, loop = automatic_root_chain([2, 0, 3, 1], pos)
    assert chain == [3, 2, 1, 0]
    assert loop is False
    ring = np.array(SQUARE)
    chain, loop = automatic_root_chain([0, 1, 2, 3], ring)
    assert chain == [0, 1, 2, 3] and loop is True


def test_automatic_mesh_on_a_flat_sheet_matches_the_sequential_non_loop_mesh():
    h = strands_rig([(0.1 * k, 0.0, 0.0) for k in range(4)])
    auto = build_cloth(h, skirt_spec(h, "automatic_mesh"))
    seq = build_cloth(h, skirt_spec(h, "sequential_non_loop_mesh"))
    assert tri_set(auto.triangles) == tri_set(seq.triangles)
    assert len(auto.triangles) == 12
    np.testing.assert_array_equal(auto.edges, seq.edges)
