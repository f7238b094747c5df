"""Animation drivers against closed-form values, composition order, windows, events, teleport."""
import math
from types import SimpleNamespace

import numpy as np
import pytest

from magica_py.kernels.math3d import q_axis_angle, q_from_euler_degrees, q_mul, q_rotate
from magica_py.scene.animation import Animation, instance_phase_offset
from magica_py.scene.hierarchy import BoneSpec, TransformHierarchy


def rig(root_position=(0.0, 0.0, 0.0), root_rotation=(0.0, 0.0, 0.0, 1.0),
        root_scale=(1.0, 1.0, 1.0)):
    return TransformHierarchy([BoneSpec("root", None, root_position, root_rotation, root_scale),
                               BoneSpec("hips", "root", (0.0, 1.0, 0.0)),
                               BoneSpec("head", "hips", (0.0, 0.6, 0.0))])


def ctx_at(t):
    return SimpleNamespace(time=SimpleNamespace(time=t, delta_time=1 / 60), events=[])


def pose_at(entries, t, h=None):
    """``h`` (default: a new ``rig()``) posed by ``entries`` at time t. The drivers are compiled
    with the driver kinds of ``MAGICA_STAGES`` (every kind in the suite: tests/conftest.py)."""
    h = h or rig()
    anim = Animation.from_specs(entries, h)
    anim.apply(h, ctx_at(t))
    h.propagate()
    return h


def local(h, name):
    i = h.index(name)
    return h.local_position[i].copy(), h.local_rotation[i].copy()


def assert_same_rotation(q, expected, atol=1e-9):
    q, e = np.asarray(q), np.asarray(expected)
    assert min(np.abs(q - e).max(), np.abs(q + e).max()) < atol, (q, e)


def euler(x, y, z):
    return np.asarray(q_from_euler_degrees(x, y, z))


# ----------------------------------------------------------------------------- orbit
def test_orbit_starts_on_plus_x_and_reaches_minus_z_at_a_quarter_period():
    spec = [{"target": "root", "orbit": {"center": [0, 1, 0], "radius": 0.5, "period": 2.0}}]
    np.testing.assert_allclose(local(pose_at(spec, 0.0), "root")[0], (0.5, 1, 0), atol=1e-12)
    # positive rotation about +Y (Unity: clockwise from above) takes +X to -Z
    np.testing.assert_allclose(local(pose_at(spec, 0.5), "root")[0], (0, 1, -0.5), atol=1e-12)
    np.testing.assert_allclose(local(pose_at(spec, 1.0), "root")[0], (-0.5, 1, 0), atol=1e-12)
    # same sense as a positive spin about the axis
    np.testing.assert_allclose(q_rotate(q_axis_angle((0, 1, 0), math.pi / 2), (0.5, 0, 0)),
                               (0, 0, -0.5), atol=1e-12)


def test_orbit_phase_and_face_path():
    spec = [{"target": "root", "orbit": {"radius": 1.0, "period": 4.0, "phase": 90,
                                         "face_path": True}}]
    h = pose_at(spec, 0.0)
    p, q = local(h, "root")
    np.testing.assert_allclose(p, (0, 0, -1), atol=1e-12)
    # velocity at angle 90 deg: axis x radial = Y x (-Z) = -X; +Z faces it, +Y stays up
    np.testing.assert_allclose(q_rotate(tuple(q), (0, 0, 1)), (-1, 0, 0), atol=1e-12)
    np.testing.assert_allclose(q_rotate(tuple(q), (0, 1, 0)), (0, 1, 0), atol=1e-12)
    # a negative period runs backwards and still faces along the motion
    spec[0]["orbit"]["period"] = -4.0
    h = pose_at(spec, 1.0)
    p, q = local(h, "root")
    np.testing.assert_allclose(p, (1, 0, 0), atol=1e-12)
    np.testing.assert_allclose(q_rotate(tuple(q), (0, 0, 1)), (0, 0, 1), atol=1e-12)


# ----------------------------------------------------------------------------- keyframes
KEYS = [{"time": 0, "position": [0, 0, 0], "euler": [0, 0, 0]},
        {"time": 2, "position": [0, 0, 2], "euler": [0, 90, 0]}]


def test_keyframes_lerp_and_slerp_midpoints():
    h = pose_at([{"target": "root", "keyframes": {"keys": KEYS}}], 1.0)
    p, q = local(h, "root")
    np.testing.assert_allclose(p, (0, 0, 1), atol=1e-12)
    assert_same_rotation(q, euler(0, 45, 0))
    h = pose_at([{"target": "root", "keyframes": {"keys": KEYS}}], 0.5)
    assert_same_rotation(local(h, "root")[1], euler(0, 22.5, 0))


