"""Propagation plans (magica_py/scene/propagation.py): the same bits as a slow reference pass,
on random hierarchies, over node subsets and threads, and inside the player's frame."""
from __future__ import annotations

import math
import os
import platform
from types import SimpleNamespace

import numpy as np
import pytest

from magica_py.runtime.clock import FixedFrameRate, TimeManager
from magica_py.runtime.phases import Phase, System
from magica_py.runtime.player import Player, default_schedule
from magica_py.scene.animation import Animation
from magica_py.scene.hierarchy import BoneSpec, TransformHierarchy
from magica_py.scene.propagation import LANE_BLOCK, SEGMENT_WIDTH, build_plan, subtree_closure


# ----------------------------------------------------------------------------- slow reference
def _normalize(q):
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    if n < 1e-12:
        return (0.0, 0.0, 0.0, 1.0)
    inv = 1.0 / n
    return (q[0] * inv, q[1] * inv, q[2] * inv, q[3] * inv)


def _mul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz)


def _matrix(q):
    x, y, z, w = q
    return ((1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w)),
            (2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w)),
            (2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y)))


def _rotate(q, v):
    qx, qy, qz, qw = q
    tx = 2.0 * (qy * v[2] - qz * v[1])
    ty = 2.0 * (qz * v[0] - qx * v[2])
    tz = 2.0 * (qx * v[1] - qy * v[0])
    return (v[0] + qw * tx + (qy * tz - qz * ty),
            v[1] + qw * ty + (qz * tx - qx * tz),
            v[2] + qw * tz + (qx * ty - qy * tx))


def _inverse(q):
    n = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]
    if n < 1e-30:
        return (0.0, 0.0, 0.0, 1.0)
    inv = 1.0 / n
    return (-q[0] * inv, -q[1] * inv, -q[2] * inv, q[3] * inv)


def reference_propagate(h):
    """Plain-Python forward pass in index order, written from the formulas of the hierarchy
    docstring with the same operations in the same order (so the same IEEE results): returns
    (world_position, world_rotation, lossy_scale, local_to_world)."""
    n = h.count
    wp, wr, lossy, m = np.zeros((n, 3)), np.zeros((n, 4)), np.zeros((n, 3)), np.zeros((n, 4, 4))
    for i in range(n):
        lp = tuple(h.local_position[i])
        lr = _normalize(tuple(h.local_rotation[i]))
        ls = tuple(h.local_scale[i])
        r = _matrix(lr)
        p = int(h.parent[i])
        if p < 0:
            for row in range(3):
                for c in range(3):
                    m[i, row, c] = r[row][c] * ls[c]
                m[i, row, 3] = lp[row]
            q = lr
        else:
            for row in range(3):
                a = m[p, row]
                for c in range(3):
                    m[i, row, c] = (a[0] * r[0][c] + a[1] * r[1][c] + a[2] * r[2][c]) * ls[c]
                m[i, row, 3] = a[0] * lp[0] + a[1] * lp[1] + a[2] * lp[2] + a[3]
            q = _normalize(_mul(tuple(wr[p]), lr))
        m[i, 3] = (0.0, 0.0, 0.0, 1.0)
        wr[i] = q
        wp[i] = m[i, :3, 3]
        for c in range(3):
            lossy[i, c] = _rotate(_inverse(q), (m[i, 0, c], m[i, 1, c], m[i, 2, c]))[c]
    return wp, wr, lossy, m


def world_state(h):
    return (h.world_position.copy(), h.world_rotation.copy(), h.lossy_scale.copy(),
            h.local_to_world.copy())


def assert_same_bits(actual, expected):
    for name, a, b in zip(("world_position", "world_rotation", "lossy_scale", "local_to_world"),
                          actual, expected):
        np.testing.assert_array_equal(a, b, err_msg=name)


def random_forest(rng, n, trees, scale=True):
    """n nodes in ``trees`` trees with random parents, poses and (non-uniform) scales; the
    bone list is shuffled so that the hierarchy reorders it."""
    bones = []
    for i in range(n):
        parent = None if i < trees else f"n{int(rng.integers(0, i))}"
        q = rng.normal(size=4)
        s = tuple(rng.uniform(0.5, 2.0, 3)) if scale else (1.0, 1.0, 1.0)
        bones.append(BoneSpec(f"n{i}", parent, tuple(rng.normal(size=3)), tuple(q), s))
    order = rng.permutation(n)
    return TransformHierarchy([bones[k] for k in order])


