"""The player loop (magica_py/runtime/player.py): the frame-phase contract of issue 2."""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from magica_py.runtime.clock import FixedFrameRate, FrameTimeList, TimeManager
from magica_py.runtime.phases import Phase, System
from magica_py.runtime.player import FrameContext, Player, default_schedule
from team_time_driver import begin_step, end_frame, frame_update
from magica_py.runtime.team_time import (
    SimulationTimeSettings,
    TeamTimeState,
)
from magica_py.scene.hierarchy import BoneSpec, TransformHierarchy


def chain_hierarchy(n=4, length=0.1):
    bones = [BoneSpec("root", None, (0.0, 1.0, 0.0))]
    for i in range(1, n):
        bones.append(BoneSpec(f"b{i}", bones[-1].name, (0.0, -length, 0.0)))
    return TransformHierarchy(bones)


class SwingAnimation:
    """Rotates the root about Z by ``amplitude * sin(time)`` and records what it wrote."""

    def __init__(self, amplitude=0.5):
        self.amplitude = amplitude
        self.written = []

    def angle(self, t):
        return self.amplitude * math.sin(t)

    def apply(self, hierarchy, ctx):
        a = self.angle(ctx.time.time)
        hierarchy.local_rotation[0] = (0.0, 0.0, math.sin(a / 2), math.cos(a / 2))
        self.written.append((ctx.frame, ctx.time.time))


def make_player(fps=30, scene=None, time_manager=None, source=None):
    scene = scene or SimpleNamespace(hierarchy=chain_hierarchy(), animation=None)
    return Player(scene, default_schedule(scene), source or FixedFrameRate(fps),
                  time_manager or TimeManager())


def tracer(log, label):
    def run(ctx):
        if ctx.phase is Phase.FIXED_UPDATE:
            log.append((ctx.frame, f"{label}#{ctx.fixed_update_index}"))
        else:
            log.append((ctx.frame, label))
    return run


# ----------------------------------------------------------------------------- phase order
def test_phase_order_each_frame_with_fixed_updates_in_between():
    player = make_player(fps=20)  # 0.05 s frames, fixedDeltaTime 0.02 -> 2 or 3 fixed updates
    log = []
    for phase in Phase:
        player.schedule.add(phase, System(f"trace_{phase.name}", tracer(log, phase.name)))
    for _ in range(4):
        ctx = player.step()
    frames = {}
    for frame, label in log:
        frames.setdefault(frame, []).append(label)
    fixed = [2, 3, 2, 3]  # 0.05/0.02: fixed clock at 0.04, 0.10, 0.14, 0.20
    for f in range(4):
        expected = ["RESTORE"] + [f"FIXED_UPDATE#{k}" for k in range(fixed[f])] + \
                   ["UPDATE", "LATE_UPDATE", "RENDER_WRITE", "AFTER_RENDERING"]
        assert frames[f] == expected, f
    assert ctx.frame == 3 and player.frame == 4


def test_default_schedule_describes_the_built_in_systems():
    player = make_player()
    assert player.schedule.describe() == [
        ("RESTORE", ["restore_bones"]), ("FIXED_UPDATE", []), ("UPDATE", ["animation"]),
        ("LATE_UPDATE", []), ("RENDER_WRITE", []), ("AFTER_RENDERING", ["reset_frame_counters"]),
    ]


def test_default_schedule_requires_a_hierarchy():
    with pytest.raises(TypeError, match="hierarchy"):
        default_schedule(object())


