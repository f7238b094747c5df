"""Wind (magica_py/wind, docs/solver.md §C / §D.1): the push direction in Unity's left-handed
frame, zone selection, moving wind, influence and depth weight, events, frequency
independence of the phase, and that a wind of zero changes no bit of a run."""
from __future__ import annotations

import math

import numpy as np
import pytest

from magica_py import solver
from magica_py.config.errors import ConfigError
from magica_py.config.load import load_scene_text
from magica_py.runtime.player import Player
from magica_py.wind.force import direction_angles, wind_block, zone_wind

CHAIN = """
scene: {{fps: {fps}, frames: 30, simulation_frequency: {frequency}}}
rigs:
  - name: r
    bones: [{{name: root, position: [0, 2, 0]}}]
    parts:
      - chain: {{name: tail, parent: root, bones: 6, length: 0.5, direction: [0, -1, 0]}}
animation: {animation}
cloths:
  - {{name: tail, root_bones: [tail_0], preset: long_hair, parameters: {parameters}}}
"""


def scene_text(wind: str = "", animation: str = "[]", parameters: str = "{}", fps: int = 60,
               frequency: int = 90) -> str:
    return CHAIN.format(animation=animation, parameters=parameters, fps=fps, frequency=frequency) + wind


def run(text: str, frames: int = 30):
    scene = load_scene_text(text)
    player = Player.for_scene(scene)
    system = solver.attach(player, scene)
    player.run(frames)
    return system


# ----------------------------------------------------------------------------- the push
def test_zone_wind_without_turbulence_blows_along_the_direction_at_main_speed():
    for direction in ((1.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0), (0.6, 0.0, 0.8)):
        w = zone_wind(5.0, 123.4, direction_angles(direction), 0.0, 1.0, 0.7, 8.38)
        assert w == pytest.approx(tuple(5.0 * c for c in direction), abs=1e-12)


def test_turbulence_tilts_a_forward_wind_down_then_right_as_unity_euler_does():
    """Blend 0 (pure sine) at a phase where sin = 1: wave = 1, so the direction is +Z turned
    45 degrees about +X (Unity, left-handed: the forward axis pitches down) and then 4.5
    degrees about +Y (towards +X); the speed gusts to main (1 - saturate(1 - main/7.5))."""
    wind_pos = 0.3
    time = (math.pi / 2 - wind_pos) / 10.0
    main = 3.0
    w = zone_wind(main, time, direction_angles((0.0, 0.0, 1.0)), 1.0, 1.0, 0.0, wind_pos)
    a, b = math.radians(45.0), math.radians(4.5)
    d = (math.sin(b) * math.cos(a), -math.sin(a), math.cos(b) * math.cos(a))
    speed = main * (1.0 - (1.0 - main / 7.5))
    assert w == pytest.approx(tuple(speed * c for c in d), abs=1e-9)


def test_direction_angles_follow_unity_euler_on_the_forward_axis():
    scene = load_scene_text(scene_text("""
wind:
  - {name: a, direction_angles: [0, 90]}
  - {name: b, direction_angles: [-90, 0]}
  - {name: c, mode: box_direction, size: [1, 2, 3], euler: [0, 90, 0]}
"""))
    assert scene.wind[0].direction == pytest.approx((1.0, 0.0, 0.0), abs=1e-12)   # yaw +90: +Z -> +X
    assert scene.wind[1].direction == pytest.approx((0.0, 1.0, 0.0), abs=1e-12)   # pitch -90: +Z -> up
    assert scene.wind[2].mode == "box"


def test_a_steady_wind_pushes_the_chain_downwind_in_world_space():
    system = run(scene_text("""
wind:
  - {name: breeze, main: 5, turbulence: 0, direction: [1, 0, 0]}
""", parameters="{wind: {influence: 1.0}}"), frames=40)
    tip = system.positions("tail")[-1]
    assert tip[0] > 0.05 and abs(tip[2]) < 1e-9
    assert system.teams.wind_felt[0] == pytest.approx((5.0, 0.0, 0.0), abs=1e-9)


