"""Blocks: teams of identical structure side by side, one per lane (docs/architecture.md, *Lane form*).

``BlockLayout`` is the solver's one allocator. Adding a team (a built ``ClothModel``) with its
*key* (everything the kernels branch on besides the state: the model's topology, its collider
shapes, its parameter row) puts it in the first block of the same key with a free lane, or
opens a new block. A block owns

* its **topology**, shared by its lanes, in block-local indices (particle j of the team, link
  k, ...): int32 segments of ``topology`` whose offsets and counts are the block's row of
  ``block_ints`` (``BI_*`` columns);
* **chunks** of every item pool: ``particle`` slots (``g = BI_G0 + j``), distance ``link``
  slots, ``edge``, ``triangle``, ``bend``, ``volume`` and ``collider`` slots, taken first-fit
  from freed space (``layout.ChunkAllocator``): other blocks never move, so their rows of
  every table stay where they are, bit for bit;
* the **per-lane model**: the packed read-only tables below, lane l holding its team's values
  (teams of one block share their topology but not their floats: a crowd's instances differ
  by round-off in their bind poses).

Team ids are never reused; ``team_block[t]`` / ``team_lane[t]`` place team t (-1 once
removed). A removed team frees its lane (the lane is left out of the block's work by the
``ENABLED`` flag); a block whose lanes are all free frees its chunks.
"""
from __future__ import annotations

import hashlib

import numpy as np

from magica_py.jit import kernel
from magica_py.solver.lanes import LANES, QUATERNION, RowTable

# ----------------------------------------------------------------------------- per-lane model tables
PARTICLE_MODEL = RowTable("particle model", "particle slot")
_m = PARTICLE_MODEL.add
DEPTH = _m("depth", 1, "[0,1] normalised arc length from the root (B.8)")
# C.1's bind pose applied to the build vertex: ``skin_bind_pose @ (local position, 1)``, ``@ (local
# normal, 0)``, ``@ (local tangent, 0)`` (``bound_vectors`` below), constant per vertex, so computed
# once when the lane is written; the skinning then applies only the bone's matrix each frame
SKIN_BOUND_POSITION = _m("skin_bound_position", 4, "bind pose @ (cloth-local build position (B.2), 1)")
SKIN_BOUND_NORMAL = _m("skin_bound_normal", 4, "bind pose @ (cloth-local unit normal (B.4), 0)")
SKIN_BOUND_TANGENT = _m("skin_bound_tangent", 4, "bind pose @ (cloth-local unit tangent (B.4), 0)")
BIND_ROTATION = _m("bind_rotation", 4, "xyzw; qinv(rot_from(n, t)) (B.4.8)", QUATERNION)
VERTEX_TO_TRANSFORM_ROTATION = _m("vertex_to_transform_rotation", 4, "xyzw; v2t (B.4.7)", QUATERNION)
BASELINE_LOCAL_POSITION = _m("baseline_local_position", 3, "m; rest position in the parent's frame (B.7)")
BASELINE_LOCAL_ROTATION = _m("baseline_local_rotation", 4, "xyzw; rest rotation relative to the parent (B.7)",
                             QUATERNION)
del _m

# the depth curves of a block's parameter row evaluated at each particle's depth (EvaluateCurve,
# §0.3; ``curve_at``, no clamp): written when a lane is placed or its parameters change
# (``particle_parameters_block``), so that the stages read them per lane instead of looking the
# curve up by depth in the step (a gather that stops the lane loops from vectorising)
PARTICLE_PARAMETERS = RowTable("particle parameters", "particle slot")
_q = PARTICLE_PARAMETERS.add
CURVE_DAMPING = _q("damping", 1, "D.1 damping curve (x0.2 applied) at the depth")
CURVE_RADIUS = _q("radius", 1, "m; D.8 collision radius curve at the depth")
CURVE_DISTANCE_STIFFNESS = _q("distance_stiffness", 1, "D.4 stiffness curve at the depth")
CURVE_RESTORATION_STIFFNESS = _q("restoration_stiffness", 1, "D.6 stiffness curve (x0.2 applied) at the depth")
CURVE_LIMIT_ANGLE = _q("limit_angle", 1, "deg; D.5 limit angle curve at the depth")
CURVE_MAX_DISTANCE = _q("max_distance", 1, "m; D.9 max distance curve at the depth squared")
CURVE_BACKSTOP_DISTANCE = _q("backstop_distance", 1, "m; D.9 backstop distance curve at the depth squared")
del _q