def perturb(rng, h, nodes):
    h.local_position[nodes] += rng.normal(size=(len(nodes), 3)) * 0.1
    h.local_rotation[nodes] = rng.normal(size=(len(nodes), 4))   # not normalised: the pass does
    h.local_scale[nodes] = rng.uniform(0.5, 2.0, (len(nodes), 3))


# ----------------------------------------------------------------------------- plans alone
@pytest.mark.parametrize("seed,n,trees", [(0, 40, 1), (1, 300, 7), (2, 1000, 40), (3, 700, 700)])
@pytest.mark.parametrize("threads", [1, 2, 3])
def test_full_plan_gives_the_reference_bits_on_random_forests(seed, n, trees, threads):
    rng = np.random.default_rng(seed)
    h = random_forest(rng, n, trees)
    perturb(rng, h, np.arange(n))
    h.threads = threads
    h.propagate()
    assert_same_bits(world_state(h), reference_propagate(h))


def chain_forest(rng, chains, lengths):
    """``chains`` roots, each with a chain of lengths[k] bones (random poses and scales)."""
    bones = []
    for k in range(chains):
        bones.append(BoneSpec(f"r{k}", None, tuple(rng.normal(size=3)), tuple(rng.normal(size=4))))
        for d in range(int(lengths[k])):
            bones.append(BoneSpec(f"c{k}_{d}", f"r{k}" if d == 0 else f"c{k}_{d - 1}",
                                  tuple(rng.normal(size=3) * 0.1), tuple(rng.normal(size=4)),
                                  tuple(rng.uniform(0.5, 2.0, 3))))
    return TransformHierarchy(bones)


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("uneven", [False, True])
def test_forest_of_chains_reads_parents_from_the_level_above_with_the_reference_bits(threads, uneven):
    rng = np.random.default_rng(11)
    width = 40
    chains = 2 * threads * width + 11                  # three segments per level and chunk
    lengths = rng.integers(1, 9, chains) if uneven else np.full(chains, 8)
    h = chain_forest(rng, chains, lengths)
    first_bones = np.flatnonzero([n.startswith("c") and n.endswith("_0") for n in h.names])
    for nodes in (None, first_bones):                  # every node, then the chains alone
        plan = build_plan(h.parent, nodes, threads, width)
        assert plan.chunks == threads
        if not uneven:
            assert (plan.parent_slot >= 0).sum() >= plan.parent_slot.size // 2
        perturb(rng, h, plan.nodes)
        plan.run(h)
        assert_same_bits(world_state(h), reference_propagate(h))


@pytest.mark.parametrize("threads", [1, 2])
def test_subtree_plan_updates_the_moved_nodes_descendants_and_nothing_else(threads):
    rng = np.random.default_rng(5)
    h = random_forest(rng, 600, 12)
    h.threads = threads
    moved = rng.choice(h.count, 25, replace=False)
    plan = h.plan(moved)
    closure = set(plan.nodes.tolist())
    for i in moved:
        assert set(h.descendants(int(i))) <= closure
    assert all(int(h.parent[i]) in closure or int(i) in set(moved.tolist()) for i in closure)
    before = world_state(h)
    perturb(rng, h, moved)
    h.propagate(plan)
    after = world_state(h)
    assert_same_bits(after, reference_propagate(h))
    outside = np.setdiff1d(np.arange(h.count), plan.nodes)
    for a, b in zip(after, before):
        np.testing.assert_array_equal(a[outside], b[outside])


def test_a_plan_is_reused_frame_after_frame_without_allocating_new_arrays():
    rng = np.random.default_rng(9)
    h = random_forest(rng, 400, 8)
    plan = h.plan(np.arange(0, 400, 37))
    scratch = plan.scratch
    for _ in range(3):
        perturb(rng, h, plan.nodes)
        h.propagate(plan)
        assert_same_bits(world_state(h), reference_propagate(h))
    assert plan.scratch is scratch


