"""The end of frame in block form (``solver/batched/frame_end``: guards, E.1 display, E.2 line
and E.3 triangle rotations, E.4 transform data and write-back) gives exactly the bits of the
per-team end of frame (``frame.end_frame_stages_team``), lane by lane: on the crowd's hair
(line) and skirt (mesh) blocks from a mid-motion state, with lanes that differ in running and
blend weight, with an animated rest pose, with a lane whose bone values are not finite, and
whole frames with blocks against frames without. A lane whose guard trips sends its block to
the per-team path with the block state untouched."""
import pathlib

import numba
import numpy as np
import pytest

from batched_harness import block_tables, crowd_system, restore, snapshot
from block_transfer import gather_block_end, gather_block_full
from magica_py.solver.batch_tables import borrow
from magica_py.solver.batched.frame_end import (
    _lane_values, bone_local_pose_block, display_block, end_frame_block, guards_trip_block, line_rotations_block,
    transform_data_block, triangle_rotations_block, write_transforms_block,
)
from magica_py.solver.batched.transfer import scatter_block, scatter_block_end
from magica_py.solver.frame import FrameInputs, as_kernel_table, end_frame_lane, end_frame_stages_team

ROOT = pathlib.Path(__file__).resolve().parents[1]
END_FIELDS = ("position", "rotation", "old_position", "old_rotation", "disp_pos", "base_pos_buffer", "old_pos",
              "velocity", "real_velocity", "friction", "static_friction", "collision_normal", "step_basic_pos",
              "step_basic_rot")


@numba.njit
def _team_end(m, ps, prm, ts, cs, tt, h, fi, teams):
    m, ps, prm, ts, cs, tt, h = borrow(m), borrow(ps), borrow(prm), borrow(ts), borrow(cs), borrow(tt), borrow(h)
    for t in teams:
        end_frame_stages_team(m, ps, prm, ts, cs, tt, h, fi, t)


@numba.njit
def _end_frame_block_general(m, ps, prm, ts, tt, h, blk, bs, b, fi):
    """``end_frame_block`` with E.2's chain entries through the general child / turn loops."""
    all_running, all_blend_one = _lane_values(m, ts, tt, blk, bs, b, fi.dt)
    if guards_trip_block(blk, bs, b):
        return False
    display_block(m, ps, blk, bs, b, fi.dt, all_running)
    ex = blk.block_exemplar[b]
    if m.team_has_lines[ex] != 0:
        line_rotations_block(m, prm, blk, bs, b, all_blend_one, False)
    if m.team_triangle_count[ex] > 0:
        triangle_rotations_block(m, blk, bs, b)
    transform_data_block(m, blk, bs, b)
    bone_local_pose_block(m, blk, bs, b, h.parent, h.world_rotation, h.lossy_scale)
    return True


@numba.njit
def _block_end(m, ps, prm, ts, cs, tt, h, blk, bs, fi, verdicts, general=False):
    """The frame kernel's end of frame for every block (``_worker_steps`` after the steps,
    ``_worker_end``), the verdict of ``end_frame_block`` of each block into ``verdicts``."""
    m, ps, prm, ts, cs, tt, h = borrow(m), borrow(ps), borrow(prm), borrow(ts), borrow(cs), borrow(tt), borrow(h)
    blk, bs = borrow(blk), borrow(bs)
    for b in range(blk.block_width.shape[0]):
        gather_block_full(m, ps, blk, bs, b)
        gather_block_end(m, ps, blk, bs, b)
        if general:
            ok = _end_frame_block_general(m, ps, prm, ts, tt, h, blk, bs, b, fi)
        else:
            ok = end_frame_block(m, ps, prm, ts, tt, h, blk, bs, b, fi)
        verdicts[b] = 1 if ok else 0
        scatter_block(m, ps, blk, bs, b)
        lanes = blk.block_lane_base[b]
        if ok:
            scatter_block_end(m, ps, blk, bs, b)
            write_transforms_block(m, blk, bs, b, h.local_position, h.local_rotation)
            for i in range(blk.block_width[b]):
                end_frame_lane(m, ps, ts, cs, tt, h, bs, blk.lane_team[lanes + i], lanes + i)
        else:
            for i in range(blk.block_width[b]):
                end_frame_stages_team(m, ps, prm, ts, cs, tt, h, fi, blk.lane_team[lanes + i])


def _frame_inputs(system):
    s = system.time_settings
    power = s.simulation_power
    return FrameInputs(1 / 60, 1 / 60, 0.02, 0, float(s.global_time_scale), float(s.simulation_delta_time),
                       int(s.max_steps_per_frame), int(s.timing_code), 90.0 / s.frequency, float(power[1]),
                       float(power[2]), float(power[3]), 1)


def _hierarchy_pose(system):
    h = system.hierarchy
    return h.local_position.copy(), h.local_rotation.copy()


