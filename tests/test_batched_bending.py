"""Triangle bending and volume (docs/solver.md §D.7) in block form: ``bending_block`` and
``apply_accumulated_block`` give exactly the bits of ``bending_team`` / ``apply_accumulated``
from a mid-motion crowd (``batched_harness``), including lanes whose pairs are degenerate
while the other lanes' are not; the branch-free per-element functions against a numpy twin
of the original (branching) maths and hand-computed cases."""
import math

import numba
import numpy as np
import pytest

from batched_harness import (
    block_rows, block_tables, compare_stage, crowd_system, restore, run_block_stage, run_team_stage, snapshot,
)
from magica_py.solver.batch_tables import borrow
from magica_py.solver.constraints.bending import (
    DONT_MOVE_INVERSE_MASS, accumulated, apply_accumulated, apply_accumulated_block, averaged, bending_block,
    bending_team, particle_inverse_mass, solve_dihedral, solve_volume,
)

RATIO, POWER_Y = 1.0, 1.0
SCRATCH = ("accum_vector", "accum_count", "bend_inverse_mass")


@pytest.fixture(scope="module")
def crowd():
    return crowd_system(instances=6, frames=25)


# ----------------------------------------------------------------------------- wrappers
@numba.njit
def _bending_teams(m, ps, prm, ts, cs, tt, teams):
    m, ps, prm, ts = borrow(m), borrow(ps), borrow(prm), borrow(ts)
    for t in teams:
        if m.team_bend_count[t] > 0 or m.team_volume_count[t] > 0:   # as frame.run_step
            bending_team(m, ps, prm, ts, t, RATIO, POWER_Y)


@numba.njit
def _bending_blocks(m, ps, prm, ts, cs, tt, blk, bs, blocks):
    m, prm, blk, bs = borrow(m), borrow(prm), borrow(blk), borrow(bs)
    for b in blocks:
        bending_block(m, bs, prm, blk, b, RATIO, POWER_Y)


@numba.njit
def _bend_apply_teams(m, ps, prm, ts, cs, tt, teams):
    m, ps, prm, ts = borrow(m), borrow(ps), borrow(prm), borrow(ts)
    for t in teams:
        if m.team_bend_count[t] > 0 or m.team_volume_count[t] > 0:
            bending_team(m, ps, prm, ts, t, RATIO, POWER_Y)
            apply_accumulated(m, ps, t, True)


@numba.njit
def _bend_apply_blocks(m, ps, prm, ts, cs, tt, blk, bs, blocks):
    m, prm, blk, bs = borrow(m), borrow(prm), borrow(blk), borrow(bs)
    for b in blocks:
        ex = blk.block_exemplar[b]
        if m.team_bend_count[ex] > 0 or m.team_volume_count[ex] > 0:
            bending_block(m, bs, prm, blk, b, RATIO, POWER_Y)
            apply_accumulated_block(m, bs, blk, b, True)


@numba.njit
def _apply_all_teams(m, ps, prm, ts, cs, tt, teams):
    m, ps = borrow(m), borrow(ps)
    for t in teams:
        apply_accumulated(m, ps, t, False)


@numba.njit
def _apply_all_blocks(m, ps, prm, ts, cs, tt, blk, bs, blocks):
    m, blk, bs = borrow(m), borrow(blk), borrow(bs)
    for b in blocks:
        apply_accumulated_block(m, bs, blk, b, False)


# ----------------------------------------------------------------------------- helpers
def _bending_teams_of(system, blk):
    m = system.model
    return [int(t) for t in blk.lane_team if m.team_bend_count[t] > 0 or m.team_volume_count[t] > 0]


def _team_rows(system, teams):
    m = system.model
    return np.concatenate([np.arange(m.team_particle_start[t], m.team_particle_start[t] + m.team_particle_count[t])
                           for t in teams])