def test_keyframes_clamp_and_loop():
    p_clamped = local(pose_at([{"target": "root", "keyframes": {"keys": KEYS}}], 5.0), "root")[0]
    np.testing.assert_allclose(p_clamped, (0, 0, 2), atol=1e-12)
    looped = [{"target": "root", "keyframes": {"keys": KEYS, "loop": True}}]
    np.testing.assert_allclose(local(pose_at(looped, 2.5), "root")[0], (0, 0, 0.5), atol=1e-12)
    np.testing.assert_allclose(local(pose_at(looped, 4.0), "root")[0], (0, 0, 0), atol=1e-12)


def test_step_interpolation_holds_the_previous_key():
    spec = [{"target": "root", "keyframes": {"interpolation": "step", "keys": KEYS}}]
    p, q = local(pose_at(spec, 1.99), "root")
    np.testing.assert_allclose(p, (0, 0, 0), atol=1e-12)
    assert_same_rotation(q, (0, 0, 0, 1))
    np.testing.assert_allclose(local(pose_at(spec, 2.0), "root")[0], (0, 0, 2), atol=1e-12)


def test_smooth_interpolation_eases_the_segment():
    spec = [{"target": "root", "keyframes": {"interpolation": "smooth", "keys": KEYS}}]
    # smoothstep(0.25) = 0.15625
    np.testing.assert_allclose(local(pose_at(spec, 0.5), "root")[0], (0, 0, 0.3125), atol=1e-12)


def test_cubic_interpolation_passes_through_keys_with_catmull_rom_tangents():
    keys = [{"time": 0, "position": [0, 0, 0]}, {"time": 1, "position": [0, 1, 0]},
            {"time": 2, "position": [0, 0, 0]}]
    spec = [{"target": "root", "keyframes": {"interpolation": "cubic", "keys": keys}}]
    # segment 0: m0 = 1 (one-sided), m1 = (0 - 0) / 2 = 0; Hermite at f = 0.5 -> 0.625
    np.testing.assert_allclose(local(pose_at(spec, 0.5), "root")[0], (0, 0.625, 0), atol=1e-12)
    np.testing.assert_allclose(local(pose_at(spec, 1.0), "root")[0], (0, 1, 0), atol=1e-12)
    # evenly spaced collinear keys stay on the line at constant speed
    line = [{"time": 0, "position": [0, 0, 0]}, {"time": 1, "position": [1, 0, 0]},
            {"time": 3, "position": [3, 0, 0]}]
    spec = [{"target": "root", "keyframes": {"interpolation": "cubic", "keys": line}}]
    np.testing.assert_allclose(local(pose_at(spec, 1.7), "root")[0], (1.7, 0, 0), atol=1e-12)


def test_each_channel_uses_only_the_keys_that_have_it():
    keys = [{"time": 0, "position": [0, 0, 0], "scale": [1, 1, 1]},
            {"time": 1, "euler": [0, 0, 90]},
            {"time": 2, "position": [2, 0, 0], "scale": [3, 1, 1]}]
    h = pose_at([{"target": "hips", "keyframes": {"keys": keys}}], 1.0)
    p, q = local(h, "hips")
    np.testing.assert_allclose(p, (1, 0, 0), atol=1e-12)
    np.testing.assert_allclose(h.local_scale[h.index("hips")], (2, 1, 1), atol=1e-12)
    assert_same_rotation(q, euler(0, 0, 90))  # a single rotation key is held


def test_keyframe_times_are_relative_to_start():
    spec = [{"target": "root", "start": 3.0, "keyframes": {"keys": KEYS}}]
    np.testing.assert_allclose(local(pose_at(spec, 1.0), "root")[0], (0, 0, 0), atol=1e-12)
    np.testing.assert_allclose(local(pose_at(spec, 4.0), "root")[0], (0, 0, 1), atol=1e-12)