TEAM_MODEL = RowTable("team model", "block")
INIT_SCALE = TEAM_MODEL.add("init_scale", 3, "component lossy scale at build (B.10)", fill=1.0)
INIT_LOCAL_GRAVITY = TEAM_MODEL.add("init_local_gravity", 3, "gravity reference in the center frame (C.2)")

LINK_MODEL = RowTable("distance link model", "distance link slot")
DISTANCE_REST = LINK_MODEL.add("distance_rest", 1, "m; signed rest length (+ vertical, - horizontal, 0 zero) (B.9)")

TRIANGLE_MODEL = RowTable("triangle model", "triangle slot")
TRIANGLE_UV = TRIANGLE_MODEL.add("triangle_uv", 6, "uv of the three corners, (u0, v0, u1, v1, u2, v2) (E.3)")

BEND_MODEL = RowTable("bend model", "bend slot")
BEND_REST_ANGLE = BEND_MODEL.add("bend_rest_angle", 1, "rad (D.7)")
BEND_SIGN = BEND_MODEL.add("bend_sign", 1, "+-1 (D.7)")

VOLUME_MODEL = RowTable("volume model", "volume slot")
VOLUME_REST = VOLUME_MODEL.add("volume_rest", 1, "1000 x rest volume (D.7)")


def bound_vectors(bind_pose, local_position, local_normal, local_tangent):
    """The build's half of C.1 for every vertex of a team: its bind pose ``bind_pose`` (N, 4, 4)
    applied to its cloth-local position (w = 1), normal and tangent (w = 0), each (N, 3): the
    4-vectors ``B @ (v, w)``. Returns (N, 3, 4): the position's, normal's and tangent's, which
    ``center.skin_block`` takes to world space each frame (``SKIN_BOUND_*``). The bind pose is
    fixed at build, so this is computed once when a lane is written. numpy: each row's four
    products summed left to right, with no fused multiply-add (numba emits none either), the
    order in which the skinning computed it per frame before; tests/test_skinning.py checks the
    bits against the reference solver's per-frame ``bind_point``."""
    out = np.empty((bind_pose.shape[0], 3, 4))
    for k, (v, w) in enumerate(((local_position, 1.0), (local_normal, 0.0), (local_tangent, 0.0))):
        for r in range(4):
            row = bind_pose[:, r]
            out[:, k, r] = row[:, 0] * v[:, 0] + row[:, 1] * v[:, 1] + row[:, 2] * v[:, 2] + row[:, 3] * w
    return out


# ----------------------------------------------------------------------------- block ints
# columns of ``block_ints`` (B, BLOCK_INT_COUNT) int32: counts, chunk starts, topology offsets
_BLOCK_INT_NAMES = (
    # sizes
    "n", "width", "lanes_used",
    # chunk starts (slots) and counts
    "g0", "link0", "links", "edge0", "edges", "triangle0", "triangles", "bend0", "bends", "volume0", "volumes",
    "collider0", "colliders", "baselines", "centers", "has_lines",
    # topology segments (offsets into ``topology``)
    "attribute", "parent", "root_index", "child_start", "child_count", "child_data",
    "distance_start", "distance_count", "distance_target",
    "baseline_flags", "baseline_start", "baseline_count", "baseline_data", "center_fixed",
    "edge_pairs", "triangle_corners", "vertex_triangle_start", "vertex_triangle_count",
    "vertex_triangle_data", "vertex_triangle_flip", "bend_vertices", "volume_vertices",
    "collider_shape", "collider_direction", "collider_reverse", "collider_aligned",
)
BLOCK_INT_COUNT = len(_BLOCK_INT_NAMES)
BI = {name: i for i, name in enumerate(_BLOCK_INT_NAMES)}
BI_N, BI_WIDTH, BI_LANES_USED = BI["n"], BI["width"], BI["lanes_used"]
BI_G0, BI_LINK0, BI_LINKS = BI["g0"], BI["link0"], BI["links"]
BI_EDGE0, BI_EDGES, BI_TRIANGLE0, BI_TRIANGLES = BI["edge0"], BI["edges"], BI["triangle0"], BI["triangles"]
BI_BEND0, BI_BENDS, BI_VOLUME0, BI_VOLUMES = BI["bend0"], BI["bends"], BI["volume0"], BI["volumes"]
BI_COLLIDER0, BI_COLLIDERS = BI["collider0"], BI["colliders"]
BI_BASELINES, BI_CENTERS, BI_HAS_LINES = BI["baselines"], BI["centers"], BI["has_lines"]
BI_ATTRIBUTE, BI_PARENT, BI_ROOT_INDEX = BI["attribute"], BI["parent"], BI["root_index"]
BI_CHILD_START, BI_CHILD_COUNT, BI_CHILD_DATA = BI["child_start"], BI["child_count"], BI["child_data"]
BI_DISTANCE_START, BI_DISTANCE_COUNT, BI_DISTANCE_TARGET = (
    BI["distance_start"], BI["distance_count"], BI["distance_target"])