def _run_both(system, team_wrapper, block_wrapper):
    """(per-team snapshot, block tables) after the stage run both ways from the same state;
    the system holds the block result (scattered fields) afterwards."""
    blk, bs = block_tables(system)
    before = snapshot(system)
    run_team_stage(system, team_wrapper, blk)
    expected = snapshot(system)
    restore(system, before)
    run_block_stage(system, block_wrapper, blk, bs)
    return before, expected, blk, bs


def _assert_scratch_equal(system, blk, bs, expected, rows):
    for name in SCRATCH:
        got = block_rows(system, blk, bs, name)[rows]
        want = expected[f"ps.{name}"][rows]
        assert np.array_equal(got, want), f"{name}: {int((got != want).sum())} values differ"


# ----------------------------------------------------------------------------- block == team
def test_crowd_has_a_bending_block_and_a_block_without_bending(crowd):
    blk, _bs = block_tables(crowd)
    m = crowd.model
    with_bending = [int(m.team_bend_count[e]) for e in blk.block_exemplar if m.team_bend_count[e] > 0]
    without = [int(e) for e in blk.block_exemplar if m.team_bend_count[e] == 0 and m.team_volume_count[e] == 0]
    assert with_bending and with_bending[0] > 0 and without


def test_bending_block_accumulates_the_per_team_bits(crowd):
    """The accumulators and inverse masses (scratch, read back from the block state) equal
    the per-team ones bit for bit, and the corrections are not trivially zero."""
    before, expected, blk, bs = _run_both(crowd, _bending_teams, _bending_blocks)
    try:
        rows = _team_rows(crowd, _bending_teams_of(crowd, blk))
        _assert_scratch_equal(crowd, blk, bs, expected, rows)
        counts = expected["ps.accum_count"][rows]
        assert counts.max() >= 4 and np.abs(expected["ps.accum_vector"][rows]).max() > 0.0
    finally:
        restore(crowd, before)


def test_block_without_bending_returns_at_once(crowd):
    """The hair block has no bend or volume pair: its scratch rows are left as gathered."""
    blk, bs = block_tables(crowd)
    before = snapshot(crowd)
    try:
        run_block_stage(crowd, _bending_blocks, blk, bs)
        m = crowd.model
        hair = [int(t) for t in blk.lane_team if m.team_bend_count[t] == 0 and m.team_volume_count[t] == 0]
        rows = _team_rows(crowd, hair)
        for name in SCRATCH:
            assert np.array_equal(block_rows(crowd, blk, bs, name)[rows], before[f"ps.{name}"][rows]), name
    finally:
        restore(crowd, before)


def test_bending_then_apply_block_is_bit_identical_and_clears_the_accumulators(crowd):
    compare_stage(crowd, _bend_apply_teams, _bend_apply_blocks, ["next_pos"])
    before, expected, blk, bs = _run_both(crowd, _bend_apply_teams, _bend_apply_blocks)
    try:
        rows = _team_rows(crowd, _bending_teams_of(crowd, blk))
        _assert_scratch_equal(crowd, blk, bs, expected, rows)
        assert not block_rows(crowd, blk, bs, "accum_vector")[rows].any()
        assert not block_rows(crowd, blk, bs, "accum_count")[rows].any()
        moved = np.abs(expected["ps.next_pos"][rows] - before["ps.next_pos"][rows]).max()
        assert moved > 1e-7   # the stage did move particles
    finally:
        restore(crowd, before)


def test_apply_block_without_move_only_adds_to_fixed_particles_too(crowd):
    """``move_only=False`` from accumulators filled with varying counts (zero in some
    lanes): every row (fixed ones included) gets the per-team bits."""
    ps = crowd.particles
    blk, _bs = block_tables(crowd)
    rows = _team_rows(crowd, [int(t) for t in blk.lane_team])
    saved = snapshot(crowd)
    rng = np.random.default_rng(3)
    try:
        ps.accum_count[rows] = rng.integers(0, 4, rows.size)
        ps.accum_vector[rows] = np.trunc(rng.normal(0.0, 2000.0, (rows.size, 3))) * (ps.accum_count[rows] > 0)[:, None]
        fixed = rows[(crowd.model.attribute[rows] & 0x02) == 0]
        assert fixed.size and (ps.accum_count[fixed] > 0).any() and (ps.accum_count[rows] == 0).any()
        compare_stage(crowd, _apply_all_teams, _apply_all_blocks, ["next_pos"])
    finally:
        restore(crowd, saved)


