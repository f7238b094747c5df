"""Property tests on generated rigs (hypothesis): baselines reach a fixed root, depth grows
along baselines, adjacency is symmetric, triangles are not degenerate, nothing is NaN."""
from __future__ import annotations

import math

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from magica_py.build import build_cloth
from magica_py.build.proxy import FIXED, MOVE
from magica_py.build.virtual_mesh import CONNECTION_MODES
from magica_py.scene.hierarchy import BoneSpec, TransformHierarchy
from test_build_rigs import Spec


@st.composite
def random_rigs(draw):
    """A hips node with 1-6 strand roots on a jittered ring; each strand is a random tree
    (every bone's parent drawn among the strand's earlier bones) with random offsets, a few of
    them zero-length."""
    strands = draw(st.integers(1, 6))
    radius = draw(st.floats(0.05, 0.5))
    bones = [BoneSpec("hips")]
    roots = []
    for s in range(strands):
        a = 2 * math.pi * s / strands + draw(st.floats(-0.2, 0.2))
        size = draw(st.integers(2, 7))
        names = [f"s{s}_0"]
        bones.append(BoneSpec(names[0], "hips", (radius * math.sin(a), draw(st.floats(-0.05, 0.05)),
                                                 radius * math.cos(a))))
        for k in range(1, size):
            parent = names[draw(st.integers(0, k - 1))]
            zero = draw(st.integers(0, 9)) == 0
            off = (0.0, 0.0, 0.0) if zero else (draw(st.floats(-0.03, 0.03)), -draw(st.floats(0.02, 0.12)),
                                                draw(st.floats(-0.03, 0.03)))
            names.append(f"s{s}_{k}")
            bones.append(BoneSpec(names[-1], parent, off))
        roots.append(names[0])
    h = TransformHierarchy(bones)
    mode = draw(st.sampled_from(CONNECTION_MODES))
    return h, Spec("random", tuple(h.index(r) for r in roots), mode)


SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@SETTINGS
@given(random_rigs())
def test_every_moving_vertex_reaches_a_fixed_root_along_its_baseline(rig):
    h, spec = rig
    m = build_cloth(h, spec)
    move = (m.attribute & MOVE) != 0
    seen = np.zeros(m.particle_count, dtype=int)
    for s, c in zip(m.baseline_start, m.baseline_count):
        line = m.baseline_data[s:s + c]
        start = line[0]
        assert m.attribute[start] & FIXED
        assert not move[start]
        for v in line[1:]:
            assert move[v]
            seen[v] += 1
            assert m.root_index[v] == start
            # walking up the parents reaches the start without leaving the baseline
            u = v
            while u != start:
                u = m.parent[u]
                assert u in line
            # pre-order: the parent comes earlier in the baseline
            assert list(line).index(m.parent[v]) < list(line).index(v)
    assert (seen[move] == 1).all()


@SETTINGS
@given(random_rigs())
def test_depth_is_normalised_and_never_decreases_along_a_baseline(rig):
    h, spec = rig
    m = build_cloth(h, spec)
    assert m.depth.min() >= 0.0 and m.depth.max() <= 1.0
    if (m.root_length > 1e-8).any():
        assert m.depth.max() == 1.0
    for v in m.baseline_data:
        p = m.parent[v]
        if p >= 0 and (m.attribute[v] & MOVE):
            assert m.depth[v] >= m.depth[p]


@SETTINGS
@given(random_rigs())
def test_adjacency_is_symmetric_and_matches_the_edges(rig):
    h, spec = rig
    m = build_cloth(h, spec)
    src = np.repeat(np.arange(m.particle_count), m.neighbor_count)
    pairs = set(zip(src.tolist(), m.neighbor_data.tolist()))
    assert all((b, a) in pairs for a, b in pairs)
    assert {(min(a, b), max(a, b)) for a, b in pairs} == set(map(tuple, m.edges.tolist()))
    assert len(pairs) == 2 * len(m.edges)
    assert (m.edges[:, 0] < m.edges[:, 1]).all()
    # every line and triangle side is an edge
    edges = set(map(tuple, m.edges.tolist()))
    assert set(map(tuple, m.lines.tolist())) <= edges
    for t in m.triangles:
        for a, b in ((t[0], t[1]), (t[1], t[2]), (t[0], t[2])):
            assert (min(a, b), max(a, b)) in edges


@SETTINGS
@given(random_rigs())
def test_no_degenerate_triangle_and_no_nan(rig):
    h, spec = rig
    m = build_cloth(h, spec)
    t = m.triangles
    assert (t[:, 0] != t[:, 1]).all() and (t[:, 1] != t[:, 2]).all() and (t[:, 0] != t[:, 2]).all()
    assert len({tuple(sorted(x)) for x in t.tolist()}) == len(t)
    p = m.local_position
    area = np.linalg.norm(np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]]), axis=1)
    assert (area > 0).all()
    for name, value in vars(m).items():
        if isinstance(value, np.ndarray) and value.dtype.kind == "f":
            assert np.isfinite(value).all(), name
    # distance rests: sign says vertical (+) / horizontal (-), magnitude is the build length
    src = np.repeat(np.arange(m.particle_count), m.distance_count)
    dst = m.distance_target
    length = np.linalg.norm(p[src] - p[dst], axis=1)
    vertical = (m.parent[src] == dst) | (m.parent[dst] == src)
    np.testing.assert_allclose(np.abs(m.distance_rest), np.where(length < 1e-8, 0.0, length))
    assert (m.distance_rest[vertical & (length >= 1e-8)] > 0).all()
    assert (m.distance_rest[~vertical & (length >= 1e-8)] < 0).all()
    # per vertex: vertical links first
    for v in range(m.particle_count):
        r = m.distance_rest[m.distance_start[v]:m.distance_start[v] + m.distance_count[v]]
        vert = vertical[m.distance_start[v]:m.distance_start[v] + m.distance_count[v]]
        assert not (np.diff(vert.astype(int)) > 0).any(), (v, r)


def test_random_rigs_build_deterministically():
    rng = np.random.default_rng(7)
    bones = [BoneSpec("hips")]
    for s in range(5):
        parent = "hips"
        for k in range(6):
            off = tuple(rng.normal(0, 0.05, 3)) if k else (0.3 * math.sin(s), 0.0, 0.3 * math.cos(s))
            bones.append(BoneSpec(f"s{s}_{k}", parent, off))
            parent = f"s{s}_{k}"
    h = TransformHierarchy(bones)
    spec = Spec("r", tuple(h.index(f"s{s}_0") for s in range(5)), "automatic_mesh")
    a, b = build_cloth(h, spec, cache=None), build_cloth(h, spec, cache=None)
    assert a.topology_key == b.topology_key
    for name, value in vars(a).items():
        if isinstance(value, np.ndarray):
            np.testing.assert_array_equal(value, getattr(b, name), err_msg=name)
