"""VirtualMesh bone import and the four connection modes (docs/solver.md §B.2, §B.3).

One vertex per collected bone.  Everything here is in **cloth-local space**: the component
transform's space at build time, scale included (§B.1).

Outputs of ``import_bones`` (N vertices):

=================  ============  =============================================================
local_position     (N, 3) m      ``W2L · P`` (cloth-local units)
local_normal       (N, 3) unit   bone +Y in cloth-local space
local_tangent      (N, 3) unit   bone +Z in cloth-local space
skin_bind_pose     (N, 4, 4)     ``inverse(TRS(P, R, S)) @ init_render_local_to_world``
=================  ============  =============================================================

``connect_*`` return lines (Ln, 2) and triangles (T, 3) int32, each row sorted ascending
(winding is fixed later by the proxy's flood fill, §B.4).  Orders follow the reference:
insertion-ordered sets everywhere, roots in list order (or the automatic chain).
"""
from __future__ import annotations

import math

import numpy as np

from magica_py.build.errors import BuildError
from magica_py.build.topology import edge_triangles, key_table, remove_duplicate_quads
from magica_py.jit import kernel
from magica_py.kernels.math3d import load3, load4, q_rotate, q_to_matrix, store3, v_length, v_normalize
from magica_py.kernels import portable

CONNECTION_MODES = ("line", "automatic_mesh", "sequential_loop_mesh", "sequential_non_loop_mesh")
MAX_LINKS_PER_VERTEX = 31      # Unity FixedList capacity (§B.3 step 4)
MAX_VERTICES_PER_LEVEL = 127
TRIANGLE_MAX_ANGLE = 120.0     # ProxyMeshBoneClothTriangleAngle, degrees
TRIANGLE_PAIR_ANGLE = 20.0     # ProxyMeshTrianglePairAngle, degrees


# ----------------------------------------------------------------------------- bone import
@kernel
def import_bone_vertices(world_position, world_rotation, lossy_scale, w2l, l2w,
                         local_position, local_normal, local_tangent, skin_bind_pose):
    """Per bone: cloth-local position, +Y/+Z axes and skin bind pose (§B.2)."""
    n = world_position.shape[0]
    for i in range(n):
        p = load3(world_position, i)
        r = load4(world_rotation, i)
        lp = (w2l[0, 0] * p[0] + w2l[0, 1] * p[1] + w2l[0, 2] * p[2] + w2l[0, 3],
              w2l[1, 0] * p[0] + w2l[1, 1] * p[1] + w2l[1, 2] * p[2] + w2l[1, 3],
              w2l[2, 0] * p[0] + w2l[2, 1] * p[1] + w2l[2, 2] * p[2] + w2l[2, 3])
        store3(local_position, i, lp)
        up = q_rotate(r, (0.0, 1.0, 0.0))
        fw = q_rotate(r, (0.0, 0.0, 1.0))
        nu = (w2l[0, 0] * up[0] + w2l[0, 1] * up[1] + w2l[0, 2] * up[2],
              w2l[1, 0] * up[0] + w2l[1, 1] * up[1] + w2l[1, 2] * up[2],
              w2l[2, 0] * up[0] + w2l[2, 1] * up[1] + w2l[2, 2] * up[2])
        nf = (w2l[0, 0] * fw[0] + w2l[0, 1] * fw[1] + w2l[0, 2] * fw[2],
              w2l[1, 0] * fw[0] + w2l[1, 1] * fw[1] + w2l[1, 2] * fw[2],
              w2l[2, 0] * fw[0] + w2l[2, 1] * fw[1] + w2l[2, 2] * fw[2])
        lu = v_length(up)
        lf = v_length(fw)
        un = v_normalize(nu)
        tn = v_normalize(nf)
        store3(local_normal, i, (un[0] * lu, un[1] * lu, un[2] * lu))
        store3(local_tangent, i, (tn[0] * lf, tn[1] * lf, tn[2] * lf))
        # inverse(TRS(P,R,S)) = [S^-1 R^T | -S^-1 R^T P], multiplied by l2w row by row
        r0, r1, r2 = q_to_matrix(r)
        s = load3(lossy_scale, i)
        for row in range(3):
            # row `row` of S^-1 R^T is column `row` of R divided by s[row]
            c0 = r0[row] / s[row]
            c1 = r1[row] / s[row]
            c2 = r2[row] / s[row]
            c3 = -(c0 * p[0] + c1 * p[1] + c2 * p[2])
            for b in range(4):
                skin_bind_pose[i, row, b] = (c0 * l2w[0, b] + c1 * l2w[1, b] + c2 * l2w[2, b]
                                             + c3 * l2w[3, b])
        for b in range(4):
            skin_bind_pose[i, 3, b] = l2w[3, b]