# ----------------------------------------------------------------------------- restore
def test_registered_bones_are_restored_before_update_others_keep_their_pose():
    h = chain_hierarchy()
    rest = h.local_rotation.copy()
    player = make_player(scene=SimpleNamespace(hierarchy=h))
    player.register_restored_bones([1, 2], owner="tail")
    bent = (0.0, 0.0, math.sin(0.3), math.cos(0.3))
    seen_in_update = []

    def write_back(ctx):  # what a cloth system does in LATE_UPDATE
        h.local_rotation[1:4] = bent
        h.local_position[2] = (0.5, 0.5, 0.5)
        h.propagate()

    def observe(ctx):
        seen_in_update.append((h.local_rotation.copy(), h.local_position.copy()))

    player.schedule.add(Phase.LATE_UPDATE, System("cloth", write_back))
    player.schedule.add(Phase.UPDATE, System("observe", observe), before="animation")
    player.run(3)
    for rot, pos in seen_in_update[1:]:
        np.testing.assert_array_equal(rot[1:3], rest[1:3])  # restored
        np.testing.assert_array_equal(pos[2], h.rest_local_position[2])
        np.testing.assert_array_equal(rot[3], bent)  # not registered: last write survives
    assert player.restored_bones.tolist() == [1, 2]
    player.unregister_restored_bones("tail")
    player.step()
    np.testing.assert_array_equal(seen_in_update[-1][0][1], bent)


# ----------------------------------------------------------------------------- update -> late update
def test_what_animation_writes_in_update_is_what_late_update_reads():
    h = chain_hierarchy(n=3, length=0.2)
    anim = SwingAnimation()
    player = make_player(fps=60, scene=SimpleNamespace(hierarchy=h, animation=anim))
    read = []
    player.schedule.add(Phase.LATE_UPDATE,
                        System("read", lambda ctx: read.append((ctx.time.time,
                                                                h.world_position[2].copy()))))
    player.run(20)
    assert [f for f, _ in anim.written] == list(range(20))
    for t, tip in read:
        a = anim.angle(t)
        # independent: root at (0,1,0) rotated by a about +Z; the tip hangs 0.4 m along -Y
        expected = np.array([0.4 * math.sin(a), 1.0 - 0.4 * math.cos(a), 0.0])
        np.testing.assert_allclose(tip, expected, atol=1e-12)
    assert read[-1][0] == pytest.approx(20 / 60)


# ----------------------------------------------------------------------------- fixed updates
def test_fixed_update_count_and_counter_reset_follow_fixed_delta_accumulation():
    player = make_player(fps=144, time_manager=TimeManager(fixed_delta_time=0.02))
    in_late, fixed_times = [], []
    player.schedule.add(Phase.LATE_UPDATE, System(
        "read", lambda ctx: in_late.append((ctx.time.fixed_update_count,
                                            ctx.counters.fixed_update_count))))
    player.schedule.add(Phase.FIXED_UPDATE, System(
        "fixed", lambda ctx: fixed_times.append((ctx.fixed_time, ctx.time.time))))
    player.run(144)
    planned = [p for p, _ in in_late]
    assert [c for _, c in in_late] == planned  # the live counter equals the plan in LATE_UPDATE
    assert sum(planned) == 50 and set(planned) == {0, 1}
    assert player.counters.fixed_update_count == 0  # reset in AFTER_RENDERING
    fixed_clock = [ft for ft, _ in fixed_times]
    np.testing.assert_allclose(np.diff(fixed_clock), 0.02, atol=1e-12)
    assert all(ft <= t + 1e-9 for ft, t in fixed_times)
    assert player.last_context.metrics["frame.fixed_updates"] == planned[-1]


def test_fixed_update_counts_are_the_same_whether_or_not_a_system_listens():
    # with no FIXED_UPDATE system the player only advances the count (no per-update loop):
    # what LATE_UPDATE sees, frame by frame, must not depend on that
    seen = {}
    for listening in (False, True):
        player = make_player(fps=60, time_manager=TimeManager(fixed_delta_time=0.02))
        log = seen[listening] = []
        player.schedule.add(Phase.LATE_UPDATE, System(
            "read", lambda ctx, log=log: log.append((ctx.time.fixed_update_count, ctx.counters.fixed_update_count,
                                                     ctx.fixed_update_index, ctx.fixed_time))))
        if listening:
            player.schedule.add(Phase.FIXED_UPDATE, System("listen", lambda ctx: None))
        player.run(40)
        assert player.last_context.metrics["time.fixed_update"] >= 0.0
    assert seen[False] == seen[True]
    assert [c for _, c, _, _ in seen[False]] == [n for n, _, _, _ in seen[False]]   # reset every frame
    assert sorted({n for n, _, _, _ in seen[False]}) == [0, 1]   # 60 fps, 50 Hz: frames with 0 and 1
    assert all(i is None and t is None for _, _, i, t in seen[False])   # outside FIXED_UPDATE


