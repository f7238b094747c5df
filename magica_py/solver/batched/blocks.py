"""Block formation: which teams run side by side (Python, outside the frame path).

Two teams can share a block when one kernel can run them in lockstep with the same
per-element inputs except their state: the same topology (``ClothModel.topology_key``), the
same per-particle model data the steps read (depth, rest lengths and angles, baseline rest
pose, build scale and gravity reference), the same parameter row (hierarchy-node parameters
such as the anchor are read per team, outside the steps) and the same collider shapes in the
same slots, and a feature set the block stages implement (``unsupported_reason``). Blocks
hold at most ``BLOCK_WIDTH`` lanes; a group of 100 teams becomes blocks of equal widths (2 x 50
at a width of 64: equal widths keep the threads' work equal), and blocks of different groups
are interleaved.

Formation runs when the system is built, after ``add_cloth`` / ``remove_cloth`` and after
``set_parameter`` (a changed team leaves its block: its parameter row differs).
"""
from __future__ import annotations

import hashlib
import math

import numpy as np

from magica_py.solver.batched.state import (
    BLOCK_WIDTH, BlockTable, COLLIDER_FIELDS, LANE_FIELDS, PARTICLE_BLOCK_FIELDS,
    I64, SHARED_PARTICLE_FIELDS, allocate_block_state, worker_capacity,
)
from magica_py.solver.fields import I32, U8

# model fields (per particle and link pools) the step stages read, compared bit for bit
STEP_MODEL_FIELDS = ("depth", "baseline_local_position", "baseline_local_rotation", "distance_rest",
                     "bend_rest_angle", "bend_sign", "volume_rest", "root_length")
# model fields the end-of-frame stages in block form read from the exemplar (docs/solver.md §E.3, E.4)
END_MODEL_FIELDS = ("triangle_uv", "vertex_to_transform_rotation")
# parameters that name hierarchy nodes (per instance; read by the per-team frame stages only)
PER_TEAM_PARAMETERS = ("anchor_transform", "culling_reference")
MIN_LANES = 2
LANE_ALIGN = 4   # doubles per vector register (LLVM prefers 256-bit vectors on this machine)


def unsupported_reason(prm, team: int, collider_count: int) -> str | None:
    """Why a team cannot run in a block (None: it can)."""
    if prm.quality[team] != 0 or prm.inextensibility[team] != 0 or prm.collision_last[team] != 0:
        return "quality mode"
    if collider_count > 0 and prm.collision_mode[team] == 2:
        return "edge collision"
    return None


def _team_signature(system, t: int) -> str | None:
    model = system.models[t]
    if model is None or not model.topology_key:
        return None
    prm = system.parameters
    ts = system.teams
    count = int(ts.collider_count[t])
    if unsupported_reason(prm, t, count) is not None:
        return None
    h = hashlib.blake2b(digest_size=16)
    h.update(model.topology_key.encode())
    for name in STEP_MODEL_FIELDS + END_MODEL_FIELDS:
        a = getattr(model, name, None)
        if a is not None:
            h.update(name.encode())
            h.update(np.ascontiguousarray(a).tobytes())
    for name in ("init_scale", "init_local_gravity_direction"):
        h.update(np.ascontiguousarray(getattr(model, name)).tobytes())
    for name in prm._fields:
        if name not in PER_TEAM_PARAMETERS:
            h.update(name.encode())
            h.update(np.ascontiguousarray(getattr(prm, name)[t]).tobytes())
    cs = system.collider_state
    start = int(ts.collider_start[t])
    for j in range(start, start + count):
        h.update(repr((int(cs.shape[j]), cs.size[j].tobytes(), int(cs.direction[j]),
                       int(cs.reverse_direction[j]), int(cs.aligned_on_center[j]),
                       cs.local_center[j].tobytes())).encode())
    return h.hexdigest()


