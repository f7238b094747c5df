"""Block forms of point collision (D.8), the step basic pose (D.2) and the end of step (D.10)
give exactly the bits of their per-team stages, from a mid-motion crowd state
(``batched_harness``), including states where lanes of one block take different paths
(contact or not, suspended colliders, static friction holding or slipping, centrifugal on
or off) and the scratch the collision keeps its sums in is left cleared."""
import numba
import numpy as np
import pytest

from batched_harness import (
    assert_same_rows, block_rows, block_tables, crowd_system, restore, run_block_stage, run_team_stage, snapshot,
)
from magica_py.solver.batch_tables import borrow
from magica_py.solver.constraints.collision import point_collision_block, point_collision_team
from magica_py.solver.step import (
    end_step_block, end_step_team, predict_team, step_basic_pose_block, step_basic_pose_team,
)

DT = 1.0 / 90.0
MOVE = 0x02
SCRATCH = ("accum_vector", "accum_normal", "accum_count", "accum_friction")


@pytest.fixture(scope="module")
def crowd():
    return crowd_system(instances=6, frames=55)  # legs swinging into the skirt


@numba.njit
def _predict_teams(m, ps, prm, ts, cs, tt, teams):
    m, ps, prm, ts = borrow(m), borrow(ps), borrow(prm), borrow(ts)
    for t in teams:
        predict_team(m, ps, prm, ts, t, tt.frame_interpolation[t], DT, 1.0, 1.0)


@numba.njit
def _collide_teams(m, ps, prm, ts, cs, tt, teams):
    m, ps, prm, ts, cs = borrow(m), borrow(ps), borrow(prm), borrow(ts), borrow(cs)
    for t in teams:
        point_collision_team(m, ps, prm, ts, cs, t)


@numba.njit
def _collide_blocks(m, ps, prm, ts, cs, tt, blk, bs, blocks):
    m, prm, blk, bs = borrow(m), borrow(prm), borrow(blk), borrow(bs)
    for b in blocks:
        point_collision_block(m, bs, prm, blk, b)


@numba.njit
def _basic_pose_teams(m, ps, prm, ts, cs, tt, teams):
    m, ps, prm, ts = borrow(m), borrow(ps), borrow(prm), borrow(ts)
    for t in teams:
        step_basic_pose_team(m, ps, prm, ts, t)


@numba.njit
def _basic_pose_blocks(m, ps, prm, ts, cs, tt, blk, bs, blocks):
    m, prm, blk, bs = borrow(m), borrow(prm), borrow(blk), borrow(bs)
    for b in blocks:
        step_basic_pose_block(m, bs, prm, blk, b)


@numba.njit
def _end_step_teams(m, ps, prm, ts, cs, tt, teams):
    m, ps, prm, ts = borrow(m), borrow(ps), borrow(prm), borrow(ts)
    for t in teams:
        end_step_team(m, ps, prm, ts, t, DT, 1.0)


@numba.njit
def _end_step_blocks(m, ps, prm, ts, cs, tt, blk, bs, blocks):
    m, prm, blk, bs = borrow(m), borrow(prm), borrow(blk), borrow(bs)
    for b in blocks:
        end_step_block(m, bs, prm, blk, b, DT, 1.0)


def compare(system, team_wrapper, block_wrapper, fields, cleared=()):
    """Per-team and block stage from the same state: ``fields`` equal bit for bit, the scratch
    fields ``cleared`` zero in every block row afterwards. Returns the per-team result
    (a snapshot) for the path counts; the system is left as it was."""
    blk, bs = block_tables(system)
    before = snapshot(system)
    run_team_stage(system, team_wrapper, blk)
    expected = snapshot(system)
    restore(system, before)
    run_block_stage(system, block_wrapper, blk, bs)
    try:
        assert_same_rows(system, blk, expected, fields)
        for name in cleared:
            rows = block_rows(system, blk, bs, name)
            inside = ~np.isnan(rows)
            assert inside.any() and (rows[inside] == 0).all(), f"{name} not cleared"
    finally:
        restore(system, before)
    return before, expected, blk


def lane_paths(system, blk, taken):
    """(elements where every lane takes a path, where none does, where the lanes differ):
    ``taken`` is a boolean per particle row; one element = one particle of one block."""
    m = system.model
    every = none = mixed = 0
    for b in range(len(blk.block_width)):
        w, base = int(blk.block_width[b]), int(blk.block_lane_base[b])
        starts = [int(m.team_particle_start[t]) for t in blk.lane_team[base:base + w]]
        for p in range(int(blk.block_particle_count[b])):
            lanes = [bool(taken[s + p]) for s in starts]
            every += all(lanes)
            none += not any(lanes)
            mixed += any(lanes) and not all(lanes)
    return every, none, mixed


