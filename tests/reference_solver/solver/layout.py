"""The solver's global model: every team's ``ClothModel`` in one SoA, one chunk per team.

Team-local indices are offset to global ones, so that one numba call processes every team
(docs/tech-notes.md LAYOUT). ``SolverLayout`` owns the chunks: each pool (particles, baselines,
distance links, ...) has a first-fit ``ChunkAllocator``; adding a team takes a chunk of every
pool (freed space first, growing the pool at its end otherwise), removing a team frees its
chunks. Other teams' chunks never move, so their rows of the model and of the state tables
stay where they are, bit for bit (MagicaCloth2's TeamManager with chunked native arrays). ``-1`` stays ``-1`` when offsetting. The ``SolverModel`` handed to kernels is
read-only; it is rebuilt (outside the frame path) when a team is added or removed.

Ragged data use ``*_start``/``*_count`` pairs: per team (``team_*``) ranges into the
per-item arrays, and per particle ranges into link data (distance, children, triangles).
Team ids index the ``team_*`` arrays; a removed team keeps its id with zero counts and is
left out of ``live_teams``, the list the frame kernel iterates.
"""
from __future__ import annotations

import numpy as np

from reference_solver.solver.fields import F64, I32, U8, make_soa

V3 = (3,)
Q4 = (4,)

MODEL_FIELDS = [
    # per team
    ("team_particle_start", "team", (), I32, "first particle of the team"),
    ("team_particle_count", "team", (), I32, ""),
    ("team_baseline_start", "team", (), I32, "first baseline of the team"),
    ("team_baseline_count", "team", (), I32, ""),
    ("team_center_start", "team", (), I32, "range in center_fixed"),
    ("team_center_count", "team", (), I32, ""),
    ("team_edge_start", "team", (), I32, "range in edges"),
    ("team_edge_count", "team", (), I32, ""),
    ("team_triangle_start", "team", (), I32, "range in triangles"),
    ("team_triangle_count", "team", (), I32, ""),
    ("team_bend_start", "team", (), I32, "range in bend_*"),
    ("team_bend_count", "team", (), I32, ""),
    ("team_volume_start", "team", (), I32, "range in volume_*"),
    ("team_volume_count", "team", (), I32, ""),
    ("team_component_transform", "team", (), I32, "hierarchy node of the component"),
    ("team_init_scale", "team", V3, F64, "component lossy scale at build"),
    ("team_init_local_gravity", "team", V3, F64, "gravity reference in the center frame (docs/solver.md §C.2)"),
    ("team_has_lines", "team", (), U8, "1: the proxy has lines (E.2 runs)"),
    ("live_teams", "live", (), I32, "ids of the teams in use, ascending (the frame kernel's team list)"),
    # per particle
    ("transform_index", "particle", (), I32, "hierarchy node of the bone"),
    ("particle_team", "particle", (), I32, "team of the particle"),
    ("attribute", "particle", (), U8, "Fixed 1, Move 2, InvalidMotion 8, DisableCollision 0x10, ZeroDistance 0x20, Triangle 0x80"),
    ("parent", "particle", (), I32, "parent particle or -1"),
    ("root_index", "particle", (), I32, "root particle of a Move particle or -1"),
    ("depth", "particle", (), F64, "[0,1] normalised arc length from the root"),
    ("local_position", "particle", V3, F64, "cloth-local build position"),
    ("local_normal", "particle", V3, F64, ""),
    ("local_tangent", "particle", V3, F64, ""),
    ("bind_rotation", "particle", Q4, F64, "qinv(rot_from(n, t)) (B.4.8)"),
    ("vertex_to_transform_rotation", "particle", Q4, F64, "v2t (B.4.7)"),
    ("skin_bind_pose", "particle", (4, 4), F64, "inverse(TRS bone) @ init render local-to-world"),
    ("baseline_local_position", "particle", V3, F64, "rest position in the parent's frame (B.7)"),
    ("baseline_local_rotation", "particle", Q4, F64, "rest rotation relative to the parent (B.7)"),
    ("child_start", "particle", (), I32, "range in child_data"),
    ("child_count", "particle", (), I32, ""),
    ("distance_start", "particle", (), I32, "range in distance_target/rest"),
    ("distance_count", "particle", (), I32, ""),
    ("vertex_triangle_start", "particle", (), I32, "range in vertex_triangle_data"),
    ("vertex_triangle_count", "particle", (), I32, ""),
    # per baseline
    ("baseline_flags", "baseline", (), U8, "bit 0x01 IncludeLine"),
    ("baseline_start", "baseline", (), I32, "range in baseline_data"),
    ("baseline_count", "baseline", (), I32, ""),
    # link data
    ("baseline_data", "baseline_entry", (), I32, "particles of each baseline, parent first"),
    ("center_fixed", "center", (), I32, "fixed particles defining the center"),
    ("child_data", "child", (), I32, "children particles"),
    ("distance_target", "distance", (), I32, "partner particle"),
    ("distance_rest", "distance", (), F64, "signed rest length (+ vertical, - horizontal, 0 zero)"),
    ("edges", "edge", (2,), I32, ""),
    ("triangles", "triangle", (3,), I32, "oriented"),
    ("triangle_uv", "triangle", (3, 2), F64, "uv of the three corners (tangent reconstruction)"),
    ("vertex_triangle_data", "vertex_triangle", (), I32, "triangles of each vertex"),
    ("vertex_triangle_flip", "vertex_triangle", (), U8, "bit 1 flip normal, bit 2 flip tangent"),
    ("bend_vertices", "bend", (4,), I32, "v0 v1 v2 v3"),
    ("bend_rest_angle", "bend", (), F64, "rad"),
    ("bend_sign", "bend", (), F64, "+-1"),
    ("volume_vertices", "volume", (4,), I32, ""),
    ("volume_rest", "volume", (), F64, "1000 x rest volume"),
]
SolverModel = make_soa("SolverModel", MODEL_FIELDS)