BI_BASELINE_FLAGS, BI_BASELINE_START, BI_BASELINE_COUNT, BI_BASELINE_DATA = (
    BI["baseline_flags"], BI["baseline_start"], BI["baseline_count"], BI["baseline_data"])
BI_CENTER_FIXED = BI["center_fixed"]
BI_EDGE_PAIRS, BI_TRIANGLE_CORNERS = BI["edge_pairs"], BI["triangle_corners"]
BI_VERTEX_TRIANGLE_START, BI_VERTEX_TRIANGLE_COUNT = BI["vertex_triangle_start"], BI["vertex_triangle_count"]
BI_VERTEX_TRIANGLE_DATA, BI_VERTEX_TRIANGLE_FLIP = BI["vertex_triangle_data"], BI["vertex_triangle_flip"]
BI_BEND_VERTICES, BI_VOLUME_VERTICES = BI["bend_vertices"], BI["volume_vertices"]
BI_COLLIDER_SHAPE, BI_COLLIDER_DIRECTION = BI["collider_shape"], BI["collider_direction"]
BI_COLLIDER_REVERSE, BI_COLLIDER_ALIGNED = BI["collider_reverse"], BI["collider_aligned"]

# columns of ``team_ints`` (B, TEAM_INT_COUNT * LANES) int32, lane l of field f at f * LANES + l
TI_TEAM = 0 * LANES                  # team id of the lane, -1 when free
TI_COMPONENT = 1 * LANES             # hierarchy node of the cloth component
TI_ANCHOR = 2 * LANES                # hierarchy node of the inertia anchor or -1 (parameter inertia.anchor)
TI_CULLING_REFERENCE = 3 * LANES     # hierarchy node of the culling reference or -1
TEAM_INT_COUNT = 4

@kernel
def lane_width(BI, b):
    """Lanes a stage runs in block b: its width, at most ``LANES``. Bounding the lane loops by
    the constant ``LANES`` lets LLVM prove that the rows of one item (``LANES`` apart) do not
    overlap, so the loops vectorise without run-time checks."""
    return min(BI[b, BI_WIDTH], LANES)


# the pools whose items have chunks (slot ranges) per block
POOLS = ("particle", "link", "edge", "triangle", "bend", "volume", "collider", "topology")

SPHERE, CAPSULE, PLANE = 0, 1, 2


class ChunkAllocator:
    """First-fit allocator of contiguous ranges in ``[0, capacity)`` with a coalescing free list.

    Capacity grows exactly to what is needed at the end (no slack: a layout that never
    removed a block is the plain concatenation of its blocks)."""

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


def _i32(a, shape=(-1,)) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(a, dtype=np.int64).reshape(shape), dtype=np.int32)


def _get(model, name, default):
    value = getattr(model, name, None)
    return default if value is None else value


