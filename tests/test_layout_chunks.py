"""``blocks.BlockLayout``, the solver's one allocator: teams of one key side by side in the
lanes of a block (at most ``LANES``), a team that matches no other a block of width one, one
chunk per block and pool taken first-fit from freed space (``ChunkAllocator``); removing a
team frees its lane, a block whose lanes are all free frees its chunks, and no operation moves
or changes another block's rows (nor another lane's columns)."""
from __future__ import annotations

import numpy as np
import pytest

from magica_py.build import build_cloth
from magica_py.scene.hierarchy import BoneSpec, TransformHierarchy
from magica_py.solver import blocks as bk
from magica_py.solver.blocks import LANES, POOLS, BlockLayout, ChunkAllocator
from magica_py.solver.views import team_model
from test_build_rigs import SQUARE, Spec, chain_rig, skirt_spec, strands_rig

# (shape, direction, reverse, aligned) of two collider slots, and their hierarchy nodes
SHAPES = [(bk.SPHERE, 0, 0, 0), (bk.CAPSULE, 1, 1, 1)]
NODES = [0, 0]


def models():
    h = strands_rig(SQUARE)
    c = chain_rig(bones=5)
    fan = strands_rig([(-0.1, 0, 0), (0.1, 0, 0)], bones=4, prefix="f")
    return [
        build_cloth(h, skirt_spec(h, "sequential_loop_mesh")),
        build_cloth(c, Spec("tail", (c.index("c0"),))),
        build_cloth(fan, Spec("fan", (fan.index("f0_0"), fan.index("f1_0")), "sequential_loop_mesh")),
        build_cloth(h, skirt_spec(h, "line")),
    ]


# the per-item tables of the layout and the pool their items come from
ITEM_TABLES = (("particle_model", "particle"), ("particle_transform", "particle"), ("link_model", "link"),
               ("triangle_model", "triangle"), ("bend_model", "bend"), ("volume_model", "volume"),
               ("collider_transform", "collider"), ("topology", "topology"))


def rows(layout, b, pool):
    start, count = layout.blocks[b].chunks[pool]
    return slice(start, start + count)


def block_rows(layout, b):
    """Copies of everything block b owns: its chunks' rows of every table, its block row."""
    out = {name: getattr(layout, name)[rows(layout, b, pool)].copy() for name, pool in ITEM_TABLES}
    out["block_ints"] = layout.block_ints[b].copy()
    out["team_ints"] = layout.team_ints[b].copy()
    out["team_model"] = layout.team_model[b].copy()
    out["chunks"] = dict(layout.blocks[b].chunks)
    return out


def lane_columns(layout, b, lane):
    """Copies of lane ``lane``'s columns of block b (per-lane tables) and its team ints."""
    out = {}
    for name, pool in ITEM_TABLES:
        if name == "topology":
            continue
        table = getattr(layout, name)[rows(layout, b, pool)]
        out[name] = (table[:, lane] if name.endswith("transform") else table[:, lane::LANES]).copy()
    out["team_model"] = layout.team_model[b, lane::LANES].copy()
    out["team_ints"] = layout.team_ints[b, lane::LANES].copy()
    return out


