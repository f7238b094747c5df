"""Emulated Unity transform hierarchy, stored as structure-of-arrays.

Unity semantics: Y up, left-handed, quaternions (x, y, z, w). A node has a local position,
rotation and scale relative to its parent; its world matrix is ``parent_local_to_world @
TRS(local)``, its world rotation ``parent_world_rotation * local_rotation`` and its lossy
scale the diagonal of ``inverse(R_world) @ local_to_world[:3, :3]`` (docs/solver.md §A.3), so
numbers read off a Unity scene carry over unchanged.

Nodes are stored parents-before-children, so one forward pass (``propagate_world``, a numba
kernel) updates every world pose. Per frame, ``propagate(plan)`` runs a precomputed
``scene.propagation.PropagationPlan``: only the subtrees of the nodes that move, in tiles of
whole trees whose pose rows are read into the cache first, by depth level with the nodes of a
level computed side by side, over ``threads`` threads, with the same bits as the forward pass.

**Deferred propagation.** ``propagate_later(plan)`` marks the plan's nodes stale instead of
computing them, as Unity does with the transforms a job writes: their world pose is computed
when something next asks for it. Reading any of the four derived arrays below (the
attribute access), ``flush()`` or the next ``propagate`` runs the stale plan first, unless
that propagation covers every stale node anyway (then the stale pass is skipped: it would be
overwritten from the same local poses). The cloth system defers the propagation of the
bones it writes back: when nothing reads them before the next frame's RESTORE and UPDATE
(no sink), that pass is never run; a sink, a test or a snapshot reading the world pose gets
exactly the bits an immediate propagation would have given. Code that keeps references to
the derived arrays across frames (the cloth system's kernel tables) must call ``flush()``
before reading them. Arrays (n = ``count``):

==================  ===========  ======  ================================================
field               shape        units   written by
==================  ===========  ======  ================================================
parent              (n,) int32   index   build; -1 for a root
local_position      (n, 3)       m       animation drivers (UPDATE), restore (RESTORE),
                                         cloth write-back (LATE_UPDATE)
local_rotation      (n, 4)       xyzw    same as local_position
local_scale         (n, 3)       1       animation drivers
world_position      (n, 3)       m       ``propagate`` (derived; reading flushes)
world_rotation      (n, 4)       xyzw    ``propagate`` (derived; reading flushes)
lossy_scale         (n, 3)       1       ``propagate`` (derived; reading flushes)
local_to_world      (n, 4, 4)    m       ``propagate`` (derived; reading flushes)
rest_local_*        like local   -       ``capture_rest_pose`` (build time)
==================  ===========  ======  ================================================
"""
from __future__ import annotations

from dataclasses import dataclass, field

import math

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels.math3d import load4, q_inverse, q_mul, q_normalize, q_rotate
from magica_py.scene.propagation import PropagationPlan, build_plan, propagate_node
from magica_py.kernels import portable


# ----------------------------------------------------------------------------- kernels
@kernel
def propagate_world(parent, local_position, local_rotation, local_scale,
                    world_position, world_rotation, lossy_scale, local_to_world):
    """Forward pass over parents-before-children nodes: world pose, lossy scale, matrices
    (``propagation.propagate_node`` for every node in index order; the plain full pass, used
    for a hierarchy's first pass and for sub-hierarchies)."""
    for i in range(parent.shape[0]):
        propagate_node(i, parent, local_position, local_rotation, local_scale,
                       world_position, world_rotation, lossy_scale, local_to_world)


@kernel
def restore_local_pose(indices, rest_position, rest_rotation, local_position, local_rotation):
    """RESTORE phase: write the build-time local position and rotation back (§A.2)."""
    for k in range(indices.shape[0]):
        i = indices[k]
        for c in range(3):
            local_position[i, c] = rest_position[i, c]
        for c in range(4):
            local_rotation[i, c] = rest_rotation[i, c]


@kernel
def world_to_local_pose(parent, local_to_world, world_rotation, i, position, rotation):
    """The local position and rotation that give node i the world pose (position, rotation)."""
    p = parent[i]
    if p < 0:
        return position, rotation
    # inverse of the parent's affine matrix applied to the point
    m = local_to_world[p]
    d = (position[0] - m[0, 3], position[1] - m[1, 3], position[2] - m[2, 3])
    a = m[0, 0]; b = m[0, 1]; c = m[0, 2]
    e = m[1, 0]; f = m[1, 1]; g = m[1, 2]
    h = m[2, 0]; k = m[2, 1]; l = m[2, 2]
    det = a * (f * l - g * k) - b * (e * l - g * h) + c * (e * k - f * h)
    if abs(det) < 1e-30:
        local_p = (0.0, 0.0, 0.0)
    else:
        inv = 1.0 / det
        local_p = (
            ((f * l - g * k) * d[0] + (c * k - b * l) * d[1] + (b * g - c * f) * d[2]) * inv,
            ((g * h - e * l) * d[0] + (a * l - c * h) * d[1] + (c * e - a * g) * d[2]) * inv,
            ((e * k - f * h) * d[0] + (b * h - a * k) * d[1] + (a * f - b * e) * d[2]) * inv,
        )
    local_r = q_normalize(q_mul(q_inverse(load4(world_rotation, p)), rotation))
    return local_p, local_r