def import_bones(setup):
    """Bone import (§B.2): returns (local_position, local_normal, local_tangent, skin_bind_pose).

    Positions and axes come from the bone pose chained below the component
    (``setup.component_position/rotation``): the same numbers as ``W2L · P`` up to rounding,
    but bit-identical for identical rigs wherever they stand, so crowds share one topology."""
    n = setup.count
    local_normal = np.empty((n, 3))
    local_tangent = np.empty((n, 3))
    skin_bind_pose = np.empty((n, 4, 4))
    scratch = np.empty((n, 3))
    import_bone_vertices(setup.world_position, setup.world_rotation, setup.lossy_scale,
                         setup.init_render_world_to_local, setup.init_render_local_to_world,
                         scratch, local_normal, local_tangent, skin_bind_pose)
    inv_scale = np.eye(4)
    inv_scale[0, 0], inv_scale[1, 1], inv_scale[2, 2] = 1.0 / setup.init_scale
    import_bone_vertices(setup.component_position, setup.component_rotation, setup.lossy_scale,
                         inv_scale, setup.init_render_local_to_world,
                         scratch, local_normal, local_tangent, np.empty((n, 4, 4)))
    return setup.component_position.copy(), local_normal, local_tangent, skin_bind_pose


# ----------------------------------------------------------------------------- line mode
def connect_lines(parent_vertex: np.ndarray) -> np.ndarray:
    """Line mode: one line (parent, i) per vertex with a collected parent, rows sorted."""
    child = np.nonzero(parent_vertex >= 0)[0].astype(np.int32)
    par = parent_vertex[child]
    return np.stack([np.minimum(par, child), np.maximum(par, child)], axis=1).astype(np.int32).reshape(-1, 2)


# ----------------------------------------------------------------------------- mesh modes
def automatic_root_chain(roots: list[int], pos: np.ndarray) -> tuple[list[int], bool]:
    """AutomaticMesh root reordering into a nearest-neighbour chain (§B.3 step 2)."""
    pool = list(roots)
    chain = [pool.pop(0)]
    last_dist = 0.0
    while pool:
        r = chain[-1]
        d = [portable.norm(pos[m] - pos[r]) for m in pool]
        k = int(np.argmin(d))
        if last_dist == 0.0 or d[k] < 1.5 * last_dist:
            chain.append(pool.pop(k))
            last_dist = d[k] if last_dist == 0.0 else (last_dist + d[k]) * 0.5
        else:
            chain.reverse()
            last_dist = 0.0
    loop = len(chain) >= 3 and portable.norm(pos[chain[0]] - pos[chain[-1]]) < 1.5 * last_dist
    return chain, loop


@kernel
def _add_link(links, link_count, v, u):
    """Append u to v's insertion-ordered link set (capacity 31, like Unity's FixedList). Callers
    pass int64 ids: one signature (docs/tech-notes.md §7)."""
    c = link_count[v]
    for k in range(c):
        if links[v, k] == u:
            return
    if c < links.shape[1]:
        links[v, c] = u
        link_count[v] = c + 1


@kernel
def hierarchy_links(parent, child_start, child_count, child_data, roots, links, link_count,
                    level, root_line, walk, stack_vertex, stack_level):
    """Step 3: per root line a LIFO walk; each vertex links to its parent and its children."""
    w = 0
    for ri in range(roots.shape[0]):
        stack_vertex[0] = roots[ri]
        stack_level[0] = 0
        top = 1
        while top > 0:
            top -= 1
            v = stack_vertex[top]
            lv = stack_level[top]
            level[v] = lv
            root_line[v] = ri
            walk[w] = v
            w += 1
            if parent[v] >= 0:
                _add_link(links, link_count, np.int64(v), np.int64(parent[v]))
            for k in range(child_count[v]):
                c = child_data[child_start[v] + k]
                _add_link(links, link_count, np.int64(v), np.int64(c))
                stack_vertex[top] = c
                stack_level[top] = lv + 1
                top += 1


