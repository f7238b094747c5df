"""TeamRegistry: one contiguous chunk per team and pool, global indices, removal and reuse that
leave other teams' data bit-identical."""
from __future__ import annotations

import numpy as np
import pytest

from magica_py.build import TeamRegistry, build_cloth
from magica_py.build.teams import POOLS
from magica_py.scene.hierarchy import BoneSpec, TransformHierarchy
from test_build_rigs import SQUARE, Spec, chain_rig, skirt_spec, strands_rig


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


def snapshot(reg, team):
    return {f: reg.team_slice(team, f).copy() for fs in POOLS.values() for f in fs}


def assert_no_overlap(reg):
    for pool in POOLS:
        spans = sorted((reg.start[t][pool], reg.count[t][pool]) for t in reg.team_ids if reg.count[t][pool])
        for (s0, c0), (s1, _) in zip(spans, spans[1:]):
            assert s0 + c0 <= s1, pool
        if spans:
            assert spans[-1][0] + spans[-1][1] <= reg.arrays[next(iter(POOLS[pool]))].shape[0]


def test_team_chunks_hold_the_model_with_indices_offset_to_global():
    reg = TeamRegistry()
    ms = models()
    teams = [reg.add(m) for m in ms]
    assert teams == [0, 1, 2, 3]
    assert_no_overlap(reg)
    for t, m in zip(teams, ms):
        ps = reg.start[t]["particle"]
        np.testing.assert_array_equal(reg.team_slice(t, "parent"), np.where(m.parent >= 0, m.parent + ps, -1))
        np.testing.assert_array_equal(reg.team_slice(t, "triangles"), m.triangles + ps)
        np.testing.assert_array_equal(reg.team_slice(t, "distance_target"), m.distance_target + ps)
        np.testing.assert_array_equal(reg.team_slice(t, "distance_start"),
                                      m.distance_start + reg.start[t]["distance"])
        np.testing.assert_array_equal(reg.team_slice(t, "baseline_start"),
                                      m.baseline_start + reg.start[t]["baseline_data"])
        np.testing.assert_array_equal(reg.team_slice(t, "vertex_triangle_data"),
                                      m.vertex_triangle_data + reg.start[t]["triangle"])
        np.testing.assert_array_equal(reg.team_slice(t, "local_position"), m.local_position)
        np.testing.assert_array_equal(reg.team_slice(t, "particle_team"), np.full(m.particle_count, t))
    # a kernel walking a global CSR lands on the same neighbours as the team-local model
    t, m = teams[2], ms[2]
    ps = reg.start[t]["particle"]
    g = reg.arrays
    for v in range(m.particle_count):
        s, c = g["distance_start"][ps + v], g["distance_count"][ps + v]
        local = m.distance_target[m.distance_start[v]:m.distance_start[v] + m.distance_count[v]]
        np.testing.assert_array_equal(g["distance_target"][s:s + c], local + ps)


def test_team_table_lists_active_teams_for_one_kernel_call():
    reg = TeamRegistry()
    ms = models()
    for m in ms:
        reg.add(m)
    reg.remove(1)
    table = reg.team_table()
    assert table["team_id"].tolist() == [0, 2, 3]
    assert table["team_particle_count"].tolist() == [ms[0].particle_count, ms[2].particle_count,
                                                      ms[3].particle_count]
    assert table["team_particle_start"].tolist() == [reg.start[t]["particle"] for t in (0, 2, 3)]
    assert reg.team_table() is table  # cached until the next add/remove
    reg.add(ms[1])
    assert reg.team_table() is not table


def test_removing_and_re_adding_a_team_leaves_the_others_bit_identical_and_reuses_space():
    reg = TeamRegistry()
    ms = models()
    for m in ms:
        reg.add(m)
    before = {t: snapshot(reg, t) for t in (0, 2, 3)}
    freed = dict(reg.start[1])
    reg.remove(1)
    assert (reg.arrays["particle_team"][freed["particle"]:freed["particle"] + ms[1].particle_count] == -1).all()
    new = reg.add(ms[1])
    assert reg.start[new]["particle"] == freed["particle"]  # first fit reuses the hole
    assert_no_overlap(reg)
    for t, snap in before.items():
        for f, a in snap.items():
            b = reg.team_slice(t, f)
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes(), (t, f)


def test_random_add_remove_sequences_never_overlap_or_disturb_other_teams():
    rng = np.random.default_rng(3)
    ms = models()
    reg = TeamRegistry()
    live: dict[int, dict] = {}
    for _ in range(60):
        if live and rng.random() < 0.4:
            t = int(rng.choice(sorted(live)))
            reg.remove(t)
            del live[t]
        else:
            t = reg.add(ms[int(rng.integers(len(ms)))])
            live[t] = snapshot(reg, t)
        assert_no_overlap(reg)
        for t, snap in live.items():
            for f, a in snap.items():
                assert a.tobytes() == reg.team_slice(t, f).tobytes(), (t, f)
        owners = reg.arrays["particle_team"]
        for t in live:
            assert (reg.team_slice(t, "particle_team") == t).all()
        assert np.count_nonzero(owners >= 0) == sum(reg.count[t]["particle"] for t in live)


def test_identical_rigs_share_a_topology_key_and_are_grouped():
    bones = []
    for c in range(3):
        bones += [BoneSpec(f"hips{c}", None, (2.0 * c, 1.0, 0.0))]
        for s, p in enumerate(SQUARE):
            parent = f"hips{c}"
            for k in range(3):
                bones.append(BoneSpec(f"c{c}s{s}_{k}", parent, p if k == 0 else (0, -0.1, 0)))
                parent = f"c{c}s{s}_{k}"
    h = TransformHierarchy(bones)
    reg = TeamRegistry()
    for c in range(3):
        reg.add(build_cloth(h, Spec(f"skirt{c}", tuple(h.index(f"c{c}s{s}_0") for s in range(4)),
                                    "sequential_loop_mesh")))
    c = chain_rig()
    reg.add(build_cloth(c, Spec("tail", (c.index("c0"),))))
    groups = sorted(reg.topology_groups().values())
    assert groups == [[0, 1, 2], [3]]


def test_removing_an_unknown_team_is_an_error():
    reg = TeamRegistry()
    with pytest.raises(KeyError, match="team 5 is not registered"):
        reg.remove(5)
