"""Rerun sink: what is written is what the simulation had (read back with rerun's own reader)."""
from __future__ import annotations

import os
import pathlib

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
    expected = {"/world", "/world/focus", "/world/rig/joints", "/world/rig/bones", "/world/colliders/ball",
                "/world/colliders/arm", "/world/colliders/floor", "/events",
                "/world/cloths/tail/particles", "/world/cloths/tail/edges", "/world/cloths/tail/baselines",
                "/world/cloths/tail/base_pose", "/world/cloths/skirt/particles",
                "/world/cloths/skirt/triangles", "/metrics/solver/steps_per_frame",
                "/metrics/quality/max_edge_stretch_pct", "/metrics/quality/max_penetration_mm",
                "/metrics/motion/max_speed_m_per_s", "/metrics/time/late_update_ms",
                "/replay/pose", "/replay/time", "/replay/scene", "/replay/nodes", "/replay/events"}
    assert expected <= set(rec.entities)
    assert "/world/cloths/tail/triangles" not in rec.entities  # line mode has no triangles
    assert "/world/root_links" not in rec.entities             # the fake root branches at once: no stem


def test_world_geometry_is_stored_mirrored_in_x_and_read_back_in_the_scene_frame(recorded):
    rec, traj = recorded
    assert rec.display_mirror_x
    _, stored = rec.stacked("/world/cloths/tail/particles", "Points3D:positions", scene_frame=False)
    _, scene = rec.stacked("/world/cloths/tail/particles", "Points3D:positions")
    tail = traj[4][1].astype(np.float32)
    np.testing.assert_array_equal(stored[4], tail * np.array([-1, 1, 1], np.float32))
    np.testing.assert_array_equal(scene[4], tail)
    _, strips = rec.rows("/world/cloths/tail/edges", "LineStrips3D:strips", scene_frame=False)
    assert strips[4][0, 0] == -tail[0, 0] and strips[4][0, 1] == tail[0, 1]
    # metrics and replay data are never mirrored
    _, pose = rec.stacked("/replay/pose", "local_position", scene_frame=False)
    np.testing.assert_array_equal(pose[4].reshape(-1), traj[4][0][0])


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


def test_each_collider_is_an_entity_with_its_frame_and_its_real_shape(recorded):
    rec, _ = recorded
    frames, center = rec.stacked("/world/colliders/ball", "Transform3D:translation")
    assert frames.tolist() == list(range(FRAMES))
    np.testing.assert_allclose(center[4], [[0.0, 0.54, 0.0]], atol=1e-7)
    _, stored = rec.stacked("/world/colliders/ball", "Transform3D:translation", scene_frame=False)
    np.testing.assert_array_equal(stored[:, 0, 1:], center[:, 0, 1:])
    shape_frames, half = rec.rows("/world/colliders/ball", "Ellipsoids3D:half_sizes")
    assert shape_frames.tolist() == [0]                     # logged once: the radius never changes
    np.testing.assert_array_equal(half[0], np.full((1, 3), 0.1, np.float32))
    # the tapered capsule (0.05 -> 0.04) is a mesh in its own frame: +Z from the start cap centre
    _, start = rec.stacked("/world/colliders/arm", "Transform3D:translation")
    np.testing.assert_allclose(start[0], [[0.2, 0.0, 0.0]], atol=1e-7)
    _, quats = rec.stacked("/world/colliders/arm", "Transform3D:quaternion")
    np.testing.assert_allclose(quats[0][0], [-np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)], atol=1e-7)  # +Z onto +Y
    _, verts = rec.rows("/world/colliders/arm", "Mesh3D:vertex_positions")
    v = verts[0].astype(np.float64)
    start_cap, end_cap = v[v[:, 2] <= 0.0], v[v[:, 2] >= 0.4 + 1e-4]
    np.testing.assert_allclose(np.linalg.norm(start_cap, axis=1), 0.05, rtol=1e-6)             # both radii
    np.testing.assert_allclose(np.linalg.norm(end_cap - [0, 0, 0.4], axis=1), 0.04, rtol=1e-6)
    assert v[:, 2].min() == pytest.approx(-0.05, abs=1e-7) and v[:, 2].max() == pytest.approx(0.44, abs=1e-7)
    # the ground is a patch under the characters' box, not a fixed square
    _, floor = rec.stacked("/world/colliders/floor", "Transform3D:translation")
    assert floor[2, 0, 1] == 0.0 and "LineStrips3D:strips" in rec.components("/world/colliders/floor")


