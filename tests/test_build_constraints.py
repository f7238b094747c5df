"""Constraint build data against slow pure-Python twins (shear links, bending and volume pairs)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from magica_py.build import build_cloth
from test_build_rigs import Spec, strands_rig


def edge_triangle_map(triangles):
    out: dict = {}
    for k, t in enumerate(triangles.tolist()):
        a, b, c = sorted(t)
        for e in ((a, b), (b, c), (a, c)):
            out.setdefault(e, []).append(k)
    return out


def bending_twin(m):
    """docs/solver.md §D.7 "Build", written out with Python loops."""
    move = (m.attribute & 2) != 0
    valid = (m.attribute & 3) != 0
    p = m.local_position
    l2w = m.init_render_local_to_world
    world = p @ l2w[:3, :3].T + l2w[:3, 3]
    bend, vol, seen = [], [], set()
    for (v2, v3), tris in edge_triangle_map(m.triangles).items():
        for x in range(len(tris)):
            for y in range(x + 1, len(tris)):
                v0 = next(v for v in m.triangles[tris[x]] if v not in (v2, v3))
                v1 = next(v for v in m.triangles[tris[y]] if v not in (v2, v3))
                q = [v0, v1, v2, v3]
                if not valid[q].all() or not move[q].any():
                    continue
                n1 = np.cross(p[v2] - p[v0], p[v3] - p[v0])
                n2 = np.cross(p[v3] - p[v1], p[v2] - p[v1])
                n1 /= np.linalg.norm(n1)
                n2 /= np.linalg.norm(n2)
                phi = math.acos(min(max(float(n1 @ n2), -1.0), 1.0))
                sign = -1.0 if float(np.cross(n1, n2) @ (p[v3] - p[v2])) < 0 else 1.0
                if math.degrees(phi) < 120:
                    bend.append((tuple(q), phi, sign))
                if 90 <= math.degrees(phi) <= 179 and frozenset(q) not in seen:
                    seen.add(frozenset(q))
                    w = world[q]
                    vol.append((tuple(q), 1000 / 6 * float(np.cross(w[1] - w[0], w[2] - w[0]) @ (w[3] - w[0]))))
    return bend, vol


@pytest.mark.parametrize("strands, mode", [(5, "sequential_loop_mesh"), (6, "automatic_mesh"),
                                           (4, "sequential_non_loop_mesh")])
def test_bending_and_volume_pairs_match_the_python_twin(strands, mode):
    rng = np.random.default_rng(strands)
    ring = [(0.2 * math.sin(a), 0.0, 0.2 * math.cos(a))
            for a in np.linspace(0, 2 * math.pi, strands, endpoint=False)]
    offsets = {k: tuple(rng.normal(0, 0.02, 3) + [0, -0.1, 0]) for k in range(1, 5)}
    h = strands_rig(ring, bones=5, offsets=offsets)
    m = build_cloth(h, Spec("s", tuple(h.index(f"s{s}_0") for s in range(strands)), mode), cache=None)
    bend, vol = bending_twin(m)
    assert len(bend) == len(m.bend_vertices) > 0
    assert [b[0] for b in bend] == [tuple(v) for v in m.bend_vertices.tolist()]
    # acos near 1 turns a 1-ulp difference in the normalisation into 1.5e-8 rad
    np.testing.assert_allclose(m.bend_rest_angle, [b[1] for b in bend], rtol=0, atol=1e-7)
    np.testing.assert_array_equal(m.bend_sign, [b[2] for b in bend])
    assert [v[0] for v in vol] == [tuple(v) for v in m.volume_vertices.tolist()]
    np.testing.assert_allclose(m.volume_rest, [v[1] for v in vol], rtol=1e-12, atol=1e-15)


def test_square_quads_get_a_shear_link_along_the_missing_diagonal():
    # flat 3 x 3 sheet with square 0.1 m quads: each quad keeps one diagonal as an edge and the
    # other diagonal becomes a pair of horizontal shear links (§B.9 step 2)
    h = strands_rig([(0.1 * k, 0.0, 0.0) for k in range(3)])
    m = build_cloth(h, Spec("sheet", tuple(h.index(f"s{s}_0") for s in range(3)), "sequential_non_loop_mesh"))
    edges = set(map(tuple, m.edges.tolist()))
    src = np.repeat(np.arange(m.particle_count), m.distance_count)
    links = list(zip(src.tolist(), m.distance_target.tolist(), m.distance_rest.tolist()))
    shear = {(a, b) for a, b, r in links if (min(a, b), max(a, b)) not in edges}
    assert len(shear) == 8  # 4 quads, both directions
    for a, b in shear:
        assert (b, a) in shear
        assert np.linalg.norm(m.local_position[a] - m.local_position[b]) == pytest.approx(math.sqrt(0.02))
    rest = {(a, b): r for a, b, r in links}
    assert all(rest[k] == pytest.approx(-math.sqrt(0.02)) for k in shear)
    # shear links come after the vertex's adjacency links, vertical ones first
    for v in range(m.particle_count):
        own = [b for a, b, _ in links if a == v]
        kinds = [0 if rest[(v, b)] > 0 else (2 if (v, b) in shear else 1) for b in own]
        assert kinds == sorted(kinds)
    # the two fixed roots' mutual edge carries no link (both DontMove)
    roots = set(m.root_vertices.tolist())
    assert not any(a in roots and b in roots for a, b, _ in links)
