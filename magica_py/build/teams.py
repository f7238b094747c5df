"""Teams: every cloth's model copied into global structure-of-arrays, one contiguous chunk per
team per pool (docs/solver.md §B.10; MagicaCloth2's TeamManager with chunked native arrays).

One kernel call can then process every team: per-team ``team_<pool>_start`` / ``_count``
arrays (``team_table()``) say where each team's chunk lies, and every index stored inside a
data array is already **global** (particle indices offset by the team's particle start,
CSR starts offset by the start of the pool they point into, triangle indices by the team's
triangle start).  -1 stays -1.

Pools and their fields (``*`` offset by the particle start, ``->pool`` offset by that pool):

==============  ==============================================================================
particle        transform_index, attribute, parent*, root_index*, root_length, child_start->child,
                child_count, depth, local_position, local_normal, local_tangent, bind_rotation,
                vertex_to_transform_rotation, skin_bind_pose, vertex_uv, baseline_local_position,
                baseline_local_rotation, neighbor_start->neighbor, neighbor_count,
                vertex_triangle_start->vertex_triangle, vertex_triangle_count,
                distance_start->distance, distance_count, particle_team (owner, -1 = free)
child           child_data*
baseline        baseline_flags, baseline_start->baseline_data, baseline_count
baseline_data   baseline_data*
center_fixed    center_fixed*
edge            edges*          line  lines*          triangle  triangles*, triangle_uv
neighbor        neighbor_data*  vertex_triangle  vertex_triangle_data->triangle, vertex_triangle_flip
distance        distance_target*, distance_rest
bend            bend_vertices*, bend_rest_angle, bend_sign
volume          volume_vertices*, volume_rest
==============  ==============================================================================

``remove`` frees a team's chunks (merged into a first-fit free list, contents reset to the
fill value); ``add`` reuses freed space first and grows capacity geometrically otherwise.
Other teams' data never moves or changes, bit for bit.
"""
from __future__ import annotations

import numpy as np

# pool -> {field: offset pool or None}; the offset pool "particle" means particle indices
POOLS: dict[str, dict[str, str | None]] = {
    "particle": {
        "transform_index": None, "attribute": None, "parent": "particle", "root_index": "particle",
        "root_length": None, "child_start": "child", "child_count": None, "depth": None,
        "local_position": None, "local_normal": None, "local_tangent": None, "bind_rotation": None,
        "vertex_to_transform_rotation": None, "skin_bind_pose": None, "vertex_uv": None,
        "baseline_local_position": None, "baseline_local_rotation": None,
        "neighbor_start": "neighbor", "neighbor_count": None,
        "vertex_triangle_start": "vertex_triangle", "vertex_triangle_count": None,
        "distance_start": "distance", "distance_count": None,
    },
    "child": {"child_data": "particle"},
    "baseline": {"baseline_flags": None, "baseline_start": "baseline_data", "baseline_count": None},
    "baseline_data": {"baseline_data": "particle"},
    "center_fixed": {"center_fixed": "particle"},
    "edge": {"edges": "particle"},
    "line": {"lines": "particle"},
    "triangle": {"triangles": "particle", "triangle_uv": None},
    "neighbor": {"neighbor_data": "particle"},
    "vertex_triangle": {"vertex_triangle_data": "triangle", "vertex_triangle_flip": None},
    "distance": {"distance_target": "particle", "distance_rest": None},
    "bend": {"bend_vertices": "particle", "bend_rest_angle": None, "bend_sign": None},
    "volume": {"volume_vertices": "particle", "volume_rest": None},
}
_FIELD_POOL = {f: pool for pool, fs in POOLS.items() for f in fs}


class _Allocator:
    """First-fit allocator of contiguous ranges in [0, capacity) with coalescing free list."""

    def __init__(self):
        self.capacity = 0
        self.free: list[list[int]] = []  # sorted [start, length]

    def allocate(self, length: int) -> tuple[int, int | None]:
        """Returns (start, new_capacity or None when no growth is needed)."""
        if length == 0:
            return 0, None
        for k, (s, l) in enumerate(self.free):
            if l >= length:
                if l == length:
                    self.free.pop(k)
                else:
                    self.free[k] = [s + length, l - length]
                return s, None
        # grow: reuse a free tail block if there is one
        start = self.capacity
        if self.free and self.free[-1][0] + self.free[-1][1] == self.capacity:
            start = self.free.pop()[0]
        new_capacity = max(start + length, 2 * self.capacity, 64)
        if new_capacity > start + length:
            self.free.append([start + length, new_capacity - start - length])
        self.capacity = new_capacity
        return start, new_capacity

    def release(self, start: int, length: int) -> None:
        if length == 0:
            return
        self.free.append([start, length])
        self.free.sort()
        merged = [self.free[0]]
        for s, l in self.free[1:]:
            if merged[-1][0] + merged[-1][1] == s:
                merged[-1][1] += l
            else:
                merged.append([s, l])
        self.free = merged