def _compare_end(system, prepare=None, general=False):
    """Per-team and block end of frame from the same state: particle rows of every block
    team, team rows and the written local poses equal bit for bit. Returns the block verdicts."""
    blk, bs = block_tables(system)
    if prepare is not None:
        prepare(system, blk)
    tables = system.kernel_tables()
    fi = _frame_inputs(system)
    h = system.hierarchy
    before = snapshot(system)
    h.local_position[...] = 0.0    # what the end of frame writes, on a pose it cannot leave as is
    h.local_rotation[...] = 0.0
    pose_before = _hierarchy_pose(system)
    _team_end(*tables, fi, blk.lane_team.copy())
    expected = snapshot(system)
    expected_pose = _hierarchy_pose(system)
    restore(system, before)
    h.local_position[...], h.local_rotation[...] = pose_before
    verdicts = np.zeros(len(blk.block_width), dtype=np.int64)
    _block_end(*tables, as_kernel_table(blk), as_kernel_table(bs), fi, verdicts, general)
    m = system.model
    rows = np.concatenate([np.arange(m.team_particle_start[t], m.team_particle_start[t] + m.team_particle_count[t])
                           for t in blk.lane_team])
    for name in END_FIELDS:
        got, want = getattr(system.particles, name)[rows], expected[f"ps.{name}"][rows]
        same = (got == want) | (np.isnan(got) & np.isnan(want))
        assert same.all(), f"{name}: {int((~same).sum())} values differ"
    for name in system.teams._fields:
        got, want = getattr(system.teams, name), expected[f"ts.{name}"]
        assert np.array_equal(got, want, equal_nan=got.dtype.kind == "f"), f"ts.{name} differs"
    for got, want in zip(_hierarchy_pose(system), expected_pose):
        assert np.array_equal(got, want), f"{int((got != want).sum())} local pose values differ"
    assert not np.array_equal(expected_pose[1], pose_before[1]), "the end of frame wrote no bone"
    return blk, verdicts


@pytest.fixture(scope="module")
def crowd():
    return crowd_system(instances=6, frames=25)


def test_the_crowd_blocks_end_their_frame_in_block_form_with_the_per_team_bits(crowd):
    before = snapshot(crowd)
    try:
        blk, verdicts = _compare_end(crowd, lambda s, blk: s._time.running.__setitem__(slice(None), True))
        assert verdicts.tolist() == [1] * len(blk.block_width)
        assert crowd.model.team_triangle_count[blk.lane_team].max() > 0      # a mesh block (E.3)
        assert crowd.model.team_has_lines[blk.lane_team].max() > 0           # a line block (E.2)
    finally:
        restore(crowd, before)


@pytest.mark.parametrize("general", [False, True], ids=["chain loop", "general loops"])
def test_lanes_that_differ_in_running_and_blend_weight_keep_their_own_bits(crowd, general):
    def prepare(system, blk):
        lanes = blk.lane_team
        system._time.running[lanes] = True
        system._time.running[lanes[1]] = False
        system.teams.blend_weight[lanes[2]] = 0.35
        system.teams.blend_weight[lanes[-1]] = 0.0
    before = snapshot(crowd)
    try:
        blk, verdicts = _compare_end(crowd, prepare, general)
        assert verdicts.min() == 1
    finally:
        restore(crowd, before)


def test_an_animated_rest_pose_ratio_keeps_the_line_rotation_bits(crowd):
    prm = crowd.parameters
    saved = prm.animation_pose_ratio.copy()
    before = snapshot(crowd)
    try:
        def prepare(system, blk):
            system._time.running[blk.lane_team] = True
            prm.animation_pose_ratio[blk.lane_team] = 0.4
        _compare_end(crowd, prepare)
    finally:
        prm.animation_pose_ratio[...] = saved
        restore(crowd, before)


def test_a_lane_with_a_non_finite_bone_is_reset_and_not_written(crowd):
    before = snapshot(crowd)
    try:
        def prepare(system, blk):
            system._time.running[blk.lane_team] = True
            t = int(blk.lane_team[3])
            system.particles.rotation[system.model.team_particle_start[t] + 2] = np.nan   # guards do not check it
        blk, verdicts = _compare_end(crowd, prepare)
        assert verdicts.min() == 1      # the guards pass; E.4 finds the non-finite bone
        assert crowd.teams.guard_code[blk.lane_team[3]] == 1
    finally:
        restore(crowd, before)