@kernel
def horizontal_links(pos, members, level_start, level_count, level, root_line, root_count, loop,
                     sequential, links, link_count):
    """Step 4: link each vertex to its nearest same-level candidate, then to every candidate
    within 1.5x that distance (all candidates in the sequential modes)."""
    last = root_count - 1
    for i in range(pos.shape[0]):
        s = level_start[level[i]]
        m = level_count[level[i]]
        ri = root_line[i]
        best = -1
        best_d = np.inf
        for pass_ in range(2):
            for k in range(m):
                j = members[s + k]
                if j == i:
                    continue
                rj = root_line[j]
                first_last = (ri == 0 and rj == last) or (ri == last and rj == 0)
                if not loop and root_count >= 2 and first_last:
                    continue
                if sequential and abs(ri - rj) > 1 and not (loop and first_last):
                    continue
                dx, dy, dz = pos[i, 0] - pos[j, 0], pos[i, 1] - pos[j, 1], pos[i, 2] - pos[j, 2]
                d = np.sqrt(dx * dx + dy * dy + dz * dz)   # products: Python's pow may round ``** 2`` otherwise
                if pass_ == 0:
                    if d < best_d:
                        best_d = d
                        best = j
                elif j != best and (sequential or d <= 1.5 * best_d):
                    _add_link(links, link_count, np.int64(i), np.int64(j))
            if best < 0:
                break
            if pass_ == 0:
                _add_link(links, link_count, np.int64(i), np.int64(best))