class TeamRegistry:
    """Global SoA of all teams; ``arrays[field]`` is the full-capacity global array."""

    def __init__(self):
        self.arrays: dict[str, np.ndarray] = {}
        self._alloc = {pool: _Allocator() for pool in POOLS}
        self.models: dict[int, object] = {}
        self.start: dict[int, dict[str, int]] = {}
        self.count: dict[int, dict[str, int]] = {}
        self._next_id = 0
        self._table = None
        self.arrays["particle_team"] = np.full(0, -1, dtype=np.int32)

    # -- lifecycle
    def add(self, model) -> int:
        team = self._next_id
        self._next_id += 1
        starts, counts = {}, {}
        for pool, fields in POOLS.items():
            first = next(iter(fields))
            length = int(np.asarray(getattr(model, first)).shape[0])
            start, grown = self._alloc[pool].allocate(length)
            if grown is not None or not self._has_pool_arrays(pool, model):
                self._grow(pool, model)
            starts[pool], counts[pool] = start, length
        for pool, fields in POOLS.items():
            s, c = starts[pool], counts[pool]
            if c == 0:
                continue
            for field, offset_pool in fields.items():
                data = np.asarray(getattr(model, field))
                if offset_pool is not None:
                    off = starts[offset_pool]
                    data = np.where(data >= 0, data + off, data).astype(data.dtype)
                self.arrays[field][s:s + c] = data
        ps, pc = starts["particle"], counts["particle"]
        self.arrays["particle_team"][ps:ps + pc] = team
        self.models[team] = model
        self.start[team], self.count[team] = starts, counts
        self._table = None
        return team

    def remove(self, team: int) -> None:
        if team not in self.models:
            raise KeyError(f"team {team} is not registered")
        for pool, fields in POOLS.items():
            s, c = self.start[team][pool], self.count[team][pool]
            for field in fields:
                self.arrays[field][s:s + c] = _fill(self.arrays[field].dtype)
            if pool == "particle":
                self.arrays["particle_team"][s:s + c] = -1
            self._alloc[pool].release(s, c)
        del self.models[team], self.start[team], self.count[team]
        self._table = None

    # -- queries
    @property
    def team_ids(self) -> list[int]:
        return sorted(self.models)

    def team_table(self) -> dict[str, np.ndarray]:
        """Per active team (ascending id): ``team_id`` and ``team_<pool>_start`` / ``team_<pool>_count``
        int32 arrays, cached until the next add/remove (one kernel call over all teams)."""
        if self._table is None:
            ids = self.team_ids
            table = {"team_id": np.asarray(ids, dtype=np.int32)}
            for pool in POOLS:
                table["team_" + pool + "_start"] = np.asarray([self.start[t][pool] for t in ids], dtype=np.int32)
                table["team_" + pool + "_count"] = np.asarray([self.count[t][pool] for t in ids], dtype=np.int32)
            for a in table.values():
                a.flags.writeable = False
            self._table = table
        return self._table

    def team_slice(self, team: int, field: str) -> np.ndarray:
        """View of one team's chunk of a global array (global indices inside)."""
        pool = "particle" if field == "particle_team" else _FIELD_POOL[field]
        s, c = self.start[team][pool], self.count[team][pool]
        return self.arrays[field][s:s + c]

    def topology_groups(self) -> dict[str, list[int]]:
        """Active teams grouped by ``topology_key`` (crowds that can be batched side by side)."""
        groups: dict[str, list[int]] = {}
        for t in self.team_ids:
            groups.setdefault(self.models[t].topology_key, []).append(t)
        return groups

    # -- storage
    def _has_pool_arrays(self, pool, model) -> bool:
        return all(f in self.arrays for f in POOLS[pool])

    def _grow(self, pool: str, model) -> None:
        cap = self._alloc[pool].capacity
        for field in POOLS[pool]:
            proto = np.asarray(getattr(model, field))
            old = self.arrays.get(field)
            dtype = proto.dtype if old is None else old.dtype
            new = np.full((cap,) + proto.shape[1:], _fill(dtype), dtype=dtype)
            if old is not None:
                new[:old.shape[0]] = old
            self.arrays[field] = new
        if pool == "particle":
            old = self.arrays["particle_team"]
            new = np.full(cap, -1, dtype=np.int32)
            new[:old.shape[0]] = old
            self.arrays["particle_team"] = new


def _fill(dtype):
    return -1 if np.issubdtype(dtype, np.signedinteger) else 0
