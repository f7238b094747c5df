"""Each block stage (``solver/batched``) gives exactly the bits of its per-team stage, from
the same mid-motion crowd state (``batched_harness``)."""
import numba
import numpy as np
import pytest

from batched_harness import block_tables, compare_stage, crowd_system
from magica_py.solver.batch_tables import borrow
from magica_py.kernels.math3d import q_slerp
from magica_py.kernels.math3d import slerp_is_near, slerp_near
from magica_py.solver.step import predict_block, predict_team

DT = 1.0 / 90.0
MOVE = 0x02


@pytest.fixture(scope="module")
def crowd():
    return crowd_system(instances=6, frames=25)


@numba.njit
def _predict_teams(m, ps, prm, ts, cs, tt, teams):
    m, ps, prm, ts = borrow(m), borrow(ps), borrow(prm), borrow(ts)
    for t in teams:
        predict_team(m, ps, prm, ts, t, tt.frame_interpolation[t], DT, 0.5, 1.0)


@numba.njit
def _predict_blocks(m, ps, prm, ts, cs, tt, blk, bs, blocks):
    m, prm, blk, bs = borrow(m), borrow(prm), borrow(blk), borrow(bs)
    for b in blocks:
        predict_block(m, bs, prm, blk, b, DT, 0.5, 1.0)


def test_predict_block_is_bit_identical_to_predict_team(crowd):
    compare_stage(crowd, _predict_teams, _predict_blocks,
             ["base_pos", "base_rot", "step_basic_pos", "step_basic_rot", "next_pos", "velocity_pos", "velocity"])


def test_predict_block_matches_with_a_mid_frame_interpolation(crowd):
    tt = crowd.time_state
    saved = tt.frame_interpolation.copy()
    tt.frame_interpolation[:] = 0.37
    try:
        compare_stage(crowd, _predict_teams, _predict_blocks, ["base_pos", "base_rot", "next_pos", "velocity"])
    finally:
        tt.frame_interpolation[:] = saved


PREDICT_FIELDS = ["base_pos", "base_rot", "step_basic_pos", "step_basic_rot", "next_pos", "velocity_pos", "velocity"]


def _predict_kinds(system, blk):
    """(Fixed, Move without the depth-inertia mix, Move with it) particles of the block lanes,
    the way predict_team decides them."""
    m, prm = system.model, system.parameters
    team_of = np.repeat(np.arange(len(m.team_particle_count)), m.team_particle_count)
    in_block = np.isin(team_of, blk.lane_team)
    move = (np.asarray(m.attribute) & MOVE) != 0
    k = prm.depth_inertia[team_of] * (1.0 - np.asarray(m.depth) ** 2)
    return in_block & ~move, in_block & move & (k == 0.0), in_block & move & (k != 0.0)


@pytest.mark.parametrize("depth_inertia", ["preset", 0.0])
@pytest.mark.parametrize("interpolation", ["last step", "per lane", "mid step"])
def test_predict_block_is_bit_identical_on_every_lane_loop_variant(crowd, interpolation, depth_inertia):
    """predict_block's lane loops, one per (every lane at its frame's last step or not, Fixed /
    Move without / Move with the depth-inertia mix): frame interpolation 1 in every lane, 1 in
    every other lane and 0.37 elsewhere (the block is not at its last step, yet those lanes take
    the frame's rotation), 0.37 everywhere; depth inertia of the presets (the mix everywhere
    but at the tips) or off."""
    tt, prm = crowd.time_state, crowd.parameters
    saved_t, saved_di = tt.frame_interpolation.copy(), prm.depth_inertia.copy()
    try:
        blk, _bs = block_tables(crowd)
        if interpolation == "last step":
            tt.frame_interpolation[blk.lane_team] = 1.0
        elif interpolation == "per lane":
            tt.frame_interpolation[blk.lane_team] = 0.37
            tt.frame_interpolation[blk.lane_team[::2]] = 1.0
        else:
            tt.frame_interpolation[blk.lane_team] = 0.37
        if depth_inertia != "preset":
            prm.depth_inertia[:] = depth_inertia
        fixed, shifted, mixed = _predict_kinds(crowd, blk)
        assert fixed.sum() > 0 and shifted.sum() > 0
        assert (mixed.sum() > 100) if depth_inertia == "preset" else (mixed.sum() == 0)
        # the animated rotation moved since the last frame: the slerp matters
        ps = crowd.particles
        assert (np.abs(ps.rotation - ps.old_rotation).max(axis=1) > 1e-6).sum() > 100
        compare_stage(crowd, _predict_teams, _predict_blocks, PREDICT_FIELDS)
    finally:
        tt.frame_interpolation[:] = saved_t
        prm.depth_inertia[:] = saved_di


