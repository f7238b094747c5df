"""Quality mode is inextensible (issue 8 item 2): max edge stretch and root-distance stretch
of the displayed bones stay within 1 % on the walking character, a 20-bone chain under
gravity 100 m/s^2 and a root spinning at 50 rad/s, where faithful mode stretches 8-56 %.

Gravity 100 is outside the [0, 20] parameter range: it is written into the solver's
parameter table after validation (``Variant.raw_parameters``), as the stability harness does.
"""
import importlib.util
import pathlib

import numpy as np
import pytest

from magica_py.bench.variants import run_variant

ROOT = pathlib.Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def bq(tmp_path_factory):
    spec = importlib.util.spec_from_file_location("bench_quality", ROOT / "benchmarks" / "bench_quality.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.SCENES = module.scenes(tmp_path_factory.mktemp("quality_scenes"))
    return module


def stretch(bq, name, params, duration):
    path, raw, _ = bq.SCENES[name]
    r = run_variant(bq.variant((path, raw, duration), "t", params), record_positions=False)
    assert not r.non_finite.any()
    return 100 * float(r.edge_stretch.max()), 100 * float(r.root_stretch.max())


@pytest.mark.parametrize("name, duration, faithful_edge", [
    ("character_walk", 2.5, 5.0),    # faithful 11.3 % (skirt rings and hair)
    ("chain20_g100", 1.5, 30.0),     # faithful 55.9 %
    ("violent_50rad", 1.5, 10.0),    # faithful 19.1 %
])
def test_quality_holds_edge_and_root_stretch_within_one_percent(bq, name, duration, faithful_edge):
    edge, root = stretch(bq, name, bq.QUALITY, duration)
    assert edge <= 1.0
    assert root <= 1.0
    f_edge, f_root = stretch(bq, name, bq.FAITHFUL, duration)
    assert f_edge >= faithful_edge and f_root >= 2.0


def test_follow_the_leader_alone_keeps_chain_edges_at_rest_length(bq):
    edge, _root = stretch(bq, "chain20_g100", {**bq.QUALITY, "solver.inextensibility": "ftl"}, 1.5)
    assert edge <= 0.01
    # the tight tether alone bounds the root distance but not the edges
    edge_t, root_t = stretch(bq, "chain20_g100", {**bq.QUALITY, "solver.inextensibility": "tether"}, 1.5)
    assert root_t <= 2.5 and edge_t >= 20.0   # tether_limit 2 % (the quality default)


def test_ftl_pass_oracle():
    """One FTL pass (``ftl_pass_block``) on a hand-made 3-particle chain: each stretched edge is
    shortened to its rest length by moving the child only, and the parent gets the DFTL
    reaction velocity."""
    from hand_blocks import HandBlock

    from magica_py.solver.quality import ftl_pass_block

    hb = HandBlock(attribute=[1, 2, 2], parent=[-1, 0, 1], baselines=[[0, 1, 2]])
    hb.write("step_basic_pos", [[0.0, 0, 0], [0, -1, 0], [0, -2, 0]])    # rest: 1 m edges
    hb.write("next_pos", [[0.0, 0, 0], [0, -1.5, 0], [0.5, -2.5, 0]])    # stretched
    hb.write("velocity_pos", np.zeros((3, 3)))
    ftl_pass_block(hb.PS, hb.BI, hb.topology, hb.b, 0.9)
    next_pos, velocity_pos = hb.read("next_pos"), hb.read("velocity_pos")
    assert next_pos[1] == pytest.approx([0, -1, 0])
    d = next_pos[2] - next_pos[1]
    assert np.linalg.norm(d) == pytest.approx(1.0)
    # child 2 moved from (0.5,-2.5) to a point 1 m from (0,-1) on the line to it
    expected = np.array([0, -1, 0]) + np.array([0.5, -1.5, 0]) / np.linalg.norm([0.5, -1.5, 0])
    assert next_pos[2] == pytest.approx(expected)
    # DFTL: particle 1 (moving parent of 2) gets velocity_pos += 0.9 x the correction of 2
    move2 = expected - np.array([0.5, -2.5, 0])
    assert velocity_pos[1] == pytest.approx(0.9 * move2)
    assert velocity_pos[0] == pytest.approx([0, 0, 0])   # fixed parent: no velocity


def test_edge_pass_and_tight_tether_oracles():
    """Hand cases: the unilateral edge projection (``edge_pass_lanes``) moves both ends by their
    inverse-mass share (fixed ends stay), leaves short edges alone; the tight tether
    (``tight_tether_block``) clamps the root distance."""
    from hand_blocks import HandBlock

    from magica_py.kernels.math3d import inverse_mass_friction_depth
    from magica_py.solver.parameters import PRM_TETHER_LIMIT
    from magica_py.solver.edge_projection import edge_pass_lanes
    from magica_py.solver.quality import tight_tether_block

    rest = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])

    def chain(next_pos):
        hb = HandBlock(attribute=[1, 2, 2], root_index=[-1, 0, 0], depth=[0.0, 0.5, 1.0], edges=[[0, 1], [1, 2]])
        hb.write("step_basic_pos", rest)
        hb.write("next_pos", next_pos)
        hb.write("friction", np.zeros(3))
        return hb

    hb = chain([[0.0, 0, 0], [1.2, 0, 0], [2.0, 0, 0]])
    edge_pass_lanes(hb.PS, hb.PM, hb.BI, hb.topology, hb.b, hb.lane, hb.lane + 1)
    # edge 0-1: fixed 0, so particle 1 takes the whole 0.2 m: back to x = 1.0
    assert hb.read("next_pos")[1] == pytest.approx([1.0, 0, 0])
    # edge 1-2 was 0.8 m long before (compressed): untouched by the first edge's move, now 1.0
    assert hb.read("next_pos")[2] == pytest.approx([2.0, 0, 0])
    hb = chain([[0.0, 0, 0], [1.0, 0, 0], [2.4, 0, 0]])
    edge_pass_lanes(hb.PS, hb.PM, hb.BI, hb.topology, hb.b, hb.lane, hb.lane + 1)
    w1 = inverse_mass_friction_depth(0.0, 0.5)
    w2 = inverse_mass_friction_depth(0.0, 1.0)
    assert hb.read("next_pos")[1, 0] == pytest.approx(1.0 + 0.4 * w1 / (w1 + w2))
    assert hb.read("next_pos")[2, 0] == pytest.approx(2.4 - 0.4 * w2 / (w1 + w2))
    # tight tether: particle 2 at 3 m from its root (rest 2 m, limit 1 %): pulled to 2.02 m
    hb = chain([[0.0, 0, 0], [1.0, 0, 0], [0.0, 3.0, 0]])
    hb.P[hb.b, PRM_TETHER_LIMIT] = 0.01
    tight_tether_block(hb.PS, hb.P, hb.BI, hb.topology, hb.b)
    assert hb.read("next_pos")[2] == pytest.approx([0.0, 2.02, 0])
    assert hb.read("next_pos")[1] == pytest.approx([1.0, 0, 0])      # within its limit: untouched
