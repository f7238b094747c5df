"""The block form of the angle constraint (D.5 limit + D.6 restoration, ``angle_block``) gives
exactly the bits of ``angle_team`` from the same mid-motion crowd state (``batched_harness``),
scratch included; a plain-Python twin of the reference's branchy routine pins ``angle_team``'s
branch-free per-element functions (up to round-off: the stage solves on the edge, the twin on
world positions) and counts which paths each lane took."""
import math

import numba
import numpy as np
import pytest

from batched_harness import (
    block_rows, block_tables, crowd_system, restore, run_block_stage, run_team_stage, snapshot,
)
from magica_py.kernels import trig
from magica_py.kernels.math3d import (
    angle_between_vectors, clamp_angle, from_to_rotation_unit, inverse_mass_friction, lerp, q_inverse,
    q_mul, q_rotate, saturate, v_add, v_dot, v_length, v_scale, v_sub,
)
from magica_py.solver.batch_tables import borrow
from magica_py.solver.constraints.angle import (
    ITERATIONS, LIMIT_ATTENUATION, LIMIT_PIVOT, MOVE, angle_block, angle_team,
)
from magica_py.solver.parameters import curve_at, curve_at_clamp01, step_rate
from magica_py.solver.rotations import full_swing


@numba.njit
def solve_pivot_pair(pp, cp, v, r, pivot_ratio, wp, wc):
    """Rotate the segment p->c from ``v`` to ``r`` about the point at ``pivot_ratio`` along it:
    the corrections (dp, dc) weighted by the inverse masses, in the reference's form on world
    positions (the stage writes it on the edge, docs/angle_maths.md)."""
    pivot = v_add(pp, v_scale(v, pivot_ratio))
    dp = v_scale(v_sub(v_sub(pivot, v_scale(r, pivot_ratio)), pp), wp)
    dc = v_scale(v_sub(v_add(pivot, v_scale(r, 1.0 - pivot_ratio)), cp), wc)
    return dp, dc

FREQUENCY_RATIO = 1.0
POWER_W = 1.0
# the scattered fields the stage writes, and its scratch (compared through block_rows)
WRITTEN = ["next_pos", "velocity_pos"]
SCRATCH = ["angle_length", "angle_local_pos", "angle_rest_vector", "angle_rotation", "angle_inverse_mass",
           "angle_local_rot", "angle_rest_length", "angle_rest_direction"]
CLEARED = ["angle_length", "angle_local_pos", "angle_rest_vector"]


@pytest.fixture(scope="module")
def crowd():
    # 32 instances: blocks of 32 lanes. LLVM enters a lane loop's vector path only from
    # 12-28 lanes on (runtime overlap checks), so 6 lanes would test the scalar loops only
    return crowd_system(instances=32, frames=25)  # per team (the harness)


@numba.njit
def _angle_teams(m, ps, prm, ts, cs, tt, teams):
    m, ps, prm, ts = borrow(m), borrow(ps), borrow(prm), borrow(ts)
    for t in teams:
        angle_team(m, ps, prm, ts, t, FREQUENCY_RATIO, POWER_W, LIMIT_ATTENUATION, prm.restoration_attenuation[t])


@numba.njit
def _angle_blocks(m, ps, prm, ts, cs, tt, blk, bs, blocks):
    m, prm, blk, bs = borrow(m), borrow(prm), borrow(blk), borrow(bs)
    for b in blocks:
        angle_block(m, bs, prm, blk, b, FREQUENCY_RATIO, POWER_W, LIMIT_ATTENUATION,
                    prm.restoration_attenuation[blk.block_exemplar[b]])


def _team_rows(system, blk):
    m = system.model
    return np.concatenate([np.arange(m.team_particle_start[t], m.team_particle_start[t] + m.team_particle_count[t])
                           for t in blk.lane_team])


def _same_bits(got, want):
    return (got == want) | (np.isnan(got) & np.isnan(want))


def run_both(system):
    """The per-team stage's result (a snapshot) and the block stage's scattered result and
    scratch (team-row order); the system is left as it was."""
    blk, bs = block_tables(system)
    before = snapshot(system)
    try:
        run_team_stage(system, _angle_teams, blk)
        team = snapshot(system)
        restore(system, before)
        run_block_stage(system, _angle_blocks, blk, bs)
        block = {f"ps.{name}": getattr(system.particles, name).copy() for name in WRITTEN}
        block.update({f"bs.{name}": block_rows(system, blk, bs, name) for name in SCRATCH})
    finally:
        restore(system, before)
    return blk, bs, team, block


