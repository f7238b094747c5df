"""Rerun sink: what is written is what the simulation had (read back with rerun's own reader)."""
from __future__ import annotations

import os

import numpy as np
import pytest
import rerun as rr

from magica_py.sinks import layout as L
from magica_py.sinks.base import LogToggles, NullSink
from magica_py.sinks.readback import Recording, RecordingError
from magica_py.sinks.rerun_sink import OutputError, RerunSink, check_output_path, grpc_url

from magica_py.sinks.fakes import frame_data, statics, trajectory

FRAMES = 10


@pytest.fixture(autouse=True)
def strict():
    rr.set_strict_mode(True)


def record(path, frames=FRAMES, batch=4, toggles=None, fail_at=None):
    traj = trajectory(frames)
    sink = RerunSink(statics(toggles), rrd_path=path, batch_frames=batch, recording_id="test",
                     collider_kind=np.array([0, 1, 2]), collider_slot=np.array([0, 0, 0]))
    try:
        for f, (joints, tail, skirt) in enumerate(traj):
            if f == fail_at:
                raise RuntimeError("simulated failure")
            sink.begin_frame(f, f / 60)
            sink.log(frame_data(f, joints, tail, skirt))
            sink.end_frame()
    except RuntimeError:
        sink.close(success=False)
        raise
    sink.close()
    return traj


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    rr.set_strict_mode(True)
    path = tmp_path_factory.mktemp("rec") / "fake.rrd"
    traj = record(path)
    return Recording(path), traj


def test_entity_paths_follow_the_documented_layout(recorded):
    rec, _ = recorded
    expected = {"/world", "/world/rig/joints", "/world/rig/bones", "/world/colliders/spheres",
                "/world/colliders/capsules", "/world/colliders/planes", "/events",
                "/world/cloths/tail/particles", "/world/cloths/tail/edges", "/world/cloths/tail/baselines",
                "/world/cloths/tail/base_pose", "/world/cloths/skirt/particles",
                "/world/cloths/skirt/triangles", "/metrics/steps", "/metrics/max_edge_stretch",
                "/metrics/max_penetration", "/metrics/max_speed", "/metrics/time/late_update",
                "/replay/pose", "/replay/time", "/replay/scene", "/replay/nodes", "/replay/events"}
    assert expected <= set(rec.entities)
    assert "/world/cloths/tail/triangles" not in rec.entities  # line mode has no triangles


def test_every_frame_is_on_both_timelines_in_every_batch(recorded):
    rec, _ = recorded
    frames, rows = rec.rows("/world/cloths/tail/particles", "Points3D:positions")
    assert frames.tolist() == list(range(FRAMES))          # batches of 4 + a partial last batch
    times, _ = rec.rows("/world/cloths/tail/particles", "Points3D:positions", timeline="sim_time")
    np.testing.assert_array_equal(times, (np.arange(FRAMES) / 60 * 1e9).astype(np.int64))  # rerun truncates to ns
    assert rec.timeline_values("frame").tolist() == list(range(FRAMES))


def test_particle_and_joint_positions_are_the_simulation_arrays_as_float32_bit_for_bit(recorded):
    rec, traj = recorded
    _, tail = rec.stacked("/world/cloths/tail/particles", "Points3D:positions")
    _, skirt = rec.stacked("/world/cloths/skirt/particles", "Points3D:positions")
    _, joints = rec.stacked("/world/rig/joints", "Points3D:positions")
    for f, (j, t, s) in enumerate(traj):
        assert tail[f].dtype == np.float32
        np.testing.assert_array_equal(tail[f], t.astype(np.float32))
        np.testing.assert_array_equal(skirt[f], s.astype(np.float32))
        np.testing.assert_array_equal(joints[f], j[[0]].astype(np.float32))  # 1..5 are cloth bones
    assert not np.array_equal(tail[3].astype(np.float64), traj[3][1])  # float32 really was stored