INCLUDE_LINE = 0x01

# pools of per-item data (the ``per`` names of MODEL_FIELDS other than team and live)
POOLS = ("particle", "baseline", "baseline_entry", "center", "child", "distance", "edge",
         "triangle", "vertex_triangle", "bend", "volume")
# pool -> its team range fields in the model (particles: team_particle_start/count, ...)
TEAM_RANGE = {"particle": "particle", "baseline": "baseline", "center": "center", "edge": "edge",
              "triangle": "triangle", "bend": "bend", "volume": "volume"}


class ChunkAllocator:
    """First-fit allocator of contiguous ranges in ``[0, capacity)`` with a coalescing free list.

    Capacity grows exactly to what is needed at the end (no slack rows: a layout that never
    removed a team is the plain concatenation of its teams)."""

    def __init__(self):
        self.capacity = 0
        self.free: list[list[int]] = []  # sorted [start, length], coalesced

    def allocate(self, length: int) -> int:
        if length == 0:
            return 0
        for k, (start, free_length) in enumerate(self.free):
            if free_length >= length:
                if free_length == length:
                    self.free.pop(k)
                else:
                    self.free[k] = [start + length, free_length - length]
                return start
        start = self.capacity
        if self.free and self.free[-1][0] + self.free[-1][1] == self.capacity:
            start = self.free.pop()[0]  # a free tail block is extended
        self.capacity = start + length
        return start

    def release(self, start: int, length: int) -> None:
        if length == 0:
            return
        for s, n in self.free:
            if start < s + n and s < start + length:
                raise ValueError(f"chunk [{start}, {start + length}) is already free (double release)")
        self.free.append([start, length])
        self.free.sort()
        merged = [self.free[0]]
        for s, n in self.free[1:]:
            if merged[-1][0] + merged[-1][1] == s:
                merged[-1][1] += n
            else:
                merged.append([s, n])
        self.free = merged

    @property
    def used(self) -> int:
        return self.capacity - sum(n for _s, n in self.free)


def _get(model, name, default=None):
    value = getattr(model, name, None)
    return default if value is None else value


def _ranges(counts):
    counts = np.asarray(counts, dtype=np.int64)
    starts = np.zeros(len(counts), dtype=np.int64)
    if len(counts):
        starts[1:] = np.cumsum(counts)[:-1]
    return starts


def _off(a, base):
    a = np.asarray(a, dtype=np.int64)
    return np.where(a >= 0, a + base, -1)