# --------------------------------------------------------------------------- D.8 point mode
COLLISION_FIELDS = ["next_pos", "friction", "collision_normal"]


def test_point_collision_block_is_bit_identical_with_lanes_in_and_out_of_contact(crowd):
    """From the predicted positions of a step (D.1 run on the mid-motion state), where the
    skirt runs into the thighs; every other lane's cloth shifted sideways by 2 cm (the
    instances' legs swing in step: their contacts would otherwise be the same in every lane)."""
    saved = snapshot(crowd)
    m = crowd.model
    try:
        blk, _bs = block_tables(crowd)
        run_team_stage(crowd, _predict_teams, blk)
        for t in blk.lane_team[1::2]:
            crowd.particles.next_pos[m.team_particle_start[t]:m.team_particle_start[t] + m.team_particle_count[t]] \
                += (0.02, 0.0, 0.01)
        before, after, blk = compare(crowd, _collide_teams, _collide_blocks, COLLISION_FIELDS, SCRATCH)
    finally:
        restore(crowd, saved)
    touched = np.abs(after["ps.collision_normal"]).sum(axis=1) > 0
    pushed = (after["ps.next_pos"] != before["ps.next_pos"]).any(axis=1)
    every, none, mixed = lane_paths(crowd, blk, pushed)
    # some particles pushed out of the thighs, most not, and lanes of one particle that
    # disagree (the instances walk with different phases)
    assert touched.sum() >= 10 and pushed.sum() >= 5, (touched.sum(), pushed.sum())
    assert none > 0 and mixed > 0, (every, none, mixed)


def test_point_collision_block_with_a_scale_per_lane_and_suspended_colliders(crowd):
    """Lanes with different scale ratios (particle radius per lane), a wider radius (more
    contacts, more AABB hits) and some lanes' collider slots suspended (skipped per lane)."""
    ts, cs, prm = crowd.teams, crowd.collider_state, crowd.parameters
    saved = ts.scale_ratio.copy(), cs.scale_suspend.copy(), prm.radius_curve.copy()
    try:
        blk, _bs = block_tables(crowd)
        for n, t in enumerate(blk.lane_team):
            ts.scale_ratio[t] = 1.0 + 0.15 * (n % 4)
            if n % 3 == 1:  # the first slot of every third lane
                cs.scale_suspend[ts.collider_start[t]] = 1
        prm.radius_curve[:] *= 2.0
        before, after, blk = compare(crowd, _collide_teams, _collide_blocks, COLLISION_FIELDS, SCRATCH)
        touched = np.abs(after["ps.collision_normal"]).sum(axis=1) > 0
        every, none, mixed = lane_paths(crowd, blk, touched)
        assert touched.sum() >= 20 and mixed > 0 and none > 0, (touched.sum(), every, none, mixed)
    finally:
        ts.scale_ratio[:], cs.scale_suspend[:], prm.radius_curve[:] = saved


# --------------------------------------------------------------------------- D.2 basic pose
BASIC_FIELDS = ["step_basic_pos", "step_basic_rot"]


def test_step_basic_pose_block_is_bit_identical(crowd):
    ts = crowd.teams
    saved = ts.scale_ratio.copy()
    try:
        blk, _bs = block_tables(crowd)
        for n, t in enumerate(blk.lane_team):
            ts.scale_ratio[t] = 1.0 + 0.05 * (n % 3)
        before, after, _blk = compare(crowd, _basic_pose_teams, _basic_pose_blocks, BASIC_FIELDS)
        changed = (after["ps.step_basic_pos"] != before["ps.step_basic_pos"]).any(axis=1)
        assert changed.sum() > 100  # the rest shape replaced the animated pose below the roots
    finally:
        ts.scale_ratio[:] = saved


@pytest.mark.parametrize("ratio", [0.5, 1.0])
def test_step_basic_pose_block_blends_towards_the_animated_pose(crowd, ratio):
    """animation_pose_ratio 0.5: rest shape and animated pose blended; 1.0 (> 0.99): untouched."""
    prm = crowd.parameters
    saved = prm.animation_pose_ratio.copy()
    try:
        prm.animation_pose_ratio[:] = ratio
        before, after, _blk = compare(crowd, _basic_pose_teams, _basic_pose_blocks, BASIC_FIELDS)
        changed = (after["ps.step_basic_pos"] != before["ps.step_basic_pos"]).any(axis=1).sum()
        assert (changed > 100) if ratio < 0.99 else (changed == 0), changed
    finally:
        prm.animation_pose_ratio[:] = saved