def test_without_the_reset_system_fixed_updates_accumulate_across_frames():
    player = make_player(fps=50)
    player.schedule.remove("reset_frame_counters")
    player.run(10)
    assert player.counters.fixed_update_count == 10


# ----------------------------------------------------------------------------- events, metrics, run
def test_time_scale_event_applies_from_the_next_frame():
    player = make_player(fps=30)

    def pause_at_frame_4(ctx):
        if ctx.frame == 4:
            ctx.events.append(("time_scale", 0.0))
        if ctx.frame == 8:
            ctx.events.append(("time_scale", 0.5))

    player.schedule.add(Phase.UPDATE, System("events", pause_at_frame_4), after="animation")
    deltas = [player.step().time.delta_time for _ in range(10)]
    assert deltas[:5] == [pytest.approx(1 / 30)] * 5
    assert deltas[5:9] == [0.0] * 4
    assert deltas[9] == pytest.approx(1 / 60)


def test_custom_event_handlers_receive_the_payload():
    player = make_player()
    got = []
    player.event_handlers["marker"] = lambda p, payload: got.append((p.frame, payload))
    player.schedule.add(Phase.UPDATE, System("mark", lambda ctx: ctx.events.append(("marker", 7))))
    player.run(2)
    assert got == [(0, 7), (1, 7)]


def test_phase_wall_times_are_recorded_every_frame_and_summed_by_run():
    player = make_player()
    player.schedule.add(Phase.LATE_UPDATE, System(
        "steps", lambda ctx: ctx.metrics.__setitem__("sim.steps", 3)))
    progress = []
    summary = player.run(5, progress=lambda done, total, ctx: progress.append((done, total)))
    metrics = player.last_context.metrics
    for phase in Phase:
        assert metrics[f"time.{phase.name.lower()}"] >= 0.0
    assert summary.frames == 5 and summary.totals["sim.steps"] == 15.0
    assert summary.wall_time >= sum(summary.totals[f"time.{p.name.lower()}"] for p in Phase)
    assert progress == [(i, 5) for i in range(1, 6)]
    with pytest.raises(ValueError):
        player.run(-1)


def test_a_phase_without_a_system_records_zero_and_a_timed_phase_its_wall_time(monkeypatch):
    import magica_py.runtime.player as player_module

    player = make_player()   # RESTORE, UPDATE, AFTER_RENDERING have systems; the others none
    clock = iter(float(k) for k in range(1000))   # every clock read one second later
    monkeypatch.setattr(player_module._time, "perf_counter", lambda: next(clock))
    metrics = player.step().metrics
    assert metrics["time.fixed_update"] == 0.0
    assert metrics["time.late_update"] == 0.0
    assert metrics["time.render_write"] == 0.0
    # one clock read per boundary of a timed phase: RESTORE 0 -> 1 s; UPDATE 1 -> 5 s (the
    # animation system reads three clocks of its own: 2, 3, 4); AFTER_RENDERING 5 -> 6 s
    assert (metrics["time.restore"], metrics["time.update"], metrics["time.after_rendering"]) == (1.0, 4.0, 1.0)
    assert (metrics["animation.drivers"], metrics["animation.propagate"]) == (1.0, 1.0)
    # a system added later gets its phase timed from the next frame on
    player.schedule.add(Phase.LATE_UPDATE, System("late", lambda ctx: None))
    assert player.step().metrics["time.late_update"] == 1.0