# ----------------------------------------------------------------------------- oscillate
def test_position_oscillation_peaks_at_a_quarter_period_inside_its_window():
    spec = [{"target": "hips", "start": 1.0, "end": 4.0,
             "oscillate": {"property": "position", "axis": [0, 2, 0], "amplitude": 0.03,
                           "frequency": 2.0, "phase": 0}}]
    np.testing.assert_allclose(local(pose_at(spec, 1.125), "hips")[0], (0, 1.03, 0), atol=1e-12)
    np.testing.assert_allclose(local(pose_at(spec, 1.375), "hips")[0], (0, 0.97, 0), atol=1e-12)
    # outside the window the periodic offset is gone
    np.testing.assert_allclose(local(pose_at(spec, 0.625), "hips")[0], (0, 1, 0), atol=1e-12)
    np.testing.assert_allclose(local(pose_at(spec, 4.125), "hips")[0], (0, 1, 0), atol=1e-12)


def test_rotation_oscillation_composes_about_local_axes_with_phase_in_degrees():
    h = rig()
    h.rest_local_rotation[h.index("hips")] = euler(0, 90, 0)
    spec = [{"target": "hips", "oscillate": {"property": "rotation", "axis": [1, 0, 0],
                                             "amplitude": 10, "frequency": 1, "phase": 90}}]
    q = local(pose_at(spec, 0.0, h), "hips")[1]
    expected = q_mul(tuple(euler(0, 90, 0)), q_axis_angle((1, 0, 0), math.radians(10)))
    assert_same_rotation(q, expected)


def test_fade_ramps_the_amplitude_in():
    spec = [{"target": "hips", "start": 0.0, "end": 10.0, "fade": 1.0,
             "oscillate": {"axis": [0, 1, 0], "amplitude": 0.1, "frequency": 1, "phase": 90}}]
    # t = 0.5: weight 0.5, sin(2 pi 0.5 + pi/2) = -1
    np.testing.assert_allclose(local(pose_at(spec, 0.5), "hips")[0], (0, 0.95, 0), atol=1e-12)


# ----------------------------------------------------------------------------- spin and walk
def test_spin_turns_at_constant_speed_and_holds_after_its_window():
    spec = [{"target": "root", "end": 1.0, "spin": {"axis": [0, 1, 0], "speed": 90}}]
    assert_same_rotation(local(pose_at(spec, 0.5), "root")[1], euler(0, 45, 0))
    assert_same_rotation(local(pose_at(spec, 3.0), "root")[1], euler(0, 90, 0))


def test_walk_bob_sway_and_forward_travel_closed_form():
    f, bob, sway, speed, t = 1.8, 0.03, 4.0, 1.2, 0.37
    spec = [{"target": "hips", "walk": {"speed": speed, "stride_frequency": f, "bob": bob,
                                        "sway": sway, "lateral": 0.02}}]
    p, q = local(pose_at(spec, t), "hips")
    phase = 2 * math.pi * f * t
    expected = (0.02 * math.sin(phase), 1 + bob * math.sin(2 * phase), speed * t)
    np.testing.assert_allclose(p, expected, atol=1e-12)
    assert_same_rotation(q, q_axis_angle((0, 0, 1), math.radians(sway * math.sin(phase))))


def test_walk_that_ends_stays_where_it_stopped_without_bob():
    spec = [{"target": "hips", "end": 2.0, "walk": {"speed": 1.0, "bob": 0.05}}]
    np.testing.assert_allclose(local(pose_at(spec, 5.0), "hips")[0], (0, 1, 2), atol=1e-12)


# ----------------------------------------------------------------------------- composition
def test_drivers_on_one_target_compose_in_list_order():
    orbit = {"target": "root", "orbit": {"radius": 1.0, "period": 4.0}}
    bob = {"target": "root", "oscillate": {"axis": [0, 1, 0], "amplitude": 0.5,
                                           "frequency": 0.25}}
    keys = {"target": "root", "keyframes": {"keys": [{"time": 0, "position": [7, 7, 7]}]}}
    # orbit then additive bob: (0, 0.5, -1) at t = 1
    np.testing.assert_allclose(local(pose_at([orbit, bob], 1.0), "root")[0], (0, 0.5, -1),
                               atol=1e-12)
    # an absolute driver later in the list overwrites the position
    np.testing.assert_allclose(local(pose_at([orbit, bob, keys], 1.0), "root")[0], (7, 7, 7))
    # additive rotations stack on the rest rotation, about local axes
    h = rig(root_rotation=tuple(euler(90, 0, 0)))
    spin = {"target": "root", "spin": {"axis": [0, 1, 0], "speed": 30}}
    q = local(pose_at([spin, spin], 1.0, h), "root")[1]
    assert_same_rotation(q, q_mul(tuple(euler(90, 0, 0)), q_axis_angle((0, 1, 0), math.radians(60))))


