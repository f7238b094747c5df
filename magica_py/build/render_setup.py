"""RenderSetupData: the transforms a BoneCloth collects at build time (docs/solver.md §B.1).

Vertex order is the reference's: every root is pushed on a LIFO stack in root-list order,
then each popped transform is appended and its children pushed in sibling order.  So the
*last* root is visited first and siblings come out in reverse order; parents always precede
their descendants.  The solver's Gauss-Seidel sweeps run in this order.

Arrays (N collected bones, all filled once here, read-only afterwards):

=========================  ==========  =====  ===============================================
transform_index            (N,) int32  index  hierarchy node of vertex i
parent_vertex              (N,) int32  index  vertex of the parent transform, -1 if not collected
world_position             (N, 3)      m      bone world position at build
world_rotation             (N, 4)      xyzw   bone world rotation at build
local_position/rotation    (N,3)/(N,4) m/xyzw bone local pose at build
lossy_scale                (N, 3)      1      bone lossy scale at build
root_vertices              (R,) int32  index  vertex of each root bone, **root-list order**
=========================  ==========  =====  ===============================================
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from magica_py.build.errors import BuildError
from magica_py.scene.hierarchy import propagate_world
from magica_py.kernels import portable

# m: a bone (or the component) further from the origin is refused at build. float64 still
# resolves 1e-7 m there; far beyond it the build's squared lengths overflow to inf and NaN.
POSITION_LIMIT = 1e9


@dataclass(frozen=True)
class RenderSetup:
    cloth_name: str
    transform_index: np.ndarray
    parent_vertex: np.ndarray
    world_position: np.ndarray
    world_rotation: np.ndarray
    local_position: np.ndarray
    local_rotation: np.ndarray
    lossy_scale: np.ndarray
    root_vertices: np.ndarray
    child_vertices: tuple   # per vertex: child vertices in the transforms' sibling order
    bone_names: tuple
    component_transform: int
    init_render_local_to_world: np.ndarray  # (4,4) TRS(pos, rot, lossy scale) of the component
    init_render_world_to_local: np.ndarray  # (4,4) its inverse: world -> cloth-local
    init_render_rotation: np.ndarray        # (4,) component world rotation at build
    init_scale: np.ndarray                  # (3,) component lossy scale at build
    # Bone pose in the component's frame, chained from the local poses below the component
    # (so identical rigs placed anywhere give bit-identical values); cloth-local position =
    # component_position, cloth-local directions = S_c^-1 (component_rotation · axis).
    component_position: np.ndarray          # (N,3) m
    component_rotation: np.ndarray          # (N,4) xyzw

    @property
    def count(self) -> int:
        return int(self.transform_index.shape[0])


def trs_matrix(position, rotation, scale) -> np.ndarray:
    """Unity TRS(position, rotation, scale) as a 4x4 matrix (column vectors)."""
    x, y, z, w = (float(c) for c in rotation)
    r = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])
    m = np.eye(4)
    m[:3, :3] = r * np.asarray(scale, dtype=np.float64)[None, :]
    m[:3, 3] = position
    return m


def collect_transforms(hierarchy, cloth_name: str, root_bones, component=None) -> RenderSetup:
    """Collect the cloth's bones from ``hierarchy`` (a ``TransformHierarchy``), §B.1.

    Raises ``BuildError`` for: no roots, a root index outside the hierarchy, a duplicate root,
    a root that lies below another root (its bones would be reached from two roots), a root
    with no child bones (nothing could move) and a zero lossy scale (no cloth-local space).
    """
    names = hierarchy.names
    n_nodes = hierarchy.count
    roots = [int(r) if r is not None else None for r in root_bones]
    if not roots:
        raise BuildError(cloth_name, "root_bones is empty: a BoneCloth needs at least one root bone")
    seen: dict[int, int] = {}
    for k, r in enumerate(roots):
        if r is None or not (0 <= r < n_nodes):
            raise BuildError(cloth_name, f"root_bones[{k}] = {r!r} is not a transform of the scene "
                                         f"(expected an index in [0, {n_nodes}))")
        if r in seen:
            raise BuildError(cloth_name, f"root bone {names[r]!r} is listed twice "
                                         f"(root_bones[{seen[r]}] and root_bones[{k}])")
        seen[r] = k
    # a root below another root would be collected twice (the reference silently drops it)
    root_set = set(roots)
    for r in roots:
        p = int(hierarchy.parent[r])
        while p >= 0:
            if p in root_set:
                raise BuildError(cloth_name, f"root bone {names[r]!r} lies below root bone {names[p]!r}: "
                                             f"its bones would be reached from two roots; list only {names[p]!r}")
            p = int(hierarchy.parent[p])
    for r in roots:
        if not hierarchy.children[r]:
            raise BuildError(cloth_name, f"root bone {names[r]!r} has no child bones: nothing to simulate "
                                         f"(a root is fixed; give it at least one child)")

    # LIFO traversal (§B.1); visited set kept for fidelity although roots are disjoint now
    order: list[int] = []
    visited = set()
    stack = list(roots)
    children = hierarchy.children
    while stack:
        t = stack.pop()
        if t in visited:
            continue
        visited.add(t)
        order.append(t)
        stack.extend(children[t])
    transform_index = np.asarray(order, dtype=np.int32)
    vertex_of = np.full(n_nodes, -1, dtype=np.int32)
    vertex_of[transform_index] = np.arange(transform_index.size, dtype=np.int32)
    hparent = hierarchy.parent[transform_index]
    parent_vertex = np.where(hparent >= 0, vertex_of[np.maximum(hparent, 0)], -1).astype(np.int32)

    lossy = hierarchy.lossy_scale[transform_index].copy()
    tiny = np.nonzero(np.any(np.abs(lossy) < 1e-12, axis=1))[0]
    if tiny.size:
        bad = [names[transform_index[i]] for i in tiny[:5]]
        raise BuildError(cloth_name, f"bones {bad} have a zero scale: their pose cannot be inverted")
    flipped = np.nonzero(np.any(lossy < 0.0, axis=1))[0]
    if flipped.size:
        raise BuildError(cloth_name, negative_scale_message(names[transform_index[flipped[0]]], lossy[flipped[0]], "in the rest pose"))

    if component is None:
        p = int(hierarchy.parent[roots[0]])
        component = p if p >= 0 else roots[0]
    component = int(component)
    if not (0 <= component < n_nodes):
        raise BuildError(cloth_name, f"component transform {component!r} is not a transform of the scene")
    c_scale = hierarchy.lossy_scale[component].copy()
    if np.any(np.abs(c_scale) < 1e-12):
        raise BuildError(cloth_name, f"component transform {names[component]!r} has a zero scale: "
                                     "cloth-local space is undefined")
    if np.any(c_scale < 0.0):
        raise BuildError(cloth_name, negative_scale_message(names[component], c_scale, "in the rest pose"))
    nodes = np.append(transform_index, component)
    far = np.nonzero(~np.all(np.abs(hierarchy.world_position[nodes]) <= POSITION_LIMIT, axis=1))[0]
    if far.size:
        node = int(nodes[far[0]])
        raise BuildError(cloth_name, f"bone {names[node]!r} is at {hierarchy.world_position[node].tolist()} m: "
                                     f"expected finite positions within {POSITION_LIMIT:g} m of the origin "
                                     "(a translation or unit scale far too large?)")
    l2w = trs_matrix(hierarchy.world_position[component], hierarchy.world_rotation[component], c_scale)
    rel_position, rel_rotation = _component_relative_pose(hierarchy, transform_index, roots, component)
    if rel_position is None:  # component not above the roots (or sheared): go through world space
        w2l = portable.inverse4(l2w)
        rel_position = portable.transform_points(w2l, hierarchy.world_position[transform_index])
        rel_rotation = _q_mul_many(_q_conj(hierarchy.world_rotation[component]),
                                   hierarchy.world_rotation[transform_index])
    return RenderSetup(
        cloth_name=cloth_name,
        transform_index=transform_index,
        parent_vertex=parent_vertex,
        world_position=hierarchy.world_position[transform_index].copy(),
        world_rotation=hierarchy.world_rotation[transform_index].copy(),
        local_position=hierarchy.local_position[transform_index].copy(),
        local_rotation=hierarchy.local_rotation[transform_index].copy(),
        lossy_scale=lossy,
        root_vertices=vertex_of[np.asarray(roots)].astype(np.int32),
        child_vertices=tuple([int(vertex_of[c]) for c in children[t]] for t in order),
        bone_names=tuple(names[t] for t in order),
        component_transform=component,
        init_render_local_to_world=l2w,
        init_render_world_to_local=portable.inverse4(l2w),
        init_render_rotation=hierarchy.world_rotation[component].copy(),
        init_scale=c_scale,
        component_position=rel_position,
        component_rotation=rel_rotation,
    )


def negative_scale_message(name: str, scale, when: str) -> str:
    """What a transform with a negative lossy scale among a cloth's gets (``when``: in the rest
    pose at build, at the start when a cloth system takes the models)."""
    return (f"transform {name!r} has a negative scale {tuple(round(float(x), 6) for x in scale)} {when}; "
            "negative scale is not supported (MagicaCloth2 refuses it at build too, docs/solver.md §H.7): "
            "use positive scales")


def _component_relative_pose(hierarchy, transform_index, roots, component):
    """Chain the local TRS of every node from below the component down to each bone (one
    ``propagate_world`` pass over a sub-hierarchy).  Returns (None, None) when a root is not
    below (or equal to) the component, or the component's matrix is not a plain TRS."""
    l2w = hierarchy.local_to_world[component]
    trs = trs_matrix(hierarchy.world_position[component], hierarchy.world_rotation[component],
                     hierarchy.lossy_scale[component])
    if not np.allclose(l2w, trs, rtol=1e-9, atol=1e-12):
        return None, None  # sheared component: cloth-local space is TRS, not the full matrix
    path: set[int] = set()
    for r in roots:
        node = r
        chain = []
        while node != component:
            chain.append(node)
            node = int(hierarchy.parent[node])
            if node < 0:
                return None, None
        path.update(chain)
    path.difference_update(int(t) for t in transform_index)
    nodes = np.concatenate([np.asarray(sorted(path), dtype=np.int32), transform_index]).astype(np.int32)
    local_of = {int(t): k for k, t in enumerate(nodes)}
    hparent = hierarchy.parent[nodes]
    parent = np.asarray([local_of.get(int(p), -1) for p in hparent], dtype=np.int32)
    n = nodes.shape[0]
    wp = np.zeros((n, 3))
    wr = np.zeros((n, 4))
    lossy = np.zeros((n, 3))
    m = np.zeros((n, 4, 4))
    propagate_world(parent, hierarchy.local_position[nodes].copy(), hierarchy.local_rotation[nodes].copy(),
                    hierarchy.local_scale[nodes].copy(), wp, wr, lossy, m)
    k = n - transform_index.shape[0]
    return wp[k:].copy(), wr[k:].copy()


def _q_conj(q):
    return np.array([-q[0], -q[1], -q[2], q[3]])


def _q_mul_many(a, b):
    """a (4,) times each row of b (N,4), Unity order (b applied first)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b[:, 0], b[:, 1], b[:, 2], b[:, 3]
    return np.stack([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz], axis=1)