def connect_mesh(cloth_name: str, mode: str, pos: np.ndarray, parent_vertex: np.ndarray,
                 child_vertices, root_vertices, bone_names):
    """Mesh connection modes (§B.3): returns (lines (Ln,2), triangles (T,3), root_line (N,))."""
    n = pos.shape[0]
    roots = [int(r) for r in root_vertices]
    loop = mode == "sequential_loop_mesh"
    sequential = mode in ("sequential_loop_mesh", "sequential_non_loop_mesh")
    if mode == "automatic_mesh":
        roots, loop = automatic_root_chain(roots, pos)

    # 3. hierarchy links (LIFO walk per root line), 4. horizontal links per level
    child_count = np.asarray([len(c) for c in child_vertices], dtype=np.int32)
    child_data = np.fromiter((c for cs in child_vertices for c in cs), dtype=np.int32, count=int(child_count.sum()))
    child_start = np.zeros(n, dtype=np.int32)
    child_start[1:] = np.cumsum(child_count[:-1])
    links = np.full((n, MAX_LINKS_PER_VERTEX), -1, dtype=np.int32)
    link_count = np.zeros(n, dtype=np.int32)
    level = np.zeros(n, dtype=np.int32)
    root_line = np.full(n, -1, dtype=np.int32)
    walk = np.zeros(n, dtype=np.int32)
    hierarchy_links(parent_vertex, child_start, child_count, child_data, np.asarray(roots, dtype=np.int32),
                    links, link_count, level, root_line, walk, np.zeros(n, np.int32), np.zeros(n, np.int32))
    members = walk[np.argsort(level[walk], kind="stable")]  # level lists, walk order inside a level
    level_count = np.bincount(level, minlength=1).astype(np.int32)
    level_start = np.zeros_like(level_count)
    level_start[1:] = np.cumsum(level_count[:-1])
    crowded = np.nonzero(level_count > MAX_VERTICES_PER_LEVEL)[0]
    if crowded.size:
        lv = int(crowded[0])
        names = [bone_names[v] for v in members[level_start[lv]:level_start[lv] + 3]]
        raise BuildError(cloth_name, f"{int(level_count[lv])} bones share hierarchy level {lv} (e.g. {names}); "
                                     f"the mesh connection modes accept at most {MAX_VERTICES_PER_LEVEL}")
    horizontal_links(pos, members, level_start, level_count, level, root_line, len(roots), loop, sequential,
                     links, link_count)

    # 5. triangles from pairs of links (vectorised candidate tests)
    counts = link_count.astype(np.int64)
    flat = links[links >= 0].astype(np.int64)  # row-major: vertex order, then link order
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    tri_i, tri_a, tri_b = [], [], []
    for k in range(2, int(counts.max(initial=0)) + 1):
        verts = np.nonzero(counts == k)[0]
        if verts.size == 0:
            continue
        xs, ys = np.triu_indices(k, 1)
        tri_i.append(np.repeat(verts, xs.size))
        tri_a.append(flat[(starts[verts][:, None] + xs[None, :]).ravel()])
        tri_b.append(flat[(starts[verts][:, None] + ys[None, :]).ravel()])
    if tri_i:
        ti = np.concatenate(tri_i)
        ta = np.concatenate(tri_a)
        tb = np.concatenate(tri_b)
        order = np.argsort(ti, kind="stable")  # per vertex i in index order, pairs in link order
        ti, ta, tb = ti[order], ta[order], tb[order]
    else:
        ti = ta = tb = np.zeros(0, dtype=np.int64)
    va = pos[ta] - pos[ti]
    vb = pos[tb] - pos[ti]
    la = (va * va).sum(axis=1)
    lb = (vb * vb).sum(axis=1)
    ok = (la >= 1e-6) & (lb >= 1e-6)
    cosang = np.clip((va * vb).sum(axis=1) / np.sqrt(np.maximum(la * lb, 1e-300)), -1.0, 1.0)
    ok &= portable.acos_array(cosang) * (180.0 / math.pi) < TRIANGLE_MAX_ANGLE
    # deviation: the reference keeps collinear (zero-area) triangles; their normal is undefined
    cr = np.cross(va, vb)
    ok &= (cr * cr).sum(axis=1) > 1e-12 * la * lb
    ri, ra, rb = root_line[ti], root_line[ta], root_line[tb]
    ok &= ~((ri != ra) & (ri != rb) & (ra != rb))

    def is_main(x, y):
        return (parent_vertex[x] == y) | (parent_vertex[y] == x)

    ok &= is_main(ti, ta) | is_main(ti, tb) | is_main(ta, tb)
    ti, ta, tb = ti[ok], ta[ok], tb[ok]
    tris_sorted = np.sort(np.stack([ti, ta, tb], axis=1), axis=1)
    triangles = _unique_rows_in_order(tris_sorted)
    marked = np.concatenate([np.sort(np.stack([ti, ta], axis=1), axis=1),
                             np.sort(np.stack([ti, tb], axis=1), axis=1)])
    # edge candidates: every link (i, j) in vertex order then link order
    link_i = np.repeat(np.arange(n), counts)
    candidates = _unique_rows_in_order(np.sort(np.stack([link_i, flat], axis=1), axis=1))
    # 6. lines = candidates that are not marked triangle edges
    cand_key = candidates[:, 0] * n + candidates[:, 1]
    mark_key = marked[:, 0] * n + marked[:, 1]
    lines = candidates[~np.isin(cand_key, mark_key)]
    # 7. duplicate quad removal
    triangles = triangles.astype(np.int32).reshape(-1, 3)
    edge_pairs, et_start, et_count, et_data, _ = edge_triangles(triangles, n)
    removed = np.zeros(triangles.shape[0], dtype=np.bool_)
    pairs = int((et_count.astype(np.int64) * (et_count - 1) // 2).sum())
    remove_duplicate_quads(pos, triangles, edge_pairs, et_start, et_count, et_data,
                           math.radians(TRIANGLE_PAIR_ANGLE), removed, key_table(pairs))
    triangles = triangles[~removed]
    return lines.astype(np.int32).reshape(-1, 2), triangles, root_line


def _unique_rows_in_order(rows: np.ndarray) -> np.ndarray:
    """Unique rows of an int array, kept in order of first appearance (insertion-ordered set)."""
    if rows.shape[0] == 0:
        return rows.reshape(0, rows.shape[1]).astype(np.int64)
    key = np.zeros(rows.shape[0], dtype=np.int64)
    for c in range(rows.shape[1]):  # indices < 32768: one int64 key per row
        key = key * 32768 + rows[:, c]
    _, first = np.unique(key, return_index=True)
    return rows[np.sort(first)]


# ----------------------------------------------------------------------------- mesh statistics
def spherical_uv(pos: np.ndarray) -> np.ndarray:
    """Spherical vertex uv used only to derive triangle tangents (§B.2, CalcUVJob)."""
    n = pos.shape[0]
    center = 0.5 * (pos.min(axis=0) + pos.max(axis=0))
    d = pos - center
    length = portable.norm(d)
    l = np.where(length[:, None] > 1e-12, d / np.maximum(length, 1e-300)[:, None], 0.0)
    u = np.clip((portable.atan2_array(l[:, 0], l[:, 2]) + math.pi) / (2.0 * math.pi), 0.0, 1.0)
    v = np.clip((l[:, 1] - 1.0) / -2.0, 0.0, 1.0)
    return np.stack([v, u], axis=1) * 10.0 + np.arange(n)[:, None] * 0.0001234


def vertex_distances(pos: np.ndarray, lines: np.ndarray, triangles: np.ndarray) -> tuple[float, float]:
    """averageVertexDistance / maxVertexDistance from stride-sampled edges (§B.4)."""
    segs = []
    if triangles.shape[0]:
        t = triangles[::max(triangles.shape[0] // 100, 1)]
        segs += [t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]
    if lines.shape[0]:
        segs.append(lines[::max(lines.shape[0] // 100, 1)])
    if not segs:
        return 0.0, 0.0
    s = np.concatenate(segs)
    sq = portable.dot3(pos[s[:, 0]] - pos[s[:, 1]], pos[s[:, 0]] - pos[s[:, 1]])
    return float(math.sqrt(sq.mean())), float(math.sqrt(sq.max()))