def test_driven_nodes_restart_from_rest_every_frame():
    h = rig()
    anim = Animation.from_specs([{"target": "hips", "oscillate": {"axis": [1, 0, 0],
                                  "amplitude": 1.0, "frequency": 0.25}}], h)
    for _ in range(3):
        anim.apply(h, ctx_at(1.0))  # additive drivers do not accumulate across frames
    np.testing.assert_allclose(local(h, "hips")[0], (1, 1, 0), atol=1e-12)
    assert anim.driven.tolist() == [h.index("hips")]


def test_phase_offset_shifts_the_driver_clock():
    base = {"target": "root", "orbit": {"radius": 1.0, "period": 4.0}}
    shifted = dict(base, phase_offset=0.75)
    np.testing.assert_allclose(local(pose_at([shifted], 0.25), "root")[0],
                               local(pose_at([base], 1.0), "root")[0], atol=1e-12)
    assert instance_phase_offset(3, 0.25) == 0.75
    a = instance_phase_offset(5, 0.0, jitter=1.0, seed=7)
    assert 0.0 <= a < 1.0 and a == instance_phase_offset(5, 0.0, jitter=1.0, seed=7)
    assert a != instance_phase_offset(6, 0.0, jitter=1.0, seed=7)


def test_config_normalised_entries_are_accepted():
    h = rig()
    entries = [{"kind": "orbit", "path": ("animation", 0), "target": "root", "start": 0.0,
                "end": None, "phase_offset": 0.0,
                "params": {"center": (0, 0, 0), "radius": 2.0, "period": 1.0,
                           "axis": (0, 1, 0), "phase": 0.0, "face_path": False}},
               {"kind": "time_scale", "path": ("animation", 1), "at": 0.0,
                "params": {"value": 0.5}}]
    anim = Animation.from_specs(entries, h)
    ctx = ctx_at(0.0)
    anim.apply(h, ctx)
    np.testing.assert_allclose(local(h, "root")[0], (2, 0, 0), atol=1e-12)
    assert ctx.events == [("time_scale", 0.5)]


# ----------------------------------------------------------------------------- events
def test_events_fire_exactly_once_when_time_passes_at():
    h = rig()
    anim = Animation.from_specs([
        {"at": 4.0, "set_parameter": {"cloth": "tail", "key": "damping", "value": 0.2}},
        {"at": 2.0, "time_scale": 0.1},
    ], h)
    fired = []
    for t in (0.0, 1.0, 1.99, 2.0, 2.5, 3.9, 4.2, 9.0):
        ctx = ctx_at(t)
        anim.apply(h, ctx)
        fired.append((t, ctx.events))
    assert [t for t, ev in fired if ev] == [2.0, 4.2]
    assert fired[3][1] == [("time_scale", 0.1)]
    assert fired[6][1] == [("set_parameter", {"cloth": "tail", "key": "damping", "value": 0.2})]
    anim.reset()
    ctx = ctx_at(10.0)
    anim.apply(h, ctx)  # a big step fires every due event, in time order
    assert [k for k, _ in ctx.events] == ["time_scale", "set_parameter"]


def test_teleport_lands_on_the_world_pose_under_a_rotated_scaled_parent():
    h = rig(root_position=(1.0, 2.0, 3.0), root_rotation=tuple(euler(10, 70, -20)),
            root_scale=(2.0, 0.5, 3.0))
    target_q = euler(0, 90, 0)
    anim = Animation.from_specs([
        {"at": 2.0, "teleport": {"target": "hips", "position": [10, 0, 0], "euler": [0, 90, 0]}},
    ], h)
    ctx = ctx_at(2.0)
    anim.apply(h, ctx)
    h.propagate()
    i = h.index("hips")
    np.testing.assert_allclose(h.world_position[i], (10, 0, 0), atol=1e-9)
    assert_same_rotation(h.world_rotation[i], target_q)
    assert ctx.events[0][0] == "teleport" and ctx.events[0][1]["name"] == "hips"
    # the undriven target stays there on later frames (offset on top of the rest pose)
    anim.apply(h, ctx_at(3.0))
    h.propagate()
    np.testing.assert_allclose(h.world_position[i], (10, 0, 0), atol=1e-9)