@pytest.mark.parametrize("threads,width", [(1, 50), (2, 50), (4, 50), (2, SEGMENT_WIDTH), (1, SEGMENT_WIDTH)])
def test_plan_levels_and_chunks_are_independent(threads, width):
    rng = np.random.default_rng(3)
    h = random_forest(rng, 2000, 30)
    plan = build_plan(h.parent, None, threads, width)
    assert plan.chunks <= threads
    chunk_of = np.full(h.count, -1)
    for c in range(plan.chunks):
        chunk_of[plan.roots[plan.chunk_roots[c]:plan.chunk_roots[c + 1]]] = c
        s0, s1 = plan.chunk_segments[c], plan.chunk_segments[c + 1]
        chunk_of[plan.order[plan.segment_start[s0]:plan.segment_start[s1]]] = c
    assert (chunk_of >= 0).all()                       # every node exactly once
    assert sorted(np.concatenate([plan.roots, plan.order]).tolist()) == list(range(h.count))
    has_parent = h.parent >= 0
    assert (chunk_of[has_parent] == chunk_of[h.parent[has_parent]]).all()   # trees stay whole
    done = np.zeros(h.count, dtype=bool)
    done[plan.roots] = True
    for g in range(plan.segment_start.size - 1):
        seg = plan.order[plan.segment_start[g]:plan.segment_start[g + 1]]
        assert 0 < seg.size <= width
        assert done[h.parent[seg]].all()               # every parent final before the segment
        done[seg] = True
    perturb(rng, h, np.arange(h.count))
    plan.run(h)                                        # scratch rows sized for the width
    assert_same_bits(world_state(h), reference_propagate(h))


def _plan_trees(parent, plan):
    """Top node of every plan node (its ancestor whose parent is outside the plan)."""
    inside = np.zeros(parent.shape[0], dtype=bool)
    inside[plan.nodes] = True
    top = np.arange(parent.shape[0])
    for i in plan.nodes:                               # parents before children
        p = parent[i]
        if p >= 0 and inside[p]:
            top[i] = top[p]
    return top


@pytest.mark.parametrize("threads,tile", [(1, 1), (1, 7), (2, 30), (3, 200), (2, 10_000)])
def test_tiles_hold_whole_plan_trees_level_by_level_and_are_warmed_whole(threads, tile):
    """Tiles (consecutive plan trees computed level by level together, after a warm-up read of
    their rows) keep every plan tree in one tile, hold at most ``tile`` nodes unless one tree is
    larger, run their segments in depth order and read every node of theirs in the warm-up;
    the results keep the reference bits."""
    rng = np.random.default_rng(13)
    h = random_forest(rng, 1500, 25)
    for nodes in (None, rng.choice(h.count, 40, replace=False)):
        plan = build_plan(h.parent, nodes, threads, 50, tile)
        top = _plan_trees(h.parent, plan)
        tiles = plan.tile_segments.size - 1
        assert plan.chunk_tiles[0] == 0 and plan.chunk_tiles[-1] == tiles
        assert np.all(np.diff(plan.chunk_tiles) >= 0)
        tile_of = np.full(h.count, -1)
        for t in range(tiles):
            s0, s1 = plan.tile_segments[t], plan.tile_segments[t + 1]
            members = plan.order[plan.segment_start[s0]:plan.segment_start[s1]]
            tile_of[members] = t
            depth = [int(_depth(h.parent, plan, plan.order[plan.segment_start[g]]))
                     for g in range(s0, s1)]
            assert depth == sorted(depth)              # level by level inside the tile
            trees = np.unique(top[members])
            if trees.size > 1:
                assert members.size <= tile
            warmed = np.zeros(h.count, dtype=bool)
            for w in range(plan.tile_warm[t], plan.tile_warm[t + 1]):
                warmed[plan.warm_start[w]:plan.warm_stop[w]] = True
            assert warmed[members].all()
        placed = plan.order
        for i in placed:                               # a plan tree never spans two tiles
            assert tile_of[i] == tile_of[top[i]] or top[i] in plan.roots
        perturb(rng, h, plan.nodes)
        plan.run(h)
        assert_same_bits(world_state(h), reference_propagate(h))


def _depth(parent, plan, i):
    inside = np.zeros(parent.shape[0], dtype=bool)
    inside[plan.nodes] = True
    d = 0
    while parent[i] >= 0 and inside[parent[i]]:
        i = parent[i]
        d += 1
    return d