def block_widths(n: int) -> list[int]:
    """Widths of the blocks of a group of n teams: as few blocks as ``BLOCK_WIDTH`` allows,
    of even widths that are multiples of ``LANE_ALIGN`` where the count allows (100 teams in
    blocks of at most 32: 28 + 24 + 24 + 24, not 25 x 4): a lane loop's remainder runs
    scalar, and 2 leftover lanes of 50 cost ~9 % of a step (measured)."""
    n_blocks = math.ceil(n / BLOCK_WIDTH)
    units, leftover = divmod(n, LANE_ALIGN)
    widths = [LANE_ALIGN * (units // n_blocks + (1 if k < units % n_blocks else 0)) for k in range(n_blocks)]
    widths[-1] += leftover
    return [w for w in widths if w > 0]


def form_blocks(system, enabled: bool = True):
    """(BlockTable, BlockState) for ``system``'s live teams."""
    team_total = len(system.models)
    groups: dict[str, list[int]] = {}
    if enabled:
        for t in system.live_teams:
            key = _team_signature(system, int(t))
            if key is not None:
                groups.setdefault(key, []).append(int(t))
    per_group: list[list[list[int]]] = []
    for teams in groups.values():
        if len(teams) < MIN_LANES:
            continue
        chunks, start = [], 0
        for width in block_widths(len(teams)):
            chunks.append(teams[start:start + width])
            start += width
        per_group.append([c for c in chunks if len(c) >= MIN_LANES])
    # groups interleaved (hair 0, skirt 0, hair 1, skirt 1, ...): the parallel frame hands
    # each thread a contiguous range of blocks, which then holds a share of every group
    blocks: list[list[int]] = []
    for k in range(max((len(g) for g in per_group), default=0)):
        blocks += [g[k] for g in per_group if k < len(g)]
    m = system.model
    nb = len(blocks)
    width = np.array([len(b) for b in blocks], dtype=I32)
    exemplar = np.array([b[0] for b in blocks], dtype=I32)
    pcount = np.array([int(m.team_particle_count[b[0]]) for b in blocks], dtype=I32)
    ccount = np.array([int(system.teams.collider_count[b[0]]) for b in blocks], dtype=I32)
    tcount = np.array([int(m.team_triangle_count[b[0]]) for b in blocks], dtype=I32)
    row_base = np.zeros(nb, dtype=I32)
    lane_base = np.zeros(nb, dtype=I32)
    shared_base = np.zeros(nb, dtype=I32)
    collider_base = np.zeros(nb, dtype=I32)
    triangle_base = np.zeros(nb, dtype=I32)
    if nb:
        row_base[1:] = np.cumsum(pcount * width)[:-1]
        lane_base[1:] = np.cumsum(width)[:-1]
        shared_base[1:] = np.cumsum(pcount)[:-1]
        collider_base[1:] = np.cumsum(ccount * width)[:-1]
        triangle_base[1:] = np.cumsum(tcount * width)[:-1]
    lane_team = np.array([t for b in blocks for t in b], dtype=I32)
    team_block = np.full(max(team_total, 1), -1, dtype=I32)
    for k, b in enumerate(blocks):
        team_block[b] = k
    # largest blocks first: the frame kernel's greedy thread assignment balances better
    order = np.argsort(-(pcount.astype(np.int64) * width), kind="stable").astype(I32)
    table = BlockTable(width, exemplar, pcount, row_base, lane_base, shared_base, ccount, collider_base,
                       np.zeros(nb, dtype=U8), lane_team, team_block, order, np.full(nb, -1, dtype=I32),
                       np.zeros(max(team_total, 1), dtype=I32), np.zeros(worker_capacity(), dtype=I64),
                       triangle_base, np.zeros(nb, dtype=U8))
    state = allocate_block_state(int((pcount * width).sum()), int(pcount.sum()), int(width.sum()),
                                 int((ccount * width).sum()), int((tcount * width).sum()))
    if nb:
        from magica_py.solver.batched.frame_begin import bind_rows_block
        bind_rows_block(m, table, state)   # the constant half of C.1, lane-innermost
    return table, state


__all__ = ["form_blocks", "unsupported_reason", "BLOCK_WIDTH",
           "PARTICLE_BLOCK_FIELDS", "SHARED_PARTICLE_FIELDS", "LANE_FIELDS", "COLLIDER_FIELDS"]