def test_teleports_of_a_parent_and_its_child_in_one_frame_both_land():
    h = rig(root_scale=(2.0, 2.0, 2.0))
    anim = Animation.from_specs([
        {"at": 1.0, "teleport": {"target": "root", "position": [5, 0, 0], "euler": [0, 90, 0]}},
        {"at": 1.0, "teleport": {"target": "head", "position": [0, 3, 0]}},
        {"at": 1.0, "teleport": {"target": "hips", "position": [1, 1, 1]}},
    ], h)
    ctx = ctx_at(1.0)
    anim.apply(h, ctx)
    h.propagate()
    np.testing.assert_allclose(h.world_position[h.index("root")], (5, 0, 0), atol=1e-9)
    np.testing.assert_allclose(h.world_position[h.index("hips")], (1, 1, 1), atol=1e-9)
    # the head was placed before its parent hips moved, so it moved along with the hips
    assert [e[1]["name"] for e in ctx.events] == ["root", "head", "hips"]
    np.testing.assert_allclose(h.world_position[h.index("head")], (0, 3, 0) + np.array([1, 1, 1])
                               - np.array([5, 2, 0]), atol=1e-9)


def test_motion_continues_relative_to_the_teleported_place():
    h = rig(root_rotation=tuple(euler(0, 90, 0)), root_scale=(2.0, 2.0, 2.0))
    walk_keys = {"target": "hips", "keyframes": {"keys": [
        {"time": 0, "position": [0, 1, 0]}, {"time": 10, "position": [0, 1, 10]}]}}
    anim = Animation.from_specs([walk_keys, {"at": 2.0, "teleport": {"target": "hips",
                                                                       "position": [5, 0, 5]}}], h)
    anim.apply(h, ctx_at(2.0))
    h.propagate()
    i = h.index("hips")
    np.testing.assert_allclose(h.world_position[i], (5, 0, 5), atol=1e-9)
    anim.apply(h, ctx_at(3.0))
    h.propagate()
    # one more metre along local +Z: the parent maps it to 2 m along world +X
    np.testing.assert_allclose(h.world_position[i], (7, 0, 5), atol=1e-9)
    anim.reset()  # offsets cleared and the teleport re-armed: back on the keyframed path
    anim.apply(h, ctx_at(1.0))
    h.propagate()
    np.testing.assert_allclose(h.world_position[i], (2, 2, 0), atol=1e-9)


# ----------------------------------------------------------------------------- errors
@pytest.mark.parametrize("entry, message", [
    ({"target": "nope", "spin": {"speed": 1}}, r"animation\[0\]\.target: no transform named 'nope'"),
    ({"target": "root", "start": 2, "end": 1, "spin": {"speed": 1}}, r"\.end: expected end > start"),
    ({"target": "root", "spin": {"axis": [0, 0, 0], "speed": 1}}, r"spin\.axis: expected a non-zero"),
    ({"target": "root", "keyframes": {"keys": [{"time": 1, "position": [0, 0, 0]},
                                               {"time": 1, "position": [0, 0, 0]}]}}, "must increase"),
    ({"target": "root", "orbit": {"radius": 1}}, r"orbit\.period: required"),
    ({"at": 1, "teleport": {"target": "root"}}, "a position and/or a rotation"),
    # rates and angles whose sine would not be finite (NaN transforms) are refused
    ({"target": "root", "orbit": {"radius": 1, "period": 1e-200}}, r"orbit\.period: expected a period of at least "
                                                                   r"0\.001 s either way, got 1e-200"),
    ({"target": "root", "orbit": {"radius": 1, "period": 1, "phase": 1e300}}, r"orbit\.phase: expected a number in "
                                                                               r"\[-1e\+06, 1e\+06\]"),
    ({"target": "root", "oscillate": {"amplitude": 1, "frequency": 1e300}}, r"oscillate\.frequency: expected a number "
                                                                           r"in \(0, 1000\]"),
    ({"target": "root", "oscillate": {"amplitude": 1e300, "frequency": 1}}, r"oscillate\.amplitude"),
    ({"target": "root", "spin": {"speed": 1e300}}, r"spin\.speed: expected a number in \[-1e\+06, 1e\+06\]"),
    ({"target": "root", "walk": {"stride_frequency": 1e300}}, r"walk\.stride_frequency"),
    ({"target": "root", "walk": {"sway": 1e300}}, r"walk\.sway"),
])
def test_bad_entries_name_the_path(entry, message):
    with pytest.raises(ValueError, match=message):
        Animation.from_specs([entry], rig())


# ----------------------------------------------------------------------------- properties
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

finite = st.floats(-3.0, 3.0, allow_nan=False)
times = st.floats(0.0, 20.0, allow_nan=False)
unit_axis = st.tuples(finite, finite, finite).filter(lambda v: np.linalg.norm(v) > 0.1)

