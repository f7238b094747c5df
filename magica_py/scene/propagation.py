"""World-pose propagation over a precomputed plan: tiles of whole trees by depth level, lanes
side by side, threads over independent trees.

A ``PropagationPlan`` is built once for a set of nodes (``TransformHierarchy.plan``: every
node, or the subtrees of the nodes that move, e.g. the animated and the cloth bones) and
reused every frame; a frame's pass allocates nothing. Every node gets exactly the arithmetic
of ``propagate_node`` (the per-node pass of ``hierarchy.propagate_world``), so the results
are the same bits; only the order of independent nodes changes:

* the plan's nodes are split into **chunks** of whole top-level trees (the hierarchy's roots),
  balanced by node count; chunks share no node and no parent, so they run on separate
  threads (``threads`` > 1: the calling thread and the plan's ``magica_py.threads.FrameThreads``,
  each running ``propagate_chunks``, a ``nogil`` kernel, over its chunk) when the plan has at
  least ``PARALLEL_PLAN`` nodes, and one after the other in the calling thread otherwise;
* a chunk's **plan trees** (a node whose parent is outside the plan, with its descendants in
  the plan) are grouped, in index order, into **tiles** of at most ``TILE_NODES`` nodes (a
  larger tree is a tile of its own). A tile starts with a **warm-up**: every cache line of its
  nodes' rows of the seven pose arrays is read once, array by array in address order
  (``warm_rows``), so that the hardware prefetcher streams them in; the level order below
  touches them scattered, and after the cloth kernel has gone through the caches each first
  touch would otherwise wait for memory on its own;
* inside a tile the nodes go by **depth level** (depth counted from the plan's own top
  nodes): every parent is final before its level starts and the nodes of a level do not
  depend on each other. A level is cut into **segments** of at most ``SEGMENT_WIDTH`` (512)
  nodes; a segment's local poses are gathered into structure-of-arrays scratch rows, computed
  in one loop that LLVM vectorises across the lanes (``compose_lanes``, whole vectors of
  ``LANE_BLOCK`` lanes: the lanes past the segment compute from stale rows and are never
  written back) and scattered back to the hierarchy's arrays. The parents' matrices and
  rotations come either from the hierarchy (gathered) or, when the segment's parents are lane
  for lane the nodes of the tile's segment one level up (a forest of chains: strands, tails,
  the light scene), straight from that segment's output rows;
* hierarchy roots (parent -1) of the plan are done first in their chunk, one by one
  (``propagate_node``).

The plan never writes the constant bottom row ``(0, 0, 0, 1)`` of ``local_to_world``: the
hierarchy's constructor writes it with its first full pass and nothing else changes it.

Arrays of a plan (k nodes in the plan, r of them hierarchy roots, s segments, t tiles, w
warm-up runs, c chunks, L output slots, R = 26 + 19 L scratch rows):

====================  ===================  ==============================================
field                 shape                meaning
====================  ===================  ==============================================
roots                 (r,) int32           hierarchy roots in the plan, chunk by chunk
chunk_roots           (c + 1,) int64       chunk j's roots: roots[chunk_roots[j]:chunk_roots[j+1]]
order                 (k - r,) int32       the other nodes, tile by tile, level by level
segment_start         (s + 1,) int64       segment g: order[segment_start[g]:segment_start[g+1]]
chunk_tiles           (c + 1,) int64       chunk j's tiles
tile_segments         (t + 1,) int64       tile i's segments (``chunk_segments``: chunk j's)
tile_warm             (t + 1,) int64       tile i's warm-up runs
warm_start, warm_stop (w,) int64           run u: nodes warm_start[u]:warm_stop[u] (a tile's
                                           nodes, gaps of at most ``WARM_GAP`` closed)
segment_slot          (s,) int32           output slot segment g writes
parent_slot           (s,) int32           slot holding g's parents lane for lane, or -1
scratch               (c, R * S + 1)       per chunk, rows of S = ``LANE_STRIDE`` lanes: 10
                      float64              input rows (local pose), 16 gathered parent rows
                                           (output layout), then L slots of 19 output rows;
                                           the last cell keeps the warm-up's sum
====================  ===================  ==============================================
"""
from __future__ import annotations

