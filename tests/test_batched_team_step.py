"""The block step's C.3 team update and G.3 collider poses in lane form
(``team_step.team_step_block``, ``colliders.collider_step_block``) give exactly the bits of the
per-team functions (``step.team_step_update``, ``colliders.collider_step_team`` and, folded in,
``collider_end_step_team``) on every
TeamState / ColliderState field and on the lane arrays ``block_transfer.load_lanes`` fills, with
lanes on both sides of each of C.3's branches."""
import math

import numba
import numpy as np
import pytest

from batched_harness import block_tables, crowd_system, restore, snapshot
from magica_py.kernels.math3d import q_angle, q_slerp, q_to_angle_axis
from magica_py.solver.batch_tables import borrow
from magica_py.solver.batched.state import COLLIDER_FIELDS, LANE_FIELDS, allocate_block_state
from block_transfer import load_lanes
from magica_py.solver.colliders import collider_end_step_team, collider_step_block, collider_step_team
from magica_py.solver.frame import as_kernel_table
from magica_py.solver.step import team_step_update
from magica_py.solver.team_step import q_angle_select, rotation_axis_select, slerp_select, team_step_block

DT = 1.0 / 90.0
# the lane fields load_lanes copied before the lane form (the block stages read these)
LOADED_LANE_FIELDS = [f[0] for f in LANE_FIELDS[:15]]
LOADED_COLLIDER_FIELDS = [f[0] for f in COLLIDER_FIELDS[:13]]


@numba.njit
def _team_steps(m, prm, ts, cs, tt, teams, dt):
    m, prm, ts, cs, tt = borrow(m), borrow(prm), borrow(ts), borrow(cs), borrow(tt)
    for t in teams:
        frac = tt.frame_interpolation[t]
        team_step_update(m, ts, prm, frac, t, dt)
        collider_step_team(cs, ts, t, frac)


@numba.njit
def _collider_end_steps(cs, ts, teams):
    cs, ts = borrow(cs), borrow(ts)
    for t in teams:
        collider_end_step_team(cs, ts, t)


@numba.njit
def _load_all(ts, cs, tt, blk, bs):
    ts, cs, tt, blk, bs = borrow(ts), borrow(cs), borrow(tt), borrow(blk), borrow(bs)
    for b in range(blk.block_width.shape[0]):
        load_lanes(blk, bs, ts, tt, cs, b)


@numba.njit
def _block_steps(m, prm, ts, cs, tt, blk, bs, dt):
    m, prm, ts, cs, tt, blk, bs = borrow(m), borrow(prm), borrow(ts), borrow(cs), borrow(tt), borrow(blk), borrow(bs)
    for b in range(blk.block_width.shape[0]):
        team_step_block(m, prm, ts, tt, blk, bs, b, dt)
        if blk.block_collider_count[b] > 0:
            collider_step_block(cs, ts, blk, bs, b)


def _fresh_lanes(blk):
    rows = int(np.sum(blk.block_particle_count * blk.block_width))
    return allocate_block_state(rows, int(np.sum(blk.block_particle_count)), len(blk.lane_team),
                                int(np.sum(blk.block_collider_count * blk.block_width)))


@pytest.fixture(scope="module")
def crowd():
    system = crowd_system(instances=8, frames=25)
    prm = system.parameters
    # every team the same (the blocks stay as formed): limits on, falloff on, slow stabilisation
    prm.local_inertia[:] = 0.6
    prm.local_movement_speed_limit[:] = 0.5      # m/s
    prm.local_rotation_speed_limit[:] = 60.0     # deg/s
    prm.gravity_falloff[:] = 0.5
    prm.stabilization_time[:] = 0.25
    system._pristine_for_tests = snapshot(system)
    return system


def _shape_lanes(system, blk):
    """Lanes on different C.3 paths: some teams jump (over the speed limits, a far frame slerp),
    some rest (no step motion: w == 0), some stabilise (velocity_weight < 1)."""
    ts, tt = system.teams, system.time_state
    teams = np.asarray(blk.lane_team)
    tt.frame_interpolation[teams] = 0.43
    for n, t in enumerate(teams):
        if n % 4 == 0:  # a jump and a 50 degree turn
            ts.frame_world_pos[t] = ts.now_world_pos[t] + np.array([0.3, 0.0, -0.2])
            half = math.radians(50.0) / 2
            ts.frame_world_rot[t] = [0.0, math.sin(half), 0.0, math.cos(half)]
            ts.old_frame_world_rot[t] = [0.0, 0.0, 0.0, 1.0]
        elif n % 4 == 1:  # at rest
            for name in ("frame_world_pos", "old_frame_world_pos"):
                getattr(ts, name)[t] = ts.now_world_pos[t]
            for name in ("frame_world_rot", "old_frame_world_rot"):
                getattr(ts, name)[t] = ts.now_world_rot[t]
        if n % 3 == 0:
            ts.velocity_weight[t] = 0.3 + 0.01 * n


def _all_near(a, b):
    """Per row: q_slerp(a, b, t) takes its lerp path (step.slerp_is_near)."""
    return ~(np.abs(np.sum(a * b, axis=1)) < 0.9995)