def test_frame_time_list_drives_the_player_and_for_scene_reads_settings():
    settings = SimpleNamespace(frame_times=[1 / 60, 1.0], fixed_delta_time=0.02,
                               maximum_delta_time=0.25, time_scale=1.0)
    scene = SimpleNamespace(hierarchy=chain_hierarchy(), settings=settings)
    player = Player.for_scene(scene)
    t = [player.step().time for _ in range(4)]
    assert [x.unscaled_delta_time for x in t] == [1 / 60, 1.0, 1 / 60, 1.0]
    assert t[1].delta_time == 0.25  # Unity's maximumDeltaTime clamp
    assert player.schedule.find("restore_bones") is Phase.RESTORE


# ----------------------------------------------------------------------------- with team time
class TeamTimeSystem:
    """A minimal LATE_UPDATE system driving team time the way the solver will."""

    def __init__(self, modes, settings):
        self.settings = settings
        self.state = TeamTimeState.allocate(len(modes))
        for t, m in enumerate(modes):
            self.state.activate(t, m)
        self.steps = []
        self.skips = []
        self.interpolations = []

    def run(self, ctx: FrameContext):
        frame_update(self.state, self.settings, ctx.time, ctx.counters.fixed_update_count)
        for k in range(self.state.max_update_count()):
            begin_step(self.state, self.settings, k)
            self.interpolations.append(self.state.frame_interpolation[self.state.step_running].copy())
        self.steps.append(self.state.update_count.copy())
        self.skips.append(self.state.skip_count.copy())
        end_frame(self.state, self.settings)


def test_player_and_team_time_30_fps_runs_3_steps_and_unity_physics_counts_fixed_updates():
    player = make_player(fps=30, time_manager=TimeManager(fixed_delta_time=0.02))
    cloth = TeamTimeSystem(["normal", "unity_physics", "unscaled"], SimulationTimeSettings())
    player.schedule.add(Phase.LATE_UPDATE, System("cloth", cloth.run))
    player.run(90)
    steps = np.array(cloth.steps)
    assert steps[:, 0].tolist() == [3] * 90
    assert steps[:, 2].tolist() == [3] * 90
    # fixed updates per 1/30 s frame go 1,2,2 (0.02 s each): frame deltas 0.02, 0.04, 0.04 plan
    # 1.8 -> 1, then 4.4 -> 4 and 4 steps, capped to 3: by hand 1,3,3 and one step dropped twice
    assert steps[:, 1].tolist() == [1, 3, 3] * 30
    assert all(((r >= 0) & (r <= 1)).all() for r in cloth.interpolations)


def test_unity_physics_team_at_60_fps_follows_50_hz_fixed_updates():
    player = make_player(fps=60, time_manager=TimeManager(fixed_delta_time=0.02))
    cloth = TeamTimeSystem(["unity_physics"], SimulationTimeSettings())
    fixed = []
    player.schedule.add(Phase.LATE_UPDATE, System(
        "fixed", lambda ctx: fixed.append(ctx.counters.fixed_update_count)))
    player.schedule.add(Phase.LATE_UPDATE, System("cloth", cloth.run))
    player.run(180)
    steps = np.array(cloth.steps)[:, 0]
    assert sum(fixed) == 150
    assert all(s == 0 for s, f in zip(steps, fixed) if f == 0)  # no FixedUpdate, no step
    assert steps.sum() in (269, 270)  # 3 s of fixed time at 90 Hz, nothing dropped


def test_hitch_in_the_player_runs_3_steps_and_drops_the_rest():
    source = FrameTimeList([1 / 60] * 5 + [1.0] + [1 / 60] * 5, cycle=False)
    player = make_player(source=source)
    cloth = TeamTimeSystem(["normal"], SimulationTimeSettings())
    player.schedule.add(Phase.LATE_UPDATE, System("cloth", cloth.run))
    player.run(11)
    # by hand: 7 steps in 5/60 s; the hitch plans 30.5 -> 30, runs 3, and the half step left
    # over makes the 60 fps rhythm continue as 2, 1, 2, ...
    assert [int(s[0]) for s in cloth.steps] == [1, 2, 1, 2, 1, 3, 2, 1, 2, 1, 2]
    # Unity clamps the 1 s frame to maximumDeltaTime 1/3 s: 30 planned, 27 dropped
    assert [int(s[0]) for s in cloth.skips] == [0] * 5 + [27] + [0] * 5
    assert cloth.state.time[0] == pytest.approx(5 / 60 + 3 / 90 + 5 / 60, abs=1e-9)


