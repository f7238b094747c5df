"""Proxy mesh conversion (docs/solver.md §B.4-§B.8): attributes, adjacency, triangle orientation,
vertex frames, baselines, baseline rest pose, root index and depth.

All positions are cloth-local (§B.1).  Orders follow the reference: insertion-ordered
unions (triangles first, then lines), triangles in build order, baselines in root-list order.
"""
from __future__ import annotations

import math
import numpy as np

from magica_py.build.errors import BuildError
from magica_py.build.topology import edge_triangles, orient_flood_fill
from magica_py.jit import kernel
from magica_py.kernels import portable
from magica_py.kernels.math3d import (
    load3,
    load4,
    q_inverse,
    q_mul,
    q_rotate,
    rot_from_normal_tangent,
    store3,
    store4,
    v_cross,
    v_length,
    v_normalize,
    v_sub,
)

# vertex attribute bits (§B.5, VertexAttribute.cs)
FIXED = 0x01
MOVE = 0x02
INVALID_MOTION = 0x08
DISABLE_COLLISION = 0x10
ZERO_DISTANCE = 0x20
TRIANGLE = 0x80
# baseline flags
BASELINE_INCLUDE_LINE = 0x01
# vertex_triangle_flip bits: negate this triangle's normal / tangent when summing (§B.4, §E.3)
FLIP_NORMAL = 0x01
FLIP_TANGENT = 0x02

MAX_TRIANGLES_PER_VERTEX = 7
SAME_SURFACE_ANGLE = 80.0  # degrees, orientation flood fill


# ----------------------------------------------------------------------------- attributes
def selection_attributes(cloth_name: str, setup, bone_attributes) -> np.ndarray:
    """Default selection (roots Fixed, every other bone Move) plus per-bone overrides (§B.5)."""
    n = setup.count
    attribute = np.full(n, MOVE, dtype=np.uint8)
    attribute[setup.root_vertices] = FIXED
    if bone_attributes:
        vertex_of = {int(t): i for i, t in enumerate(setup.transform_index)}
        codes = {"fixed": FIXED, "move": MOVE, "invalid": 0}
        for bone, kind in bone_attributes.items():
            if int(bone) not in vertex_of:
                raise BuildError(cloth_name, f"bone_attributes names transform {bone!r} which is not a bone "
                                             "of this cloth (expected a root bone or one of its descendants)")
            if kind not in codes:
                raise BuildError(cloth_name, f"bone_attributes[{bone!r}] = {kind!r}: expected one of "
                                             "'fixed', 'move', 'invalid'")
            attribute[vertex_of[int(bone)]] = codes[kind]
    return attribute


# ----------------------------------------------------------------------------- adjacency
def _unique_pairs_in_order(pairs: np.ndarray, n: int) -> np.ndarray:
    if pairs.shape[0] == 0:
        return pairs.reshape(0, 2).astype(np.int32)
    key = pairs[:, 0].astype(np.int64) * n + pairs[:, 1]
    _, first = np.unique(key, return_index=True)
    return pairs[np.sort(first)].astype(np.int32)


def adjacency(n: int, lines: np.ndarray, triangles: np.ndarray):
    """Vertex adjacency CSR and the unique edge list (§B.4 step 2).

    Returns (neighbor_start, neighbor_count, neighbor_data, edges): neighbours of each vertex in
    insertion order (triangles first, each vertex linked to the other two, then lines both
    ways); edges (E, 2) sorted pairs in first-appearance order.
    """
    t = triangles.astype(np.int64)
    l = lines.astype(np.int64)
    directed = np.concatenate([
        np.stack([t[:, [0, 0, 1, 1, 2, 2]].ravel(), t[:, [1, 2, 0, 2, 0, 1]].ravel()], axis=1),
        np.stack([l[:, [0, 1]].ravel(), l[:, [1, 0]].ravel()], axis=1),
    ]).reshape(-1, 2)
    directed = _unique_pairs_in_order(directed, n)
    order = np.argsort(directed[:, 0], kind="stable")
    neighbor_data = directed[order, 1].astype(np.int32)
    neighbor_count = np.bincount(directed[:, 0], minlength=n).astype(np.int32)
    neighbor_start = _starts(neighbor_count)
    undirected = np.concatenate([
        np.sort(np.stack([t[:, [0, 1, 0]].ravel(), t[:, [1, 2, 2]].ravel()], axis=1), axis=1)
        if t.shape[0] else np.zeros((0, 2), np.int64),
        l,
    ]).reshape(-1, 2)
    edges = _unique_pairs_in_order(undirected, n)
    return neighbor_start, neighbor_count, neighbor_data, edges