@pytest.mark.parametrize("width", [1, 3, 13, 64])
def test_lanes_past_a_segment_are_computed_and_never_written(width):
    """The lane loop runs whole vectors: a segment whose lane count is not a multiple of
    ``LANE_BLOCK`` computes the lanes past it from stale scratch rows; they are never
    scattered, so every node outside the plan keeps its pose and every node in it gets the
    reference bits."""
    rng = np.random.default_rng(17)
    h = chain_forest(rng, 70, rng.integers(1, 9, 70))
    nodes = np.flatnonzero([n.startswith("c") and n.endswith("_1") for n in h.names])
    plan = build_plan(h.parent, nodes, 1, width, 97)
    assert (np.diff(plan.segment_start) % LANE_BLOCK != 0).any()
    outside = np.setdiff1d(np.arange(h.count), plan.nodes)
    for _ in range(2):
        before = world_state(h)
        perturb(rng, h, plan.nodes)
        plan.run(h)
        after = world_state(h)
        for a, b in zip(after, before):
            np.testing.assert_array_equal(a[outside], b[outside])
        assert_same_bits(after, reference_propagate(h))


def test_closure_of_no_nodes_is_empty_and_a_bad_index_is_named():
    rng = np.random.default_rng(1)
    h = random_forest(rng, 50, 2)
    assert subtree_closure(h.parent, []).size == 0
    empty = h.plan([])
    before = world_state(h)
    h.propagate(empty)
    assert_same_bits(world_state(h), before)
    with pytest.raises(IndexError, match=r"out of range \[0, 50\).*\[50\]"):
        h.plan([3, 50])
    with pytest.raises(ValueError, match="threads"):
        h.threads = 0
    for width in (0, SEGMENT_WIDTH + 1):      # the scratch rows are SEGMENT_WIDTH lanes long
        with pytest.raises(ValueError, match=f"1 <= width <= {SEGMENT_WIDTH}, got 1, {width}"):
            build_plan(h.parent, None, 1, width)


# ----------------------------------------------------------------------------- inside the frame
def character():
    """root > hips > (spine > head > hat, leg) and a static prop root with a child."""
    return TransformHierarchy([
        BoneSpec("root", None, (0.0, 0.0, 0.0)),
        BoneSpec("hips", "root", (0.0, 1.0, 0.0)),
        BoneSpec("spine", "hips", (0.0, 0.2, 0.0), (0.1, 0.0, 0.0, 1.0)),
        BoneSpec("head", "spine", (0.0, 0.3, 0.0)),
        BoneSpec("hat", "head", (0.0, 0.1, 0.05), scale=(1.0, 2.0, 1.0)),
        BoneSpec("leg", "hips", (0.1, -0.1, 0.0)),
        BoneSpec("prop", None, (2.0, 0.0, 0.0)),
        BoneSpec("prop_child", "prop", (0.0, 0.5, 0.0)),
    ])


def frame_player(h, entries, restored=()):
    anim = Animation.from_specs(entries, h)
    scene = SimpleNamespace(hierarchy=h, animation=anim)
    player = Player(scene, default_schedule(scene), FixedFrameRate(30), TimeManager())
    if len(restored):
        player.register_restored_bones([h.index(n) for n in restored], owner="cloth")
    seen = []
    player.schedule.add(Phase.UPDATE, System("check", lambda ctx: seen.append(
        (world_state(h), reference_propagate(h)))), after="animation")
    return player, seen


def run_and_compare(player, seen, frames=6):
    seen.clear()
    player.run(frames)
    assert len(seen) == frames
    for actual, expected in seen:
        assert_same_bits(actual, expected)


def test_a_driven_bone_moves_its_undriven_children():
    h = character()
    player, seen = frame_player(h, [{"target": "spine", "oscillate": {
        "property": "rotation", "axis": [1, 0, 0], "amplitude": 30, "frequency": 1.0}}])
    run_and_compare(player, seen)
    assert not np.allclose(seen[0][0][0][h.index("hat")], seen[-1][0][0][h.index("hat")])