# --------------------------------------------------------------------------- D.10 end of step
END_FIELDS = ["next_pos", "old_pos", "velocity", "real_velocity", "friction", "static_friction"]


def _end_step_paths(system, snap, blk):
    """Which D.10 paths the block particles take in ``snap``: (contact, holding, centrifugal)
    as particle booleans (Move particles only), the way end_step_team decides them."""
    m, prm = system.model, system.parameters
    team_of = np.repeat(np.arange(len(m.team_particle_count)), m.team_particle_count)
    move = (np.asarray(m.attribute) & MOVE) != 0
    cn, f = snap["ps.collision_normal"], snap["ps.friction"]
    contact = move & ((cn * cn).sum(axis=1) > 1e-8) & (f > 1e-8)
    d = snap["ps.next_pos"] - snap["ps.old_pos"]
    tv = d - cn * (d * cn).sum(axis=1)[:, None]
    threshold = prm.friction[team_of] * snap["ts.scale_ratio"][team_of]
    holding = contact & (np.linalg.norm(tv, axis=1) / DT < threshold)
    spinning = move & (snap["ts.angular_velocity"][team_of] > 1e-8) & (prm.centrifugal_acceleration[team_of] > 1e-8)
    return contact, holding, spinning


def _mid_step(system, blk):
    """Into the middle of a step: D.1 and D.8 per team (particles moved, contacts recorded)."""
    run_team_stage(system, _predict_teams, blk)
    run_team_stage(system, _collide_teams, blk)


def test_end_step_block_is_bit_identical_with_friction_paths_per_lane(crowd):
    """Particles in contact (friction and collision normal of this step's collision) holding
    and slipping; every other lane's friction cleared (no contact there: the instances' legs
    swing in step, their contacts would otherwise be the same in every lane), and every third
    lane scaled up 60x (static threshold friction x scale: 3 m/s, those hold)."""
    ps, m, ts = crowd.particles, crowd.model, crowd.teams
    saved = snapshot(crowd)
    try:
        blk, _bs = block_tables(crowd)
        _mid_step(crowd, blk)
        for t in blk.lane_team[1::2]:
            ps.friction[m.team_particle_start[t]:m.team_particle_start[t] + m.team_particle_count[t]] = 0.0
        ts.scale_ratio[blk.lane_team[::3]] = 60.0
        before, _after, blk = compare(crowd, _end_step_teams, _end_step_blocks, END_FIELDS)
    finally:
        restore(crowd, saved)
    contact, holding, _spin = _end_step_paths(crowd, before, blk)
    _e, _n, mixed = lane_paths(crowd, blk, contact)
    assert contact.sum() >= 5 and mixed > 0, (contact.sum(), mixed)
    assert holding.sum() > 0 and (contact & ~holding).sum() > 0, (holding.sum(), contact.sum())


def test_end_step_block_with_centrifugal_force_on_some_lanes(crowd):
    """Centrifugal acceleration on, the lanes turning about +Y at 3 rad/s except every third
    one (angular velocity 0, at this state the crowd walks straight): the term is added per lane."""
    ts, prm = crowd.teams, crowd.parameters
    saved, saved_c = snapshot(crowd), prm.centrifugal_acceleration.copy()
    try:
        blk, _bs = block_tables(crowd)
        _mid_step(crowd, blk)
        prm.centrifugal_acceleration[:] = 0.5
        ts.angular_velocity[blk.lane_team] = 3.0
        ts.rotation_axis[blk.lane_team] = (0.0, 1.0, 0.0)
        ts.angular_velocity[blk.lane_team[::3]] = 0.0
        before, after, blk = compare(crowd, _end_step_teams, _end_step_blocks, END_FIELDS)
        _c, _h, spinning = _end_step_paths(crowd, before, blk)
    finally:
        restore(crowd, saved)
        prm.centrifugal_acceleration[:] = saved_c
    _e, _n, mixed = lane_paths(crowd, blk, spinning)
    assert spinning.sum() > 50 and mixed > 0, (spinning.sum(), mixed)