def _starts(counts: np.ndarray) -> np.ndarray:
    s = np.zeros(counts.shape[0], dtype=np.int32)
    if counts.shape[0] > 1:
        s[1:] = np.cumsum(counts[:-1])
    return s


# ----------------------------------------------------------------------------- triangles
def orient_triangles(pos: np.ndarray, triangles: np.ndarray):
    """Orientation flood fill (``OptimizeTriangleDirection``, §B.4 step 3).

    Returns oriented triangles (T,3) int32 and their unit normals (T,3)."""
    tris = triangles.astype(np.int32).copy()
    normals = _triangle_normals(pos, tris)
    if tris.shape[0] == 0:
        return tris.reshape(0, 3), normals
    edge_pairs, et_start, et_count, et_data, tri_edges = edge_triangles(tris, pos.shape[0])
    visited = np.zeros(tris.shape[0], dtype=np.bool_)
    queue = np.zeros(tris.shape[0], dtype=np.int64)
    orient_flood_fill(pos, tris, normals, tri_edges, edge_pairs, et_start, et_count, et_data,
                      math.radians(SAME_SURFACE_ANGLE), visited, queue)
    return tris, normals


def _triangle_normals(pos, tris):
    if tris.shape[0] == 0:
        return np.zeros((0, 3))
    n = np.cross(pos[tris[:, 1]] - pos[tris[:, 0]], pos[tris[:, 2]] - pos[tris[:, 0]])
    length = portable.norm(n)
    return np.where(length[:, None] > 1e-12, n / np.maximum(length, 1e-300)[:, None], 0.0)


def triangle_tangents(pos, tris, uv):
    """UV tangents, negated for Unity's left-handed convention; zero uv area counts as 1."""
    if tris.shape[0] == 0:
        return np.zeros((0, 3))
    p0, p1, p2 = pos[tris[:, 0]], pos[tris[:, 1]], pos[tris[:, 2]]
    w0, w1, w2 = uv[tris[:, 0]], uv[tris[:, 1]], uv[tris[:, 2]]
    e1, e2 = p1 - p0, p2 - p0
    d1, d2 = w1 - w0, w2 - w0
    area = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    area = np.where(area == 0.0, 1.0, area)
    t = -(e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) / area[:, None]
    length = portable.norm(t)
    return np.where(length[:, None] > 1e-12, t / np.maximum(length, 1e-300)[:, None], 0.0)


def vertex_triangles(n: int, tris: np.ndarray):
    """Vertex-to-triangle CSR (at most 7 per vertex, triangle index order) and the Triangle mask."""
    T = tris.shape[0]
    vt = np.stack([tris.ravel().astype(np.int64), np.repeat(np.arange(T), 3)], axis=1)
    order = np.argsort(vt[:, 0], kind="stable")
    vt = vt[order]
    full_count = np.bincount(vt[:, 0], minlength=n)
    full_start = np.concatenate([[0], np.cumsum(full_count)[:-1]]).astype(np.int64)
    rank = np.arange(vt.shape[0]) - full_start[vt[:, 0]]
    keep = rank < MAX_TRIANGLES_PER_VERTEX
    count = np.minimum(full_count, MAX_TRIANGLES_PER_VERTEX).astype(np.int32)
    return _starts(count), count, vt[keep, 1].astype(np.int32), full_count > 0


@kernel
def _aligned_sum(vectors, vt_data, s, c, flip, flip_bit):
    """Sum of the vertex's triangle vectors; if shorter than 0.5, the sign-aligned sum around
    the triangle that maximises it, recording negated triangles in ``flip`` (§B.4 step 3)."""
    sx = 0.0
    sy = 0.0
    sz = 0.0
    for k in range(c):
        t = vt_data[s + k]
        sx += vectors[t, 0]
        sy += vectors[t, 1]
        sz += vectors[t, 2]
    if np.sqrt(sx * sx + sy * sy + sz * sz) >= 0.5:
        return sx, sy, sz
    best = -1.0
    best_k = 0
    for ref in range(c):
        r = vt_data[s + ref]
        ax = 0.0
        ay = 0.0
        az = 0.0
        for k in range(c):
            t = vt_data[s + k]
            d = vectors[t, 0] * vectors[r, 0] + vectors[t, 1] * vectors[r, 1] + vectors[t, 2] * vectors[r, 2]
            g = -1.0 if d < 0.0 else 1.0
            ax += g * vectors[t, 0]
            ay += g * vectors[t, 1]
            az += g * vectors[t, 2]
        length = np.sqrt(ax * ax + ay * ay + az * az)
        if length > best:
            best = length
            best_k = ref
            sx = ax
            sy = ay
            sz = az
    r = vt_data[s + best_k]
    for k in range(c):
        t = vt_data[s + k]
        d = vectors[t, 0] * vectors[r, 0] + vectors[t, 1] * vectors[r, 1] + vectors[t, 2] * vectors[r, 2]
        if d < 0.0:
            flip[s + k] |= flip_bit
    return sx, sy, sz