def test_restored_bones_are_propagated_with_their_subtrees():
    h = character()
    player, seen = frame_player(h, [{"target": "root", "orbit": {"radius": 0.5, "period": 2.0}}],
                                restored=["head", "leg"])

    def write_back(ctx):  # a cloth bending the head and the leg after the animation
        h.local_rotation[h.index("head")] = (0.3, 0.0, 0.0, 1.0)
        h.local_rotation[h.index("leg")] = (0.0, 0.0, 0.4, 1.0)
        h.propagate()

    player.schedule.add(Phase.LATE_UPDATE, System("cloth", write_back))
    run_and_compare(player, seen)


def test_a_restored_bone_outside_every_driven_subtree_gets_its_rest_world_pose_back():
    h = character()
    player, seen = frame_player(h, [{"target": "leg", "spin": {"speed": 90}}],
                                restored=["prop_child"])
    rest = world_state(h)

    def push_prop(ctx):
        h.local_position[h.index("prop_child")] = (0.0, 3.0, 0.0)
        h.propagate()

    player.schedule.add(Phase.LATE_UPDATE, System("cloth", push_prop))
    run_and_compare(player, seen)
    k = h.index("prop_child")
    np.testing.assert_array_equal(seen[-1][0][0][k], rest[0][k])


def test_a_teleport_moves_the_targets_subtree_in_the_same_frame():
    h = character()
    player, seen = frame_player(h, [
        {"target": "hips", "walk": {"speed": 1.0}},
        {"at": 0.1, "teleport": {"target": "hips", "position": [5, 1, 0], "euler": [0, 90, 0]}}])
    run_and_compare(player, seen)
    hat = h.index("hat")
    assert seen[-1][0][0][hat][0] > 4.0


def test_an_animated_scale_reaches_the_lossy_scale_of_the_children():
    h = character()
    player, seen = frame_player(h, [{"target": "spine", "keyframes": {"keys": [
        {"time": 0.0, "scale": [1, 1, 1]}, {"time": 0.2, "scale": [2, 0.5, 1]}]}}])
    run_and_compare(player, seen, frames=8)
    np.testing.assert_allclose(seen[-1][0][2][h.index("hat")], [2.0, 1.0, 1.0], rtol=1e-6)


def test_the_update_plan_follows_changes_of_the_restore_registry_and_threads():
    h = character()
    player, seen = frame_player(h, [{"target": "root", "orbit": {"radius": 0.5, "period": 2.0}}])
    player.run(2)
    player.register_restored_bones([h.index("prop_child")], owner="late")
    h.local_position[h.index("prop_child")] = (1.0, 1.0, 1.0)     # restored at the next frame
    h.threads = 2
    run_and_compare(player, seen, frames=3)


def test_an_animation_without_a_driven_list_propagates_every_node():
    h = character()

    class Lift:
        def apply(self, hierarchy, ctx):
            hierarchy.local_position[hierarchy.index("prop")] = (2.0, ctx.time.time, 0.0)

    scene = SimpleNamespace(hierarchy=h, animation=Lift())
    player = Player(scene, default_schedule(scene), FixedFrameRate(30), TimeManager())
    player.run(3)
    assert_same_bits(world_state(h), reference_propagate(h))
    assert h.world_position[h.index("prop_child"), 1] == pytest.approx(0.5 + 3 / 30)


@pytest.mark.parametrize("small_plan", [0, 10_000])
def test_small_and_lane_paths_give_the_same_reference_bits(small_plan, monkeypatch):
    """A plan of at most ``SMALL_PLAN`` nodes runs as a plain pass over its nodes: both paths
    give the reference bits (``small_plan`` 0 forces the lane path, 10,000 the plain pass)."""
    from magica_py.scene import propagation

    monkeypatch.setattr(propagation, "SMALL_PLAN", small_plan)
    rng = np.random.default_rng(21)
    h = random_forest(rng, 300, 5)
    perturb(rng, h, np.arange(300))
    h.propagate()
    assert_same_bits(world_state(h), reference_propagate(h))