DRIVER_SAMPLES = [
    {"orbit": {"center": [0.1, 0.2, 0.3], "radius": 0.7, "period": 1.3, "axis": [1, 2, 0],
               "face_path": True}},
    {"keyframes": {"loop": True, "keys": KEYS + [{"time": 3, "position": [1, 0, 0],
                                                  "euler": [30, 0, 10]}]}},
    {"oscillate": {"property": "rotation", "axis": [0, 1, 1], "amplitude": 20, "frequency": 0.7}},
    {"oscillate": {"property": "position", "axis": [1, 0, 1], "amplitude": 0.2, "frequency": 1.1}},
    {"spin": {"axis": [1, 1, 0], "speed": -45}},
    {"walk": {"speed": 0.8, "stride_frequency": 1.5, "bob": 0.04, "sway": 5, "twist": 3,
              "lateral": 0.01}},
]


@settings(max_examples=40, deadline=None)
@given(kind=st.integers(0, len(DRIVER_SAMPLES) - 1), t=times, offset=st.floats(0.0, 5.0))
def test_phase_offset_equals_evaluating_later_for_every_driver_kind(kind, t, offset):
    entry = dict(DRIVER_SAMPLES[kind], target="hips")
    p1, q1 = local(pose_at([dict(entry, phase_offset=offset)], t), "hips")
    p2, q2 = local(pose_at([entry], t + offset), "hips")
    np.testing.assert_allclose(p1, p2, atol=1e-9)
    assert_same_rotation(q1, q2, atol=1e-9)
    assert abs(np.linalg.norm(q1) - 1.0) < 1e-12


@settings(max_examples=40, deadline=None)
@given(t=times, axis=unit_axis, radius=st.floats(0.01, 5.0), period=st.floats(0.1, 10.0))
def test_orbit_stays_on_its_circle_and_repeats_every_period(t, axis, radius, period):
    spec = [{"target": "root", "orbit": {"center": [1, 2, 3], "radius": radius,
                                         "period": period, "axis": list(axis)}}]
    p = local(pose_at(spec, t), "root")[0] - (1, 2, 3)
    a = np.asarray(axis) / np.linalg.norm(axis)
    assert np.linalg.norm(p) == pytest.approx(radius, rel=1e-9)
    assert abs(np.dot(p, a)) < 1e-9 * max(1.0, radius)
    np.testing.assert_allclose(local(pose_at(spec, t + period), "root")[0] - (1, 2, 3), p,
                               atol=1e-8 * max(1.0, radius))


@settings(max_examples=30, deadline=None)
@given(parent=st.tuples(finite, finite, finite), parent_euler=st.tuples(finite, finite, finite),
       scale=st.tuples(st.floats(0.2, 3.0), st.floats(0.2, 3.0), st.floats(0.2, 3.0)),
       goal=st.tuples(finite, finite, finite), goal_euler=st.tuples(finite, finite, finite))
def test_teleport_lands_exactly_for_random_parents(parent, parent_euler, scale, goal, goal_euler):
    h = rig(root_position=parent, root_rotation=tuple(euler(*(100 * np.array(parent_euler)))),
            root_scale=scale)
    goal_q = euler(*(100 * np.array(goal_euler)))
    anim = Animation.from_specs([
        {"target": "head", "spin": {"axis": [0, 1, 0], "speed": 40}},
        {"at": 0.5, "teleport": {"target": "head", "position": list(goal), "rotation": list(goal_q)}}], h)
    anim.apply(h, ctx_at(0.6))
    h.propagate()
    i = h.index("head")
    np.testing.assert_allclose(h.world_position[i], goal, atol=1e-9)
    assert_same_rotation(h.world_rotation[i], goal_q, atol=1e-9)


# ----------------------------------------------------------------------------- numpy twin
def _qmul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz])


def _matrix(q):
    x, y, z, w = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _aa(axis, angle):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    return np.append(a * math.sin(angle / 2), math.cos(angle / 2))


def _slerp(a, b, f):
    if np.dot(a, b) < 0:
        b = -b
    omega = math.acos(min(1.0, np.dot(a, b)))
    if omega < 1e-9:
        return a
    return (math.sin((1 - f) * omega) * a + math.sin(f * omega) * b) / math.sin(omega)