def test_edges_baselines_and_bones_are_segments_between_the_logged_points(recorded):
    rec, traj = recorded
    _, edges = rec.rows("/world/cloths/skirt/edges", "LineStrips3D:strips")
    skirt = traj[5][2]
    want = skirt[np.array([[0, 1], [0, 2], [1, 3], [2, 3], [1, 2]])].reshape(-1, 3).astype(np.float32)
    np.testing.assert_array_equal(edges[5], want)
    _, base = rec.rows("/world/cloths/tail/baselines", "LineStrips3D:strips")
    tail = traj[2][1]
    np.testing.assert_array_equal(base[2], tail[[0, 1, 1, 2]].astype(np.float32))
    _, bones = rec.rows("/world/rig/bones", "LineStrips3D:strips")
    j = traj[7][0]
    # links between two cloth particles (1-2, 2-3 of the tail, 4-5 of the skirt) are the cloths'
    # edges already: the rig keeps only root-a0 and root-b0
    pairs = [(0, 1), (0, 4)]
    np.testing.assert_array_equal(bones[7], j[np.array(pairs).ravel()].astype(np.float32))


def test_particle_colours_follow_fixed_and_move_attributes(recorded):
    rec, _ = recorded
    colors = rec.static_value("/world/cloths/tail/particles", "Points3D:colors")
    rgba = lambda c: (c[0] << 24) | (c[1] << 16) | (c[2] << 8) | c[3]
    assert colors.tolist() == [rgba(L.COLOR_FIXED), rgba(L.COLOR_MOVE), rgba(L.COLOR_MOVE)]
    radii = rec.static_value("/world/cloths/tail/particles", "Points3D:radii")
    np.testing.assert_array_equal(radii, np.array([0.02, 0.02, 0.03], np.float32))


def test_triangles_are_a_mesh_with_static_indices(recorded):
    rec, traj = recorded
    tri = rec.static_value("/world/cloths/skirt/triangles", "Mesh3D:triangle_indices")
    assert tri.tolist() == [[0, 2, 1], [1, 2, 3]]
    _, verts = rec.rows("/world/cloths/skirt/triangles", "Mesh3D:vertex_positions")
    np.testing.assert_array_equal(verts[9], traj[9][2].astype(np.float32))


def test_colliders_have_their_real_shapes(recorded):
    rec, _ = recorded
    _, half = rec.rows("/world/colliders/spheres", "Ellipsoids3D:half_sizes")
    _, centers = rec.rows("/world/colliders/spheres", "Ellipsoids3D:centers")
    np.testing.assert_array_equal(half[4], np.full((1, 3), 0.1, np.float32))
    np.testing.assert_array_equal(centers[4], np.array([[0.0, 0.54, 0.0]], np.float32))
    _, lengths = rec.rows("/world/colliders/capsules", "Capsules3D:lengths")
    _, quats = rec.rows("/world/colliders/capsules", "Capsules3D:quaternions")
    _, radii = rec.rows("/world/colliders/capsules", "Capsules3D:radii")
    assert lengths[0].tolist() == [pytest.approx(0.4)]
    assert radii[0].tolist() == [pytest.approx(0.05)]
    # capsule axis +Z turned onto +Y: -90 degrees about X
    np.testing.assert_allclose(quats[0][0], [-np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)], atol=1e-7)
    _, planes = rec.rows("/world/colliders/planes", "Boxes3D:half_sizes")
    np.testing.assert_array_equal(planes[0], np.array([[2.0, 0.0, 2.0]], np.float32))


def test_metrics_are_time_series_with_hand_checked_values(recorded):
    rec, traj = recorded
    frames, steps = rec.scalars("/metrics/steps")
    assert frames.tolist() == list(range(FRAMES)) and steps.tolist() == [2.0] * FRAMES
    _, late = rec.scalars("/metrics/time/late_update")
    assert late.tolist() == [2.0] * FRAMES   # seconds -> milliseconds
    _, speed = rec.scalars("/metrics/max_speed")
    allx = [np.vstack([t, s]) for _, t, s in traj]
    want = np.linalg.norm(allx[6] - allx[5], axis=1).max() * 60
    assert speed[0] == 0.0 and speed[6] == pytest.approx(want, rel=1e-12)
    _, stretch = rec.scalars("/metrics/max_edge_stretch")
    t, s = traj[1][1], traj[1][2]
    lengths = [np.linalg.norm(t[0] - t[1]) / 0.1, np.linalg.norm(t[1] - t[2]) / 0.1]
    lengths += [np.linalg.norm(s[a] - s[b]) / r for (a, b), r in
                zip([(0, 1), (0, 2), (1, 3), (2, 3), (1, 2)], [0.1, 0.1, 0.1, 0.1, 0.1414])]
    assert stretch[1] == pytest.approx(max(abs(v - 1) for v in lengths), rel=1e-12)


def test_events_are_a_text_log_at_their_frame(recorded):
    rec, _ = recorded
    assert rec.text_rows("/events", "TextLog:text") == [(3, 'teleport: {"frame": 3, "target": "root"}')]