import weakref
from functools import partial

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels.cache_lines import read_lines
from magica_py.kernels.math3d import (
    load3, load4, q_inverse, q_mul, q_normalize, q_rotate, q_to_matrix, store4,
)
from magica_py.threads import FrameThreads

# lanes per segment: wide enough that the per-segment work is small beside the lanes' (128: 10 %
# slower on the light scene, 64: twice as slow), small enough for the scratch to stay in L2
SEGMENT_WIDTH = 512
# a plan of at most this many nodes runs as a plain pass over its sorted nodes: for a few
# dozen bones the call with the plan's lane arrays costs more than the nodes themselves
# (a single 8-bone tail: two calls a frame, ~2 us each)
SMALL_PLAN = 256
# a plan of fewer nodes runs its chunks one after the other in the calling thread: handing a
# chunk to another thread and waiting for it costs ~30-40 us (the median on a 2-core VM), the
# work of ~600 nodes; two threads drew level with one at ~1,100 nodes and were ahead at ~2,200
# (docs/BENCHMARKS.md, session 25)
PARALLEL_PLAN = 2048
# lanes computed together by the vectorised loop (8 doubles: AVX-512; two vectors with AVX2):
# a segment's lane count is rounded up to a multiple of it
LANE_BLOCK = 8
# scratch rows are padded so that rows do not sit a multiple of 4 KiB apart (cache set
# conflicts between the row streams of a segment)
_ROW_PAD = 8
# distance between two scratch rows (doubles): a compile-time constant, so that LLVM sees the
# rows of a segment as one group of fixed offsets (see ``compose_lanes``)
LANE_STRIDE = SEGMENT_WIDTH + _ROW_PAD
# input rows: local position 0-2, local rotation 3-6, local scale 7-9
LANE_INPUT = 10
# output rows: local_to_world rows 0-2 at 0-3, 4-7, 8-11, world rotation 12-15, lossy scale
# 16-18; gathered parent rows: the parents' rows 0-15 in the same layout
LANE_OUTPUT = 19
LANE_PARENT = 16
# first output row of a chunk's scratch (after the input and the gathered parent rows)
OUTPUT_ROW = LANE_INPUT + LANE_PARENT
# nodes per tile: consecutive plan trees computed level by level together, small enough that
# their rows of the hierarchy's pose arrays (288 bytes a node) stay in the L2 cache between
# the tile's levels
TILE_NODES = 1024
# gaps of at most this many nodes between a tile's nodes are read by the warm-up pass too (one
# sequential run instead of several short ones)
WARM_GAP = 8


# ----------------------------------------------------------------------------- per node
@kernel
def propagate_node(i, parent, local_position, local_rotation, local_scale,
                   world_position, world_rotation, lossy_scale, local_to_world):
    """Node i's world pose, lossy scale and matrix from its local pose and its parent's (final)
    world pose: ``world = parent_l2w @ TRS(local)``, ``world_rotation = normalize(parent *
    normalize(local))``, lossy scale = ``diag(R_world^-1 @ M3x3)`` (docs/solver.md §A.3)."""
    lp = load3(local_position, i)
    lr = q_normalize(load4(local_rotation, i))
    ls = load3(local_scale, i)
    p = np.int64(parent[i])   # int64 node ids: one signature of the row helpers (docs/tech-notes.md §7)
    r0, r1, r2 = q_to_matrix(lr)
    if p < 0:
        for c in range(3):
            local_to_world[i, 0, c] = r0[c] * ls[c]
            local_to_world[i, 1, c] = r1[c] * ls[c]
            local_to_world[i, 2, c] = r2[c] * ls[c]
            local_to_world[i, 3, c] = 0.0
        local_to_world[i, 0, 3] = lp[0]
        local_to_world[i, 1, 3] = lp[1]
        local_to_world[i, 2, 3] = lp[2]
        local_to_world[i, 3, 3] = 1.0
        wr = lr
    else:
        # world = parent_l2w @ TRS(local); expand the product without temporaries
        for row in range(3):
            a0 = local_to_world[p, row, 0]
            a1 = local_to_world[p, row, 1]
            a2 = local_to_world[p, row, 2]
            a3 = local_to_world[p, row, 3]
            for c in range(3):
                local_to_world[i, row, c] = (a0 * r0[c] + a1 * r1[c] + a2 * r2[c]) * ls[c]
            local_to_world[i, row, 3] = a0 * lp[0] + a1 * lp[1] + a2 * lp[2] + a3
        local_to_world[i, 3, 0] = 0.0
        local_to_world[i, 3, 1] = 0.0
        local_to_world[i, 3, 2] = 0.0
        local_to_world[i, 3, 3] = 1.0
        wr = q_normalize(q_mul(load4(world_rotation, p), lr))
    store4(world_rotation, i, wr)
    world_position[i, 0] = local_to_world[i, 0, 3]
    world_position[i, 1] = local_to_world[i, 1, 3]
    world_position[i, 2] = local_to_world[i, 2, 3]
    # lossy scale = diag(R^-1 @ M3x3): column c of M rotated back, component c
    for c in range(3):
        col = (local_to_world[i, 0, c], local_to_world[i, 1, c], local_to_world[i, 2, c])
        back = q_rotate(q_inverse(wr), col)
        lossy_scale[i, c] = back[c]