def _team_parts(m) -> tuple[dict[str, int], dict[str, np.ndarray], dict[str, np.ndarray]]:
    """One model as (pool lengths, team-local per-item arrays, per-team values).

    Per-item index fields are returned *local*; ``SolverLayout.add`` offsets them."""
    n = int(m.particle_count)
    bl_count = np.asarray(m.baseline_count)
    tri = np.asarray(_get(m, "triangles", np.zeros((0, 3))), dtype=np.int64).reshape(-1, 3)
    edges = np.asarray(_get(m, "edges", np.zeros((0, 2))), dtype=np.int64).reshape(-1, 2)
    bend = np.asarray(_get(m, "bend_vertices", np.zeros((0, 4))), dtype=np.int64).reshape(-1, 4)
    vol = np.asarray(_get(m, "volume_vertices", np.zeros((0, 4))), dtype=np.int64).reshape(-1, 4)
    center = np.asarray(m.center_fixed, dtype=np.int64)
    lines = _get(m, "lines", np.zeros((0, 2)))
    vt_count = np.asarray(_get(m, "vertex_triangle_count", np.zeros(n)), dtype=np.int64)
    vt_start = np.asarray(_get(m, "vertex_triangle_start", _ranges(vt_count)), dtype=np.int64)
    vt_data = np.asarray(_get(m, "vertex_triangle_data", np.zeros(0)), dtype=np.int64)
    vt_flip = np.asarray(_get(m, "vertex_triangle_flip", np.zeros(len(vt_data))), dtype=np.int64)
    uv = np.asarray(_get(m, "triangle_uv", np.zeros((len(tri), 3, 2))), dtype=np.float64)
    if uv.shape != (len(tri), 3, 2):  # per-vertex uv (N, 2): gather per triangle corner
        uv = uv.reshape(-1, 2)[tri] if len(tri) else np.zeros((0, 3, 2))
    lengths = {"particle": n, "baseline": len(bl_count), "baseline_entry": len(np.asarray(m.baseline_data)),
               "center": len(center), "child": len(np.asarray(m.child_data)),
               "distance": len(np.asarray(m.distance_target)), "edge": len(edges), "triangle": len(tri),
               "vertex_triangle": len(vt_data), "bend": len(bend), "volume": len(vol)}
    items = {
        "transform_index": m.transform_index, "attribute": m.attribute, "parent": m.parent,
        "root_index": m.root_index, "depth": m.depth, "child_start": m.child_start,
        "child_count": m.child_count, "distance_start": m.distance_start,
        "distance_count": m.distance_count, "vertex_triangle_start": vt_start,
        "vertex_triangle_count": vt_count, "baseline_flags": m.baseline_flags,
        "baseline_start": m.baseline_start, "baseline_count": bl_count,
        "baseline_data": m.baseline_data, "center_fixed": center, "child_data": m.child_data,
        "distance_target": m.distance_target, "distance_rest": m.distance_rest, "edges": edges,
        "triangles": tri, "triangle_uv": uv, "vertex_triangle_data": vt_data,
        "vertex_triangle_flip": vt_flip, "bend_vertices": bend,
        "bend_rest_angle": _get(m, "bend_rest_angle", np.zeros(len(bend))),
        "bend_sign": _get(m, "bend_sign", np.ones(len(bend))), "volume_vertices": vol,
        "volume_rest": _get(m, "volume_rest", np.zeros(len(vol))),
    }
    for name in ("local_position", "local_normal", "local_tangent", "bind_rotation",
                 "vertex_to_transform_rotation", "skin_bind_pose", "baseline_local_position",
                 "baseline_local_rotation"):
        items[name] = getattr(m, name)
    team = {"team_component_transform": int(m.component_transform),
            "team_init_scale": np.asarray(m.init_scale, dtype=np.float64).reshape(3),
            "team_init_local_gravity": np.asarray(m.init_local_gravity_direction, dtype=np.float64).reshape(3),
            "team_has_lines": 1 if len(lines) > 0 else 0}
    return lengths, items, team


# index fields and the pool their values point into (offset by that pool's chunk start)
_INDEX_POOL = {
    "parent": "particle", "root_index": "particle", "child_start": "child",
    "distance_start": "distance", "vertex_triangle_start": "vertex_triangle",
    "baseline_start": "baseline_entry", "baseline_data": "particle", "center_fixed": "particle",
    "child_data": "particle", "distance_target": "particle", "edges": "particle",
    "triangles": "particle", "vertex_triangle_data": "triangle", "bend_vertices": "particle",
    "volume_vertices": "particle",
}
# CSR starts are offsets, not indices: -1 never occurs and 0 must be offset too
_START_FIELDS = ("child_start", "distance_start", "vertex_triangle_start", "baseline_start")
_FIELD_INFO = {name: (per, tuple(shape), dtype) for name, per, shape, dtype, _doc in MODEL_FIELDS}