@pytest.mark.parametrize("shaped", [False, True], ids=["as_simulated", "lanes_on_every_path"])
def test_team_and_collider_step_in_lane_form_are_bit_identical(crowd, shaped):
    system = crowd
    restore(system, system._pristine_for_tests)
    blk, _ = block_tables(system)
    if shaped:
        _shape_lanes(system, blk)
    else:
        # as simulated, whole blocks have every slerp near (the lane loops' LANES_NEAR form)
        ts, cs = system.teams, system.collider_state
        b0 = np.asarray(blk.lane_team[blk.block_lane_base[0]:blk.block_lane_base[0] + blk.block_width[0]])
        assert _all_near(ts.old_frame_world_rot[b0], ts.frame_world_rot[b0]).all()
        slots = ts.collider_start[b0]
        assert _all_near(cs.old_frame_rot[slots], cs.frame_rot[slots]).all()
    m, _ps, prm, ts, cs, tt, _h = system.kernel_tables()
    kb = as_kernel_table(blk)
    teams = blk.lane_team.copy()
    before = snapshot(system)
    vw_before = system.teams.velocity_weight[teams].copy()

    _team_steps(m, prm, ts, cs, tt, teams, DT)
    expected_lanes = _fresh_lanes(blk)
    _load_all(ts, cs, tt, kb, as_kernel_table(expected_lanes))
    # the block form leaves the slots as the step's end does (old pose = now pose)
    _collider_end_steps(cs, ts, teams)
    expected = snapshot(system)

    restore(system, before)
    lanes = _fresh_lanes(blk)
    _block_steps(m, prm, ts, cs, tt, kb, as_kernel_table(lanes), DT)
    got = snapshot(system)

    for key, want in expected.items():
        same = (got[key] == want) | (np.isnan(got[key]) & np.isnan(want))
        assert same.all(), f"{key}: {int((~same).sum())} values differ"
    for name in LOADED_LANE_FIELDS:
        a, b = getattr(lanes, "lane_" + name), getattr(expected_lanes, "lane_" + name)
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), f"lane_{name} differs"
    slots = slice(0, int(np.sum(blk.block_collider_count * blk.block_width)))
    assert slots.stop > 0, "the crowd's blocks have collider slots"
    for name in LOADED_COLLIDER_FIELDS:
        a, b = getattr(lanes, "col_" + name)[..., slots], getattr(expected_lanes, "col_" + name)[..., slots]
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), f"col_{name} differs"

    if not shaped:
        return
    # both sides of each branch occurred (from the per-team results)
    e_mv = expected["ts.step_move_inertia_ratio"][teams]
    e_rv = expected["ts.step_rotation_inertia_ratio"][teams]
    w = expected["ts.angular_velocity"][teams]
    free = 1.0 - 0.6
    assert (e_mv > free).sum() > 0 and (e_mv == free).sum() > 0, "move limit: both sides"
    assert (e_rv > free).sum() > 0 and (e_rv == free).sum() > 0, "rotation limit: both sides"
    assert (w > 1e-8).sum() > 0 and (w <= 1e-8).sum() > 0, "turning and at rest"
    assert (vw_before < 1.0).sum() > 0 and (vw_before >= 1.0).sum() > 0, "stabilising and stable"
    stabilised = expected["ts.velocity_weight"][teams]
    assert np.all(stabilised[vw_before < 1.0] > vw_before[vw_before < 1.0])


def _random_quaternions(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


@numba.njit
def _twins(a, b, t):
    n = a.shape[0]
    out = np.empty((n, 11))
    for i in range(n):
        qa = (a[i, 0], a[i, 1], a[i, 2], a[i, 3])
        qb = (b[i, 0], b[i, 1], b[i, 2], b[i, 3])
        s1 = q_slerp(qa, qb, t[i])
        s2 = slerp_select(qa, qb, t[i])
        _angle, axis = q_to_angle_axis(qb)
        axis2 = rotation_axis_select(qb)
        out[i, 0] = 1.0 if s1 == s2 else 0.0
        out[i, 1] = 1.0 if q_angle(qa, qb) == q_angle_select(qa, qb) else 0.0
        out[i, 2] = 1.0 if axis == axis2 else 0.0
    return out


def test_branch_free_twins_give_the_math3d_bits_on_near_and_far_pairs():
    rng = np.random.default_rng(7)
    n = 4000
    a = _random_quaternions(rng, n)
    b = _random_quaternions(rng, n)
    # a quarter nearly equal (slerp's lerp path, q_angle's 0), some exactly equal or negated
    near = rng.random(n) < 0.25
    b[near] = a[near] + rng.normal(scale=1e-3, size=(near.sum(), 4))
    b[:50] = a[:50]
    b[50:100] = -a[50:100]
    b[100:120] = [0.0, 0.0, 0.0, 1.0]
    t = rng.random(n)
    out = _twins(a, b, t)
    assert out[:, 0].all() and out[:, 1].all() and out[:, 2].all()
    d = np.abs(np.sum(a * b, axis=1))
    assert (d < 0.9995).sum() > 100 and (d >= 0.9995).sum() > 100