# ----------------------------------------------------------------------------- python API
@dataclass
class BoneSpec:
    """One node to add: name, parent name (None for a root) and local TRS."""

    name: str
    parent: str | None = None
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    tags: dict = field(default_factory=dict)


class HierarchyError(ValueError):
    """A hierarchy that cannot be built (duplicate name, missing parent, cycle)."""


class _DerivedArray:
    """A derived pose array of ``TransformHierarchy`` (stored as ``_<name>``): reading the
    attribute runs a deferred propagation first, so a reader never sees a stale pose."""

    def __set_name__(self, owner, name):
        self.storage = "_" + name

    def __get__(self, hierarchy, owner=None):
        if hierarchy is None:
            return self
        if hierarchy._stale is not None:
            hierarchy.flush()
        return getattr(hierarchy, self.storage)

    def __set__(self, hierarchy, value):
        raise AttributeError(f"TransformHierarchy.{self.storage[1:]} is derived by propagation; "
                             "write into the array in place")


class TransformHierarchy:
    """All transforms of a scene in one structure-of-arrays (see the module docstring)."""

    def __init__(self, bones: list[BoneSpec]):
        order = _topological_order(bones)
        self.names: list[str] = [bones[i].name for i in order]
        self.index_of: dict[str, int] = {name: i for i, name in enumerate(self.names)}
        n = len(order)
        self.count = n
        self.parent = np.full(n, -1, dtype=np.int32)
        self.local_position = np.zeros((n, 3))
        self.local_rotation = np.zeros((n, 4))
        self.local_rotation[:, 3] = 1.0
        self.local_scale = np.ones((n, 3))
        self.tags: list[dict] = []
        for new, old in enumerate(order):
            b = bones[old]
            self.parent[new] = -1 if b.parent is None else self.index_of[b.parent]
            self.local_position[new] = b.position
            q = np.asarray(b.rotation, dtype=np.float64)
            norm = portable.norm(q) if np.isfinite(q).all() else math.nan
            if not np.isfinite(q).all() or norm < 1e-12:
                raise HierarchyError(f"transform {b.name!r}: rotation {tuple(b.rotation)} is not a valid quaternion (zero length or non-finite)")
            self.local_rotation[new] = q / norm
            self.local_scale[new] = b.scale
            self.tags.append(dict(b.tags))
        # the derived arrays, behind the flushing properties below
        self._world_position = np.zeros((n, 3))
        self._world_rotation = np.zeros((n, 4))
        self._lossy_scale = np.ones((n, 3))
        self._local_to_world = np.zeros((n, 4, 4))
        self._stale: PropagationPlan | None = None   # deferred plan (``propagate_later``)
        self.children: list[list[int]] = [[] for _ in range(n)]
        for i in range(n):  # sibling order = order of appearance in the bone list
            if self.parent[i] >= 0:
                self.children[self.parent[i]].append(i)
        self._threads = 1
        self._full_plan: PropagationPlan | None = None
        # the first pass also writes the constant bottom row of every matrix, which the
        # propagation plans leave alone
        propagate_world(*self._pose_arrays())
        self.capture_rest_pose()

    # -- derived arrays: reading one runs a deferred propagation first (``_DerivedArray``)
    world_position = _DerivedArray()
    world_rotation = _DerivedArray()
    lossy_scale = _DerivedArray()
    local_to_world = _DerivedArray()

    def _pose_arrays(self) -> tuple:
        return (self.parent, self.local_position, self.local_rotation, self.local_scale,
                self._world_position, self._world_rotation, self._lossy_scale,
                self._local_to_world)

    # -- queries
    def index(self, name: str) -> int:
        try:
            return self.index_of[name]
        except KeyError:
            raise KeyError(f"no transform named {name!r}") from None

    def descendants(self, i: int) -> list[int]:
        """Node i's subtree in pre-order (i first)."""
        out, stack = [], [i]
        while stack:
            j = stack.pop()
            out.append(j)
            stack.extend(reversed(self.children[j]))
        return out

    # -- updates
    @property
    def threads(self) -> int:
        """Threads a propagation may use (1 by default; plans built from now on use them)."""
        return self._threads

    @threads.setter
    def threads(self, value: int) -> None:
        value = int(value)
        if value < 1:
            raise ValueError(f"hierarchy threads: expected >= 1, got {value}")
        if value != self._threads:
            self._threads = value
            self._full_plan = None

    def plan(self, nodes=None) -> PropagationPlan:
        """A propagation plan (``scene/propagation.py``) for ``nodes`` and all their
        descendants, or for every node (None). Build it once for a set of nodes whose local
        poses change (the animated bones, the cloth bones) and pass it to ``propagate`` each
        frame; rebuild it when the set or ``threads`` changes."""
        if nodes is None:
            if self._full_plan is None or self._full_plan.threads != self._threads:
                self._full_plan = build_plan(self.parent, None, self._threads)
            return self._full_plan
        return build_plan(self.parent, nodes, self._threads)

    def propagate(self, plan: PropagationPlan | None = None) -> None:
        """Recompute world poses from the local poses: every node (``plan=None``), or the nodes
        of ``plan`` (``plan(nodes)``: the subtrees of nodes whose local pose changed). Either
        way one numba call, the same bits as a full pass over the nodes it covers. A deferred
        plan runs first unless ``plan`` covers all of its nodes."""
        plan = plan if plan is not None else self.plan()
        stale = self._stale
        if stale is not None:
            self._stale = None
            if not plan.covers(stale):
                stale.execute(*self._pose_arrays())
        plan.execute(*self._pose_arrays())

    def propagate_later(self, plan: PropagationPlan) -> None:
        """Mark the nodes of ``plan`` stale: their world poses are computed at the next read of
        a derived array, ``flush()`` or ``propagate`` (module docstring). Deferring a second
        plan that neither covers nor is covered by the stale one runs the stale one now."""
        stale = self._stale
        if stale is None or plan.covers(stale):
            self._stale = plan
        elif not stale.covers(plan):
            self.flush()
            self._stale = plan

    def flush(self) -> None:
        """Run the deferred propagation now (nothing when none is pending)."""
        stale = self._stale
        if stale is not None:
            self._stale = None
            stale.execute(*self._pose_arrays())

    @property
    def deferred(self) -> bool:
        """True while a deferred propagation is pending (world poses of its nodes are stale)."""
        return self._stale is not None

    def discard_deferred(self) -> None:
        """Forget a pending deferred propagation: for callers that have just written every
        derived array themselves (a snapshot restore)."""
        self._stale = None

    def capture_rest_pose(self) -> None:
        """Remember the current local pose as the rest (build-time) pose restored each frame."""
        self.rest_local_position = self.local_position.copy()
        self.rest_local_rotation = self.local_rotation.copy()
        self.rest_local_scale = self.local_scale.copy()

    def restore_rest_pose(self, indices: np.ndarray) -> None:
        restore_local_pose(indices, self.rest_local_position, self.rest_local_rotation,
                           self.local_position, self.local_rotation)

    def set_world_pose(self, i: int, position=None, rotation=None, propagate: bool = True) -> None:
        """Set node i's world position and/or rotation; its local pose is recomputed."""
        pos = tuple(self.world_position[i]) if position is None else tuple(map(float, position))
        rot = tuple(self.world_rotation[i]) if rotation is None else tuple(map(float, rotation))
        lp, lr = world_to_local_pose(self.parent, self.local_to_world, self.world_rotation, i, pos, rot)
        self.local_position[i] = lp
        self.local_rotation[i] = lr
        if propagate:
            self.propagate()

    # -- Unity Transform helpers (after propagate)
    def transform_point(self, i: int, p) -> np.ndarray:
        m = self.local_to_world[i]
        return portable.transform_points(m, p)

    def inverse_transform_point(self, i: int, p) -> np.ndarray:
        m = self.local_to_world[i]
        return portable.rotate_vectors(portable.inverse3(m[:3, :3]), np.asarray(p, dtype=np.float64) - m[:3, 3])

    def transform_direction(self, i: int, d) -> np.ndarray:
        """Rotate a direction by node i's world rotation (scale ignored, as Unity does)."""
        return np.asarray(q_rotate(tuple(self.world_rotation[i]), tuple(map(float, d))))

    def inverse_transform_direction(self, i: int, d) -> np.ndarray:
        q = self.world_rotation[i]
        return np.asarray(q_rotate((-q[0], -q[1], -q[2], q[3]), tuple(map(float, d))))


def _topological_order(bones: list[BoneSpec]) -> list[int]:
    """Indices of ``bones`` with every parent before its children (stable otherwise)."""
    by_name: dict[str, int] = {}
    for i, b in enumerate(bones):
        if b.name in by_name:
            raise HierarchyError(f"duplicate transform name {b.name!r}")
        by_name[b.name] = i
    children: dict[int, list[int]] = {}
    roots = []
    for i, b in enumerate(bones):
        if b.parent is None:
            roots.append(i)
        elif b.parent not in by_name:
            raise HierarchyError(f"transform {b.name!r}: parent {b.parent!r} does not exist")
        else:
            children.setdefault(by_name[b.parent], []).append(i)
    order: list[int] = []
    stack = list(reversed(roots))
    while stack:
        i = stack.pop()
        order.append(i)
        stack.extend(reversed(children.get(i, [])))
    if len(order) != len(bones):
        cyclic = sorted(bones[i].name for i in set(range(len(bones))) - set(order))
        raise HierarchyError(f"transform parents form a cycle through {cyclic}")
    return order
