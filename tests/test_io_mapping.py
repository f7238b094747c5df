"""VRM spring parameters → BoneCloth parameters: the documented rule (magica_py.io.mapping)."""
import pytest

from magica_py.io.mapping import map_spring_parameters
from magica_py.params import resolve_parameters


def _map(**kw):
    args = dict(stiffness=1.0, gravity_power=0.0, gravity_dir=(0, -1, 0), drag_force=0.1, hit_radius=0.02,
                segment_length=0.1)
    args.update(kw)
    return map_spring_parameters(**args)


def test_damping_matches_velocity_retention_per_second():
    m = _map(drag_force=0.1)
    damping = m.parameters["damping"]["value"]
    assert (1 - 0.2 * damping) ** 90 == pytest.approx(0.9 ** 60, rel=1e-6)
    assert damping == pytest.approx((1 - 0.9 ** (2 / 3)) / 0.2, abs=1e-9)


def test_strong_drag_is_clamped_to_full_damping_with_a_note():
    m = _map(drag_force=0.4)
    assert m.parameters["damping"]["value"] == 1.0
    assert any("clamped to 1" in n for n in m.notes)


def test_restoration_matches_the_restoring_acceleration():
    m = _map(stiffness=1.0, segment_length=0.1)
    value = m.parameters["angle_restoration.stiffness"]["value"]
    omega2_vrm = 1.0 / (0.1 / 60.0)                      # stiffness / (L dt_vrm)
    omega2_mc = 3 * 0.2 * 0.8 * value * 90.0 ** 2          # 0.48 value / dt_mc^2
    assert omega2_mc == pytest.approx(omega2_vrm, rel=1e-6)
    assert value == pytest.approx(60 / (0.48 * 8100 * 0.1), rel=1e-6)


def test_gravity_keeps_the_static_sag_angle_even_when_restoration_clamps():
    free = _map(stiffness=1.0, gravity_power=0.2, segment_length=0.2)
    value = free.parameters["angle_restoration.stiffness"]["value"]
    assert value < 1.0
    omega2 = 0.48 * value * 8100
    assert free.parameters["gravity"] == pytest.approx(0.2 / 1.0 * omega2 * 0.2, rel=1e-6) == 12.0
    clamped = _map(stiffness=4.0, gravity_power=0.2, segment_length=0.05)
    assert clamped.parameters["angle_restoration.stiffness"]["value"] == 1.0
    assert clamped.parameters["gravity"] == pytest.approx(0.2 / 4.0 * 0.48 * 8100 * 0.05, rel=1e-6)


def test_gravity_without_stiffness_and_its_clamp():
    assert _map(stiffness=0.0, gravity_power=0.1).parameters["gravity"] == pytest.approx(6.0)
    m = _map(stiffness=0.0, gravity_power=1.0)
    assert m.parameters["gravity"] == 20.0 and any("clamped" in n for n in m.notes)


def test_center_maps_to_an_anchor_and_everything_validates():
    m = _map(center="hips")
    p = resolve_parameters(None, m.parameters, "parameters")
    assert p["inertia.anchor"] == "hips" and p["inertia.anchor_inertia"] == 0.0
    assert p["angle_restoration.stiffness"].use_curve is False
    assert p["rotational_interpolation"] == 1.0 and p["root_rotation"] == 1.0


def test_hit_radius_is_kept_within_magica_range():
    assert _map(hit_radius=0.0).parameters["radius"]["value"] == 0.001
    assert _map(hit_radius=0.3).parameters["radius"]["value"] == 0.3


def _vrm_segment_rest_angle(stiffness, gravity_power, drag, length, fps=60.0, frames=4000):
    """UniVRM's per-frame Verlet spring for one segment with a horizontal rest direction."""
    import numpy as np
    dt = 1.0 / fps
    rest = np.array([1.0, 0.0, 0.0])
    cur = prev = rest * length
    for _ in range(frames):
        nxt = cur + (cur - prev) * (1.0 - drag) + rest * stiffness * dt + np.array([0.0, -1.0, 0.0]) * gravity_power * dt
        nxt = nxt / np.linalg.norm(nxt) * length
        prev, cur = cur, nxt
    return float(np.arctan2(-cur[1], cur[0]))


@pytest.mark.parametrize("stiffness, power, drag, length", [(1.0, 0.2, 0.4, 0.1), (4.0, 1.0, 0.1, 0.3), (2.5, 2.5, 0.7, 0.05)])
def test_vrm_rest_angle_is_atan_of_gravity_over_stiffness(stiffness, power, drag, length):
    """The VRM equilibrium the gravity rule matches does not depend on length, drag or rate."""
    import math
    angle = _vrm_segment_rest_angle(stiffness, power, drag, length)
    assert angle == pytest.approx(math.atan(power / stiffness), abs=1e-6)
    assert _vrm_segment_rest_angle(stiffness, power, drag, length, fps=30.0) == pytest.approx(angle, abs=1e-6)