# ----------------------------------------------------------------------------- selection
SELECTION = """
wind:
  - {name: everywhere, mode: global, main: 2}
  - {name: big, mode: sphere, radius: 5, main: 3}
  - {name: small, mode: sphere, radius: 3, position: [0, 2, 0], main: 4}
  - {name: far_box, mode: box, size: [1, 1, 1], position: [0, 10, 0], main: 5}
  - {name: extra, mode: sphere, radius: 1, position: [0, 2, 0], main: 1, addition: true}
  - {name: unplugged, mode: global, main: 6, addition: true, enabled: false}
  - {name: weak, mode: global, main: 0.005, addition: true}
  - {name: blast, mode: radial, radius: 2, position: [1, 2, 0], main: 4, addition: true}
  - {name: gust, mode: global, main: 1.5, addition: true}
  - {name: fourth, mode: global, main: 1.5, addition: true}
"""


def _selected(system):
    system.select_wind()
    ts = system.teams
    n = int(ts.wind_zone_count[0])
    direction = ts.wind_zone_direction[0].reshape(-1, 3)   # x, y, z rows of slot 0, then slot 1, ...
    return {system.wind.names[ts.wind_zone_id[0, s]]: (ts.wind_zone_main[0, s], direction[s],
                                                      ts.wind_zone_time[0, s]) for s in range(n)}


def _system(text):
    scene = load_scene_text(text)
    player = Player.for_scene(scene)
    return solver.attach(player, scene)


def test_smallest_containing_area_zone_wins_additive_zones_add_weak_and_disabled_are_skipped():
    system = _system(scene_text(SELECTION))
    chosen = _selected(system)
    # area: small (volume 113) beats big (524) and the global zone; the box does not contain the
    # center; additive: extra, blast, gust (three at most: fourth is left out); unplugged and weak skipped
    assert set(chosen) == {"small", "extra", "blast", "gust"}
    main, direction, time = chosen["blast"]
    # radial: from its centre (1, 2, 0) to the team center (0, 2, 0), at half the radius the
    # default ease-in-out attenuation is 0.5
    assert main == pytest.approx(2.0, abs=1e-12)
    assert direction == pytest.approx((-1.0, 0.0, 0.0), abs=1e-12)
    assert time == -10000.0


def test_a_zone_keeps_its_phase_while_it_is_felt_and_restarts_after_a_gap():
    system = _system(scene_text(SELECTION))
    _selected(system)
    system.write_team(0, "wind_zone_time", [7.0] * 4)
    assert all(v[2] == 7.0 for v in _selected(system).values())
    system.wind.set_zone("small", enabled=False)
    chosen = _selected(system)
    assert "small" not in chosen and "big" in chosen and chosen["big"][2] == -10000.0
    system.wind.set_zone("small", enabled=True)
    assert _selected(system)["small"][2] == -10000.0


def test_no_influence_means_no_zone():
    system = _system(scene_text(SELECTION, parameters="{wind: {influence: 0}}"))
    assert _selected(system) == {}


# ----------------------------------------------------------------------------- scaling
def test_influence_friction_and_depth_weight_scale_the_push_per_particle():
    system = _system(scene_text("""
wind:
  - {name: breeze, main: 5, turbulence: 0, direction: [1, 0, 0]}
""", parameters="{wind: {influence: 0.5, depth_weight: 1.0}}"))
    system.select_wind()
    n = len(system.model.depth)
    friction = np.zeros(n)
    friction[3] = 0.25
    system.write_particles(0, "velocity", np.zeros((n, 3)))
    system.write_particles(0, "next_pos", np.zeros((n, 3)))
    system.write_particles(0, "friction", friction)
    system.write_team(0, "scale_ratio", 1.0)
    dt = 1.0 / 90.0
    T = system.tables
    b, _lane = system.layout.place(0)
    wind_block(T.PS, T.PM, T.TS, T.TI, T.P, T.BI, T.topology, b, dt, system._wind_zones())
    p = system.particles
    depth = system.model.depth
    moving = (system.model.attribute & 0x02) != 0
    expected = np.where(moving, 5.0 * 0.5 * (1.0 - friction) * depth * depth * dt, 0.0)
    np.testing.assert_allclose(p.velocity[:, 0], expected, rtol=1e-14, atol=0)
    np.testing.assert_allclose(p.next_pos[:, 0], expected * dt, rtol=1e-14, atol=0)
    # y and z: the direction (1, 0, 0) rebuilt from its Euler angles (cos 90 degrees ~ 6e-17)
    assert np.abs(p.velocity[:, 1:]).max() < 1e-15 and np.abs(p.next_pos[:, 1:]).max() < 1e-15
    assert system.teams.wind_zone_time[0, 0] == pytest.approx(-10000.0 + (0.2 + 0.5 * 5.0 / 7.5) * dt, abs=1e-9)