def twin_local_pose(entries, h, t):
    """Slow, independent re-statement of the module docstring's rules (one target: hips)."""
    i = h.index("hips")
    pos, rot = h.rest_local_position[i].copy(), h.rest_local_rotation[i].copy()
    for e in entries:
        start, end = e.get("start", 0.0), e.get("end", math.inf)
        tau = min(max(t, start), end) - start + e.get("phase_offset", 0.0)
        inside = start <= t <= end
        if "orbit" in e:
            o = e["orbit"]
            a = np.asarray(o["axis"], float) / np.linalg.norm(o["axis"])
            ref = np.array([1.0, 0, 0]) if abs(a[0]) < 0.99 else np.array([0, 0, 1.0])
            u = ref - a * np.dot(ref, a)
            u /= np.linalg.norm(u)
            ang = 2 * math.pi * tau / o["period"]
            radial = _matrix(_aa(a, ang)) @ u
            pos = np.asarray(o.get("center", (0, 0, 0)), float) + o["radius"] * radial
        elif "keyframes" in e:
            keys = e["keyframes"]["keys"]
            ts = np.array([k["time"] for k in keys])
            s = min(max(tau, ts[0]), ts[-1])
            j = min(np.searchsorted(ts, s, side="right") - 1, len(ts) - 2)
            f = (s - ts[j]) / (ts[j + 1] - ts[j])
            pos = (1 - f) * np.asarray(keys[j]["position"], float) + f * np.asarray(keys[j + 1]["position"], float)
            rot = _slerp(euler(*keys[j]["euler"]), euler(*keys[j + 1]["euler"]), f)
        elif "oscillate" in e and inside:
            o = e["oscillate"]
            v = o["amplitude"] * math.sin(2 * math.pi * o["frequency"] * tau)
            if o["property"] == "rotation":
                rot = _qmul(rot, _aa(o["axis"], math.radians(v)))
            else:
                pos = pos + np.asarray(o["axis"], float) / np.linalg.norm(o["axis"]) * v
        elif "spin" in e:
            rot = _qmul(rot, _aa(e["spin"]["axis"], math.radians(e["spin"]["speed"] * tau)))
    return pos, rot / np.linalg.norm(rot)


TWIN_DRIVERS = [
    {"orbit": {"radius": 0.4, "period": 1.7, "axis": [0.2, 1, 0.1]}},
    {"keyframes": {"keys": [{"time": 0.0, "position": [0, 1, 0], "euler": [0, 0, 0]},
                            {"time": 1.5, "position": [0.5, 1, 1], "euler": [20, 80, 0]},
                            {"time": 4.0, "position": [1, 1.2, 0], "euler": [0, 170, 10]}]}},
    {"oscillate": {"property": "rotation", "axis": [1, 0, 0.3], "amplitude": 12, "frequency": 0.9}},
    {"oscillate": {"property": "position", "axis": [0, 1, 0], "amplitude": 0.05, "frequency": 2}},
    {"spin": {"axis": [0, 1, 0], "speed": 33}},
]


@settings(max_examples=60, deadline=None)
@given(order=st.lists(st.integers(0, len(TWIN_DRIVERS) - 1), min_size=1, max_size=5),
       windows=st.lists(st.tuples(st.floats(0.0, 3.0), st.floats(0.1, 4.0), st.floats(0.0, 2.0)),
                        min_size=5, max_size=5),
       t=st.floats(0.0, 8.0))
def test_kernel_matches_the_numpy_twin_for_random_driver_stacks(order, windows, t):
    """The compiled drivers against the numpy twin above. Every driver kind is compiled in
    (``MAGICA_STAGES=all``, tests/conftest.py: a kind with no driver runs none), so the random
    stacks share one compile instead of one per subset of kinds; the switches are pinned
    further down."""
    entries = []
    for n, k in enumerate(order):
        start, span, offset = windows[n]
        entries.append(dict(TWIN_DRIVERS[k], target="hips", start=start, end=start + span,
                            phase_offset=offset))
    h = rig(root_rotation=tuple(euler(0, 30, 0)))
    h.rest_local_rotation[h.index("hips")] = euler(5, 10, 15)
    p, q = local(pose_at(entries, t, h), "hips")
    tp, tq = twin_local_pose(entries, h, t)
    np.testing.assert_allclose(p, tp, atol=1e-9)
    assert_same_rotation(q, tq, atol=1e-9)