def test_replay_pose_is_stored_as_float64_exactly(recorded):
    rec, traj = recorded
    frames, pos = rec.stacked("/replay/pose", "local_position")
    assert pos.dtype == np.float64 and frames.tolist() == list(range(FRAMES))
    np.testing.assert_array_equal(pos[8], traj[8][0][0])
    assert rec.static_value("/replay/nodes", "names") == ["root"]
    assert rec.static_value("/replay/scene", "yaml") == ["scene: {name: fake}\n"]
    assert rec.text_rows("/replay/events", "events") == [(3, '[["teleport", {}]]')]


def test_blueprint_and_view_coordinates_are_stored(recorded):
    rec, _ = recorded
    assert rec.blueprint_count == 1
    assert "ViewCoordinates:xyz" in rec.components("/world")
    # rerun's direction codes: Right 3, Up 1, Forward 5 -> X right, Y up, Z forward (Unity)
    assert rec.static_value("/world", "ViewCoordinates:xyz").tolist() == [[3, 1, 5]]


def test_toggles_leave_out_what_was_switched_off(tmp_path):
    path = tmp_path / "lean.rrd"
    record(path, frames=3, toggles=LogToggles(skeleton=False, edges=False, colliders=False, replay=False))
    ents = set(Recording(path).entities)
    assert "/world/cloths/tail/particles" in ents
    assert not ents & {"/world/rig/joints", "/world/cloths/tail/edges", "/world/colliders/spheres",
                       "/replay/pose", "/world/cloths/tail/baselines"}


def test_unknown_toggle_is_rejected_with_the_expected_names():
    with pytest.raises(ValueError, match=r"output.log: unknown toggles \['skeletons'\]"):
        LogToggles.from_any({"skeletons": True})


@pytest.mark.parametrize("name, message", [
    ("missing/sub/out.rrd", "folder .*missing/sub' does not exist"),
    ("out.txt", "must end in .rrd"),
    ("folder.rrd", "is a folder"),
])
def test_bad_path_gives_a_clear_error_before_anything_is_written(tmp_path, name, message):
    (tmp_path / "folder.rrd").mkdir()
    with pytest.raises(OutputError, match=message):
        RerunSink(statics(), rrd_path=tmp_path / name)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder.rrd"]