@kernel
def vertex_frames_kernel(tri_normals, tri_tangents, vt_start, vt_count, vt_data, normal, tangent, flip):
    """Vertex normal = normalize(Σ±n_tri), tangent = normalize(cross(n, Σ±t_tri)), in place."""
    for v in range(vt_start.shape[0]):
        c = vt_count[v]
        if c == 0:
            continue
        s = vt_start[v]
        ns = _aligned_sum(tri_normals, vt_data, s, c, flip, np.int64(FLIP_NORMAL))
        ts = _aligned_sum(tri_tangents, vt_data, s, c, flip, np.int64(FLIP_TANGENT))
        nn = v_normalize(ns)
        tn = v_normalize(ts)
        b = v_normalize(v_cross(nn, tn))
        if v_length(nn) == 0.0 or v_length(b) == 0.0:
            continue  # degenerate fan: keep the bone axes
        store3(normal, v, nn)
        store3(tangent, v, b)


def vertex_frames(tri_normals, tri_tangents, vt_start, vt_count, vt_data, local_normal, local_tangent):
    """Vertex normal/tangent from adjacent triangles (§B.4 step 3); bone axes elsewhere.

    Returns (local_normal, local_tangent, vertex_triangle_flip (S,) uint8)."""
    normal = local_normal.copy()
    tangent = local_tangent.copy()
    flip = np.zeros(vt_data.shape[0], dtype=np.uint8)
    if vt_data.shape[0]:
        vertex_frames_kernel(tri_normals, tri_tangents, vt_start, vt_count, vt_data, normal, tangent, flip)
    return normal, tangent, flip


# ----------------------------------------------------------------------------- center
def center_fixed_list(attribute, neighbor_start, neighbor_count, neighbor_data) -> np.ndarray:
    """Non-Move vertices with a Move neighbour or with no neighbour at all (§B.4 step 4)."""
    move = (attribute & MOVE) != 0
    src = np.repeat(np.arange(attribute.shape[0]), neighbor_count)
    has_move_nb = np.bincount(src, weights=move[neighbor_data], minlength=attribute.shape[0]) > 0
    return np.nonzero(~move & (has_move_nb | (neighbor_count == 0)))[0].astype(np.int32)


# ----------------------------------------------------------------------------- baselines
def children_csr(parent: np.ndarray):
    """Children of each vertex in increasing vertex index (§B.6)."""
    n = parent.shape[0]
    child = np.nonzero(parent >= 0)[0]
    order = np.argsort(parent[child], kind="stable")
    child_data = child[order].astype(np.int32)
    child_count = np.bincount(parent[child], minlength=n).astype(np.int32)
    return _starts(child_count), child_count, child_data


@kernel
def baselines_kernel(root_vertices, move, child_start, child_count, child_data,
                     starts, counts, data, stack):
    """``CreateTransformBaseLine`` walk; returns (baseline count, data length)."""
    nb = 0
    nd = 0
    for r in range(root_vertices.shape[0]):
        stack[0] = root_vertices[r]
        top = 1
        while top > 0:
            top -= 1
            a = stack[top]
            if move[a]:
                continue
            s = child_start[a]
            c = child_count[a]
            has_move = False
            for k in range(c):
                if move[child_data[s + k]]:
                    has_move = True
            if not has_move:
                # children pop in increasing index: push them in decreasing order
                for k in range(c - 1, -1, -1):
                    stack[top] = child_data[s + k]
                    top += 1
                continue
            starts[nb] = nd
            inner = top
            stack[inner] = a
            inner += 1
            while inner > top:
                inner -= 1
                v = stack[inner]
                data[nd] = v
                nd += 1
                for k in range(child_count[v] - 1, -1, -1):
                    ch = child_data[child_start[v] + k]
                    if move[ch]:
                        stack[inner] = ch
                        inner += 1
            counts[nb] = nd - starts[nb]
            nb += 1
    return nb, nd