def _degenerate_pairs(system, blk, lanes_hit):
    """Collapse, in the lanes ``lanes_hit`` of the bending block, one bend pair's shared
    edge (v3 onto v2: zero edge), another pair's triangle (v0 onto v2: zero normal) and one
    volume pair's tetra (all four onto v0). Returns the number of pairs changed."""
    m = system.model
    ps = system.particles
    b = next(b for b in range(len(blk.block_width)) if m.team_bend_count[blk.block_exemplar[b]] > 0)
    changed = 0
    for i in lanes_hit:
        t = int(blk.lane_team[blk.block_lane_base[b] + i])
        bs0 = int(m.team_bend_start[t])
        v = m.bend_vertices[bs0 + 3]
        ps.next_pos[v[3]] = ps.next_pos[v[2]]
        v = m.bend_vertices[bs0 + 11]
        ps.next_pos[v[0]] = ps.next_pos[v[2]]
        changed += 2
        if m.team_volume_count[t] > 0:
            v = m.volume_vertices[int(m.team_volume_start[t]) + 5]
            ps.next_pos[v[1:]] = ps.next_pos[v[0]]
            changed += 1
    return changed


def test_lanes_with_degenerate_pairs_match_per_team_while_others_correct(crowd):
    """Some lanes hit the degenerate (not ok) path on pairs whose other lanes correct: the
    count of accumulated contributions shows both paths, and the bits still match."""
    blk, _bs = block_tables(crowd)
    saved = snapshot(crowd)
    try:
        _degenerate_pairs(crowd, blk, lanes_hit=(0, 2, 3))
        before, expected, blk, bs = _run_both(crowd, _bending_teams, _bending_blocks)
        m = crowd.model
        teams = _bending_teams_of(crowd, blk)
        rows = _team_rows(crowd, teams)
        _assert_scratch_equal(crowd, blk, bs, expected, rows)
        pairs = int(sum(m.team_bend_count[t] + m.team_volume_count[t] for t in teams))
        accumulated_pairs = int(expected["ps.accum_count"][rows].sum()) // 4
        skipped = pairs - accumulated_pairs
        assert accumulated_pairs > 0 and skipped >= 6   # both paths, in 3 of the block's lanes
        restore(crowd, before)
        compare_stage(crowd, _bend_apply_teams, _bend_apply_blocks, ["next_pos"])
    finally:
        restore(crowd, saved)


def test_pairs_with_a_repeated_vertex_take_the_unscoped_loop_with_the_same_bits(crowd):
    """The scoped (alias-metadata) lane loop assumes four distinct vertices; a pair that
    repeats one (never built, but not excluded by the model's type) takes the plain loop,
    which accumulates the repeated vertex twice exactly as the per-team stage does."""
    from magica_py.solver.frame import as_kernel_table

    model = crowd.model
    bend_vertices = model.bend_vertices.copy()
    blk, _bs = block_tables(crowd)
    hit = []
    for t in _bending_teams_of(crowd, blk):
        c = int(model.team_bend_start[t]) + 7
        bend_vertices[c, 1] = bend_vertices[c, 0]
        hit.append(c)
    tables = crowd.kernel_tables()
    before = snapshot(crowd)
    run_team_stage(crowd, _bending_teams, blk)
    plain_counts = crowd.particles.accum_count.copy()
    restore(crowd, before)
    try:
        crowd._tables = (as_kernel_table(model._replace(bend_vertices=bend_vertices)),) + tables[1:]
        before_, expected, blk, bs = _run_both(crowd, _bending_teams, _bending_blocks)
        rows = _team_rows(crowd, _bending_teams_of(crowd, blk))
        _assert_scratch_equal(crowd, blk, bs, expected, rows)
        v0 = bend_vertices[hit[0], 0]   # now in pair hit[0] twice, in place of its v1
        assert expected["ps.accum_count"][v0] == plain_counts[v0] + 1
        restore(crowd, before_)
        compare_stage(crowd, _bend_apply_teams, _bend_apply_blocks, ["next_pos"])
    finally:
        crowd._tables = tables
        restore(crowd, before)