# ----------------------------------------------------------------------------- moving wind
def test_moving_wind_blows_against_the_cloths_own_movement():
    walk = "[{target: root, keyframes: {keys: [{time: 0, position: [0, 2, 0]}, {time: 2, position: [0, 2, 2]}]}}]"
    system = run(scene_text(animation=walk, parameters="{wind: {moving_wind: 2.0, turbulence: 0}}"), frames=30)
    ts = system.teams
    # the felt movement: the smoothed component speed (1 m/s after the smoothing's ramp)
    assert ts.frame_moving_speed[0] == pytest.approx(1.0, rel=0.05)
    assert ts.wind_zone_count[0] == 0
    assert ts.moving_wind_main[0] == pytest.approx(2.0 * ts.frame_moving_speed[0] / ts.scale_ratio[0], rel=1e-12)
    # against the movement (+Z), scaled by the long_hair preset's influence 0.2
    assert ts.wind_felt[0] == pytest.approx((0.0, 0.0, -0.2 * ts.moving_wind_main[0]), abs=1e-12)


# ----------------------------------------------------------------------------- events, time
def test_wind_events_switch_a_zone_and_change_its_speed_at_their_time():
    events = "[{at: 0.2, wind: {zone: breeze, main: 2.5}}, {at: 0.4, wind: {zone: breeze, enabled: false}}]"
    scene = load_scene_text(scene_text("""
wind:
  - {name: breeze, main: 5, turbulence: 0, direction: [1, 0, 0]}
""", animation=events))
    player = Player.for_scene(scene)
    system = solver.attach(player, scene)
    player.run(6)           # t = 0.1
    assert system.teams.wind_zone_main[0, 0] == 5.0
    player.run(7)           # t = 0.216
    assert system.teams.wind_zone_main[0, 0] == 2.5
    player.run(13)          # t = 0.433
    assert system.teams.wind_zone_count[0] == 0 and not system.teams.wind_felt[0].any()


def test_zone_phase_advances_with_time_not_with_the_step_count():
    """After 0.5 s the phase of a zone is -10000 + rate x 0.5 s at 60, 90 and 120 Hz, 30 and
    60 fps (quality mode): the wind's time behaviour does not depend on the frequency or the
    frame rate (as long as no frame needs more than max_steps_per_frame steps: §A.4 drops
    that time, for the wind as for everything else)."""
    wind = "\nwind:\n  - {name: breeze, main: 3, direction: [1, 0, 0]}\n"
    rate = min((0.2 + 0.5 * 3.0 / 7.5) * 1.0, 1.5)
    for fps, frequency in ((60, 60), (60, 90), (30, 90), (60, 120)):
        frames = fps // 2
        system = run(scene_text(wind, parameters="{solver.mode: quality}", fps=fps, frequency=frequency), frames)
        # the first frame selects the zone before its steps: every step of 0.5 s advanced it
        assert system.teams.wind_zone_time[0, 0] == pytest.approx(-10000.0 + rate * 0.5, abs=1e-8)


def test_a_wind_of_zero_changes_no_bit_of_a_run():
    base = run(scene_text(), frames=40)
    calm = run(scene_text("""
wind:
  - {name: calm, main: 0, direction: [1, 0, 0]}
  - {name: calm_box, mode: box, size: [9, 9, 9], main: 0}
"""), frames=40)
    for name in ("position", "velocity", "old_pos", "next_pos", "rotation"):
        assert np.array_equal(getattr(base.particles, name), getattr(calm.particles, name)), name
    assert np.array_equal(base.hierarchy.world_rotation, calm.hierarchy.world_rotation)