@pytest.mark.parametrize("parallel_plan", [0, 10**9])
@pytest.mark.parametrize("threads", [2, 3])
def test_threaded_and_in_turn_passes_of_a_chunked_plan_give_the_reference_bits(parallel_plan, threads,
                                                                              monkeypatch):
    """A plan of several chunks runs them on its threads from ``PARALLEL_PLAN`` nodes on and
    one after the other below: both give the reference bits (``parallel_plan`` 0 forces the
    threads, 10**9 the calling thread), frame after frame on the same threads."""
    from magica_py.scene import propagation

    monkeypatch.setattr(propagation, "PARALLEL_PLAN", parallel_plan)
    rng = np.random.default_rng(31)
    h = random_forest(rng, 1200, 24)
    h.threads = threads
    plan = h.plan()
    assert plan.chunks == threads
    pools = []
    for _frame in range(3):
        perturb(rng, h, np.arange(1200))
        h.propagate(plan)
        assert_same_bits(world_state(h), reference_propagate(h))
        pools.append(plan._pool)
    if parallel_plan == 0:   # one pool of threads - 1 threads, made at the first pass and kept
        assert pools[0] is not None and all(p is pools[0] for p in pools)
        assert pools[0].count == threads - 1
        assert all(t.is_alive() for t in pools[0]._threads)
    else:
        assert pools == [None, None, None]


def test_an_error_in_a_chunks_thread_is_raised_in_the_calling_thread(monkeypatch):
    """A chunk that fails on another thread fails the pass in the thread that asked for it,
    after the other chunks are done (nothing is left running on the hierarchy's arrays)."""
    from magica_py.scene import propagation

    monkeypatch.setattr(propagation, "PARALLEL_PLAN", 0)
    rng = np.random.default_rng(32)
    h = random_forest(rng, 600, 12)
    h.threads = 2
    plan = h.plan()
    calls = []
    real = propagation.propagate_chunks

    def failing_second_chunk(c0, c1, *rest):
        calls.append(c0)
        if c0 == 1:
            raise RuntimeError("chunk 1 failed")
        return real(c0, c1, *rest)

    monkeypatch.setattr(propagation, "propagate_chunks", failing_second_chunk)
    with pytest.raises(RuntimeError, match="chunk 1 failed"):
        h.propagate(plan)
    assert sorted(calls) == [0, 1]


# ----------------------------------------------------------------------------- deferred propagation
def _count_runs(monkeypatch, plan):
    """Record how often ``plan`` runs its pass (``plan.execute``)."""
    runs = []
    original = plan.execute
    monkeypatch.setattr(plan, "execute", lambda *a: (runs.append(1), original(*a)))
    return runs


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_deferred_plan_runs_when_a_world_array_is_read_with_the_reference_bits(seed, monkeypatch):
    rng = np.random.default_rng(seed)
    h = random_forest(rng, 600, 9)
    moved = rng.choice(h.count, 12, replace=False)
    plan = h.plan(moved)
    runs = _count_runs(monkeypatch, plan)
    perturb(rng, h, plan.nodes)
    h.propagate_later(plan)
    assert h.deferred and runs == []                   # nothing computed yet
    for name in ("world_position", "world_rotation", "lossy_scale", "local_to_world"):
        h.propagate_later(plan)
        getattr(h, name)                               # any derived array brings it up to date
        assert not h.deferred
    assert len(runs) == 4
    assert_same_bits(world_state(h), reference_propagate(h))


@pytest.mark.parametrize("seed", [3, 4])
def test_a_propagation_covering_the_deferred_nodes_skips_their_stale_pass(seed, monkeypatch):
    """The cloth defers its written bones; next frame RESTORE rewrites their local poses and
    UPDATE's plan (a superset) recomputes them: the deferred pass is never run, same bits."""
    rng = np.random.default_rng(seed)
    h = random_forest(rng, 800, 12)
    inner = h.plan(rng.choice(h.count, 10, replace=False))
    outer = h.plan(np.concatenate([inner.nodes, rng.choice(h.count, 10, replace=False)]))
    assert outer.covers(inner)
    runs = _count_runs(monkeypatch, inner)
    perturb(rng, h, inner.nodes)
    h.propagate_later(inner)
    perturb(rng, h, outer.nodes)                       # later writes, before anyone read
    h.propagate(outer)
    assert runs == [] and not h.deferred
    assert_same_bits(world_state(h), reference_propagate(h))