# ----------------------------------------------------------------------------- lanes
def _inlined(fn):
    """``fn`` (a math3d kernel) compiled again with numba's ``inline="always"``: the lane loop
    needs its per-lane maths in its own body to vectorise (a call in the loop body stops
    LLVM's vectoriser). The same Python source, so the same arithmetic and bits."""
    return kernel(getattr(fn, "py_func", fn), inline="always")


_normalize = _inlined(q_normalize)
_to_matrix = _inlined(q_to_matrix)
_mul = _inlined(q_mul)
_inverse = _inlined(q_inverse)
_rotate = _inlined(q_rotate)


@kernel
def gather_local(order, k0, k1, local_position, local_rotation, local_scale, inputs):
    """Local poses of nodes order[k0:k1] into the input rows (row r of lane j at
    ``r * LANE_STRIDE + j``). Unsigned indices: no wraparound selects."""
    for j in range(k1 - k0):
        i = np.uint64(order[k0 + j])
        o = np.uint64(j)
        for c in range(3):
            inputs[o + np.uint64(c * LANE_STRIDE)] = local_position[i, np.uint64(c)]
            inputs[o + np.uint64((7 + c) * LANE_STRIDE)] = local_scale[i, np.uint64(c)]
        for c in range(4):
            inputs[o + np.uint64((3 + c) * LANE_STRIDE)] = local_rotation[i, np.uint64(c)]


@kernel
def gather_parents(order, k0, k1, parent, world_rotation, local_to_world, parents):
    """The parents' matrix rows and world rotations of nodes order[k0:k1], in the row layout of
    the output rows (so that an aligned segment reads its parents' output rows instead)."""
    for j in range(k1 - k0):
        p = parent[order[k0 + j]]
        o = np.uint64(j)
        for row in range(3):
            for c in range(4):
                parents[o + np.uint64((4 * row + c) * LANE_STRIDE)] = local_to_world[p, row, c]
        for c in range(4):
            parents[o + np.uint64((12 + c) * LANE_STRIDE)] = world_rotation[p, c]


@kernel(inline="always")
def _matrix_row(a0, a1, a2, a3, r0, r1, r2, ls, lp):
    """One row of ``parent_l2w @ TRS(local)``: ``propagate_node``'s expression, element by element."""
    return ((a0 * r0[0] + a1 * r1[0] + a2 * r2[0]) * ls[0],
            (a0 * r0[1] + a1 * r1[1] + a2 * r2[1]) * ls[1],
            (a0 * r0[2] + a1 * r1[2] + a2 * r2[2]) * ls[2],
            a0 * lp[0] + a1 * lp[1] + a2 * lp[2] + a3)


@kernel(inline="always")
def _row(rows, row, u):
    """Lane u of row ``row`` of a block of scratch rows (rows ``LANE_STRIDE`` apart)."""
    return rows[np.uint64(row * LANE_STRIDE) + u]