def test_unscaled_team_ignores_unity_time_scale_in_the_player():
    player = make_player(fps=30, time_manager=TimeManager(time_scale=0.0))
    cloth = TeamTimeSystem(["normal", "unscaled"], SimulationTimeSettings())
    player.schedule.add(Phase.LATE_UPDATE, System("cloth", cloth.run))
    player.run(10)
    assert np.array(cloth.steps).sum(axis=0).tolist() == [0, 30]


# ----------------------------------------------------------------------------- with the real Animation
def test_real_animation_spin_and_time_scale_event_through_the_player():
    from magica_py.scene.animation import Animation

    h = chain_hierarchy(n=2, length=0.5)  # root at (0,1,0), child 0.5 below
    h.local_position[1] = (0.5, 0.0, 0.0)  # child along +X so that a spin about Y moves it
    h.propagate()
    h.capture_rest_pose()
    anim = Animation.from_specs([
        {"target": "root", "spin": {"axis": [0, 1, 0], "speed": 90.0}},
        {"at": 0.5, "time_scale": 0.5},
    ], h)
    player = make_player(fps=10, scene=SimpleNamespace(hierarchy=h, animation=anim))
    seen = []
    player.schedule.add(Phase.LATE_UPDATE, System(
        "read", lambda ctx: seen.append((ctx.time.time, ctx.time.delta_time, h.world_position[1].copy()))))
    player.run(10)
    # the event fires at t = 0.5 (frame 4); from frame 5 on the game clock runs at half speed
    assert [round(d, 12) for _, d, _ in seen] == [0.1] * 5 + [0.05] * 5
    for t, _, child in seen:
        a = math.radians(90.0 * t)  # Unity: +Y spin turns +X towards -Z
        np.testing.assert_allclose(child, (0.5 * math.cos(a), 1.0, -0.5 * math.sin(a)), atol=1e-9)


def test_system_errors_name_the_system_phase_and_frame():
    player = make_player()

    def broken(ctx):
        if ctx.frame == 2:
            raise RuntimeError("boom")

    player.schedule.add(Phase.LATE_UPDATE, System("cloth", broken))
    with pytest.raises(RuntimeError, match="boom") as info:
        player.run(5)
    assert "in system 'cloth' (LATE_UPDATE) at frame 2" in info.value.__notes__


def test_profile_systems_records_per_system_wall_time_and_reset_restarts_time():
    player = make_player(fps=30)
    player.profile_systems = True
    player.run(3)
    metrics = player.last_context.metrics
    assert {"time.system.restore_bones", "time.system.animation",
            "time.system.reset_frame_counters"} <= set(metrics)
    assert metrics["time.system.animation"] <= metrics["time.update"]
    player.reset()
    ctx = player.step()
    assert ctx.frame == 0 and ctx.time.frame_count == 1 and ctx.time.time == pytest.approx(1 / 30)
    assert player.metric_totals["time.update"] == ctx.metrics["time.update"]


def test_systems_added_or_removed_between_frames_run_from_the_next_frame():
    log = []
    player = make_player()
    player.schedule.add(Phase.LATE_UPDATE, System("first", tracer(log, "first")))
    player.step()
    player.schedule.add(Phase.LATE_UPDATE, System("second", tracer(log, "second")), before="first")
    player.step()
    player.schedule.remove("first")
    player.step()
    assert log == [(0, "first"), (1, "second"), (1, "first"), (2, "second")]
