"""Edge-to-triangle structure and the numba kernels that walk triangle pairs at build time:
duplicate-quad removal (docs/solver.md §B.3 step 7), orientation flood fill (§B.4 step 3), shear links
(§B.9) and bending / volume pairs (§D.7).

``edge_triangles(triangles, n)`` keys every triangle edge (rows of a triangle sorted, edges
(a,b), (b,c), (a,c)) in first-appearance order, i.e. the insertion order of the reference's
hash maps; the triangles of an edge are listed in triangle index order.
"""
from __future__ import annotations

import math

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels.math3d import closest_segment_segment, load3, v_cross, v_dot, v_length, v_sub
from magica_py.kernels import portable

BENDING_MAX_ANGLE = 120.0     # TriangleBendingMaxAngle, degrees
VOLUME_MIN_ANGLE = 90.0       # VolumeMinAngle
VOLUME_MAX_ANGLE = 179.0
SHEAR_NORMAL_DOT = 0.9396926  # cos 20°
SHEAR_SQUARE_TOLERANCE = 0.3


def edge_triangles(triangles: np.ndarray, n: int):
    """Returns (edge_pairs (E,2), et_start (E,), et_count (E,), et_data (3T,), tri_edges (T,3))."""
    T = triangles.shape[0]
    if T == 0:
        z = np.zeros(0, dtype=np.int32)
        return np.zeros((0, 2), np.int32), z, z, z, np.zeros((0, 3), np.int32)
    s = np.sort(triangles.astype(np.int64), axis=1)
    a = np.stack([s[:, 0], s[:, 1], s[:, 0]], axis=1).ravel()
    b = np.stack([s[:, 1], s[:, 2], s[:, 2]], axis=1).ravel()
    key = a * n + b
    uniq, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    # renumber unique edges by first appearance
    rank = np.empty(uniq.shape[0], dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(uniq.shape[0])
    edge_id = rank[inverse]
    order_first = np.sort(first)
    edge_pairs = np.stack([a[order_first], b[order_first]], axis=1).astype(np.int32)
    tri_of = np.repeat(np.arange(T), 3)
    order = np.argsort(edge_id, kind="stable")
    et_data = tri_of[order].astype(np.int32)
    et_count = np.bincount(edge_id, minlength=uniq.shape[0]).astype(np.int32)
    et_start = np.zeros_like(et_count)
    et_start[1:] = np.cumsum(et_count[:-1])
    return edge_pairs, et_start, et_count, et_data, edge_id.reshape(T, 3).astype(np.int32)


def key_table(capacity: int) -> np.ndarray:
    """Empty open-addressing set for non-negative int64 keys holding up to ``capacity`` keys
    (a plain array: compiles much faster in numba than a typed set)."""
    size = 16
    while size < 2 * capacity + 1:
        size *= 2
    return np.full(size, -1, dtype=np.int64)


@kernel
def key_insert(table, key):
    """Insert ``key`` (>= 0); True when it was not there yet."""
    mask = table.shape[0] - 1
    # the low bits of key * 2654435761 depend only on the low bits of key: masking first keeps
    # the product below 2**63 (the same slot; no int64 overflow, which numpy warns about when
    # the build runs with NUMBA_DISABLE_JIT=1)
    h = ((key & mask) * 2654435761) & mask
    while True:
        k = table[h]
        if k == key:
            return False
        if k < 0:
            table[h] = key
            return True
        h = (h + 1) & mask


@kernel
def opposite_vertex(triangles, t, a, b):
    """The corner of triangle t that is neither a nor b (-1 when none). Callers pass t as int64:
    one signature (docs/tech-notes.md §7)."""
    for k in range(3):
        v = triangles[t, k]
        if v != a and v != b:
            return v
    return -1


@kernel
def fold_angle(pos, a, b, z, w):
    """Fold angle (rad) of triangles (a,b,z) and (a,b,w) over edge a-b: 0 when flat, pi when
    the two lie on top of each other (MathUtility.TriangleAngle)."""
    pa = load3(pos, a)
    e = v_sub(load3(pos, b), pa)
    n1 = v_cross(e, v_sub(load3(pos, z), pa))
    n2 = v_cross(v_sub(load3(pos, w), pa), e)
    l1 = v_length(n1)
    l2 = v_length(n2)
    if l1 < 1e-12 or l2 < 1e-12:
        return 0.0
    c = v_dot(n1, n2) / (l1 * l2)
    return portable.acos(c)


@kernel
def remove_duplicate_quads(pos, triangles, edge_pairs, et_start, et_count, et_data, max_angle, removed, quads):
    """Mark in ``removed`` one triangulation of every quad triangulated along both diagonals
    (``quads``: a ``key_table`` sized for every triangle pair)."""
    for e in range(edge_pairs.shape[0]):
        if et_count[e] < 2:
            continue
        a = edge_pairs[e, 0]
        b = edge_pairs[e, 1]
        for x in range(et_count[e]):
            for y in range(x + 1, et_count[e]):
                t1 = et_data[et_start[e] + x]
                t2 = et_data[et_start[e] + y]
                if removed[t1] or removed[t2]:
                    continue
                z = opposite_vertex(triangles, np.int64(t1), a, b)
                w = opposite_vertex(triangles, np.int64(t2), a, b)
                if fold_angle(pos, a, b, z, w) > max_angle:
                    continue
                s, t, _ca, _cb = closest_segment_segment(load3(pos, a), load3(pos, b), load3(pos, z), load3(pos, w))
                if s <= 0.0 or s >= 1.0 or t <= 0.0 or t >= 1.0:
                    continue
                q0 = min(a, b)
                q1 = max(a, b)
                q2 = min(z, w)
                q3 = max(z, w)
                # sort four indices (each < 2^15) into one int64 key
                lo = (q0, q2) if q0 < q2 else (q2, q0)
                hi = (q1, q3) if q1 < q3 else (q3, q1)
                m1 = min(lo[1], hi[0])
                m2 = max(lo[1], hi[0])
                key = ((np.int64(lo[0]) * 32768 + m1) * 32768 + m2) * 32768 + hi[1]
                if not key_insert(quads, key):
                    removed[t1] = True
                    removed[t2] = True


@kernel
def orient_flood_fill(pos, triangles, normals, tri_edges, edge_pairs, et_start, et_count, et_data,
                      max_angle, visited, queue):
    """OptimizeTriangleDirection (§B.4 step 3), in place on ``triangles`` and ``normals``.

    Breadth-first layers across edges whose fold angle is <= max_angle; a neighbour facing the
    other way is flipped; a layer with more "closed" than "open" pairs is flipped as a whole."""
    T = triangles.shape[0]
    for seed in range(T):
        if visited[seed]:
            continue
        visited[seed] = True
        head = 0
        tail = 0
        queue[tail] = seed
        tail += 1
        n_open = 0
        n_closed = 0
        while head < tail:
            k = queue[head]
            head += 1
            for j in range(3):
                e = tri_edges[k, j]
                a = edge_pairs[e, 0]
                b = edge_pairs[e, 1]
                for x in range(et_count[e]):
                    u = et_data[et_start[e] + x]
                    if visited[u]:
                        continue
                    z = opposite_vertex(triangles, np.int64(k), a, b)
                    w = opposite_vertex(triangles, np.int64(u), a, b)
                    if fold_angle(pos, a, b, z, w) > max_angle:
                        continue
                    if (normals[k, 0] * normals[u, 0] + normals[k, 1] * normals[u, 1]
                            + normals[k, 2] * normals[u, 2]) < 0.0:
                        tmp = triangles[u, 1]
                        triangles[u, 1] = triangles[u, 2]
                        triangles[u, 2] = tmp
                        for c in range(3):
                            normals[u, c] = -normals[u, c]
                    d = v_sub(load3(pos, w), load3(pos, a))
                    dl = v_length(d)
                    side = 0.0
                    if dl > 0.0:
                        side = (normals[k, 0] * d[0] + normals[k, 1] * d[1] + normals[k, 2] * d[2]) / dl
                    if side <= 0.0:
                        n_open += 1
                    else:
                        n_closed += 1
                    visited[u] = True
                    queue[tail] = u
                    tail += 1
        if n_closed > n_open:
            for q in range(tail):
                k = queue[q]
                tmp = triangles[k, 1]
                triangles[k, 1] = triangles[k, 2]
                triangles[k, 2] = tmp
                for c in range(3):
                    normals[k, c] = -normals[k, c]


@kernel
def shear_links(pos, triangles, normals, edge_pairs, et_start, et_count, et_data, valid, move,
                link_src, link_dst, out_src, out_dst, connected):
    """Shear links p3<->p4 across near-flat, near-square quads (§B.9 step 2).

    ``link_src/link_dst`` are the existing links; returns how many entries of out_src/out_dst
    (sized for the worst case) were written; ``connected`` is a ``key_table`` for all links."""
    n = pos.shape[0]
    for k in range(link_src.shape[0]):
        key_insert(connected, np.int64(link_src[k]) * n + link_dst[k])
    count = 0
    for e in range(edge_pairs.shape[0]):
        if et_count[e] < 2:
            continue
        p1 = edge_pairs[e, 0]
        p2 = edge_pairs[e, 1]
        edge_len = v_length(v_sub(load3(pos, p1), load3(pos, p2)))
        if edge_len < 1e-8:
            continue
        for x in range(et_count[e]):
            for y in range(x + 1, et_count[e]):
                t1 = et_data[et_start[e] + x]
                t2 = et_data[et_start[e] + y]
                p3 = opposite_vertex(triangles, np.int64(t1), p1, p2)
                p4 = opposite_vertex(triangles, np.int64(t2), p1, p2)
                if not (move[p3] or move[p4]) or not (valid[p3] and valid[p4]):
                    continue
                d = (normals[t1, 0] * normals[t2, 0] + normals[t1, 1] * normals[t2, 1]
                     + normals[t1, 2] * normals[t2, 2])
                if abs(d) < SHEAR_NORMAL_DOT:
                    continue
                ratio = v_length(v_sub(load3(pos, p3), load3(pos, p4))) / edge_len
                if abs(ratio - 1.0) > SHEAR_SQUARE_TOLERANCE:
                    continue
                if not key_insert(connected, np.int64(p3) * n + p4):
                    continue
                key_insert(connected, np.int64(p4) * n + p3)
                out_src[count] = p3
                out_dst[count] = p4
                out_src[count + 1] = p4
                out_dst[count + 1] = p3
                count += 2
    return count


@kernel
def bending_pairs(pos, world, triangles, edge_pairs, et_start, et_count, et_data, valid, move,
                  want_volume, bend_vertices, bend_angle, bend_sign, volume_vertices, volume_rest, seen):
    """Bending and volume pairs per edge and triangle pair (§D.7 "Build").

    Returns (bending count, volume count) written into the worst-case sized outputs; ``seen``
    is a ``key_table`` for the registered volume vertex sets."""
    nb = 0
    nv = 0
    deg = 180.0 / math.pi
    for e in range(edge_pairs.shape[0]):
        v2 = edge_pairs[e, 0]
        v3 = edge_pairs[e, 1]
        for x in range(et_count[e]):
            for y in range(x + 1, et_count[e]):
                v0 = opposite_vertex(triangles, np.int64(et_data[et_start[e] + x]), v2, v3)
                v1 = opposite_vertex(triangles, np.int64(et_data[et_start[e] + y]), v2, v3)
                if not (valid[v0] and valid[v1] and valid[v2] and valid[v3]):
                    continue
                if not (move[v0] or move[v1] or move[v2] or move[v3]):
                    continue
                p0 = load3(pos, v0)
                p1 = load3(pos, v1)
                p2 = load3(pos, v2)
                p3 = load3(pos, v3)
                n1 = v_cross(v_sub(p2, p0), v_sub(p3, p0))
                n2 = v_cross(v_sub(p3, p1), v_sub(p2, p1))
                l1 = v_length(n1)
                l2 = v_length(n2)
                if l1 < 1e-12 or l2 < 1e-12:
                    continue  # degenerate triangle: no dihedral angle
                n1 = (n1[0] / l1, n1[1] / l1, n1[2] / l1)
                n2 = (n2[0] / l2, n2[1] / l2, n2[2] / l2)
                phi = portable.acos(v_dot(n1, n2))
                sign = -1.0 if v_dot(v_cross(n1, n2), v_sub(p3, p2)) < 0.0 else 1.0
                angle = phi * deg
                if angle < BENDING_MAX_ANGLE:
                    bend_vertices[nb, 0] = v0
                    bend_vertices[nb, 1] = v1
                    bend_vertices[nb, 2] = v2
                    bend_vertices[nb, 3] = v3
                    bend_angle[nb] = phi
                    bend_sign[nb] = sign
                    nb += 1
                if want_volume and VOLUME_MIN_ANGLE <= angle <= VOLUME_MAX_ANGLE:
                    # the 4-vertex set as one key: sort four indices (< 2^15 each)
                    a0 = min(v0, v1)
                    a1 = max(v0, v1)
                    b0 = min(v2, v3)
                    b1 = max(v2, v3)
                    lo0 = min(a0, b0)
                    lo1 = max(a0, b0)
                    hi0 = min(a1, b1)
                    hi1 = max(a1, b1)
                    key = ((np.int64(lo0) * 32768 + min(lo1, hi0)) * 32768 + max(lo1, hi0)) * 32768 + hi1
                    if not key_insert(seen, key):
                        continue
                    w0 = load3(world, v0)
                    volume_vertices[nv, 0] = v0
                    volume_vertices[nv, 1] = v1
                    volume_vertices[nv, 2] = v2
                    volume_vertices[nv, 3] = v3
                    volume_rest[nv] = 1000.0 / 6.0 * v_dot(
                        v_cross(v_sub(load3(world, v1), w0), v_sub(load3(world, v2), w0)),
                        v_sub(load3(world, v3), w0))
                    nv += 1
    return nb, nv