def test_orbits_evaluated_all_at_once_give_the_per_driver_formula_bit_for_bit():
    """``orbit_radials`` evaluates every orbit in one vectorised loop before the drivers run;
    each position must still be, to the bit, the per-driver expression ``center + radius *
    rotate(axis_angle(axis, 2 pi tau / period + phase), u)`` (math3d's own helpers)."""
    rng = np.random.default_rng(4)
    bones = [BoneSpec(f"n{k}", None if k % 3 == 0 else f"n{k - 1}") for k in range(30)]
    h = TransformHierarchy(bones)
    entries = []
    for k in range(0, 30, 2):                 # orbits on every other node, oscillations between
        axis = rng.normal(size=3)
        entries.append({"target": f"n{k}", "start": float(rng.uniform(0, 0.5)),
                        "end": None if k % 4 else float(rng.uniform(1.0, 2.0)),
                        "phase_offset": float(rng.uniform(0, 1)), "orbit": {
                            "center": rng.normal(size=3).tolist(), "radius": float(rng.uniform(0.1, 2)),
                            "period": float(rng.choice([-1.0, 1.0]) * rng.uniform(0.3, 3)),
                            "axis": axis.tolist(), "phase": float(rng.uniform(-180, 180)),
                            "face_path": bool(k % 6 == 0)}})
        entries.append({"target": f"n{k + 1}", "oscillate": {"axis": [0, 1, 0], "amplitude": 0.1,
                                                             "frequency": 1.0}})
    anim = Animation.from_specs(entries, h)
    for t in (0.0, 0.37, 1.5, 2.75):
        anim.apply(h, ctx_at(t))
        for d in np.flatnonzero(anim.kind == 1):
            p = anim.params[d]
            tau = min(max(t, anim.start[d]), anim.end[d]) - anim.start[d] + anim.phase_offset[d]
            turn = q_axis_angle(tuple(p[5:8]), 2.0 * math.pi * tau / p[4] + p[11])
            radial = q_rotate(turn, tuple(p[8:11]))
            expected = [p[c] + p[3] * radial[c] for c in range(3)]
            np.testing.assert_array_equal(h.local_position[anim.target[d]], expected)


def test_drivers_compile_only_the_kinds_a_scene_uses(used_stages):
    """``Animation.kinds_used`` switches each driver kind's code on (1) or off (None, pruned by
    numba before typing): an orbit-only list is compiled without the keyframe, oscillate, spin
    and walk code, and still gives the orbit's closed form."""
    import numba

    from magica_py.scene.animation import apply_drivers

    orbit = {"target": "root", "orbit": {"radius": 1.0, "period": 4.0}}
    spin = {"target": "root", "spin": {"axis": [0, 1, 0], "speed": 30}}
    assert Animation.from_specs([orbit], rig()).kinds_used == (None, 1, None, None, None)
    assert Animation.from_specs([orbit, spin], rig()).kinds_used == (None, 1, None, 1, None)
    assert Animation.from_specs([], rig()).kinds_used == (None,) * 5
    np.testing.assert_allclose(local(pose_at([orbit], 1.0), "root")[0], (0, 0, -1), atol=1e-12)
    if not numba.config.DISABLE_JIT:
        none, one = numba.types.none, numba.typeof(1)
        assert any(tuple(sig[-5:]) == (none, one, none, none, none) for sig in apply_drivers.signatures), \
            apply_drivers.signatures


def test_every_driver_kind_compiled_gives_the_bits_of_the_kinds_a_scene_uses(monkeypatch):
    """``MAGICA_STAGES=all`` switches every driver kind on (one compile of the drivers for every
    scene); a kind with no driver then runs none, so an orbit and a spin stacked on one bone
    give the same bits as when only their two kinds are compiled, at times before, inside and
    after their windows."""
    entries = [dict(TWIN_DRIVERS[0], target="hips", start=0.5, end=3.0),
               dict(TWIN_DRIVERS[4], target="hips", phase_offset=0.25)]
    poses = {}
    for policy in ("used", "all"):
        monkeypatch.setenv("MAGICA_STAGES", policy)
        h = rig()
        anim = Animation.from_specs(entries, h)
        assert anim.kinds_used == ((None, 1, None, 1, None) if policy == "used" else (1,) * 5)
        poses[policy] = []
        for t in (0.0, 0.7, 2.9, 4.2):
            anim.apply(h, ctx_at(t))
            poses[policy].append(local(h, "hips"))
    for (p_used, q_used), (p_all, q_all) in zip(poses["used"], poses["all"]):
        np.testing.assert_array_equal(p_all, p_used)
        np.testing.assert_array_equal(q_all, q_used)
    assert not np.array_equal(poses["all"][1][1], poses["all"][2][1])   # the drivers moved the bone