def same(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(
        (a[k] == b[k]) if isinstance(a[k], dict) else (a[k].dtype == b[k].dtype and a[k].tobytes() == b[k].tobytes())
        for k in a)


def assert_no_overlap(layout):
    live = [b for b, blk in enumerate(layout.blocks) if blk is not None]
    for pool in POOLS:
        spans = sorted(layout.blocks[b].chunks[pool] for b in live if layout.blocks[b].chunks[pool][1])
        for (s0, c0), (s1, _) in zip(spans, spans[1:]):
            assert s0 + c0 <= s1, pool
        if spans:
            assert spans[-1][0] + spans[-1][1] <= layout.capacity(pool), pool
        free = layout.allocators[pool].free
        for s, n in spans:
            assert all(s + n <= fs or fs + fn <= s for fs, fn in free), (pool, "a used chunk is on the free list")


def assert_lane_holds(layout, team, model):
    """Team ``team``'s lane holds its model's floats; its block's topology is its model's."""
    b, lane = layout.place(team)
    g = layout.slots(team)["particle"]
    pm = bk.PARTICLE_MODEL
    assert np.array_equal(pm.view(layout.particle_model, "baseline_local_position", g, lane),
                          model.baseline_local_position)
    bound = bk.bound_vectors(np.reshape(model.skin_bind_pose, (-1, 4, 4)), np.asarray(model.local_position),
                             np.asarray(model.local_normal), np.asarray(model.local_tangent))
    assert np.array_equal(pm.view(layout.particle_model, "skin_bound_position", g, lane), bound[:, 0])
    assert np.array_equal(pm.view(layout.particle_model, "depth", g, lane), model.depth)
    assert np.array_equal(bk.LINK_MODEL.view(layout.link_model, "distance_rest", layout.slots(team)["link"], lane),
                          model.distance_rest)
    assert np.array_equal(layout.particle_transform[g, lane], model.transform_index)
    assert layout.team_ints[b, bk.TI_TEAM + lane] == team
    assert layout.team_ints[b, bk.TI_COMPONENT + lane] == model.component_transform
    assert np.array_equal(layout.segment(b, "parent"), model.parent)
    assert np.array_equal(layout.segment(b, "distance_target"), model.distance_target)


def test_a_team_that_matches_no_other_is_a_block_of_width_one_in_block_local_indices():
    layout = BlockLayout()
    ms = models()
    teams = [layout.add(m) for m in ms]
    assert teams == [0, 1, 2, 3]
    assert [layout.place(t) for t in teams] == [(0, 0), (1, 0), (2, 0), (3, 0)]
    assert_no_overlap(layout)
    for t, m in zip(teams, ms):
        b, _lane = layout.place(t)
        assert layout.block_ints[b, bk.BI_WIDTH] == 1 and layout.block_ints[b, bk.BI_LANES_USED] == 1
        assert layout.block_ints[b, bk.BI_N] == m.particle_count
        assert layout.block_ints[b, bk.BI_G0] == layout.slots(t)["particle"][0]
        assert_lane_holds(layout, t, m)
        # the topology is block-local: particle j of the team, link k, triangle i ...
        np.testing.assert_array_equal(layout.segment(b, "triangle_corners"), np.asarray(m.triangles).reshape(-1))
        np.testing.assert_array_equal(layout.segment(b, "distance_start"), m.distance_start)
        np.testing.assert_array_equal(layout.segment(b, "baseline_data"), m.baseline_data)
        np.testing.assert_array_equal(layout.segment(b, "vertex_triangle_data"), m.vertex_triangle_data)
    # a layout that never freed a block is the plain concatenation of its blocks (no slack)
    assert layout.capacity("particle") == sum(m.particle_count for m in ms)
    assert [layout.slots(t)["particle"][0] for t in teams] == list(np.cumsum([0] + [m.particle_count
                                                                                     for m in ms[:-1]]))


def test_teams_of_one_key_share_a_block_up_to_lanes_lanes():
    layout = BlockLayout()
    tail = models()[1]
    teams = [layout.add(tail) for _ in range(LANES + 1)]
    assert [layout.place(t) for t in teams] == [(0, lane) for lane in range(LANES)] + [(1, 0)]
    assert layout.block_ints[0, bk.BI_WIDTH] == LANES and layout.block_ints[0, bk.BI_LANES_USED] == LANES
    assert layout.block_ints[1, bk.BI_WIDTH] == 1
    # lanes share the block's chunks: one particle chunk per block, not per team
    assert layout.capacity("particle") == 2 * tail.particle_count
    assert np.array_equal(layout.slots(teams[0])["particle"], layout.slots(teams[LANES - 1])["particle"])
    for t in teams:
        assert_lane_holds(layout, t, tail)


def test_the_key_holds_the_parameter_row_and_the_collider_shapes():
    layout = BlockLayout()
    tail = models()[1]
    a = layout.add(tail, b"row a")
    b = layout.add(tail, b"row b")                      # another parameter row: another block
    c = layout.add(tail, b"row a", SHAPES, NODES)       # colliders: another block, with collider slots
    d = layout.add(tail, b"row a")
    assert [layout.place(t) for t in (a, b, c, d)] == [(0, 0), (1, 0), (2, 0), (0, 1)]
    assert layout.key_of(tail, b"row a") == layout.blocks[0].key
    assert layout.key_of(tail, b"row a", SHAPES) == layout.blocks[2].key != layout.blocks[0].key
    assert len(layout.slots(c)["collider"]) == 2 and len(layout.slots(a)["collider"]) == 0
    assert layout.block_ints[2, bk.BI_COLLIDERS] == 2
    np.testing.assert_array_equal(layout.segment(2, "collider_shape"), [bk.SPHERE, bk.CAPSULE])
    np.testing.assert_array_equal(layout.segment(2, "collider_reverse"), [0, 1])


def test_identical_rigs_share_a_key_and_a_block():
    # the key the build cache (ModelCache) shares models by, and the block key
    bones = []
    for c in range(3):
        bones += [BoneSpec(f"hips{c}", None, (2.0 * c, 1.0, 0.0))]
        for s, p in enumerate(SQUARE):
            parent = f"hips{c}"
            for k in range(3):
                bones.append(BoneSpec(f"c{c}s{s}_{k}", parent, p if k == 0 else (0, -0.1, 0)))
                parent = f"c{c}s{s}_{k}"
    h = TransformHierarchy(bones)
    skirts = [build_cloth(h, Spec(f"skirt{c}", tuple(h.index(f"c{c}s{s}_0") for s in range(4)),
                                  "sequential_loop_mesh")) for c in range(3)]
    c = chain_rig()
    tail = build_cloth(c, Spec("tail", (c.index("c0"),)))
    assert len({m.topology_key for m in skirts}) == 1
    assert tail.topology_key != skirts[0].topology_key
    layout = BlockLayout()
    teams = [layout.add(m) for m in skirts] + [layout.add(tail)]
    assert [layout.place(t) for t in teams] == [(0, 0), (0, 1), (0, 2), (1, 0)]
    for t, m in zip(teams, skirts):   # same topology, each lane its own floats (other bones)
        assert_lane_holds(layout, t, m)


def test_a_removed_team_frees_its_lane_and_leaves_the_other_lanes_and_blocks_untouched():
    layout = BlockLayout()
    ms = models()
    tail = ms[1]
    teams = [layout.add(tail) for _ in range(3)] + [layout.add(ms[0])]
    b, lane = layout.place(teams[1])
    others = {t: lane_columns(layout, *layout.place(t)) for t in (teams[0], teams[2])}
    skirt_block = block_rows(layout, layout.place(teams[3])[0])
    assert layout.remove(teams[1]) == (b, lane)
    assert layout.blocks[b].lanes[:3] == [teams[0], -1, teams[2]]
    assert layout.block_ints[b, bk.BI_WIDTH] == 3 and layout.block_ints[b, bk.BI_LANES_USED] == 2
    # the freed lane's model columns are back to fresh values, its team id -1
    fresh = bk.PARTICLE_MODEL.allocate(tail.particle_count)
    g = rows(layout, b, "particle")
    np.testing.assert_array_equal(layout.particle_model[g, lane::LANES], fresh[:, lane::LANES])
    assert (layout.team_ints[b, lane::LANES] == -1).all()
    for t, before in others.items():
        assert same(lane_columns(layout, *layout.place(t)), before), t
    assert same(block_rows(layout, layout.place(teams[3])[0]), skirt_block)
    with pytest.raises(KeyError, match=f"no cloth team {teams[1]}"):
        layout.place(teams[1])
    # the next team of that key takes the free lane; ids are never reused
    new = layout.add(tail)
    assert new == 4 and layout.place(new) == (b, lane)
    assert_lane_holds(layout, new, tail)
    # the last lane removed: the width shrinks to the highest lane in use
    layout.remove(teams[2])
    assert layout.block_ints[b, bk.BI_WIDTH] == 2


def test_a_block_whose_lanes_are_all_free_frees_its_chunks_and_first_fit_reuses_them():
    layout = BlockLayout()
    ms = models()
    skirt, tail, fan = ms[0], ms[1], ms[2]
    a = layout.add(skirt)
    t1, t2 = layout.add(tail), layout.add(tail)
    c = layout.add(fan)
    freed = dict(layout.blocks[1].chunks)
    kept = {t: block_rows(layout, layout.place(t)[0]) for t in (a, c)}
    layout.remove(t1)
    assert layout.blocks[1] is not None                  # one lane still in use
    layout.remove(t2)
    assert layout.blocks[1] is None                      # the last lane frees the block ...
    assert (layout.block_ints[1] == 0).all()
    for pool, (start, count) in freed.items():           # ... and its chunks
        if count:
            assert any(s <= start and start + count <= s + n for s, n in layout.allocators[pool].free), pool
    for t, before in kept.items():
        assert same(block_rows(layout, layout.place(t)[0]), before), t
    # a new block takes the freed block id and, first fit, the freed chunks
    new = layout.add(tail, b"another row")
    assert layout.place(new) == (1, 0)
    assert layout.blocks[1].chunks["particle"] == freed["particle"]
    assert layout.blocks[1].chunks["link"] == freed["link"]
    assert_lane_holds(layout, new, tail)
    # a block that does not fit in the remaining holes grows the pool at its end
    capacity = layout.capacity("particle")
    big = layout.add(skirt, b"another row")
    assert layout.slots(big)["particle"][0] == capacity
    assert_no_overlap(layout)
    for t, before in kept.items():
        assert same(block_rows(layout, layout.place(t)[0]), before), t


def test_random_add_remove_sequences_never_overlap_nor_move_other_rows():
    rng = np.random.default_rng(3)
    ms = models()
    kinds = [(0, b""), (1, b""), (1, b"x"), (2, b""), (3, b"")]
    layout = BlockLayout()
    live: dict[int, tuple[int, bytes]] = {}
    for step in range(160):
        snapshot = {b: block_rows(layout, b) for b, blk in enumerate(layout.blocks) if blk is not None}
        lanes = {t: lane_columns(layout, *layout.place(t)) for t in live}
        if live and rng.random() < 0.4:
            t = int(rng.choice(sorted(live)))
            touched, _lane = layout.remove(t)
            del live[t]
        else:
            i, extra = kinds[int(rng.integers(len(kinds)))] if step % 7 else kinds[1]
            key = layout.key_of(ms[i], extra)
            # the first block of that key with a free lane, its first free lane (else a new block)
            expected = next(((b, blk.lanes.index(-1)) for b, blk in enumerate(layout.blocks)
                             if blk is not None and blk.key == key and -1 in blk.lanes), None)
            t = layout.add(ms[i], extra)
            live[t] = (i, extra)
            touched = layout.place(t)[0]
            if expected is not None:
                assert layout.place(t) == expected
            else:
                assert touched not in snapshot and layout.block_ints[touched, bk.BI_LANES_USED] == 1
        assert_no_overlap(layout)
        for b, before in snapshot.items():               # other blocks: every row as it was
            if b != touched:
                assert same(block_rows(layout, b), before), (step, b)
        for t, before in lanes.items():                   # other lanes of the touched block too
            if t in live:
                assert same(lane_columns(layout, *layout.place(t)), before), (step, t)
        assert sorted(live) == layout.live_teams
        for t, (i, extra) in live.items():
            b, lane = layout.place(t)
            assert layout.blocks[b].lanes[lane] == t and layout.blocks[b].key == layout.key_of(ms[i], extra)
            assert_lane_holds(layout, t, ms[i])
        for b, blk in enumerate(layout.blocks):
            if blk is not None:
                used = blk.used
                assert used and len(used) <= LANES
                assert layout.block_ints[b, bk.BI_WIDTH] == max(used) + 1
                assert layout.block_ints[b, bk.BI_LANES_USED] == len(used)
    assert max(len(blk.used) for blk in layout.blocks if blk is not None) > 1


def test_removing_an_unknown_team_is_an_error():
    layout = BlockLayout()
    with pytest.raises(KeyError, match="no cloth team 5"):
        layout.remove(5)
    layout.add(models()[1])
    with pytest.raises(KeyError, match="no cloth team -1"):   # not the last id counted from the end
        layout.place(-1)
    layout.remove(0)
    with pytest.raises(KeyError, match="no cloth team 0"):
        layout.remove(0)


def test_chunk_allocator_reuses_freed_space_first_and_coalesces():
    a = ChunkAllocator()
    assert [a.allocate(n) for n in (5, 3, 4)] == [0, 5, 8]
    assert a.capacity == 12
    a.release(5, 3)
    assert a.allocate(2) == 5           # first fit inside the hole
    assert a.allocate(2) == 12          # the 1-row rest of the hole is too small: grow
    assert a.free == [[7, 1]]
    a.release(0, 5)
    a.release(5, 2)                     # 0..8 coalesce into one block
    assert a.free == [[0, 8]]
    assert a.used == 14 - 8
    with pytest.raises(ValueError, match="already free"):
        a.release(6, 1)
    a.release(12, 2)                    # a free tail is extended rather than left behind
    assert a.allocate(3) == 0
    assert a.allocate(9) == 12 and a.capacity == 21 and a.free == [[3, 5]]


def test_the_team_ordered_model_lists_the_live_teams_with_global_indices():
    ms = models()
    live = [ms[0], None, ms[2], ms[3]]                    # team 1 removed
    m = team_model(live, [0, 0, 2, 0])
    assert m.live_teams.tolist() == [0, 2, 3]
    assert m.team_particle_count.tolist() == [ms[0].particle_count, 0, ms[2].particle_count, ms[3].particle_count]
    starts = np.cumsum([0, ms[0].particle_count, 0, ms[2].particle_count])
    assert m.team_particle_start.tolist() == starts.tolist()
    assert m.team_collider_count.tolist() == [0, 0, 2, 0] and m.team_collider_start[3] == 2
    for t in (0, 2, 3):
        s, n = int(m.team_particle_start[t]), int(m.team_particle_count[t])
        np.testing.assert_array_equal(m.parent[s:s + n], np.where(ms[t].parent >= 0, ms[t].parent + s, -1))
        np.testing.assert_array_equal(m.particle_team[s:s + n], np.full(n, t))
        np.testing.assert_array_equal(m.local_position[s:s + n], ms[t].local_position)
        e, k = int(m.team_triangle_start[t]), int(m.team_triangle_count[t])
        np.testing.assert_array_equal(m.triangles[e:e + k], np.asarray(ms[t].triangles).reshape(-1, 3) + s)
    assert m.transform_index.shape[0] == sum(x.particle_count for x in live if x is not None)
    assert not m.parent.flags.writeable
