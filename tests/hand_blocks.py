"""Hand-made blocks: a topology written by hand, placed by the solver's own allocator, for the
oracles of stage drivers (``*_block`` / ``*_lane``) on cases no rig builds (a bare ring of
edges, a three-particle chain).

``HandBlock`` puts a minimal cloth model (the fields ``blocks.BlockLayout`` reads: attributes,
parents, roots, depths, edges, baselines; every other per-particle value at its rest default)
into lane 0 of a block of a fresh ``BlockLayout``, and allocates fresh state tables at the
layout's capacities, as ``ClothSystem`` does. ``read`` / ``write`` move one field of the
team's particles in particle order (``lanes.RowTable.view`` / ``write``), so a test states its
case and its expectations per particle as before the lane form.
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from magica_py.solver import state as st
from magica_py.solver.blocks import BlockLayout
from magica_py.solver.parameters import PARAMETER_COUNT

IDENTITY = (0.0, 0.0, 0.0, 1.0)


def _csr(lists):
    start = np.cumsum([0] + [len(x) for x in lists[:-1]]).astype(np.int32) if lists else np.zeros(0, np.int32)
    count = np.asarray([len(x) for x in lists], np.int32)
    data = np.asarray([v for x in lists for v in x], np.int32)
    return start, count, data


def hand_model(attribute, parent=None, root_index=None, depth=None, edges=(), baselines=()):
    """A model with ``n = len(attribute)`` particles; ``parent`` / ``root_index`` default to -1,
    ``depth`` to 1; ``edges`` (E, 2) and ``baselines`` (lists of particles, parent first) as
    given; no distance links, triangles, bends or colliders."""
    attribute = np.asarray(attribute, np.uint8)
    n = attribute.shape[0]
    parent = np.full(n, -1, np.int32) if parent is None else np.asarray(parent, np.int32)
    children = [[int(c) for c in np.nonzero(parent == p)[0]] for p in range(n)]
    child_start, child_count, child_data = _csr(children)
    bl_start, bl_count, bl_data = _csr([list(b) for b in baselines])
    zeros3 = np.zeros((n, 3))
    quats = np.tile(IDENTITY, (n, 1))
    return SimpleNamespace(
        particle_count=n, attribute=attribute, parent=parent,
        root_index=np.full(n, -1, np.int32) if root_index is None else np.asarray(root_index, np.int32),
        child_start=child_start, child_count=child_count, child_data=child_data,
        distance_start=np.zeros(n, np.int32), distance_count=np.zeros(n, np.int32),
        distance_target=np.zeros(0, np.int32), distance_rest=np.zeros(0),
        baseline_flags=np.zeros(len(baselines), np.int32), baseline_start=bl_start, baseline_count=bl_count,
        baseline_data=bl_data, center_fixed=np.zeros(0, np.int32),
        edges=np.asarray(edges, np.int32).reshape(-1, 2),
        depth=np.ones(n) if depth is None else np.asarray(depth, np.float64),
        local_position=zeros3, local_normal=zeros3, local_tangent=zeros3, bind_rotation=quats,
        vertex_to_transform_rotation=quats, skin_bind_pose=np.tile(np.eye(4), (n, 1, 1)),
        baseline_local_position=zeros3, baseline_local_rotation=quats,
        init_scale=np.ones(3), init_local_gravity_direction=np.array([0.0, -1.0, 0.0]),
        transform_index=np.arange(n, dtype=np.int32), component_transform=0)


class HandBlock:
    """One team (``hand_model(...)``) in lane 0 of its block, with fresh state tables.

    ``PS``, ``EDS`` state; ``PM``, ``BI``, ``topology`` the layout's tables; ``P`` a zero
    parameter row per block (set the columns a driver reads); ``b``, ``lane`` its place."""

    def __init__(self, **model):
        self.model = hand_model(**model)
        self.layout = BlockLayout()
        self.team = self.layout.add(self.model)
        self.b, self.lane = self.layout.place(self.team)
        self.slots = self.layout.slots(self.team)
        self.PS = st.PARTICLE.allocate(self.layout.capacity("particle"))
        self.EDS = st.EDGE_STATE.allocate(max(1, self.layout.capacity("edge")))
        self.P = np.zeros((self.layout.block_count, PARAMETER_COUNT))

    @property
    def PM(self):
        return self.layout.particle_model

    @property
    def BI(self):
        return self.layout.block_ints

    @property
    def topology(self):
        return self.layout.topology

    def read(self, field: str) -> np.ndarray:
        """One particle field of the team, particle order ((n,) or (n, k), a copy)."""
        return st.PARTICLE.view(self.PS, field, self.slots["particle"], self.lane)

    def write(self, field: str, values) -> None:
        st.PARTICLE.write(self.PS, field, self.slots["particle"], self.lane, values)