@pytest.mark.parametrize("general", [False, True], ids=["chain loop", "general loops"])
def test_an_edge_folded_back_onto_its_parent_takes_the_opposite_cases_with_the_per_team_bits(crowd, general):
    """E.2's degenerate cases (a child's simulated edge opposite its rest edge: pi about a
    fallback axis, for the child's swing and the parent's turn) are left out of the vector
    pass and redone lane by lane."""
    from magica_py.kernels.math3d import q_rotate

    before = snapshot(crowd)
    try:
        def prepare(system, blk):
            system._time.running[blk.lane_team] = True
            m, ps = system.model, system.particles
            t = int(blk.lane_team[2])                     # a hair lane
            assert m.team_has_lines[t]
            b0 = m.team_baseline_start[t]
            x = int(m.baseline_data[m.baseline_start[b0]])    # a strand's fixed root
            c = int(m.child_data[m.child_start[x]])
            tv = np.array(q_rotate(tuple(ps.rotation[x]), tuple(m.baseline_local_position[c])))
            folded = ps.position[x] - tv                   # E.1 displays the child there
            ps.old_pos[c] = folded
            ps.disp_pos[c] = folded
            ps.real_velocity[c] = 0.0
        _compare_end(crowd, prepare, general)
    finally:
        restore(crowd, before)


@numba.njit
def _guards_only(m, ps, prm, ts, tt, blk, bs, fi, verdicts):
    m, ps, prm, ts, tt, blk, bs = borrow(m), borrow(ps), borrow(prm), borrow(ts), borrow(tt), borrow(blk), borrow(bs)
    for b in range(blk.block_width.shape[0]):
        gather_block_full(m, ps, blk, bs, b)
        gather_block_end(m, ps, blk, bs, b)


@numba.njit
def _end_only(m, ps, prm, ts, tt, h, blk, bs, fi, verdicts):
    m, ps, prm, ts, tt, h = borrow(m), borrow(ps), borrow(prm), borrow(ts), borrow(tt), borrow(h)
    blk, bs = borrow(blk), borrow(bs)
    for b in range(blk.block_width.shape[0]):
        verdicts[b] = 1 if end_frame_block(m, ps, prm, ts, tt, h, blk, bs, b, fi) else 0


def test_a_guard_trip_sends_the_block_to_the_per_team_path_untouched(crowd):
    before = snapshot(crowd)
    try:
        blk, bs = block_tables(crowd)
        t = int(blk.lane_team[4])
        crowd.particles.velocity[crowd.model.team_particle_start[t] + 5, 1] = np.inf
        m, ps, prm, ts, cs, tt, h = crowd.kernel_tables()
        kb, kbs = as_kernel_table(blk), as_kernel_table(bs)
        fi = _frame_inputs(crowd)
        verdicts = np.zeros(len(blk.block_width), dtype=np.int64)
        _guards_only(m, ps, prm, ts, tt, kb, kbs, fi, verdicts)
        particle_fields = [f for f in bs._fields if not f.startswith(("lane_", "col_", "shared_"))]
        gathered = {f: getattr(bs, f).copy() for f in particle_fields}
        _end_only(m, ps, prm, ts, tt, h, kb, kbs, fi, verdicts)
        b = int(blk.team_block[t])
        assert verdicts[b] == 0 and verdicts.sum() == len(blk.block_width) - 1
        for f in particle_fields:   # the tripped block's rows as gathered (the others ran)
            rows = slice(int(blk.block_row_base[b]),
                         int(blk.block_row_base[b] + blk.block_width[b] * blk.block_particle_count[b]))
            if getattr(bs, f).shape[-1] == gathered[f].shape[-1] and f not in ("triangle_normal", "triangle_tangent"):
                assert np.array_equal(getattr(bs, f)[..., rows], gathered[f][..., rows], equal_nan=True), f
    finally:
        restore(crowd, before)


# ----------------------------------------------------------------------------- whole frames
def _run(batched, frames=30, sets=(), parallel=False):
    from magica_py.config import load_scene
    from magica_py.runtime.player import Player
    from magica_py.solver.system import ClothSystem

    scene = load_scene(ROOT / "configs" / "crowd.yaml", overrides=["rigs.0.instances.count=6", *sets])
    player = Player.for_scene(scene)
    system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings, batched=batched,
                         parallel=parallel).attach(player)
    ended_in_block = 0
    for _ in range(frames):
        player.step()
        ended_in_block += int(system.block_table.block_end.sum()) if batched else 0
    p, h = system.particles, scene.hierarchy
    return ended_in_block, [p.position.copy(), p.rotation.copy(), p.old_position.copy(), p.old_rotation.copy(),
                            p.disp_pos.copy(), p.base_pos_buffer.copy(), h.local_position.copy(),
                            h.local_rotation.copy()]


@pytest.mark.parametrize("sets", [
    ("cloths.0.parameters.blend_weight=0.6", "cloths.1.parameters.blend_weight=0.8"),
    ("cloths.0.parameters.animation_pose_ratio=0.3", "cloths.1.parameters.animation_pose_ratio=0.5"),
])
def test_frames_with_the_end_in_block_form_equal_frames_without_blocks(sets):
    ended, with_blocks = _run(True, sets=sets)
    _, without = _run(False, sets=sets)
    assert ended == 2 * 30   # both blocks, every frame
    for x, y in zip(with_blocks, without):
        assert np.array_equal(x, y), f"{int((x != y).sum())} values differ"