@kernel
def compose_lanes(count, inputs, parents, outputs):
    """``propagate_node``'s arithmetic for ``count`` nodes with a parent, lane by lane: reads the
    input rows ``inputs`` and the parent rows ``parents``, writes the output rows ``outputs``
    (three row blocks of one chunk's scratch, rows ``LANE_STRIDE`` apart). The row distance
    is a compile-time constant and the per-lane maths is inlined, so LLVM sees three groups
    of fixed-offset rows and vectorises the loop across lanes behind two overlap checks."""
    for j in range(count):
        u = np.uint64(j)
        lp = (_row(inputs, 0, u), _row(inputs, 1, u), _row(inputs, 2, u))
        lr = _normalize((_row(inputs, 3, u), _row(inputs, 4, u), _row(inputs, 5, u),
                         _row(inputs, 6, u)))
        ls = (_row(inputs, 7, u), _row(inputs, 8, u), _row(inputs, 9, u))
        r0, r1, r2 = _to_matrix(lr)
        m0 = _matrix_row(_row(parents, 0, u), _row(parents, 1, u), _row(parents, 2, u),
                         _row(parents, 3, u), r0, r1, r2, ls, lp)
        m1 = _matrix_row(_row(parents, 4, u), _row(parents, 5, u), _row(parents, 6, u),
                         _row(parents, 7, u), r0, r1, r2, ls, lp)
        m2 = _matrix_row(_row(parents, 8, u), _row(parents, 9, u), _row(parents, 10, u),
                         _row(parents, 11, u), r0, r1, r2, ls, lp)
        wr = _normalize(_mul((_row(parents, 12, u), _row(parents, 13, u), _row(parents, 14, u),
                              _row(parents, 15, u)), lr))
        inverse = _inverse(wr)
        s0 = _rotate(inverse, (m0[0], m1[0], m2[0]))[0]
        s1 = _rotate(inverse, (m0[1], m1[1], m2[1]))[1]
        s2 = _rotate(inverse, (m0[2], m1[2], m2[2]))[2]
        for c in range(4):
            outputs[np.uint64(c * LANE_STRIDE) + u] = m0[c]
            outputs[np.uint64((4 + c) * LANE_STRIDE) + u] = m1[c]
            outputs[np.uint64((8 + c) * LANE_STRIDE) + u] = m2[c]
            outputs[np.uint64((12 + c) * LANE_STRIDE) + u] = wr[c]
        outputs[np.uint64(16 * LANE_STRIDE) + u] = s0
        outputs[np.uint64(17 * LANE_STRIDE) + u] = s1
        outputs[np.uint64(18 * LANE_STRIDE) + u] = s2


@kernel
def scatter_lanes(order, k0, k1, world_position, world_rotation, lossy_scale, local_to_world,
                  outputs):
    """Results of lanes 0..k1-k0 (the output rows) to nodes order[k0:k1] (the bottom matrix
    row is constant)."""
    for j in range(k1 - k0):
        i = np.uint64(order[k0 + j])
        o = np.uint64(j)
        for row in range(3):
            r = np.uint64(row)
            for c in range(4):
                local_to_world[i, r, np.uint64(c)] = outputs[o + np.uint64((4 * row + c) * LANE_STRIDE)]
            world_position[i, r] = outputs[o + np.uint64((4 * row + 3) * LANE_STRIDE)]
            lossy_scale[i, r] = outputs[o + np.uint64((16 + row) * LANE_STRIDE)]
        for c in range(4):
            world_rotation[i, np.uint64(c)] = outputs[o + np.uint64((12 + c) * LANE_STRIDE)]


@kernel(inline="always")
def _slot_rows(lanes, slot):
    """The 19 output rows of output slot ``slot`` of a chunk's scratch (a view)."""
    first = (OUTPUT_ROW + LANE_OUTPUT * slot) * LANE_STRIDE
    return lanes[first:first + LANE_OUTPUT * LANE_STRIDE]


@kernel
def warm_rows(warm_start, warm_stop, w0, w1, local_position, local_rotation, local_scale,
              world_position, world_rotation, lossy_scale, local_to_world):
    """Read every cache line of the pose rows of nodes ``warm_start[w]:warm_stop[w]`` (w in
    w0..w1), array by array in address order, before a tile's levels run: the level order
    touches a tile's rows scattered, so that each first touch would wait for memory on its own;
    read in sequence, the hardware prefetcher streams them into the cache. Returns the sum of
    the values read (stored by the caller, so that the reads are kept)."""
    acc = 0.0
    lp = local_position.reshape(-1)
    lr = local_rotation.reshape(-1)
    ls = local_scale.reshape(-1)
    wp = world_position.reshape(-1)
    wr = world_rotation.reshape(-1)
    sc = lossy_scale.reshape(-1)
    m = local_to_world.reshape(-1)
    for w in range(w0, w1):
        a = warm_start[w]
        b = warm_stop[w]
        acc += read_lines(lp, 3 * a, 3 * b)
        acc += read_lines(lr, 4 * a, 4 * b)
        acc += read_lines(ls, 3 * a, 3 * b)
        acc += read_lines(m, 16 * a, 16 * b)
        acc += read_lines(wp, 3 * a, 3 * b)
        acc += read_lines(wr, 4 * a, 4 * b)
        acc += read_lines(sc, 3 * a, 3 * b)
    return acc