def _axis_angle(axis, degrees):
    a = np.radians(degrees) / 2.0
    return np.array([*(np.asarray(axis, float) / np.linalg.norm(axis) * np.sin(a)), np.cos(a)])


@pytest.mark.parametrize("last_step", [True, False])
@pytest.mark.parametrize("rotations", ["near, sign flipped in some lanes", "far in some lanes"])
def test_predict_block_is_bit_identical_whichever_path_the_depth_inertia_slerp_takes(crowd, rotations, last_step):
    """The depth-inertia slerp (inertia rotation towards the step rotation) skips its acos and
    sines in a block whose lanes all take its lerp path (dot >= 0.9995, either sign), and
    computes both paths otherwise: step rotations of 2 degrees with the step rotation's sign
    flipped in every third lane (same rotation, negative dot), or of 2 degrees against 40 in
    every fourth lane."""
    ts, tt = crowd.teams, crowd.time_state
    saved = {n: getattr(ts, n).copy() for n in ("inertia_rotation", "step_rotation")}
    saved_t = tt.frame_interpolation.copy()
    try:
        blk, _bs = block_tables(crowd)
        lanes = blk.lane_team
        tt.frame_interpolation[lanes] = 1.0 if last_step else 0.37
        ts.inertia_rotation[lanes] = _axis_angle((0.2, 1.0, 0.1), 1.0)
        ts.step_rotation[lanes] = _axis_angle((0.0, 1.0, 0.3), 2.0)
        if rotations.startswith("near"):
            ts.step_rotation[lanes[::3]] *= -1.0
        else:
            ts.step_rotation[lanes[::4]] = _axis_angle((1.0, 0.0, 0.0), 40.0)
        d = (ts.inertia_rotation[lanes] * ts.step_rotation[lanes]).sum(axis=1)
        if rotations.startswith("near"):
            assert (np.abs(d) >= 0.9995).all() and (d < 0).sum() > 0
        else:
            assert (np.abs(d) < 0.9995).sum() > 0 and (np.abs(d) >= 0.9995).sum() > 0
        compare_stage(crowd, _predict_teams, _predict_blocks, PREDICT_FIELDS)
    finally:
        for n, v in saved.items():
            getattr(ts, n)[:] = v
        tt.frame_interpolation[:] = saved_t


@pytest.mark.parametrize("rotations", ["near in every lane", "near, sign flipped in some lanes",
                                       "far in some lanes"])