def assert_block_equals_team(system, blk, team, block):
    rows = _team_rows(system, blk)
    for name in WRITTEN:
        same = _same_bits(block[f"ps.{name}"][rows], team[f"ps.{name}"][rows])
        assert same.all(), f"{name}: {int((~same).sum())} values differ"
    for name in SCRATCH:
        same = _same_bits(block[f"bs.{name}"][rows], team[f"ps.{name}"][rows])
        assert same.all(), f"scratch {name}: {int((~same).sum())} values differ"
    for name in CLEARED:
        assert not np.any(block[f"bs.{name}"][rows]), f"{name} not cleared"


def test_angle_block_is_bit_identical_to_angle_team(crowd):
    blk, bs, team, block = run_both(crowd)
    assert_block_equals_team(crowd, blk, team, block)


# ----------------------------------------------------------------------------- reference twin
def reference_angle_team(system, team, frequency_ratio, power_w, limit_attenuation, restoration_attenuation,
                         paths):
    """The reference's D.5/D.6 routine as written before the per-element functions (early
    returns, acos only for a violation), in plain Python on ``system.particles``; appends
    (team-local particle, iteration, half, path) to ``paths``."""
    m, ps, prm, ts = system.model, system.particles, system.parameters, system.teams
    use_limit = prm.use_angle_limit[team] != 0
    use_restoration = prm.use_restoration[team] != 0
    mode = int(prm.rate_mode[team])
    stiffness = float(prm.limit_stiffness[team])
    gravity_factor = lerp(1.0 - float(prm.restoration_gravity_falloff[team]), 1.0, float(ts.gravity_dot[team]))
    start = int(m.team_particle_start[team])
    t3 = lambda a, i: tuple(float(x) for x in a[i])  # noqa: E731
    inv_mass, length_buf, local_pos, local_rot, rest_len, rest_dir, limit, limit_cos, rate = ({} for _ in range(9))
    for b in range(int(m.team_baseline_start[team]), int(m.team_baseline_start[team] + m.team_baseline_count[team])):
        entries = [int(x) for x in m.baseline_data[m.baseline_start[b]:m.baseline_start[b] + m.baseline_count[b]]]
        for n, c in enumerate(entries):
            ps.angle_rotation[c] = ps.step_basic_rot[c]
            inv_mass[c] = inverse_mass_friction(float(ps.friction[c]))
            ps.angle_inverse_mass[c] = inv_mass[c]
            if n == 0:
                continue
            p = int(m.parent[c])
            length = v_length(v_sub(t3(ps.next_pos, c), t3(ps.next_pos, p)))
            bv = v_sub(t3(ps.step_basic_pos, c), t3(ps.step_basic_pos, p))
            blen = v_length(bv)
            if length < 1e-8 or blen < 1e-8:
                length_buf[c], local_pos[c], local_rot[c] = 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)
            else:
                iq = q_inverse(t3(ps.step_basic_rot, p))
                length_buf[c] = length
                local_pos[c] = q_rotate(iq, v_scale(bv, 1.0 / blen))
                local_rot[c] = q_mul(iq, t3(ps.step_basic_rot, c))
            ps.angle_length[c], ps.angle_local_pos[c], ps.angle_local_rot[c] = length_buf[c], local_pos[c], local_rot[c]
            ps.angle_rest_vector[c] = bv
            rest_len[c] = blen
            ps.angle_rest_length[c] = blen
            if blen >= 1e-8:
                ps.angle_rest_direction[c] = v_scale(bv, 1.0 / blen)
            rest_dir[c] = t3(ps.angle_rest_direction, c)
            depth = float(m.depth[c])
            limit[c] = math.radians(curve_at(prm.limit_angle_curve, team, depth))
            limit_cos[c] = trig.cos(limit[c])
            kr = curve_at_clamp01(prm.restoration_stiffness_curve, team, depth)
            rate[c] = saturate(step_rate(kr, frequency_ratio, power_w, mode)) * gravity_factor
        for it in range(ITERATIONS):
            pivot = lerp(0.1, 0.5, it / 2.0)
            for c in entries[1:]:
                if (m.attribute[c] & MOVE) == 0:
                    continue
                p = int(m.parent[c])
                p_move = (m.attribute[p] & MOVE) != 0
                cp, pp = t3(ps.next_pos, c), t3(ps.next_pos, p)
                if use_limit:
                    cp, pp = _reference_limit(ps, c, p, cp, pp, inv_mass[c], inv_mass[p], p_move, length_buf[c],
                                              local_pos[c], local_rot[c], limit[c], limit_cos[c], stiffness,
                                              limit_attenuation, paths, (c - start, it))
                if use_restoration:
                    key = (c - start, it, "restoration")
                    if rest_len[c] < 1e-8:
                        paths.append(key + ("snap",))
                        ps.velocity_pos[c] = v_add(t3(ps.velocity_pos, c), v_sub(pp, cp))
                        ps.next_pos[c] = pp
                        continue
                    v = v_sub(cp, pp)
                    vl = v_length(v)
                    if vl < 1e-8:
                        paths.append(key + ("skip",))
                        continue
                    paths.append(key + ("solve",))
                    q = from_to_rotation_unit(v_scale(v, 1.0 / vl), rest_dir[c], rate[c])
                    dp, dc = solve_pivot_pair(pp, cp, v, q_rotate(q, v), pivot, inv_mass[p], inv_mass[c])
                    ps.next_pos[c] = v_add(t3(ps.next_pos, c), dc)
                    ps.velocity_pos[c] = v_add(t3(ps.velocity_pos, c), v_scale(dc, restoration_attenuation))
                    if p_move:
                        ps.next_pos[p] = v_add(t3(ps.next_pos, p), dp)
                        ps.velocity_pos[p] = v_add(t3(ps.velocity_pos, p), v_scale(dp, restoration_attenuation))
        for c in entries:
            ps.angle_length[c] = 0.0
            ps.angle_local_pos[c] = 0.0
            ps.angle_rest_vector[c] = 0.0