# ----------------------------------------------------------------------------- validation
@pytest.mark.parametrize("entry, message", [
    ("{name: a, mode: global, radius: 3}", "'radius' is not used by a global zone"),
    ("{name: a, mode: radial, direction: [1, 0, 0]}", "'direction' is not used by a radial zone"),
    ("{name: a, mode: sphere, size: [1, 1, 1]}", "'size' is not used by a sphere zone"),
    ("{name: a, main: 40}", "expected a number in [0, 30]"),
    ("{name: a, mode: cone}", "unknown value 'cone'"),
    ("{name: a, direction: [1, 0, 0], direction_angles: [0, 0]}", "give only one of direction, direction_angles"),
    ("{name: a, transform: nope}", "unknown transform 'nope'"),
    ("{name: a, mode: radial, attenuation: {value: 1, curve: 3}}", "expected [start, end]"),
])
def test_bad_wind_entries_are_reported_with_their_path(entry, message):
    with pytest.raises(ConfigError) as err:
        load_scene_text(scene_text(f"wind:\n  - {entry}\n"))
    text = str(err.value)
    assert "wind[0]" in text and message in text


def test_a_wind_event_must_name_a_zone_and_change_something():
    with pytest.raises(ConfigError) as err:
        load_scene_text(scene_text("wind:\n  - {name: breeze}\n",
                                   animation="[{at: 1, wind: {zone: breze, main: 2}}, {at: 2, wind: {zone: breeze}}]"))
    text = str(err.value)
    assert "unknown wind zone 'breze'" in text and "did you mean" in text
    assert "expected 'enabled' and/or 'main'" in text


# ----------------------------------------------------------------------------- recording
def test_the_recording_draws_the_zones_and_plots_the_wind_each_cloth_feels(tmp_path):
    from magica_py.sinks import SinkOptions, attach
    from magica_py.sinks.readback import Recording

    scene = load_scene_text(scene_text("""
wind:
  - {name: breeze, main: 5, turbulence: 0, direction: [1, 0, 0]}
  - {name: puff, mode: box, size: [2, 2, 2], position: [0, 1, 0], main: 2, direction: [0, 0, 1], addition: true}
"""))
    player = Player.for_scene(scene)
    system = solver.attach(player, scene)
    path = tmp_path / "wind.rrd"
    recorder = attach(player, scene, SinkOptions(rrd=path, batch_frames=4))
    player.run(6)
    recorder.close()
    rec = Recording(path)
    assert {"/world/wind/breeze", "/world/wind/puff", "/world/wind/breeze/arrows"} <= set(rec.entities)
    _, vectors = rec.stacked("/world/wind/breeze/arrows", "Arrows3D:vectors")
    # 0.1 m per m/s along the zone's +X, in its frame as drawn (x mirrored for the viewer: the
    # reader restores world-space geometry only)
    assert vectors[-1, 0] == pytest.approx((-0.5, 0.0, 0.0), abs=1e-6)
    frames, felt = rec.scalars("/metrics/wind/tail/felt_m_per_s2")
    expected = float(np.linalg.norm(system.teams.wind_felt[0]))
    assert len(frames) == 6 and felt[-1] == pytest.approx(expected, rel=1e-6) and expected > 0.9


def test_a_free_strand_in_a_steady_wind_hangs_along_wind_plus_gravity():
    """MagicaCloth2's wind is an acceleration main x influence beside gravity: with restoration
    and the angle limit off, a strand settles along (a, -g), at atan(a / g) from the vertical
    (long_hair: g = 5, influence 0.2, 5 m/s: 11.3 degrees)."""
    system = run(scene_text("""
wind:
  - {name: steady, main: 5, turbulence: 0, direction: [1, 0, 0]}
""", parameters="{angle_restoration.use: false, angle_limit.use: false}"), frames=300)
    tip = system.positions("tail")[-1]
    angle = math.degrees(math.atan2(tip[0], 2.0 - tip[1]))
    assert angle == pytest.approx(math.degrees(math.atan2(5.0 * 0.2, 5.0)), abs=0.3)
    assert abs(tip[2]) < 1e-9
