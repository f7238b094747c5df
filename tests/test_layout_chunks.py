"""SolverLayout, the one chunk allocator: one contiguous chunk per team and pool, global
indices, removal and reuse that leave other teams' data bit-identical."""
from __future__ import annotations

import numpy as np
import pytest

from magica_py.build import build_cloth
from magica_py.solver.layout import _FIELD_INFO, POOLS, SolverLayout
from magica_py.scene.hierarchy import BoneSpec, TransformHierarchy
from test_build_rigs import SQUARE, Spec, chain_rig, skirt_spec, strands_rig

# per-item fields (team-range and team-level fields are compared through the chunks)
ITEM_FIELDS = [name for name, (per, _shape, _dtype) in _FIELD_INFO.items() if per in POOLS]


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


def team_slice(layout, team, field):
    """One team's rows of a global array of the layout's current model (global indices inside)."""
    start, count = layout.chunks[team][_FIELD_INFO[field][0]]
    return getattr(layout.model(), field)[start:start + count]


def snapshot(layout, team):
    return {f: team_slice(layout, team, f).copy() for f in ITEM_FIELDS}


def assert_no_overlap(layout):
    for pool in POOLS:
        spans = sorted(layout.chunks[t][pool] for t in layout.live_teams if layout.chunks[t][pool][1])
        for (s0, c0), (s1, _) in zip(spans, spans[1:]):
            assert s0 + c0 <= s1, pool
        if spans:
            assert spans[-1][0] + spans[-1][1] <= layout.capacity(pool), pool


def test_team_chunks_hold_the_model_with_indices_offset_to_global():
    layout = SolverLayout()
    ms = models()
    teams = [layout.add(m) for m in ms]
    assert teams == [0, 1, 2, 3]
    assert_no_overlap(layout)
    for t, m in zip(teams, ms):
        chunk = layout.chunks[t]
        ps = chunk["particle"][0]
        np.testing.assert_array_equal(team_slice(layout, t, "parent"), np.where(m.parent >= 0, m.parent + ps, -1))
        np.testing.assert_array_equal(team_slice(layout, t, "triangles"), m.triangles + ps)
        np.testing.assert_array_equal(team_slice(layout, t, "distance_target"), m.distance_target + ps)
        np.testing.assert_array_equal(team_slice(layout, t, "distance_start"),
                                      m.distance_start + chunk["distance"][0])
        np.testing.assert_array_equal(team_slice(layout, t, "baseline_start"),
                                      m.baseline_start + chunk["baseline_entry"][0])
        np.testing.assert_array_equal(team_slice(layout, t, "vertex_triangle_data"),
                                      m.vertex_triangle_data + chunk["triangle"][0])
        np.testing.assert_array_equal(team_slice(layout, t, "local_position"), m.local_position)
        np.testing.assert_array_equal(team_slice(layout, t, "particle_team"), np.full(m.particle_count, t))
    # a kernel walking a global CSR lands on the same neighbours as the team-local model
    t, m = teams[2], ms[2]
    ps = layout.chunks[t]["particle"][0]
    g = layout.model()
    for v in range(m.particle_count):
        s, c = g.distance_start[ps + v], g.distance_count[ps + v]
        local = m.distance_target[m.distance_start[v]:m.distance_start[v] + m.distance_count[v]]
        np.testing.assert_array_equal(g.distance_target[s:s + c], local + ps)


def test_the_model_lists_the_live_teams_for_one_kernel_call():
    layout = SolverLayout()
    ms = models()
    for m in ms:
        layout.add(m)
    layout.remove(1)
    model = layout.model()
    assert model.live_teams.tolist() == [0, 2, 3]
    assert model.team_particle_count.tolist() == [ms[0].particle_count, 0, ms[2].particle_count,
                                                  ms[3].particle_count]   # a removed id keeps zero counts
    assert model.team_particle_start[[0, 2, 3]].tolist() == [layout.chunks[t]["particle"][0] for t in (0, 2, 3)]
    assert layout.model() is model  # cached until the next add/remove
    assert not model.parent.flags.writeable
    layout.add(ms[1])
    assert layout.model() is not model


def test_the_model_has_exactly_the_rows_in_use():
    layout = SolverLayout()
    ms = models()
    for m in ms * 3:   # the storage grows geometrically, the model holds the rows in use only
        layout.add(m)
    model = layout.model()
    assert model.transform_index.shape[0] == 3 * sum(m.particle_count for m in ms) == layout.capacity("particle")
    assert model.team_particle_start.shape[0] == layout.team_count == 12


def test_removing_and_re_adding_a_team_leaves_the_others_bit_identical_and_reuses_space():
    layout = SolverLayout()
    ms = models()
    for m in ms:
        layout.add(m)
    before = {t: snapshot(layout, t) for t in (0, 2, 3)}
    freed = dict(layout.chunks[1])
    layout.remove(1)
    start, count = freed["particle"]
    assert (layout.model().particle_team[start:start + count] == -1).all()
    new = layout.add(ms[1])
    assert new == 4                                          # ids are never reused
    assert layout.chunks[new]["particle"] == freed["particle"]  # first fit reuses the hole
    assert_no_overlap(layout)
    for t, snap in before.items():
        for f, a in snap.items():
            b = team_slice(layout, t, f)
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes(), (t, f)


def test_random_add_remove_sequences_never_overlap_or_disturb_other_teams():
    rng = np.random.default_rng(3)
    ms = models()
    layout = SolverLayout()
    live: dict[int, dict] = {}
    for _ in range(60):
        if live and rng.random() < 0.4:
            t = int(rng.choice(sorted(live)))
            layout.remove(t)
            del live[t]
        else:
            t = layout.add(ms[int(rng.integers(len(ms)))])
            live[t] = snapshot(layout, t)
        assert_no_overlap(layout)
        for t, snap in live.items():
            for f, a in snap.items():
                assert a.tobytes() == team_slice(layout, t, f).tobytes(), (t, f)
        owners = layout.model().particle_team
        for t in live:
            assert (team_slice(layout, t, "particle_team") == t).all()
        assert np.count_nonzero(owners >= 0) == sum(layout.chunks[t]["particle"][1] for t in live)
        assert sorted(live) == layout.live_teams


def test_identical_rigs_share_a_topology_key():
    # the key the build cache (ModelCache) shares models by
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


def test_removing_an_unknown_team_is_an_error():
    layout = SolverLayout()
    with pytest.raises(KeyError, match="no cloth team 5"):
        layout.remove(5)
    layout.add(models()[1])
    layout.remove(0)
    with pytest.raises(KeyError, match="no cloth team 0"):
        layout.remove(0)