def _reference_limit(ps, c, p, cp, pp, wc, wp, p_move, lb, local_pos, local_rot, max_angle, max_angle_cos,
                     stiffness, attenuation, paths, key):
    t3 = lambda a, i: tuple(float(x) for x in a[i])  # noqa: E731
    key = key + ("limit",)
    v = v_sub(cp, pp)
    vl = v_length(v)
    if vl < 1e-8:
        paths.append(key + ("skip",))
        return cp, pp
    tv = q_rotate(t3(ps.angle_rotation, p), local_pos)
    tl = v_length(tv)
    if tl < 1e-8:
        paths.append(key + ("snap",))
        ps.velocity_pos[c] = v_add(t3(ps.velocity_pos, c), v_sub(pp, cp))
        ps.next_pos[c] = pp
        ps.angle_rotation[c] = q_mul(t3(ps.angle_rotation, p), local_rot)
        return cp, pp
    vn = v_scale(v, 1.0 / vl)
    tn = v_scale(tv, 1.0 / tl)
    lc = (vl + lb) * 0.5
    if lb < 1e-8 or lc < 1e-8:
        paths.append(key + ("degenerate",))
        return cp, pp
    v = v_scale(vn, lc)
    r = v
    path = "free"
    if v_dot(vn, tn) < max_angle_cos:
        alpha = angle_between_vectors(v, tn)
        if alpha > max_angle:
            path = "clamp"
            r = clamp_angle(v, tn, lerp(alpha, max_angle, stiffness))
    paths.append(key + (path,))
    dp, dc = solve_pivot_pair(pp, cp, v, r, LIMIT_PIVOT, wp, wc)
    cp = v_add(cp, dc)
    ps.next_pos[c] = cp
    ps.velocity_pos[c] = v_add(t3(ps.velocity_pos, c), v_scale(dc, attenuation))
    if p_move:
        pp = v_add(pp, dp)
        ps.next_pos[p] = pp
        ps.velocity_pos[p] = v_add(t3(ps.velocity_pos, p), v_scale(dp, attenuation))
    u = v_sub(cp, pp)
    ul = v_length(u)
    if ul >= 1e-8:
        ps.angle_rotation[c] = q_mul(full_swing(tn, v_scale(u, 1.0 / ul)), q_mul(t3(ps.angle_rotation, p), local_rot))
    return cp, pp


def _perturb_lanes(system, blk):
    """Per-lane variety in every block: lane 1 gets a zero-length segment (first Move particle
    on its fixed parent: the limit skips it, then snaps it), lane 2 a zero-length rest edge
    (a Move particle's step basic position on its Move parent's: limit and restoration
    snap), lane 3 a hard random bend of every Move particle (limit violations); the other
    lanes keep their mid-motion state."""
    m, ps = system.model, system.particles
    rng = np.random.default_rng(4)
    for b in range(len(blk.block_width)):
        teams = [int(t) for t in blk.lane_team[blk.block_lane_base[b]:blk.block_lane_base[b] + blk.block_width[b]]]
        assert len(teams) >= 4
        s = [int(m.team_particle_start[t]) for t in teams]
        n = int(m.team_particle_count[teams[0]])
        move = [(m.attribute[s[0] + i] & MOVE) != 0 for i in range(n)]
        parent = [int(m.parent[s[0] + i]) - s[0] if m.parent[s[0] + i] >= 0 else -1 for i in range(n)]
        first = next(i for i in range(n) if move[i] and parent[i] >= 0 and not move[parent[i]])
        middle = next(i for i in range(n) if move[i] and parent[i] >= 0 and move[parent[i]])
        ps.next_pos[s[1] + first] = ps.next_pos[s[1] + parent[first]]
        ps.step_basic_pos[s[2] + middle] = ps.step_basic_pos[s[2] + parent[middle]]
        for i in range(n):
            if move[i]:
                ps.next_pos[s[3] + i] += rng.normal(0.0, 0.08, 3)