class SolverLayout:
    """The chunked global model: ``add(model) -> team id``, ``remove(team)``, ``model()``.

    Team ids are never reused (a removed id keeps zero counts). ``chunks[team][pool]`` is the
    ``(start, count)`` of the team's chunk in each pool."""

    def __init__(self):
        self.allocators = {pool: ChunkAllocator() for pool in POOLS}
        self.chunks: list[dict[str, tuple[int, int]] | None] = []
        self.arrays: dict[str, np.ndarray] = {}
        for name, (per, shape, dtype) in _FIELD_INFO.items():
            self.arrays[name] = np.zeros((0,) + shape, dtype=dtype)
        self._model = None

    @property
    def team_count(self) -> int:
        """Team ids handed out so far (the length of every ``team_*`` array)."""
        return len(self.chunks)

    @property
    def live_teams(self) -> list[int]:
        return [t for t, c in enumerate(self.chunks) if c is not None]

    def capacity(self, pool: str) -> int:
        return self.allocators[pool].capacity

    def add(self, model) -> int:
        lengths, items, team_values = _team_parts(model)
        chunk = {pool: (self.allocators[pool].allocate(lengths[pool]), lengths[pool]) for pool in POOLS}
        for pool in POOLS:
            self._fit(pool, self.allocators[pool].capacity)
        team = len(self.chunks)
        self.chunks.append(chunk)
        self._fit("team", team + 1)
        for name, data in items.items():
            per, shape, dtype = _FIELD_INFO[name]
            start, count = chunk[per]
            data = np.asarray(data).reshape((-1,) + shape)
            if name in _INDEX_POOL:
                base = chunk[_INDEX_POOL[name]][0]
                data = np.asarray(data, dtype=np.int64) + base if name in _START_FIELDS else _off(data, base)
            self.arrays[name][start:start + count] = data
        self.arrays["particle_team"][chunk["particle"][0]:chunk["particle"][0] + lengths["particle"]] = team
        for pool, short in TEAM_RANGE.items():
            self.arrays[f"team_{short}_start"][team] = chunk[pool][0]
            self.arrays[f"team_{short}_count"][team] = chunk[pool][1]
        for name, value in team_values.items():
            self.arrays[name][team] = value
        self._model = None
        return team

    def remove(self, team: int) -> None:
        """Free the team's chunks (their rows reset to zero, ``particle_team`` to -1)."""
        if not 0 <= team < len(self.chunks) or self.chunks[team] is None:
            raise KeyError(f"no cloth team {team}")
        chunk = self.chunks[team]
        for name, (per, _shape, _dtype) in _FIELD_INFO.items():
            if per in chunk:
                start, count = chunk[per]
                self.arrays[name][start:start + count] = -1 if name == "particle_team" else 0
        for pool in POOLS:
            self.allocators[pool].release(*chunk[pool])
        for short in TEAM_RANGE.values():
            self.arrays[f"team_{short}_start"][team] = 0
            self.arrays[f"team_{short}_count"][team] = 0
        self.chunks[team] = None
        self._model = None

    def model(self) -> "SolverModel":
        """The read-only ``SolverModel`` of the current teams (cached until add/remove)."""
        if self._model is None:
            arrays = {}
            for name, a in self.arrays.items():
                a = a[:self._rows(_FIELD_INFO[name][0])].copy()   # the storage may hold spare rows
                a.flags.writeable = False
                arrays[name] = a
            live = np.asarray(self.live_teams, dtype=np.int32)
            live.flags.writeable = False
            arrays["live_teams"] = live
            self._model = SolverModel(**arrays)
        return self._model

    def _rows(self, per: str) -> int:
        """Rows of ``per`` in use: the pool's capacity, the team count for ``team`` (``live``,
        replaced by ``model()``: all)."""
        if per == "team":
            return self.team_count
        return self.allocators[per].capacity if per in self.allocators else None

    def _fit(self, per: str, size: int) -> None:
        """Make every array of ``per`` hold at least ``size`` rows (old rows kept, new rows zero,
        ``particle_team`` -1). The storage grows geometrically so that adding n teams copies
        O(n) rows, not O(n^2); ``model()`` publishes the rows in use only."""
        for name, (p, shape, dtype) in _FIELD_INFO.items():
            if p != per or name == "live_teams":
                continue
            old = self.arrays[name]
            if old.shape[0] >= size:
                continue
            new = np.zeros((max(size, 2 * old.shape[0]),) + shape, dtype=dtype)
            if name == "particle_team":
                new[:] = -1
            new[:old.shape[0]] = old
            self.arrays[name] = new