# ----------------------------------------------------------------------------- per element
def _dihedral_twin(p, w, rest_angle, sign, k):
    """The original branching maths in numpy (libm arccos): None for a degenerate pair."""
    p0, p1, p2, p3 = (np.asarray(x, dtype=float) for x in p)
    e = p3 - p2
    el = np.linalg.norm(e)
    if el < 1e-8:
        return None
    n1 = np.cross(p2 - p0, p3 - p0)
    n2 = np.cross(p3 - p1, p2 - p1)
    l1, l2 = n1 @ n1, n2 @ n2
    if l1 == 0.0 or l2 == 0.0:
        return None
    n1u, n2u = n1 / math.sqrt(l1), n2 / math.sqrt(l2)
    n1, n2 = n1 / l1, n2 / l2
    d = [n1 * el, n2 * el,
         ((p0 - p3) @ e / el) * n1 + ((p1 - p3) @ e / el) * n2,
         ((p2 - p0) @ e / el) * n1 + ((p2 - p1) @ e / el) * n2]
    phi = math.acos(min(1.0, max(-1.0, n1u @ n2u)))
    if np.cross(n1u, n2u) @ e < 0.0:
        phi = -phi
    denom = sum(wi * (di @ di) for wi, di in zip(w, d))
    lam = (sign * rest_angle - phi) / denom * k
    return [-wi * lam * di for wi, di in zip(w, d)]


def test_solve_dihedral_matches_a_numpy_twin_of_the_branching_maths():
    rng = np.random.default_rng(11)
    for _ in range(200):
        p = [tuple(rng.normal(0.0, 0.3, 3)) for _ in range(4)]
        w = tuple(rng.uniform(0.01, 1.0, 4))
        rest, sign, k = rng.uniform(0.0, 3.0), (1.0 if rng.random() < 0.5 else -1.0), rng.uniform(0.05, 1.0)
        ok, *c = solve_dihedral(*p, *w, rest, sign, k)
        want = _dihedral_twin(p, w, rest, sign, k)
        assert ok
        scale = max(np.abs(np.array(want)).max(), 1e-12)
        np.testing.assert_allclose(np.array(c), np.array(want), rtol=0.0, atol=1e-12 * scale)


def _signed_dihedral(p0, p1, p2, p3):
    p0, p1, p2, p3 = (np.asarray(x, dtype=float) for x in (p0, p1, p2, p3))
    n1 = np.cross(p2 - p0, p3 - p0)
    n2 = np.cross(p3 - p1, p2 - p1)
    n1, n2 = n1 / np.linalg.norm(n1), n2 / np.linalg.norm(n2)
    phi = math.acos(np.clip(n1 @ n2, -1.0, 1.0))
    return -phi if np.cross(n1, n2) @ (p3 - p2) < 0.0 else phi


def test_flat_pair_at_its_rest_angle_gets_no_correction_and_a_folded_one_unfolds():
    # two triangles sharing the edge v2-v3 on the X axis, v0 above (+Y), v1 below (-Y): flat
    p0, p1, p2, p3 = (0.5, 1.0, 0.0), (0.5, -1.0, 0.0), (0.0, 0.0, 0.0), (1.0, 0.0, 0.0)
    ok, *c = solve_dihedral(p0, p1, p2, p3, 1.0, 1.0, 1.0, 1.0, 0.0, 1.0, 1.0)
    assert ok and np.abs(np.array(c)).max() < 1e-15
    # fold v1 out of the plane by 90 degrees: half the correction (stiffness 0.5) unfolds it
    folded = (p0, (0.5, 0.0, -1.0), p2, p3)
    phi = _signed_dihedral(*folded)
    assert abs(abs(phi) - math.pi / 2) < 1e-12
    ok, *c = solve_dihedral(*folded, 1.0, 1.0, 1.0, 1.0, 0.0, 1.0, 0.5)
    after = [np.add(p, ci) for p, ci in zip(folded, c)]
    assert ok and abs(_signed_dihedral(*after)) < 0.75 * abs(phi)
    np.testing.assert_allclose(np.sum(c, axis=0), 0.0, atol=1e-14)   # equal weights: momentum kept