@pytest.mark.parametrize("seed", [5, 6])
def test_a_propagation_not_covering_the_deferred_nodes_runs_them_first(seed):
    rng = np.random.default_rng(seed)
    h = random_forest(rng, 500, 20)
    trees = np.flatnonzero(h.parent < 0)
    first, second = h.plan(trees[:3]), h.plan(trees[3:6])   # disjoint subtrees
    assert not first.covers(second) and not second.covers(first)
    perturb(rng, h, first.nodes)
    h.propagate_later(first)
    perturb(rng, h, second.nodes)
    h.propagate_later(second)                          # runs ``first`` now, defers ``second``
    assert h.deferred
    perturb(rng, h, first.nodes[:1])
    h.propagate(first)                                 # runs ``second`` first, then ``first``
    assert not h.deferred
    assert_same_bits(world_state(h), reference_propagate(h))


def test_in_the_player_an_unread_deferred_write_back_is_covered_by_the_next_update(monkeypatch):
    """The cloth's pattern: write the restored bones back in LATE_UPDATE and defer their
    propagation. Nothing reads them, so the deferred pass never runs (the next UPDATE plan
    covers them) and UPDATE still sees the reference bits; the first read runs it once."""
    h = character()
    player, seen = frame_player(h, [{"target": "root", "orbit": {"radius": 0.5, "period": 2.0}}],
                                restored=["head", "leg"])
    written = h.plan([h.index("head"), h.index("leg")])
    runs = _count_runs(monkeypatch, written)

    def write_back(ctx):
        h.local_rotation[h.index("head")] = (0.3, 0.0, 0.1 * ctx.frame, 1.0)
        h.local_rotation[h.index("leg")] = (0.0, 0.0, 0.4, 1.0)
        h.propagate_later(written)

    player.schedule.add(Phase.LATE_UPDATE, System("cloth", write_back))
    run_and_compare(player, seen)
    assert runs == [] and h.deferred
    expected = reference_propagate(h)                  # from the written-back local poses
    assert_same_bits(world_state(h), expected)         # the read runs the deferred pass
    assert len(runs) == 1 and not h.deferred


def test_a_snapshot_taken_while_deferred_saves_the_up_to_date_world_poses():
    from magica_py.runtime.snapshot import capture, restore

    rng = np.random.default_rng(7)
    h = random_forest(rng, 300, 4)
    scene = SimpleNamespace(hierarchy=h)
    player = Player(scene, default_schedule(scene), FixedFrameRate(30), TimeManager())
    plan = h.plan(rng.choice(h.count, 5, replace=False))
    perturb(rng, h, plan.nodes)
    h.propagate_later(plan)
    snap = capture(player)
    expected = reference_propagate(h)
    perturb(rng, h, plan.nodes)
    h.propagate_later(plan)                            # stale again when restored
    restore(player, snap)
    assert not h.deferred                              # the restored arrays agree already
    assert_same_bits(world_state(h), expected)


# ----------------------------------------------------------------------------- vectorisation
_ASM_SNIPPET = """
import re
import numba
import numpy as np
from magica_py.scene import propagation

fresh = numba.njit(cache=False, error_model="numpy")(propagation.compose_lanes.py_func)
s = propagation.LANE_STRIDE
rows = np.zeros((propagation.OUTPUT_ROW + propagation.LANE_OUTPUT) * s)
fresh(4, rows[:10 * s], rows[10 * s:26 * s], rows[26 * s:])
asm = "\\n".join(fresh.inspect_asm().values())
print("packed" if re.search(r"\\bv?mulpd\\b", asm) else "scalar")
"""


@pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64"),
                    reason="the check looks for x86-64 packed-double mnemonics (mulpd) in the assembly; "
                           "other CPUs name them otherwise")
def test_the_lane_loop_compiles_to_packed_double_arithmetic():
    """``compose_lanes`` is the propagation's hot loop: it vectorises only while its maths is
    inlined and LLVM can group its rows (once lost silently when process-wide LLVM options
    went away: the plans fell back to the speed of the plain pass). Compiled afresh (cached
    code cannot be inspected) in a process of its own with the JIT on and bounds checking off
    (as users run it; CI's NUMBA_BOUNDSCHECK=1 adds a branch per access, which stops any loop
    from vectorising), its assembly must multiply packed doubles."""
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_DISABLE_JIT", "NUMBA_BOUNDSCHECK")}
    out = subprocess.run([sys.executable, "-c", _ASM_SNIPPET], env=env, capture_output=True, text=True,
                         timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "packed", "compose_lanes no longer vectorises"