@kernel
def propagate_chunk(chunk, roots, chunk_roots, order, segment_start, chunk_tiles, tile_segments,
                    tile_warm, warm_start, warm_stop, segment_slot, parent_slot, scratch, parent,
                    local_position, local_rotation, local_scale, world_position, world_rotation,
                    lossy_scale, local_to_world):
    """One chunk of a plan: its hierarchy roots, then its tiles in order, each after a warm-up
    read of its rows (``warm_rows``), its segments level by level; a segment whose parents are
    lane for lane the nodes of the tile's segment one level up (``parent_slot`` >= 0) reads
    their results from that segment's output rows."""
    for k in range(chunk_roots[chunk], chunk_roots[chunk + 1]):
        propagate_node(np.int64(roots[k]), parent, local_position, local_rotation, local_scale,
                       world_position, world_rotation, lossy_scale, local_to_world)
    lanes = scratch[chunk]
    inputs = lanes[:LANE_INPUT * LANE_STRIDE]
    gathered = lanes[LANE_INPUT * LANE_STRIDE:OUTPUT_ROW * LANE_STRIDE]
    warmed = 0.0
    for t in range(chunk_tiles[chunk], chunk_tiles[chunk + 1]):
        warmed += warm_rows(warm_start, warm_stop, tile_warm[t], tile_warm[t + 1], local_position,
                            local_rotation, local_scale, world_position, world_rotation,
                            lossy_scale, local_to_world)
        for g in range(tile_segments[t], tile_segments[t + 1]):
            k0 = segment_start[g]
            k1 = segment_start[g + 1]
            gather_local(order, k0, k1, local_position, local_rotation, local_scale, inputs)
            outputs = _slot_rows(lanes, segment_slot[g])
            if parent_slot[g] >= 0:
                parents = _slot_rows(lanes, parent_slot[g])
            else:
                gather_parents(order, k0, k1, parent, world_rotation, local_to_world, gathered)
                parents = gathered
            # whole vectors: the lanes past the segment compute from stale rows and are not
            # scattered (a scalar remainder lane costs about as much as a vector of 8)
            compose_lanes((k1 - k0 + LANE_BLOCK - 1) // LANE_BLOCK * LANE_BLOCK, inputs, parents,
                          outputs)
            scatter_lanes(order, k0, k1, world_position, world_rotation, lossy_scale,
                          local_to_world, outputs)
    lanes[lanes.shape[0] - 1] = warmed


@kernel
def propagate_chunks(c0, c1, roots, chunk_roots, order, segment_start, chunk_tiles, tile_segments,
                     tile_warm, warm_start, warm_stop, segment_slot, parent_slot, scratch, parent,
                     local_position, local_rotation, local_scale, world_position, world_rotation,
                     lossy_scale, local_to_world):
    """Chunks ``c0 .. c1 - 1`` of a plan, one after the other: a whole plan in one thread, or
    one thread's chunk of a parallel pass (chunks share no node: the same bits either way)."""
    for chunk in range(c0, c1):
        propagate_chunk(chunk, roots, chunk_roots, order, segment_start, chunk_tiles,
                        tile_segments, tile_warm, warm_start, warm_stop, segment_slot,
                        parent_slot, scratch, parent, local_position, local_rotation,
                        local_scale, world_position, world_rotation, lossy_scale, local_to_world)


@kernel
def propagate_listed(nodes, parent, local_position, local_rotation, local_scale,
                     world_position, world_rotation, lossy_scale, local_to_world):
    """``propagate_node`` for ``nodes`` (sorted: parents before children), one after another."""
    for k in range(nodes.shape[0]):
        propagate_node(np.int64(nodes[k]), parent, local_position, local_rotation, local_scale,
                       world_position, world_rotation, lossy_scale, local_to_world)