def test_an_oversized_collider_is_a_wireframe():
    from magica_py.sinks.collider_view import ColliderView

    calls = []

    class Rec:
        def send_columns(self, *a, **k):
            pass

        def set_time(self, *a, **k):
            pass

        def log(self, path, archetype):
            calls.append((path, archetype))

    view = ColliderView(["big", "small"], np.array([0, 0]), np.array([0, 1]), ["", ""])
    shapes = {"sphere_center": np.zeros((1, 2, 3)), "sphere_radius": np.array([[1.0, 0.1]])}
    view.send(rr, Rec(), [], np.array([0]), np.array([0.0]), shapes, np.zeros((1, 2, 3)))
    fill = {path: arch.fill_mode.as_arrow_array().to_pylist()[0] for path, arch in calls}
    assert fill == {"world/colliders/big": 1, "world/colliders/small": 4}   # major wireframe / light fill + outline


def test_metrics_are_time_series_with_units_and_hand_checked_values(recorded):
    rec, traj = recorded
    frames, steps = rec.scalars("/metrics/solver/steps_per_frame")
    assert frames.tolist() == list(range(FRAMES)) and steps.tolist() == [2.0] * FRAMES
    frames, late = rec.scalars("/metrics/time/late_update_ms")
    assert frames.tolist() == list(range(1, FRAMES))   # the first frame (JIT compilation) is left out
    assert late.tolist() == [2.0] * (FRAMES - 1)       # seconds -> milliseconds
    _, speed = rec.scalars("/metrics/motion/max_speed_m_per_s")
    allx = [np.vstack([t, s]) for _, t, s in traj]
    want = np.linalg.norm(allx[6] - allx[5], axis=1).max() * 60
    assert speed[0] == 0.0 and speed[6] == pytest.approx(want, rel=1e-12)
    _, stretch = rec.scalars("/metrics/quality/max_edge_stretch_pct")
    t, s = traj[1][1], traj[1][2]
    lengths = [np.linalg.norm(t[0] - t[1]) / 0.1, np.linalg.norm(t[1] - t[2]) / 0.1]
    lengths += [np.linalg.norm(s[a] - s[b]) / r for (a, b), r in
                zip([(0, 1), (0, 2), (1, 3), (2, 3), (1, 2)], [0.1, 0.1, 0.1, 0.1, 0.1414])]
    assert stretch[1] == pytest.approx(100 * max(abs(v - 1) for v in lengths), rel=1e-12)   # percent
    _, pen = rec.scalars("/metrics/quality/max_penetration_mm")
    assert pen.tolist() == [0.0] * FRAMES                # the fake's points stay clear of its colliders
    assert rec.static_value("/metrics/quality/max_edge_stretch_pct", "SeriesLines:names") == \
        ["max edge stretch (%)"]
    assert rec.static_value("/metrics/time/late_update_ms", "SeriesLines:names") == ["late update (ms)"]


def test_penetration_is_logged_in_millimetres(tmp_path):
    path = tmp_path / "pen.rrd"
    joints, tail, skirt = trajectory(1)[0]
    tail = tail.copy()
    tail[1] = (0.0, 0.5, 0.0)          # a Move particle (r 0.02) at the centre of the 0.1 m ball
    sink = RerunSink(statics(), rrd_path=path, collider_kind=np.array([0, 1, 2]), collider_slot=np.array([0, 0, 0]))
    sink.begin_frame(0, 0.0)
    sink.log(frame_data(0, joints, tail, skirt))
    sink.end_frame()
    sink.close()
    _, pen = Recording(path).scalars("/metrics/quality/max_penetration_mm")
    assert pen.tolist() == [pytest.approx(120.0, rel=1e-12)]


