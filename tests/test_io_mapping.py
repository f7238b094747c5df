"""VRM spring parameters → BoneCloth parameters: the documented rule (magica_py.io.mapping)."""
import numpy as np
import pytest

from magica_py.io.mapping import map_spring_parameters, restoration_fraction
from magica_py.params import resolve_parameters


def _map(**kw):
    args = dict(stiffness=1.0, gravity_power=0.0, gravity_dir=(0, -1, 0), drag_force=0.1, hit_radius=0.02,
                segment_length=0.1)
    args.update(kw)
    return map_spring_parameters(**args)


def _linear_vrm(k, drag, x0=0.0, force=0.0, frames=60):
    """VRM frame recurrence on the deviation x (units of L), constant tangential force."""
    x = prev = x0
    out = []
    for _ in range(frames):
        x, prev = x + (1 - drag) * (x - prev) - k * x + force, x
        out.append(x)
    return np.array(out)


def _linear_magica(m, steps, x0=0.0, gravity_term=0.0):
    """MagicaCloth step recurrence (module docstring) with the mapped values."""
    p = m.parameters
    f = float(restoration_fraction(p["angle_restoration.stiffness"]["value"]))
    d = 0.2 * p["damping"]["value"]
    a = p["angle_restoration.velocity_attenuation"]
    x, u = x0, 0.0
    out = []
    for _ in range(steps):
        u = u * (1 - d) + gravity_term
        y = x + u
        x = (1 - f) * y
        u = u - (1 - a) * f * y
        out.append(x)
    return np.array(out)


def test_restoration_fraction_compounds_three_pivoted_iterations():
    assert restoration_fraction(1.0) == pytest.approx(1 - 0.82 * 0.86 * 0.90)
    assert restoration_fraction(0.0) == 0.0
    assert restoration_fraction(0.5) == pytest.approx(1 - 0.91 * 0.93 * 0.95)


def test_without_stiffness_only_velocity_retention_is_matched():
    m = _map(stiffness=0.0, drag_force=0.1)
    damping = m.parameters["damping"]["value"]
    assert (1 - 0.2 * damping) ** 90 == pytest.approx(0.9 ** 60, rel=1e-3)
    assert m.parameters["angle_restoration.stiffness"]["value"] == 0.0
    assert _map(stiffness=0.0, drag_force=0.4).parameters["damping"]["value"] == 1.0   # needs 1.44: clamped


@pytest.mark.parametrize("stiffness, drag, length", [(1.0, 0.1, 0.1), (2.5, 0.4, 0.076), (1.0, 0.4, 0.3)])
def test_released_segment_moves_alike_in_both_linear_models(stiffness, drag, length):
    m = _map(stiffness=stiffness, drag_force=drag, segment_length=length)
    assert m.mismatch < 0.05
    k = stiffness / 60.0 / length
    vrm = _linear_vrm(k, drag, x0=1.0, frames=60)            # one second at 60 Hz
    mc = _linear_magica(m, 90, x0=1.0)                       # one second at 90 Hz
    t = np.arange(1, 61) / 60.0
    mc_at = np.interp(t, np.arange(1, 91) / 90.0, mc)
    assert np.max(np.abs(mc_at - vrm)) < 0.08               # deviation, in units of the initial one


def test_gravity_gives_the_vrm_sag_angle_in_the_magica_recurrence():
    import math
    length, stiffness, power = 0.2, 1.0, 0.1
    m = _map(stiffness=stiffness, gravity_power=power, drag_force=0.2, segment_length=length)
    g = m.parameters["gravity"]
    assert g < 20.0
    theta = math.atan(power / stiffness)
    steady = _linear_magica(m, 4000, gravity_term=g * math.cos(theta) / 8100.0)[-1]
    assert steady / length == pytest.approx(theta, rel=1e-6)


def test_a_vrm_spring_too_stiff_for_magica_is_clamped_with_a_note():
    m = _map(stiffness=4.0, drag_force=0.4, segment_length=0.05)
    assert m.mismatch > 0.05 and any("differs by" in n for n in m.notes)
    assert m.parameters["angle_restoration.stiffness"]["value"] == 1.0


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