# ----------------------------------------------------------------------------- plans
class PropagationPlan:
    """The nodes to update and the order to update them in (module docstring); built by
    ``build_plan``, run by ``run`` against the hierarchy arrays it was built for."""

    def __init__(self, roots, chunk_roots, order, segment_start, chunk_tiles, tile_segments,
                 tile_warm, warm_start, warm_stop, segment_slot, parent_slot, slots, nodes,
                 threads, width):
        self.roots = roots
        self.chunk_roots = chunk_roots
        self.order = order
        self.segment_start = segment_start
        self.chunk_tiles = chunk_tiles
        self.tile_segments = tile_segments
        self.tile_warm = tile_warm
        self.warm_start = warm_start
        self.warm_stop = warm_stop
        self.segment_slot = segment_slot
        self.parent_slot = parent_slot
        self.nodes = nodes              # (k,) int32 sorted: every node the plan updates
        self.threads = threads          # threads it was built for (``chunks`` <= threads)
        self.width = width
        chunks = max(chunk_roots.shape[0] - 1, 1)
        # per chunk one flat row block: input rows, gathered parent rows, then two levels of
        # output slots (the level being computed and the one above it), and one cell that keeps
        # the warm-up reads
        rows = OUTPUT_ROW + LANE_OUTPUT * max(slots, 1)
        self.scratch = np.zeros((chunks, rows * LANE_STRIDE + 1))
        self._covers = weakref.WeakKeyDictionary()   # other plan -> self.covers(other)
        self._pool = None   # FrameThreads for chunks 1 .. c - 1, made at the first threaded pass

    @property
    def chunks(self) -> int:
        return self.chunk_roots.shape[0] - 1

    @property
    def chunk_segments(self) -> np.ndarray:
        """(c + 1,) chunk j's segments: ``chunk_segments[j]:chunk_segments[j + 1]``."""
        return self.tile_segments[self.chunk_tiles]

    @property
    def size(self) -> int:
        return int(self.nodes.shape[0])

    def covers(self, other: "PropagationPlan") -> bool:
        """True if every node of ``other`` is a node of this plan (remembered per plan)."""
        known = self._covers.get(other)
        if known is None:
            known = bool(np.isin(other.nodes, self.nodes, assume_unique=True).all())
            self._covers[other] = known
        return known

    def run(self, h) -> None:
        """Update the plan's nodes of hierarchy ``h``: ``h.propagate(self)``."""
        h.propagate(self)

    def execute(self, parent, local_position, local_rotation, local_scale, world_position,
                world_rotation, lossy_scale, local_to_world) -> None:
        """The plan's pass over these hierarchy arrays (one numba call, or one per chunk on the
        plan's threads: module docstring); ``TransformHierarchy`` calls it with its own arrays."""
        if self.size == 0:
            return
        if self.size <= SMALL_PLAN:
            propagate_listed(self.nodes, parent, local_position, local_rotation, local_scale,
                             world_position, world_rotation, lossy_scale, local_to_world)
            return
        head = (self.roots, self.chunk_roots, self.order, self.segment_start, self.chunk_tiles,
                self.tile_segments, self.tile_warm, self.warm_start, self.warm_stop, self.segment_slot,
                self.parent_slot, self.scratch, parent, local_position, local_rotation, local_scale,
                world_position, world_rotation, lossy_scale, local_to_world)
        chunks = self.chunks
        if chunks == 1 or self.size < PARALLEL_PLAN:
            propagate_chunks(0, chunks, *head)
            return
        pool = self._pool
        if pool is None:
            pool = self._pool = FrameThreads(chunks - 1, name="magica-propagation")
        pool.run([partial(propagate_chunks, c, c + 1, *head) for c in range(1, chunks)])
        try:
            propagate_chunks(0, 1, *head)
        finally:
            pool.join()   # raises the first error a chunk's thread raised


def subtree_closure(parent: np.ndarray, nodes) -> np.ndarray:
    """Sorted int32 indices of ``nodes`` and all their descendants (parents-before-children
    storage: one forward pass)."""
    mark = np.zeros(parent.shape[0], dtype=bool)
    seeds = np.asarray(nodes, dtype=np.int64).ravel()
    if seeds.size:
        if seeds.min() < 0 or seeds.max() >= parent.shape[0]:
            raise IndexError(f"propagation plan: node index out of range [0, {parent.shape[0]}): "
                             f"{seeds[(seeds < 0) | (seeds >= parent.shape[0])][:5].tolist()}")
        mark[seeds] = True
    _mark_descendants(parent, mark)
    return np.flatnonzero(mark).astype(np.int32)