@pytest.mark.skipif(os.geteuid() == 0, reason="root can write into read-only folders")
def test_unwritable_folder_gives_a_clear_error(tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        with pytest.raises(OutputError, match="is not writable"):
            check_output_path(locked / "x.rrd")
    finally:
        locked.chmod(0o700)


def test_unwritable_folder_check_uses_access_rights(tmp_path, monkeypatch):
    monkeypatch.setattr(os, "access", lambda p, mode: False)
    with pytest.raises(OutputError, match=f"folder '{tmp_path}' is not writable"):
        check_output_path(tmp_path / "x.rrd")


def test_failed_run_leaves_no_file_and_no_temporary(tmp_path):
    (tmp_path / "keep.rrd").write_bytes(b"old")
    with pytest.raises(RuntimeError, match="simulated failure"):
        record(tmp_path / "keep.rrd", frames=8, fail_at=5)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.rrd"]
    assert (tmp_path / "keep.rrd").read_bytes() == b"old"   # the previous recording survives


def test_reading_a_file_that_is_not_a_recording_is_a_clear_error(tmp_path):
    bad = tmp_path / "bad.rrd"
    bad.write_bytes(b"not an rrd")
    with pytest.raises(RecordingError, match="bad.rrd: not a readable .rrd recording"):
        Recording(bad)
    with pytest.raises(RecordingError, match="no such recording file"):
        Recording(tmp_path / "none.rrd")


def test_connect_address_becomes_a_grpc_url():
    assert grpc_url("127.0.0.1:9876") == "rerun+http://127.0.0.1:9876/proxy"
    assert grpc_url("rerun+http://h:1/proxy") == "rerun+http://h:1/proxy"
    with pytest.raises(OutputError, match="host:port"):
        grpc_url("localhost")


def test_null_sink_counts_frames_and_keeps_nothing():
    sink = NullSink()
    traj = trajectory(3)
    for f, (j, t, s) in enumerate(traj):
        sink.begin_frame(f, 0.0)
        sink.log(frame_data(f, j, t, s))
        sink.end_frame()
    sink.close()
    assert sink.frames == 3


def test_instances_of_a_cloth_share_one_entity_in_team_order(tmp_path):
    from dataclasses import replace

    from magica_py.sinks.base import FrameData, SceneStatics
    from magica_py.sinks.fakes import JOINT_NAMES, JOINT_PARENT, colliders_frame, topologies

    tail, skirt = topologies()
    cloths = [replace(tail, name="hair#0"), replace(skirt, name="skirt#0"), replace(tail, name="hair#1")]
    st = SceneStatics(name="inst", joint_names=JOINT_NAMES, joint_parent=JOINT_PARENT, cloths=cloths,
                      toggles=LogToggles(replay=False))
    x = np.arange(30, dtype=np.float64).reshape(10, 3) / 7.0
    sink = RerunSink(st, rrd_path=tmp_path / "inst.rrd", collider_kind=np.array([0, 1, 2]),
                     collider_slot=np.array([0, 0, 0]))
    for f in range(3):
        sink.begin_frame(f, f * 0.1)
        sink.log(FrameData(frame=f, sim_time=f * 0.1, delta_time=0.1, joint_positions=np.zeros((6, 3)),
                           positions=x + f, colliders=colliders_frame(f), metrics={}, events=[]))
        sink.end_frame()
    sink.close()
    rec = Recording(tmp_path / "inst.rrd")
    assert sorted(e for e in rec.entities if e.endswith("/particles")) == \
        ["/world/cloths/hair/particles", "/world/cloths/skirt/particles"]
    _, hair = rec.stacked("/world/cloths/hair/particles", "Points3D:positions")
    np.testing.assert_array_equal(hair[2], (x[[0, 1, 2, 7, 8, 9]] + 2).astype(np.float32))
    _, edges = rec.rows("/world/cloths/hair/edges", "LineStrips3D:strips")
    want = (x[[0, 1, 1, 2, 7, 8, 8, 9]] + 1).astype(np.float32)   # hair#1's edges offset to its particles
    np.testing.assert_array_equal(edges[1], want)


@pytest.mark.parametrize("batch", [1, 3, 64])
def test_every_batch_size_records_the_same_frames(tmp_path, batch):
    traj = record(tmp_path / "b.rrd", frames=7, batch=batch)
    frames, tail = Recording(tmp_path / "b.rrd").stacked("/world/cloths/tail/particles", "Points3D:positions")
    assert frames.tolist() == list(range(7))
    np.testing.assert_array_equal(tail, np.array([t for _, t, _ in traj]).astype(np.float32))


def test_scene_description_is_recorded_even_without_replay_data(tmp_path):
    from magica_py.sinks.resim import load_replay

    path = tmp_path / "noreplay.rrd"
    record(path, frames=2, toggles=LogToggles(replay=False))
    rec = Recording(path)
    assert rec.static_value("/replay/scene", "name") == ["fake"]
    with pytest.raises(RecordingError, match="no replay data"):
        load_replay(rec)


def test_a_failure_while_opening_leaves_no_temporary_file(tmp_path, monkeypatch):
    def broken(self):
        raise RuntimeError("cannot log statics")

    monkeypatch.setattr(RerunSink, "_log_statics", broken)
    with pytest.raises(RuntimeError, match="cannot log statics"):
        RerunSink(statics(), rrd_path=tmp_path / "x.rrd")
    assert list(tmp_path.iterdir()) == []


def test_spawn_and_connect_choose_live_sinks_with_one_frame_batches(tmp_path, monkeypatch):
    """Wiring only: the viewer start and the gRPC sink are replaced, nothing leaves the process."""
    calls = {}

    class FakeGrpc:
        def __init__(self, url=None):
            calls.setdefault("grpc", []).append(url)

    monkeypatch.setattr(rr, "spawn", lambda **kw: calls.setdefault("spawn", []).append(kw))
    monkeypatch.setattr(rr, "GrpcSink", FakeGrpc)
    monkeypatch.setattr(rr.RecordingStream, "set_sinks",
                        lambda self, *sinks, default_blueprint=None: calls.setdefault("sinks", sinks))
    sink = RerunSink(statics(), spawn=True, connect="10.0.0.7:9999")
    assert calls["spawn"] == [{"connect": False}]
    assert calls["grpc"] == [None, "rerun+http://10.0.0.7:9999/proxy"]
    assert len(calls["sinks"]) == 2 and sink.batch == 1 and sink.final_path is None
    sink.close()