def model_topology(model, collider_shapes=()) -> dict[str, np.ndarray]:
    """The block-local int data of a team (everything its block's lanes share), by
    ``block_ints`` column name, each a flat int32 array; ``collider_shapes`` is
    ``[(shape, direction, reverse, aligned), ...]`` of its collider slots."""
    n = int(model.particle_count)
    tri = _i32(_get(model, "triangles", np.zeros((0, 3))), (-1, 3))
    edges = _i32(_get(model, "edges", np.zeros((0, 2))), (-1, 2))
    bends = _i32(_get(model, "bend_vertices", np.zeros((0, 4))), (-1, 4))
    volumes = _i32(_get(model, "volume_vertices", np.zeros((0, 4))), (-1, 4))
    vt_count = _i32(_get(model, "vertex_triangle_count", np.zeros(n)))
    vt_start = _get(model, "vertex_triangle_start", None)
    if vt_start is None:
        vt_start = np.concatenate([[0], np.cumsum(vt_count)[:-1]]) if n else np.zeros(0)
    vt_data = _i32(_get(model, "vertex_triangle_data", np.zeros(0)))
    cs = np.asarray(collider_shapes, dtype=np.int64).reshape(-1, 4)
    return {
        "attribute": _i32(model.attribute), "parent": _i32(model.parent), "root_index": _i32(model.root_index),
        "child_start": _i32(model.child_start), "child_count": _i32(model.child_count),
        "child_data": _i32(model.child_data),
        "distance_start": _i32(model.distance_start), "distance_count": _i32(model.distance_count),
        "distance_target": _i32(model.distance_target),
        "baseline_flags": _i32(model.baseline_flags), "baseline_start": _i32(model.baseline_start),
        "baseline_count": _i32(model.baseline_count), "baseline_data": _i32(model.baseline_data),
        "center_fixed": _i32(model.center_fixed),
        "edge_pairs": edges.reshape(-1), "triangle_corners": tri.reshape(-1),
        "vertex_triangle_start": _i32(vt_start), "vertex_triangle_count": vt_count,
        "vertex_triangle_data": vt_data,
        "vertex_triangle_flip": _i32(_get(model, "vertex_triangle_flip", np.zeros(len(vt_data)))),
        "bend_vertices": bends.reshape(-1), "volume_vertices": volumes.reshape(-1),
        "collider_shape": _i32(cs[:, 0]), "collider_direction": _i32(cs[:, 1]),
        "collider_reverse": _i32(cs[:, 2]), "collider_aligned": _i32(cs[:, 3]),
        # the sizes that are not segment lengths
        "_lines": np.asarray([len(_get(model, "lines", np.zeros((0, 2))))], dtype=np.int32),
    }


def topology_key(topology: dict[str, np.ndarray], extra: bytes = b"") -> str:
    """The block key of a team: a hash of its block-local int data and ``extra`` (the
    parameter row and the collider structure as the system packs them)."""
    h = hashlib.sha256()
    for name in sorted(topology):
        h.update(name.encode())
        h.update(np.ascontiguousarray(topology[name], dtype=np.int32).tobytes())
    h.update(extra)
    return h.hexdigest()


class Block:
    """One block's bookkeeping (Python side): key, lanes, chunks."""

    def __init__(self, key: str, chunks: dict[str, tuple[int, int]], n: int):
        self.key = key
        self.chunks = chunks
        self.n = n
        self.lanes: list[int] = [-1] * LANES   # team id per lane, -1 free

    @property
    def used(self) -> list[int]:
        return [lane for lane, team in enumerate(self.lanes) if team >= 0]

    @property
    def width(self) -> int:
        used = self.used
        return (max(used) + 1) if used else 0