# --------------------------------------------------------------------------- D.8: slots out of reach
def test_point_collision_block_skips_leading_slots_that_reach_no_lane(crowd):
    """Every team's first collider slot moved 100 m away (out of every particle's bounds), the
    skirt's second slot put where its first was: the hair's only slot reaches nothing (no
    contact anywhere), the skirt's second slot is the first one near (the block starts there
    without re-testing it). Bit-identical, scratch cleared, and the skirt still in contact."""
    saved = snapshot(crowd)
    m, cs, ts, prm = crowd.model, crowd.collider_state, crowd.teams, crowd.parameters
    saved_radius = prm.radius_curve.copy()
    try:
        blk, _bs = block_tables(crowd)
        run_team_stage(crowd, _predict_teams, blk)
        prm.radius_curve[:] *= 2.0  # more contacts
        for t in blk.lane_team[1::2]:
            crowd.particles.next_pos[m.team_particle_start[t]:m.team_particle_start[t] + m.team_particle_count[t]] \
                += (0.02, 0.0, 0.01)
        first = ts.collider_start[blk.lane_team]
        assert (cs.shape[first] != 2).all()  # not planes: planes are near at any distance
        several = first[ts.collider_count[blk.lane_team] > 1]
        for name in ("shape", "start_old", "end_old", "start_new", "end_new", "radius_start", "radius_end",
                     "inverse_old_rot", "now_rot", "aabb_min", "aabb_max"):
            getattr(cs, name)[several + 1] = getattr(cs, name)[several]  # the second slot takes the first's place
        for name in ("start_old", "end_old", "start_new", "end_new", "aabb_min", "aabb_max"):
            getattr(cs, name)[first] += 100.0
        before, after, blk = compare(crowd, _collide_teams, _collide_blocks, COLLISION_FIELDS, SCRATCH)
    finally:
        restore(crowd, saved)
        prm.radius_curve[:] = saved_radius
    touched = np.abs(after["ps.collision_normal"]).sum(axis=1) > 0
    single = [t for t in blk.lane_team if ts.collider_count[t] == 1]
    several = [t for t in blk.lane_team if ts.collider_count[t] > 1]
    rows = lambda teams: np.concatenate([np.arange(m.team_particle_start[t],  # noqa: E731
                                                   m.team_particle_start[t] + m.team_particle_count[t]) for t in teams])
    assert single and several
    assert not touched[rows(single)].any() and touched[rows(several)].sum() >= 5, touched[rows(several)].sum()


def _rotate_about_x(q, degrees):
    """q * (rotation about X), rows of (x, y, z, w)."""
    s, c = np.sin(np.radians(degrees) / 2.0), np.cos(np.radians(degrees) / 2.0)
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([w * s + x * c, y * c + z * s, z * c - y * s, w * c - x * s], axis=1)


def test_step_basic_pose_block_blends_with_either_slerp_path(crowd):
    """The blend's slerp (rest shape towards the animated pose) skips its acos and sines for a
    baseline entry whose lanes are all within 3.6 degrees of the animated pose, and takes both
    paths otherwise: the animated rotation of every fourth hair lane turned 40 degrees, the
    skirts left as they are; both kinds of entries occur, the result has the per-team bits."""
    prm, ps, m = crowd.parameters, crowd.particles, crowd.model
    saved_a, saved_rot = prm.animation_pose_ratio.copy(), ps.base_rot.copy()
    try:
        blk, _bs = block_tables(crowd)
        prm.animation_pose_ratio[:] = 0.0  # the rest shape alone (no blend), to state the premise
        _before, rest, _blk = compare(crowd, _basic_pose_teams, _basic_pose_blocks, BASIC_FIELDS)
        hair = [t for t in blk.lane_team if m.team_particle_count[t] == 30]
        for t in hair[::4]:
            rows = slice(m.team_particle_start[t], m.team_particle_start[t] + m.team_particle_count[t])
            ps.base_rot[rows] = _rotate_about_x(ps.base_rot[rows], 40.0)
        dot = np.abs((rest["ps.step_basic_rot"] * ps.base_rot).sum(axis=1))
        near_entries = far_entries = 0
        for b in range(len(blk.block_width)):
            w, base = int(blk.block_width[b]), int(blk.block_lane_base[b])
            starts = np.array([m.team_particle_start[t] for t in blk.lane_team[base:base + w]])
            for p in range(int(blk.block_particle_count[b])):
                near = (dot[starts + p] >= 0.9995).all()
                near_entries += near
                far_entries += not near
        assert near_entries > 10 and far_entries > 10, (near_entries, far_entries)
        prm.animation_pose_ratio[:] = 0.5
        before, after, _blk = compare(crowd, _basic_pose_teams, _basic_pose_blocks, BASIC_FIELDS)
        assert ((after["ps.step_basic_rot"] != before["ps.step_basic_rot"]).any(axis=1)).sum() > 100
    finally:
        prm.animation_pose_ratio[:] = saved_a
        ps.base_rot[:] = saved_rot