def test_degenerate_pairs_are_not_ok_and_give_zero_corrections():
    a, b, c = (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.5, 1.0, 0.0)
    cases = [((c, (0.5, -1, 0), a, a), "zero edge"),
             ((a, (0.5, -1, 0), a, b), "v0 on the edge: zero normal"),
             (((0.5, 0.0, 0.0), (0.5, -1, 0), a, b), "v0 on the edge line")]
    for p, why in cases:
        ok, *corr = solve_dihedral(*p, 1.0, 1.0, 1.0, 1.0, 0.3, 1.0, 1.0)
        assert not ok, why
        assert all(x == 0.0 for v in corr for x in v), why
    ok, *corr = solve_volume(a, a, a, a, 1.0, 1.0, 1.0, 1.0, 5.0, 1.0)
    assert not ok and all(x == 0.0 for v in corr for x in v)


def test_solve_volume_restores_a_unit_tetra_hand_computed():
    o, x, y, z = (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)
    rest = 1000.0 / 6.0
    ok, *c = solve_volume(o, x, y, z, 1.0, 1.0, 1.0, 1.0, rest, 1.0)
    assert ok and np.abs(np.array(c)).max() == 0.0
    # squashed to half height: volume 1000/12; gradients g3 = (0, 0, 1), g0 = (0.5, 0.5, 0.5)...
    ok, c0, c1, c2, c3 = solve_volume(o, x, y, (0.0, 0.0, 0.5), 1.0, 1.0, 1.0, 1.0, rest, 1.0)
    # g0 = (1-y... ) computed by hand: g0 = (-0.5, -0.5, -1), g1 = (0.5, 0, 0), g2 = (0, 0.5, 0), g3 = (0, 0, 1)
    # sum |g|^2 = 1.5 + 0.25 + 0.25 + 1 = 3; lam = (1000/6 - 1000/12) / (1000 * 3) = 1/36
    lam = 1.0 / 36.0
    np.testing.assert_allclose(c3, (0.0, 0.0, lam), atol=1e-15)
    np.testing.assert_allclose(c0, (-0.5 * lam, -0.5 * lam, -lam), atol=1e-15)
    np.testing.assert_allclose(c1, (0.5 * lam, 0.0, 0.0), atol=1e-15)


def test_fixed_point_accumulation_truncates_toward_zero_and_averages():
    acc, n = accumulated((0.0, 0.0, 0.0), 0, (1.9e-6, -2.7e-6, 0.4e-6), True)
    assert acc == (1.0, -2.0, 0.0) and n == 1
    acc, n = accumulated(acc, n, (3.0e-6, 3.0e-6, -0.99e-6), True)
    assert acc == (4.0, 1.0, 0.0) and n == 2
    assert accumulated(acc, n, (1.0, 1.0, 1.0), False) == (acc, n)
    assert averaged((1.0, 2.0, 3.0), acc, n) == (1.0 + 4.0 / 2e6, 2.0 + 1.0 / 2e6, 3.0)
    assert averaged((1.0, 2.0, 3.0), (0.0, 0.0, 0.0), 0) == (1.0, 2.0, 3.0)


def test_inverse_mass_of_fixed_and_moving_vertices():
    assert particle_inverse_mass(False, 0.7, 0.2) == DONT_MOVE_INVERSE_MASS
    assert particle_inverse_mass(True, 0.0, 1.0) == 1.0
    assert particle_inverse_mass(True, 0.5, 0.5) == pytest.approx(1.0 / (1.0 + 1.5 + 5.0 * 0.25))