class BlockLayout:
    """Teams in blocks (module docstring). ``add(model, key_extra, collider_shapes) -> team``,
    ``remove(team)``; the tables: ``block_ints``, ``team_ints``, ``topology``,
    ``particle_transform`` (G, LANES) int32 hierarchy node of every particle slot and lane,
    and the per-lane model tables ``particle_model`` (PM), ``team_model`` (TM),
    ``link_model`` (LM), ``triangle_model``, ``bend_model``, ``volume_model``.

    ``blocks[b]`` is None for a freed block id (ids are reused for new blocks)."""

    def __init__(self):
        self.allocators = {pool: ChunkAllocator() for pool in POOLS}
        self.blocks: list[Block | None] = []
        self.team_block: list[int] = []
        self.team_lane: list[int] = []
        self.topology = np.zeros(0, dtype=np.int32)
        self.block_ints = np.zeros((0, BLOCK_INT_COUNT), dtype=np.int32)
        self.team_ints = np.full((0, TEAM_INT_COUNT * LANES), -1, dtype=np.int32)
        self.particle_transform = np.zeros((0, LANES), dtype=np.int32)
        self.collider_transform = np.zeros((0, LANES), dtype=np.int32)
        self.particle_model = PARTICLE_MODEL.allocate(0)
        self.team_model = TEAM_MODEL.allocate(0)
        self.link_model = LINK_MODEL.allocate(0)
        self.triangle_model = TRIANGLE_MODEL.allocate(0)
        self.bend_model = BEND_MODEL.allocate(0)
        self.volume_model = VOLUME_MODEL.allocate(0)
        self.version = 0   # incremented by every add / remove (tables may have been reallocated)

    # ------------------------------------------------------------------ queries
    @property
    def team_count(self) -> int:
        """Team ids handed out so far."""
        return len(self.team_block)

    @property
    def live_teams(self) -> list[int]:
        return [t for t, b in enumerate(self.team_block) if b >= 0]

    @property
    def block_count(self) -> int:
        return len(self.blocks)

    def capacity(self, pool: str) -> int:
        return self.allocators[pool].capacity

    def place(self, team: int) -> tuple[int, int]:
        """(block, lane) of a live team."""
        if not 0 <= team < len(self.team_block) or self.team_block[team] < 0:
            raise KeyError(f"no cloth team {team}")
        return self.team_block[team], self.team_lane[team]

    def particle_slots(self, team: int) -> np.ndarray:
        """The particle slots (g) of a team, in particle order."""
        b, _lane = self.place(team)
        g0 = int(self.block_ints[b, BI_G0])
        return np.arange(g0, g0 + int(self.block_ints[b, BI_N]))

    def collider_slots(self, team: int) -> np.ndarray:
        b, _lane = self.place(team)
        c0 = int(self.block_ints[b, BI_COLLIDER0])
        return np.arange(c0, c0 + int(self.block_ints[b, BI_COLLIDERS]))

    def segment(self, block: int, name: str, length: int | None = None) -> np.ndarray:
        """A block's topology segment ``name`` (a view); ``length`` defaults to the count stored
        with it."""
        start = int(self.block_ints[block, BI[name]])
        if length is None:
            length = self._segment_lengths[block][name]
        return self.topology[start:start + length]

    # ------------------------------------------------------------------ add / remove
    def key_of(self, model, key_extra: bytes = b"", collider_shapes=()) -> str:
        """The block key a team with this model, parameter row and colliders would have."""
        return topology_key(model_topology(model, collider_shapes), key_extra)

    def slots(self, team: int) -> dict[str, np.ndarray]:
        """The item indices of a live team in every pool (particle slots in particle order,
        its collider slots in its cloth's collider order, ...): its block's chunks."""
        b, _lane = self.place(team)
        return {pool: np.arange(start, start + count) for pool, (start, count) in self.blocks[b].chunks.items()}

    def add(self, model, key_extra: bytes = b"", collider_shapes=(), collider_nodes=(), team: int | None = None) -> int:
        """Place a built team; returns its team id (the next one, or ``team``: a team moved to
        another block keeps its id). ``key_extra``: what else its block's lanes must share
        (the packed parameter row); ``collider_shapes``: ``[(shape, direction, reverse,
        aligned), ...]`` of its collider slots, ``collider_nodes`` their hierarchy nodes."""
        topo = model_topology(model, collider_shapes)
        key = topology_key(topo, key_extra)
        if team is None:
            team = len(self.team_block)
        while len(self.team_block) <= team:
            self.team_block.append(-1)
            self.team_lane.append(-1)
        if self.team_block[team] >= 0:
            raise ValueError(f"team {team} is placed already")
        for b, block in enumerate(self.blocks):
            if block is not None and block.key == key and -1 in block.lanes:
                lane = block.lanes.index(-1)
                break
        else:
            b = self._open_block(key, model, topo)
            lane = 0
        block = self.blocks[b]
        block.lanes[lane] = team
        self.team_block[team] = b
        self.team_lane[team] = lane
        self._write_lane(b, lane, team, model, collider_nodes)
        self._update_width(b)
        self.version += 1
        return team

    def remove(self, team: int) -> tuple[int, int]:
        """Free a team's lane (its model columns back to fresh values); the block's chunks are
        freed with its last lane. Returns the (block, lane) it had (a team moved to another
        block is removed, then added again with ``add(..., team=team)``)."""
        b, lane = self.place(team)
        block = self.blocks[b]
        block.lanes[lane] = -1
        self.team_block[team] = -1
        self.team_lane[team] = -1
        g = self._rows(b, "particle")
        PARTICLE_MODEL.reset_lanes(self.particle_model, g, lane)
        TEAM_MODEL.reset_lanes(self.team_model, b, lane)
        self.particle_transform[g, lane] = 0
        self.collider_transform[self._rows(b, "collider"), lane] = 0
        self.team_ints[b, lane::LANES] = -1
        if not block.used:
            for pool, (start, count) in block.chunks.items():
                self.allocators[pool].release(start, count)
            self.block_ints[b] = 0
            self.blocks[b] = None
        else:
            self._update_width(b)
        self.version += 1
        return b, lane

    # ------------------------------------------------------------------ internals
    def _rows(self, b: int, pool: str) -> slice:
        start, count = self.blocks[b].chunks[pool]
        return slice(start, start + count)

    def _open_block(self, key: str, model, topo: dict[str, np.ndarray]) -> int:
        n = int(model.particle_count)
        counts = {"particle": n, "link": len(topo["distance_target"]), "edge": len(topo["edge_pairs"]) // 2,
                  "triangle": len(topo["triangle_corners"]) // 3, "bend": len(topo["bend_vertices"]) // 4,
                  "volume": len(topo["volume_vertices"]) // 4, "collider": len(topo["collider_shape"]),
                  "topology": sum(len(v) for k, v in topo.items() if not k.startswith("_"))}
        chunks = {pool: (self.allocators[pool].allocate(count), count) for pool, count in counts.items()}
        try:
            b = self.blocks.index(None)
        except ValueError:
            b = len(self.blocks)
            self.blocks.append(None)
        self.blocks[b] = Block(key, chunks, n)
        self._fit(b)
        row = np.zeros(BLOCK_INT_COUNT, dtype=np.int32)
        row[BI_N] = n
        row[BI_G0], row[BI_LINK0], row[BI_LINKS] = chunks["particle"][0], *chunks["link"]
        row[BI_EDGE0], row[BI_EDGES] = chunks["edge"]
        row[BI_TRIANGLE0], row[BI_TRIANGLES] = chunks["triangle"]
        row[BI_BEND0], row[BI_BENDS] = chunks["bend"]
        row[BI_VOLUME0], row[BI_VOLUMES] = chunks["volume"]
        row[BI_COLLIDER0], row[BI_COLLIDERS] = chunks["collider"]
        row[BI_BASELINES] = len(topo["baseline_start"])
        row[BI_CENTERS] = len(topo["center_fixed"])
        row[BI_HAS_LINES] = 1 if int(topo["_lines"][0]) > 0 else 0
        at = chunks["topology"][0]
        lengths = {}
        for name, values in topo.items():
            if name.startswith("_"):
                continue
            row[BI[name]] = at
            self.topology[at:at + len(values)] = values
            lengths[name] = len(values)
            at += len(values)
        self.block_ints[b] = row
        if not hasattr(self, "_segment_lengths"):
            self._segment_lengths = {}
        self._segment_lengths[b] = lengths
        return b

    def _write_lane(self, b: int, lane: int, team: int, model, collider_nodes) -> None:
        g = self._rows(b, "particle")
        pm, w = PARTICLE_MODEL, self.particle_model
        pm.write(w, "depth", g, lane, model.depth)
        bound = bound_vectors(np.ascontiguousarray(model.skin_bind_pose, dtype=np.float64).reshape(-1, 4, 4),
                              np.ascontiguousarray(model.local_position, dtype=np.float64),
                              np.ascontiguousarray(model.local_normal, dtype=np.float64),
                              np.ascontiguousarray(model.local_tangent, dtype=np.float64))
        pm.write(w, "skin_bound_position", g, lane, bound[:, 0])
        pm.write(w, "skin_bound_normal", g, lane, bound[:, 1])
        pm.write(w, "skin_bound_tangent", g, lane, bound[:, 2])
        pm.write(w, "bind_rotation", g, lane, model.bind_rotation)
        pm.write(w, "vertex_to_transform_rotation", g, lane, model.vertex_to_transform_rotation)
        pm.write(w, "baseline_local_position", g, lane, model.baseline_local_position)
        pm.write(w, "baseline_local_rotation", g, lane, model.baseline_local_rotation)
        TEAM_MODEL.write(self.team_model, "init_scale", b, lane, np.asarray(model.init_scale).reshape(1, 3))
        TEAM_MODEL.write(self.team_model, "init_local_gravity", b, lane,
                         np.asarray(model.init_local_gravity_direction).reshape(1, 3))
        LINK_MODEL.write(self.link_model, "distance_rest", self._rows(b, "link"), lane, model.distance_rest)
        tri = self._rows(b, "triangle")
        if tri.stop > tri.start:
            uv = np.asarray(_get(model, "triangle_uv", np.zeros((tri.stop - tri.start, 3, 2))), dtype=np.float64)
            if uv.shape != (tri.stop - tri.start, 3, 2):   # per-vertex uv (N, 2): per triangle corner
                corners = np.asarray(model.triangles, dtype=np.int64).reshape(-1, 3)
                uv = uv.reshape(-1, 2)[corners]
            TRIANGLE_MODEL.write(self.triangle_model, "triangle_uv", tri, lane, uv.reshape(-1, 6))
        bend = self._rows(b, "bend")
        if bend.stop > bend.start:
            BEND_MODEL.write(self.bend_model, "bend_rest_angle", bend, lane, model.bend_rest_angle)
            BEND_MODEL.write(self.bend_model, "bend_sign", bend, lane, model.bend_sign)
        vol = self._rows(b, "volume")
        if vol.stop > vol.start:
            VOLUME_MODEL.write(self.volume_model, "volume_rest", vol, lane, model.volume_rest)
        self.particle_transform[g, lane] = np.asarray(model.transform_index, dtype=np.int32)
        cs = self._rows(b, "collider")
        if cs.stop > cs.start:
            self.collider_transform[cs, lane] = np.asarray(collider_nodes, dtype=np.int32)
        self.team_ints[b, TI_TEAM + lane] = team
        self.team_ints[b, TI_COMPONENT + lane] = int(model.component_transform)

    def _update_width(self, b: int) -> None:
        block = self.blocks[b]
        self.block_ints[b, BI_WIDTH] = block.width
        self.block_ints[b, BI_LANES_USED] = len(block.used)

    def _fit(self, b: int) -> None:
        """Grow every table to the pools' capacities and ``b + 1`` blocks (old rows kept,
        new rows fresh). Growth is geometric, so adding n teams copies O(n) rows."""
        def grow(a, rows, fresh):
            if a.shape[0] >= rows:
                return a
            new = fresh(max(rows, 2 * a.shape[0]))
            new[:a.shape[0]] = a
            return new

        cap = self.capacity
        self.topology = grow(self.topology, cap("topology"), lambda n: np.zeros(n, dtype=np.int32))
        self.particle_model = grow(self.particle_model, cap("particle"), PARTICLE_MODEL.allocate)
        self.particle_transform = grow(self.particle_transform, cap("particle"),
                                       lambda n: np.zeros((n, LANES), dtype=np.int32))
        self.collider_transform = grow(self.collider_transform, cap("collider"),
                                       lambda n: np.zeros((n, LANES), dtype=np.int32))
        self.link_model = grow(self.link_model, cap("link"), LINK_MODEL.allocate)
        self.triangle_model = grow(self.triangle_model, cap("triangle"), TRIANGLE_MODEL.allocate)
        self.bend_model = grow(self.bend_model, cap("bend"), BEND_MODEL.allocate)
        self.volume_model = grow(self.volume_model, cap("volume"), VOLUME_MODEL.allocate)
        blocks = len(self.blocks)
        self.block_ints = grow(self.block_ints, blocks, lambda n: np.zeros((n, BLOCK_INT_COUNT), dtype=np.int32))
        self.team_ints = grow(self.team_ints, blocks, lambda n: np.full((n, TEAM_INT_COUNT * LANES), -1,
                                                                         dtype=np.int32))
        self.team_model = grow(self.team_model, blocks, TEAM_MODEL.allocate)