def test_phase_series_have_distinct_colours():
    colours = list(L.COLOR_PHASES.values()) + list(L.COLOR_SERIES.values())
    assert len(set(colours)) == len(colours)
    rgb = np.array(list(L.COLOR_PHASES.values()))[:, :3]
    gaps = [np.abs(a - b).sum() for i, a in enumerate(rgb) for b in rgb[i + 1:]]
    assert min(gaps) > 120          # no two near-identical pinks


def test_events_are_a_text_log_at_their_frame(recorded):
    rec, _ = recorded
    rows = rec.text_rows("/events", "TextLog:text")
    assert rows[1] == (3, 'teleport: {"frame": 3, "target": "root"}')
    assert rows[0][0] == 0 and rows[0][1].startswith("first frame wall times, left out of the plots")
    assert "time.late_update 2.0 ms" in rows[0][1]


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
    # rerun's direction codes: Left 4, Up 1, Forward 5 -> LUF, right-handed: Unity's frame mirrored in X
    assert rec.static_value("/world", "ViewCoordinates:xyz").tolist() == [[4, 1, 5]]
    assert "mirrored" in rec.static_value("/world", "coordinates")[0]


def test_toggles_leave_out_what_was_switched_off(tmp_path):
    path = tmp_path / "lean.rrd"
    record(path, frames=3, toggles=LogToggles(skeleton=False, edges=False, colliders=False, replay=False))
    ents = set(Recording(path).entities)
    assert "/world/cloths/tail/particles" in ents
    assert not ents & {"/world/rig/joints", "/world/cloths/tail/edges", "/world/colliders/ball",
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


def test_unwritable_folder_gives_a_clear_error(tmp_path):
    """A folder this process may not write into: a read-only (0o500) folder, or for root, whom
    the mode bits do not stop, Linux's ``/proc/self`` (no process can create a file there)."""
    if os.geteuid() != 0:
        locked = tmp_path / "locked"
        locked.mkdir()
        locked.chmod(0o500)
    else:
        locked = pathlib.Path("/proc/self")
        if not locked.is_dir() or os.access(locked, os.W_OK | os.X_OK):
            pytest.skip("running as root without Linux's /proc: no folder here that root cannot write into")
    try:
        with pytest.raises(OutputError, match=f"folder '{locked}' is not writable"):
            check_output_path(locked / "x.rrd")
        with pytest.raises(OSError):   # and the folder really refuses a new file
            (locked / "x.rrd").open("wb").close()
    finally:
        if locked.parent == tmp_path:
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


@pytest.mark.parametrize("node_group, prefix", [
    (None, ["instance_0", "instance_0", "instance_1"]),                       # from the `#i` suffix
    (["", "character_0", "character_0", "character_0", "character_1", "character_1"],
     ["character_0", "character_1", "character_0"])])                        # from the rig instances
def test_each_rig_instance_has_its_own_entities_so_a_hover_names_it(tmp_path, node_group, prefix):
    from dataclasses import replace

    from magica_py.sinks.base import FrameData, SceneStatics
    from magica_py.sinks.fakes import JOINT_NAMES, JOINT_PARENT, colliders_frame, topologies

    tail, skirt = topologies()
    cloths = [replace(tail, name="hair#0"), replace(skirt, name="skirt#0"), replace(tail, name="hair#1")]
    st = SceneStatics(name="inst", joint_names=JOINT_NAMES, joint_parent=JOINT_PARENT, cloths=cloths,
                      toggles=LogToggles(replay=False), node_group=node_group or [])
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
    hair0 = f"/world/{prefix[0]}/cloths/hair/particles"
    want = {hair0, f"/world/{prefix[1]}/cloths/skirt/particles", f"/world/{prefix[2]}/cloths/hair/particles"}
    assert {e for e in rec.entities if e.endswith("/particles")} == want
    _, hair = rec.stacked(hair0, "Points3D:positions")
    if node_group is None:
        np.testing.assert_array_equal(hair[2], (x[[0, 1, 2]] + 2).astype(np.float32))
        _, edges = rec.rows("/world/instance_1/cloths/hair/edges", "LineStrips3D:strips")
        np.testing.assert_array_equal(edges[1], (x[[7, 8, 8, 9]] + 1).astype(np.float32))   # hair#1's own particles
    else:   # both hair cloths hang on character_0's nodes: one entity, members in team order
        np.testing.assert_array_equal(hair[2], (x[[0, 1, 2, 7, 8, 9]] + 2).astype(np.float32))
        assert "/world/character_1/rig/joints" in rec.entities and "/world/rig/joints" in rec.entities


def test_stem_links_from_a_root_to_its_first_branch_are_drawn_apart():
    from magica_py.sinks.rerun_sink import stem_links

    # spot -> root -> hips -> (spine, leg); a lone static node; a root whose child is a cloth bone
    parent = np.array([-1, 0, 1, 2, 2, -1, -1, 6])
    cloth = np.array([False] * 7 + [True])
    link, stem = stem_links(parent, cloth)
    assert np.flatnonzero(link).tolist() == [1, 2]            # spot -> root, root -> hips
    assert np.flatnonzero(stem).tolist() == [0, 1, 2, 5, 6]   # hips is a stem node; its branches are bones


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


class _Interrupt(BaseException):
    """Stands in for ^C (KeyboardInterrupt) or SIGTERM (cli.Terminated): not an Exception."""


@pytest.mark.parametrize("where", ["send_recording_name", "_log_statics"])
def test_an_interrupt_while_opening_leaves_no_temporary_file(tmp_path, monkeypatch, where):
    """^C or SIGTERM while the stream's sinks open, or while the statics are written (a job
    scheduler ending a run at its first frame): the interrupt goes on, the file does not stay."""
    def interrupted(*args, **kwargs):
        raise _Interrupt()

    monkeypatch.setattr(rr.RecordingStream if where == "send_recording_name" else RerunSink, where, interrupted)
    with pytest.raises(_Interrupt):
        RerunSink(statics(), rrd_path=tmp_path / "x.rrd")
    assert list(tmp_path.iterdir()) == []


def test_spawn_and_connect_stream_with_one_frame_batches(tmp_path, monkeypatch):
    """Wiring only: the viewer start, the port checks and the gRPC sink are replaced."""
    from magica_py.sinks import live

    calls = {}

    class FakeGrpc:
        def __init__(self, url=None):
            calls.setdefault("grpc", []).append(url)

    monkeypatch.setattr(live, "display_problem", lambda: None)
    monkeypatch.setattr(live, "listening", lambda host, port, timeout=0: None)
    monkeypatch.setattr(rr, "spawn", lambda **kw: calls.setdefault("spawn", []).append(kw))
    monkeypatch.setattr(rr, "GrpcSink", FakeGrpc)
    monkeypatch.setattr(rr.RecordingStream, "set_sinks",
                        lambda self, *sinks, default_blueprint=None: calls.setdefault("sinks", sinks))
    monkeypatch.setattr(rr.RecordingStream, "flush", lambda self, timeout_sec=0: calls.setdefault("flush", timeout_sec))
    sink = RerunSink(statics(), spawn=True, connect="10.0.0.7:9999")
    assert calls["spawn"][0]["port"] == live.SPAWN_PORT and calls["spawn"][0]["recording"] is sink.rec
    assert calls["spawn"][0]["executable_path"]                # the venv's viewer, PATH or not
    assert calls["grpc"] == ["rerun+http://127.0.0.1:9876/proxy", "rerun+http://10.0.0.7:9999/proxy"]
    assert len(calls["sinks"]) == 2 and sink.batch == 1 and sink.final_path is None
    assert calls["flush"] == live.FLUSH_SECONDS               # statics delivered before the first frame
    sink.close()


def test_spawn_without_a_display_fails_before_anything_is_written(tmp_path, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_SOCKET", raising=False)
    monkeypatch.setattr("sys.platform", "linux")
    with pytest.raises(OutputError, match="--spawn: cannot start the Rerun viewer: no display"):
        RerunSink(statics(), spawn=True, rrd_path=tmp_path / "x.rrd")
    assert list(tmp_path.iterdir()) == []


def test_connect_to_a_port_nobody_listens_on_fails_with_the_address(tmp_path):
    import socket

    with socket.socket() as s:          # a port that was free a moment ago
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(OutputError, match=f"--connect: no Rerun viewer listens at 127.0.0.1:{port}"):
        RerunSink(statics(), connect=f"127.0.0.1:{port}", rrd_path=tmp_path / "x.rrd")
    assert list(tmp_path.iterdir()) == []


def test_a_stream_lost_during_the_run_is_an_error_at_close(tmp_path, monkeypatch):
    """The file is complete and kept, but the run must not pass for a success."""
    monkeypatch.setattr(rr.RecordingStream, "flush", lambda self, timeout_sec=0: None)
    sink = RerunSink(statics(), rrd_path=tmp_path / "x.rrd", live_urls=["rerun+http://127.0.0.1:1/proxy"])

    def lost(self, timeout_sec=0):
        raise RuntimeError("gRPC has been unable to connect for 6s")

    monkeypatch.setattr(rr.RecordingStream, "flush", lost)
    with pytest.raises(OutputError, match="failed after 0 frames: gRPC has been unable to connect"):
        sink.close()
    assert (tmp_path / "x.rrd").exists()


def test_live_runs_write_a_file_only_when_asked():
    from types import SimpleNamespace

    from magica_py.sinks.recorder import SinkOptions, output_rrd

    scene = SimpleNamespace(output=SimpleNamespace(rrd="replays/x.rrd"))
    assert output_rrd(SinkOptions(), scene) == "replays/x.rrd"
    assert output_rrd(SinkOptions(spawn=True), scene) is None
    assert output_rrd(SinkOptions(connect="h:1"), scene) is None
    assert output_rrd(SinkOptions(spawn=True, rrd="asked.rrd"), scene) == "asked.rrd"
    assert output_rrd(SinkOptions(no_rrd=True, rrd="asked.rrd"), scene) is None


def test_a_crowd_file_uses_long_batches_and_a_small_scene_short_ones(tmp_path):
    from dataclasses import replace

    from magica_py.sinks import rerun_sink
    from magica_py.sinks.base import SceneStatics
    from magica_py.sinks.fakes import JOINT_NAMES, JOINT_PARENT, topologies

    tail, _ = topologies()
    many = [replace(tail, name=f"hair#{i}") for i in range(rerun_sink.CROWD_ENTITY_SETS + 1)]
    crowd = SceneStatics(name="crowd", joint_names=JOINT_NAMES, joint_parent=JOINT_PARENT, cloths=many)
    sink = RerunSink(crowd, rrd_path=tmp_path / "c.rrd")
    assert sink.batch == rerun_sink.CROWD_BATCH_FRAMES
    sink.close()
    small = RerunSink(statics(), rrd_path=tmp_path / "s.rrd")
    assert small.batch == rerun_sink.FILE_BATCH_FRAMES
    small.close()


def test_the_focus_box_spans_the_characters_joints_and_particles_but_not_the_stems(recorded):
    rec, traj = recorded
    frames, box = rec.stacked("/world/focus", "Points3D:positions")
    assert frames.tolist() == list(range(FRAMES))
    for f in (0, 5, 9):
        joints, tail, skirt = traj[f]
        points = np.vstack([joints[1:], tail, skirt])          # joint 0 (the root) is a stem
        np.testing.assert_array_equal(box[f], np.stack([points.min(0), points.max(0)]).astype(np.float32))


def test_a_recording_file_that_cannot_be_created_names_the_recording_not_its_temporary(tmp_path, monkeypatch):
    """A folder that passes the access check but refuses the file (root in /proc): rerun's error
    names the hidden temporary file; the message leads with the recording the user asked for."""
    def refused(path, *args, **kwargs):
        raise RuntimeError(f"Failed to create file: No such file or directory (os error 2), path: {path}")

    monkeypatch.setattr(rr, "FileSink", refused)
    with pytest.raises(OutputError, match=rf"cannot write the recording '{tmp_path / 'x.rrd'}' \(its temporary "
                                          r"file beside it: Failed to create file"):
        RerunSink(statics(), rrd_path=tmp_path / "x.rrd")
    assert list(tmp_path.iterdir()) == []