@pytest.fixture(scope="module")
def perturbed(crowd):
    """The crowd with per-lane degenerate and violent cases; the paths the reference routine
    takes there, per team: {team: [(particle, iteration, half, path), ...]}; and its result."""
    blk, _bs = block_tables(crowd)
    before = snapshot(crowd)
    _perturb_lanes(crowd, blk)
    perturbed_state = snapshot(crowd)
    prm = crowd.parameters
    paths = {}
    for t in blk.lane_team:
        t = int(t)
        assert prm.use_angle_limit[t] and prm.use_restoration[t]
        paths[t] = []
        reference_angle_team(crowd, t, FREQUENCY_RATIO, POWER_W, LIMIT_ATTENUATION,
                             float(prm.restoration_attenuation[t]), paths[t])
    reference = snapshot(crowd)
    restore(crowd, perturbed_state)
    yield crowd, blk, paths, reference
    restore(crowd, before)


def test_angle_team_equals_the_reference_routine_on_every_path(perturbed):
    system, blk, paths, reference = perturbed
    before = snapshot(system)
    try:
        run_team_stage(system, _angle_teams, blk)
        rows = _team_rows(system, blk)
        # the buffers: the same bits
        for name in ["angle_rest_direction", "angle_rest_length", "angle_inverse_mass", "angle_length",
                     "angle_local_pos", "angle_rest_vector"]:
            got = getattr(system.particles, name)[rows]
            same = _same_bits(got, reference[f"ps.{name}"][rows])
            assert same.all(), f"{name}: {int((~same).sum())} values differ"
        # positions, velocities and rotations: the stage writes the reference's solves on the
        # edge (tests/test_angle_maths.py), the twin on world positions: round-off of those
        # positions (ulp 1.8e-15 m at 8-16 m), carried over 3 iterations down the chains
        eps = np.finfo(float).eps
        scale = np.abs(reference["ps.next_pos"][rows]).max()
        for name, bound in (("next_pos", 16 * eps * scale), ("velocity_pos", 16 * eps * scale),
                            ("angle_rotation", 1e-12)):
            got, want = getattr(system.particles, name)[rows], reference[f"ps.{name}"][rows]
            assert np.all(np.isfinite(got) == np.isfinite(want)), name
            err = float(np.nanmax(np.abs(got - want)))
            assert err <= bound, (name, err, bound)
            print(f"{name}: max |stage - twin| {err:.2e} (bound {bound:.1e})")
    finally:
        restore(system, before)
    taken = {}
    for events in paths.values():
        for _c, _it, half, path in events:
            taken[(half, path)] = taken.get((half, path), 0) + 1
    # every reachable path ran (the 'degenerate' rest-length path needs |cp - pp| < 1e-8
    # with a non-degenerate rest direction: unreachable, the snap catches it first)
    for key in [("limit", "skip"), ("limit", "snap"), ("limit", "clamp"), ("limit", "free"),
                ("restoration", "snap"), ("restoration", "skip"), ("restoration", "solve")]:
        assert taken.get(key, 0) > 0, (key, taken)


def test_angle_block_is_bit_identical_when_lanes_take_different_paths(perturbed):
    system, blk, paths, _reference = perturbed
    # the same (particle, iteration, half) takes different paths in different lanes of a block
    mixed = {}
    for b in range(len(blk.block_width)):
        teams = [int(t) for t in blk.lane_team[blk.block_lane_base[b]:blk.block_lane_base[b] + blk.block_width[b]]]
        by_key = {}
        for lane, t in enumerate(teams):
            for c, it, half, path in paths[t]:
                by_key.setdefault((c, it, half), {})[lane] = path
        for outcomes in by_key.values():
            if len(set(outcomes.values())) > 1:
                for path in set(outcomes.values()):
                    mixed[(b, path)] = mixed.get((b, path), 0) + 1
        for path in ("snap", "skip", "clamp", "free", "solve"):
            assert mixed.get((b, path), 0) > 0, (b, path, mixed)
    blk, _bs, team, block = run_both(system)
    assert_block_equals_team(system, blk, team, block)
