"""The sink inside the player loop: capture, RENDER_WRITE, close, and resim round trips."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import rerun as rr

from magica_py.runtime.clock import FrameTimeList, TimeManager
from magica_py.runtime.phases import Phase
from magica_py.runtime.player import Player, default_schedule
from magica_py.scene.colliders import ColliderSet
from magica_py.scene.hierarchy import BoneSpec, TransformHierarchy
from magica_py.sinks import SinkOptions, attach
from magica_py.sinks.base import ClothFrame, ClothTopology
from magica_py.sinks.readback import Recording
from magica_py.sinks.resim import build_player, load_replay, resimulate

FRAMES = 12
# hitches and a variable frame rate: resim must reproduce the recorded UnityTime, not 1/fps
FRAME_TIMES = [1 / 60, 1 / 30, 0.5, 1 / 144, 1 / 60]


@pytest.fixture(autouse=True)
def strict():
    rr.set_strict_mode(True)


class Wiggle:
    """Animation: root orbits, `mid` twists (irrational numbers so float32 loses bits)."""

    targets = None

    def apply(self, hierarchy, ctx):
        t = ctx.time.time
        root, mid = hierarchy.index("root"), hierarchy.index("mid")
        hierarchy.local_position[root] = (np.cos(3.1 * t) / 3, 1.0 + t / 7, np.sin(2.3 * t) / 3)
        a = 0.37 * np.sin(5.0 * t)
        hierarchy.local_rotation[mid] = (np.sin(a / 2), 0.0, 0.0, np.cos(a / 2))
        if ctx.frame == 4:
            ctx.events.append(("set_parameter", {"cloth": "tail", "key": "damping", "value": 0.25}))
        if ctx.frame == 6:
            ctx.events.append(("time_scale", 0.5))


def make_scene(path=None):
    bones = [BoneSpec("root"), BoneSpec("mid", "root", (0, -0.2, 0)), BoneSpec("tip", "mid", (0, -0.2, 0.05)),
             BoneSpec("end", "tip", (0, -0.2, 0.0)), BoneSpec("head", "root", (0, 0.3, 0))]
    h = TransformHierarchy(bones)
    colliders = ColliderSet.from_specs([
        {"name": "ball", "transform": "head", "center": [0, 0.05, 0], "sphere": {"radius": 0.1}},
        {"name": "arm", "transform": "root", "capsule": {"radius": 0.05, "end_radius": 0.03, "length": 0.4,
                                                         "direction": "x"}},
        {"name": "floor", "transform": "root", "center": [0, -1, 0], "plane": {}}], h)
    return SimpleNamespace(name="wiggle", source=None, hierarchy=h, colliders=colliders, animation=Wiggle(),
                           cloths=[], output=SimpleNamespace(rrd=path, log={"baselines": True, "base_pose": True}),
                           settings=SimpleNamespace(frame_times=FRAME_TIMES, fps=None))


class KinematicCloth:
    """Snapshot provider standing in for the solver: the particles follow mid, tip, end."""

    def __init__(self, scene):
        self.h = scene.hierarchy
        self.nodes = np.array([self.h.index(n) for n in ("mid", "tip", "end")])

    def cloth_topologies(self):
        return [ClothTopology(name="tail", attribute=np.array([1, 2, 2], np.uint8), radius=np.full(3, 0.02),
                              parent=np.array([-1, 0, 1], np.int32), edges=np.array([[0, 1], [1, 2]], np.int32),
                              triangles=np.zeros((0, 3), np.int32), rest_length=np.array([0.2, 0.2]),
                              transform_index=self.nodes.astype(np.int32), colliders=np.array([0, 1, 2], np.int32))]

    def cloth_frames(self):
        x = self.h.world_position[self.nodes]
        return [ClothFrame(positions=x, base_positions=x + 0.01, steps=1)]


def run(scene, path, frames=FRAMES, options=None):
    player = Player(scene, default_schedule(scene), FrameTimeList(FRAME_TIMES), TimeManager())
    recorder = attach(player, scene, options or SinkOptions(rrd=path, snapshots=KinematicCloth(scene),
                                                            batch_frames=5))
    positions = []
    ok = False
    try:
        for _ in range(frames):
            player.step()
            positions.append(scene.hierarchy.world_position.copy())
        ok = True
    finally:
        recorder.close(success=ok)
    return player, np.array(positions)


@pytest.fixture(scope="module")
def original(tmp_path_factory):
    rr.set_strict_mode(True)
    path = tmp_path_factory.mktemp("orig") / "wiggle.rrd"
    player, positions = run(make_scene(), path)
    return path, player, positions


def test_attach_registers_capture_after_animation_and_the_sink_in_render_write(original):
    _, player, _ = original
    d = dict(player.schedule.describe())
    assert d["UPDATE"] == ["animation", "capture_replay"]
    assert d["RENDER_WRITE"] == ["rerun_sink"]


def test_recorded_joints_and_particles_are_the_hierarchy_positions_as_float32(original):
    path, _, positions = original
    rec = Recording(path)
    frames, joints = rec.stacked("/world/rig/joints", "Points3D:positions")
    assert frames.tolist() == list(range(FRAMES))
    # the cloth's bones (mid, tip, end) are its particles; the rig shows root and head
    np.testing.assert_array_equal(joints, positions[:, [0, 4]].astype(np.float32))
    _, tail = rec.stacked("/world/cloths/tail/particles", "Points3D:positions")
    np.testing.assert_array_equal(tail, positions[:, 1:4].astype(np.float32))


def test_sim_time_timeline_is_unity_scaled_time_with_hitch_clamp_and_time_scale(original):
    path, _, _ = original
    times, _ = Recording(path).rows("/world/rig/joints", "Points3D:positions", timeline="sim_time")
    # Unity: delta = min(raw, maximumDeltaTime 1/3) * time scale (0.5 from the frame after frame 6)
    raw = [FRAME_TIMES[i % 5] for i in range(FRAMES)]
    scale = [1.0] * 7 + [0.5] * (FRAMES - 7)
    expected = np.cumsum([min(r, 1 / 3) * s for r, s in zip(raw, scale)])
    np.testing.assert_allclose(times / 1e9, expected, atol=2e-9)


def test_collider_shapes_follow_their_transforms(original):
    path, _, positions = original
    rec = Recording(path)
    _, centers = rec.stacked("/world/colliders/ball", "Transform3D:translation")
    head = positions[:, 4] + [0, 0.05, 0]
    np.testing.assert_array_equal(centers[:, 0], head.astype(np.float32))
    # the tapered arm is a mesh in its own frame along +Z: aligned on centre, the caps sit at
    # +-(L/2 - r): 0.15 and 0.17 from the centre, 0.32 apart
    _, verts = rec.rows("/world/colliders/arm", "Mesh3D:vertex_positions")
    assert verts[0][:, 2].max() - 0.03 == pytest.approx(0.32, rel=1e-6)
    _, start = rec.stacked("/world/colliders/arm", "Transform3D:translation")
    _, quat = rec.stacked("/world/colliders/arm", "Transform3D:quaternion")
    assert np.isfinite(start).all() and np.allclose(np.linalg.norm(quat, axis=2), 1.0, atol=1e-6)


def test_replay_pose_time_and_events_are_recorded_exactly(original):
    path, player, _ = original
    replay = load_replay(path)
    assert replay.frame_count == FRAMES
    assert replay.node_names == ["root", "mid", "tip", "end", "head"]   # nothing restored: all nodes
    assert replay.events == {4: [("set_parameter", {"cloth": "tail", "key": "damping", "value": 0.25})],
                             6: [("time_scale", 0.5)]}
    k = replay.time_fields.index("time")
    assert replay.time_values[-1, k] == player.last_context.time.time      # float64, exact


def test_resim_round_trip_reproduces_pose_time_and_particles_bit_for_bit(original, tmp_path):
    path, player, positions = original
    scene = make_scene()
    out = tmp_path / "again.rrd"
    replayed, recorder, _ = resimulate(path, scene, out, snapshots=KinematicCloth(scene))
    assert replayed.frame == FRAMES
    assert replayed.last_context.time == player.last_context.time
    a, b = Recording(path), Recording(out)
    for entity, comp in [("/world/cloths/tail/particles", "Points3D:positions"),
                         ("/world/rig/joints", "Points3D:positions"),
                         ("/world/colliders/arm", "Transform3D:quaternion")]:
        fa, ra = a.stacked(entity, comp)
        fb, rb = b.stacked(entity, comp)
        assert fa.tolist() == fb.tolist()
        np.testing.assert_array_equal(ra, rb)
    ta, _ = a.rows("/world/rig/joints", "Points3D:positions", timeline="sim_time")
    tb, _ = b.rows("/world/rig/joints", "Points3D:positions", timeline="sim_time")
    np.testing.assert_array_equal(ta, tb)
    _, pa = a.stacked("/replay/pose", "local_position")
    _, pb = b.stacked("/replay/pose", "local_position")
    np.testing.assert_array_equal(pa, pb)                                   # float64 bit for bit
    assert load_replay(out).events == load_replay(path).events


def test_resim_replaces_the_animation_by_the_playback(original):
    path, _, _ = original
    player = build_player(load_replay(path), make_scene())
    assert dict(player.schedule.describe())["UPDATE"] == ["replay_pose"]


def test_resim_on_a_rig_without_the_recorded_bones_is_a_clear_error(original):
    path, _, _ = original
    scene = make_scene()
    scene.hierarchy = TransformHierarchy([BoneSpec("root")])
    with pytest.raises(ValueError, match=r"no transforms named \['mid', 'tip', 'end', 'head'\]"):
        build_player(load_replay(path), scene)


def test_scene_output_path_is_used_and_a_crash_leaves_nothing(tmp_path):
    scene = make_scene(tmp_path / "from_scene.rrd")

    class Boom(Exception):
        pass

    player = Player(scene, default_schedule(scene), FrameTimeList(FRAME_TIMES), TimeManager())
    recorder = attach(player, scene, SinkOptions(snapshots=KinematicCloth(scene), batch_frames=2))
    from magica_py.runtime.phases import System

    def explode(ctx):
        if ctx.frame == 5:
            raise Boom()
    player.schedule.add(Phase.LATE_UPDATE, System("explode", explode))
    with pytest.raises(Boom):
        try:
            player.run(10)
        finally:
            recorder.close(success=False)
    assert list(tmp_path.iterdir()) == []
    player2, _ = run(make_scene(tmp_path / "from_scene.rrd"), None, frames=3,
                     options=SinkOptions(batch_frames=2, snapshots=None))
    assert [p.name for p in tmp_path.iterdir()] == ["from_scene.rrd"]


def test_bad_output_path_fails_at_attach_before_any_frame(tmp_path):
    scene = make_scene(tmp_path / "nope" / "x.rrd")
    player = Player(scene, default_schedule(scene), FrameTimeList(FRAME_TIMES), TimeManager())
    with pytest.raises(ValueError, match=r"output.rrd: cannot write .*folder .*nope' does not exist"):
        attach(player, scene, SinkOptions())
    assert player.frame == 0


def test_no_output_at_all_uses_the_null_sink(tmp_path):
    scene = make_scene(None)
    player, _ = run(scene, None, frames=2, options=SinkOptions())
    assert list(tmp_path.iterdir()) == []


def test_only_the_nodes_the_animation_drives_are_recorded_and_resim_stays_exact(tmp_path):
    scene = make_scene()

    class Listed(Wiggle):
        driven = np.array([scene.hierarchy.index("mid"), scene.hierarchy.index("root")])

    scene.animation = Listed()
    path = tmp_path / "listed.rrd"
    run(scene, path)
    replay = load_replay(path)
    assert replay.node_names == ["root", "mid"]
    again = make_scene()
    out = tmp_path / "listed_again.rrd"
    resimulate(replay, again, out, snapshots=KinematicCloth(again))
    _, a = Recording(path).stacked("/world/rig/joints", "Points3D:positions")
    _, b = Recording(out).stacked("/world/rig/joints", "Points3D:positions")
    np.testing.assert_array_equal(a, b)


def test_a_run_of_zero_frames_still_writes_a_readable_recording(tmp_path):
    scene = make_scene(tmp_path / "empty.rrd")
    player = Player(scene, default_schedule(scene), FrameTimeList(FRAME_TIMES), TimeManager())
    recorder = attach(player, scene, SinkOptions(snapshots=KinematicCloth(scene)))
    player.run(0)
    recorder.close(success=True)
    rec = Recording(tmp_path / "empty.rrd")
    assert rec.timeline_values("frame").size == 0 and rec.blueprint_count == 1
    assert "/world/cloths/tail/particles" in rec.entities


def test_the_runs_overrides_are_recorded_for_resim(tmp_path):
    scene = make_scene(tmp_path / "ov.rrd")
    scene.overrides = ("cloths.tail.parameters.gravity=9",)
    run(scene, None, frames=2, options=SinkOptions(snapshots=KinematicCloth(scene)))
    assert load_replay(tmp_path / "ov.rrd").scene_overrides == ("cloths.tail.parameters.gravity=9",)


def test_an_animation_driving_nothing_records_empty_pose_rows(tmp_path):
    scene = make_scene(tmp_path / "still.rrd")

    class Still(Wiggle):
        driven = np.zeros(0, np.int32)

    scene.animation = Still()
    run(scene, None, frames=3, options=SinkOptions(snapshots=KinematicCloth(scene)))
    replay = load_replay(tmp_path / "still.rrd")
    assert replay.node_names == [] and replay.local_position.shape == (3, 0, 3)