@kernel
def _mark_descendants(parent, mark):
    for i in range(parent.shape[0]):
        p = parent[i]
        if p >= 0 and mark[p]:
            mark[i] = True


def build_plan(parent: np.ndarray, nodes, threads: int = 1, width: int = SEGMENT_WIDTH,
               tile: int = TILE_NODES) -> PropagationPlan:
    """The plan that updates ``nodes`` and their descendants (``nodes=None``: every node) of a
    hierarchy with parents-before-children ``parent``, split into at most ``threads`` chunks,
    tiles of about ``tile`` nodes and segments of at most ``width`` lanes."""
    if int(threads) < 1 or not 1 <= int(width) <= SEGMENT_WIDTH:
        raise ValueError(f"propagation plan: expected threads >= 1 and 1 <= width <= "
                         f"{SEGMENT_WIDTH}, got {threads}, {width}")
    if int(tile) < 1:
        raise ValueError(f"propagation plan: expected tile >= 1 (nodes), got {tile}")
    n = parent.shape[0]
    members = np.arange(n, dtype=np.int32) if nodes is None else subtree_closure(parent, nodes)
    in_plan = np.zeros(n, dtype=bool)
    in_plan[members] = True
    # depth from the plan's top nodes, the hierarchy root (tree) and the plan's top node of
    # every node
    depth = np.zeros(n, dtype=np.int64)
    tree = np.zeros(n, dtype=np.int64)
    top = np.zeros(n, dtype=np.int64)
    _depth_and_tree(parent, in_plan, depth, tree, top)
    m_tree = tree[members]
    # chunks: whole trees, contiguous in index order, about members / threads nodes each
    chunks = max(1, min(int(threads), int(np.unique(m_tree).size) if members.size else 1))
    chunk = np.zeros(members.size, dtype=np.int64)
    if chunks > 1:
        trees, counts = np.unique(m_tree, return_counts=True)
        before = np.cumsum(counts) - counts            # plan nodes in earlier trees
        tree_chunk = np.minimum((before * chunks) // members.size, chunks - 1)
        chunk = tree_chunk[np.searchsorted(trees, m_tree)]
        chunks = int(tree_chunk.max()) + 1
    tile_of = _tiles(chunk, top[members], int(tile))
    tiles = int(tile_of.max()) + 1 if members.size else 0
    is_root = parent[members] < 0
    roots = members[is_root]
    chunk_roots = np.searchsorted(chunk[is_root], np.arange(chunks + 1)).astype(np.int64)
    rest = members[~is_root]
    rest_tile = tile_of[~is_root]
    rest_depth = depth[rest]
    key = np.lexsort((rest, rest_depth, rest_tile))
    order = rest[key].astype(np.int32)
    rest_tile = rest_tile[key]
    rest_depth = rest_depth[key]
    # segments: a new one where the tile or the depth changes or the width is reached
    starts = [0]
    for k in range(1, order.size + 1):
        if k == order.size or rest_tile[k] != rest_tile[k - 1] or rest_depth[k] != rest_depth[k - 1] \
                or k - starts[-1] >= width:
            starts.append(k)
    starts = np.asarray(starts, dtype=np.int64)
    first = starts[:-1]
    seg_tile = rest_tile[first]
    seg_depth = rest_depth[first]
    tile_chunk = np.zeros(tiles, dtype=np.int64)
    tile_chunk[tile_of] = chunk
    chunk_tiles = np.searchsorted(tile_chunk, np.arange(chunks + 1)).astype(np.int64)
    tile_segments = np.searchsorted(seg_tile, np.arange(tiles + 1)).astype(np.int64)
    slot, parent_slot, slots = _output_slots(parent, order, starts, seg_tile, seg_depth)
    tile_warm, warm_start, warm_stop = _warm_runs(members, tile_of, tiles)
    return PropagationPlan(roots.astype(np.int32), chunk_roots, order, starts, chunk_tiles,
                           tile_segments, tile_warm, warm_start, warm_stop, slot, parent_slot,
                           slots, members, int(threads), int(width))


def _tiles(chunk, top, size):
    """Tile of each plan node (``chunk`` and ``top`` per node, members in index order): the plan
    trees (a top node and its plan descendants) of a chunk in the order of their top nodes,
    grouped into tiles of at most ``size`` nodes (a larger tree is a tile of its own); tiles are
    numbered chunk by chunk."""
    tile_of = np.zeros(chunk.size, dtype=np.int64)
    if chunk.size == 0:
        return tile_of
    trees, first, inverse, counts = np.unique(top, return_index=True, return_inverse=True,
                                              return_counts=True)
    tree_chunk = chunk[first]
    by_chunk = np.lexsort((trees, tree_chunk))         # trees chunk by chunk, by top node
    tree_tile = np.zeros(trees.size, dtype=np.int64)
    current, filled, last_chunk = -1, size, -1
    for t in by_chunk:
        if tree_chunk[t] != last_chunk or filled + counts[t] > size:
            current += 1
            filled = 0
            last_chunk = tree_chunk[t]
        tree_tile[t] = current
        filled += counts[t]
    return tree_tile[inverse]


def _warm_runs(members, tile_of, tiles):
    """Index ranges a tile's warm-up reads: its nodes in runs, gaps of at most ``WARM_GAP``
    nodes closed (CSR ``tile_warm`` over ``warm_start`` / ``warm_stop``)."""
    by_tile = np.lexsort((members, tile_of))
    nodes = members[by_tile].astype(np.int64)
    node_tile = tile_of[by_tile]
    cut = np.ones(nodes.size, dtype=bool)
    if nodes.size:
        cut[1:] = (node_tile[1:] != node_tile[:-1]) | (nodes[1:] - nodes[:-1] > WARM_GAP + 1)
    begin = np.flatnonzero(cut)
    end = np.append(begin[1:], nodes.size).astype(np.int64) - 1
    warm_start = nodes[begin]
    warm_stop = nodes[end] + 1 if nodes.size else np.zeros(0, dtype=np.int64)
    tile_warm = np.searchsorted(node_tile[begin], np.arange(tiles + 1)).astype(np.int64)
    return tile_warm, warm_start, warm_stop


def _output_slots(parent, order, starts, seg_tile, seg_depth):
    """Output rows of each segment: segment s of a level (s-th of its tile and depth) writes
    slot ``(depth % 2) * per_level + s``, which stays untouched during the next level. A segment
    whose parents are, lane for lane, the nodes of the same-numbered segment one level up (a
    forest of chains) reads them from there (``parent_slot``); -1: gather from the hierarchy."""
    count = seg_tile.size
    slot = np.zeros(count, dtype=np.int32)
    parent_slot = np.full(count, -1, dtype=np.int32)
    index_in_level = np.zeros(count, dtype=np.int64)
    where: dict[tuple[int, int, int], int] = {}
    for g in range(count):
        if g > 0 and seg_tile[g] == seg_tile[g - 1] and seg_depth[g] == seg_depth[g - 1]:
            index_in_level[g] = index_in_level[g - 1] + 1
        where[(int(seg_tile[g]), int(seg_depth[g]), int(index_in_level[g]))] = g
    per_level = int(index_in_level.max()) + 1 if count else 1
    for g in range(count):
        slot[g] = (seg_depth[g] % 2) * per_level + index_in_level[g]
        up = where.get((int(seg_tile[g]), int(seg_depth[g]) - 1, int(index_in_level[g])))
        if up is None:
            continue
        lanes = parent[order[starts[g]:starts[g + 1]]]
        above = order[starts[up]:starts[up + 1]]
        if lanes.size <= above.size and np.array_equal(lanes, above[:lanes.size]):
            parent_slot[g] = (seg_depth[up] % 2) * per_level + index_in_level[up]
    return slot, parent_slot, 2 * per_level


@kernel
def _depth_and_tree(parent, in_plan, depth, tree, top):
    for i in range(parent.shape[0]):
        p = parent[i]
        if p < 0:
            tree[i] = i
            depth[i] = 0
            top[i] = i
        else:
            tree[i] = tree[p]
            if in_plan[p]:
                depth[i] = depth[p] + 1
                top[i] = top[p]
            else:
                depth[i] = 0
                top[i] = i