def test_predict_block_is_bit_identical_whichever_path_the_base_pose_slerp_takes(crowd, rotations):
    """At a step before the last of its frame, the animated pose slerps each particle's rotation
    from the previous frame's towards this frame's; a particle whose lanes all take the slerp's
    lerp path (dot >= 0.9995, either sign) skips its acos and sines. Frame rotations 1 degree
    apart, the new one's sign flipped in every third lane, or 30 degrees apart in every fifth
    lane: the per-team bits either way."""
    ps, tt = crowd.particles, crowd.time_state
    saved = {n: getattr(ps, n).copy() for n in ("old_rotation", "rotation")}
    saved_t = tt.frame_interpolation.copy()
    try:
        blk, _bs = block_tables(crowd)
        lanes = blk.lane_team
        tt.frame_interpolation[lanes] = 0.37
        rows = [np.arange(crowd.model.team_particle_start[t],
                          crowd.model.team_particle_start[t] + crowd.model.team_particle_count[t]) for t in lanes]
        rng = np.random.default_rng(11)
        for i, r in enumerate(rows):
            old = _axis_angle(rng.normal(size=3), rng.uniform(-170, 170))
            turn = _axis_angle(rng.normal(size=3), 30.0 if (rotations.startswith("far") and i % 5 == 0) else 1.0)
            new = np.array([  # old * turn (Hamilton product, x y z w)
                old[3] * turn[0] + old[0] * turn[3] + old[1] * turn[2] - old[2] * turn[1],
                old[3] * turn[1] - old[0] * turn[2] + old[1] * turn[3] + old[2] * turn[0],
                old[3] * turn[2] + old[0] * turn[1] - old[1] * turn[0] + old[2] * turn[3],
                old[3] * turn[3] - old[0] * turn[0] - old[1] * turn[1] - old[2] * turn[2]])
            if rotations.startswith("near, sign") and i % 3 == 0:
                new = -new
            ps.old_rotation[r] = old
            ps.rotation[r] = new
        all_rows = np.concatenate(rows)
        d = (ps.old_rotation[all_rows] * ps.rotation[all_rows]).sum(axis=1)
        if rotations.startswith("far"):
            assert (np.abs(d) < 0.9995).sum() > 0 and (np.abs(d) >= 0.9995).sum() > 0
        else:
            assert (np.abs(d) >= 0.9995).all()
            assert ((d < 0).sum() > 0) == rotations.startswith("near, sign")
        compare_stage(crowd, _predict_teams, _predict_blocks, PREDICT_FIELDS)
    finally:
        for n, v in saved.items():
            getattr(ps, n)[:] = v
        tt.frame_interpolation[:] = saved_t


def test_slerp_near_gives_the_bits_of_q_slerp_on_its_lerp_path():
    """slerp_near is q_slerp's lerp path alone: on random pairs within 3 degrees (either sign of
    the second quaternion) and random t, the same bits, and slerp_is_near says so; pairs 5 to
    90 degrees apart are not near."""
    rng = np.random.default_rng(4)
    near_pairs = far_pairs = 0
    for _ in range(300):
        q1 = _axis_angle(rng.normal(size=3), rng.uniform(-180, 180))
        q1 = q1 * (1.0 if rng.random() < 0.5 else -1.0)
        for degrees, near in ((rng.uniform(0.0, 3.0), True), (rng.uniform(5.0, 90.0), False)):
            dq = _axis_angle(rng.normal(size=3), degrees)
            q2 = np.array([  # q1 * dq (Hamilton product, x y z w)
                q1[3] * dq[0] + q1[0] * dq[3] + q1[1] * dq[2] - q1[2] * dq[1],
                q1[3] * dq[1] - q1[0] * dq[2] + q1[1] * dq[3] + q1[2] * dq[0],
                q1[3] * dq[2] + q1[0] * dq[1] - q1[1] * dq[0] + q1[2] * dq[3],
                q1[3] * dq[3] - q1[0] * dq[0] - q1[1] * dq[1] - q1[2] * dq[2]])
            q2 = q2 * (1.0 if rng.random() < 0.5 else -1.0)
            a, b = tuple(q1), tuple(q2)
            assert slerp_is_near(a, b) == near, (degrees, np.dot(q1, q2))
            if near:
                t = rng.uniform(0.0, 1.0)
                assert slerp_near(a, b, t) == q_slerp(a, b, t)
                near_pairs += 1
            else:
                far_pairs += 1
    assert near_pairs == 300 and far_pairs == 300