def baselines(root_vertices, attribute, child_start, child_count, child_data):
    """``CreateTransformBaseLine`` (§B.6): returns (flags, start, count, data).

    Per root (root-list order) a depth-first walk over DontMove vertices; a DontMove vertex with
    a Move child starts a baseline holding it and its Move subtree in LIFO pop order."""
    n = attribute.shape[0]
    move = (attribute & MOVE) != 0
    starts = np.zeros(n, dtype=np.int32)
    counts = np.zeros(n, dtype=np.int32)
    data = np.zeros(n, dtype=np.int32)
    nb, nd = baselines_kernel(np.asarray(root_vertices, dtype=np.int32), move, child_start, child_count,
                              child_data, starts, counts, data, np.zeros(2 * n + 1, dtype=np.int32))
    starts, counts, data = starts[:nb].copy(), counts[:nb].copy(), data[:nd].copy()
    tri = (attribute & TRIANGLE) != 0
    all_tri = np.logical_and.reduceat(tri[data], starts) if nb else np.zeros(0, dtype=bool)
    flags = np.where(all_tri, 0, BASELINE_INCLUDE_LINE).astype(np.uint8)
    return flags, starts, counts, data


@kernel
def vertex_rotations(local_normal, local_tangent, bone_world_rotation, init_render_rotation,
                     bind_rotation, vertex_to_transform_rotation):
    """bind = qinv(rot_from(n, t)); v2t = bind · qinv(R_render) · R_bone (§B.4 steps 7-8)."""
    render_inv = q_inverse((init_render_rotation[0], init_render_rotation[1],
                            init_render_rotation[2], init_render_rotation[3]))
    for i in range(local_normal.shape[0]):
        bind = q_inverse(rot_from_normal_tangent(load3(local_normal, i), load3(local_tangent, i)))
        store4(bind_rotation, i, bind)
        store4(vertex_to_transform_rotation, i, q_mul(bind, q_mul(render_inv, load4(bone_world_rotation, i))))


@kernel
def baseline_pose(baseline_data, parent, local_position, local_normal, local_tangent,
                  baseline_local_position, baseline_local_rotation, attribute, zero_distance_bit):
    """Rest pose of each baseline vertex relative to its parent (§B.7); flags ZeroDistance."""
    for k in range(baseline_data.shape[0]):
        v = np.int64(baseline_data[k])   # int64 ids: one signature of the row helpers (docs/tech-notes.md §7)
        p = np.int64(parent[v])
        if p < 0:
            continue
        qp = rot_from_normal_tangent(load3(local_normal, p), load3(local_tangent, p))
        qv = rot_from_normal_tangent(load3(local_normal, v), load3(local_tangent, v))
        qpi = q_inverse(qp)
        lp = q_rotate(qpi, v_sub(load3(local_position, v), load3(local_position, p)))
        store3(baseline_local_position, v, lp)
        store4(baseline_local_rotation, v, q_mul(qpi, qv))
        if v_length(lp) < 1e-8:
            attribute[v] |= zero_distance_bit


@kernel
def root_index_and_length(parent, attribute, local_position, move_bit, root_index, root_length):
    """Root (first non-Move ancestor) and arc length to it for every Move vertex (§B.8).

    Vertices are parents-first, so one forward pass suffices.  A Move vertex whose chain has no
    DontMove ancestor gets the top-most ancestor (a parentless Move vertex gets -1)."""
    for i in range(parent.shape[0]):
        root_index[i] = -1
        root_length[i] = 0.0
        if (attribute[i] & move_bit) == 0:
            continue
        p = np.int64(parent[i])
        if p < 0:
            continue
        seg = v_length(v_sub(load3(local_position, i), load3(local_position, p)))
        if (attribute[p] & move_bit) != 0:
            root_length[i] = root_length[p] + seg
            root_index[i] = root_index[p] if root_index[p] >= 0 else p
        else:
            root_length[i] = seg
            root_index[i] = p


def depth_from_length(root_length: np.ndarray) -> np.ndarray:
    """depth = saturate(rootLen / max rootLen) over the whole cloth, 0 everywhere if max < 1e-8."""
    max_len = float(root_length.max(initial=0.0))
    if max_len > 1e-8:
        return np.clip(root_length / max_len, 0.0, 1.0)
    return np.zeros_like(root_length)
