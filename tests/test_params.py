"""Parameter table, depth curves and presets (docs/solver.md §0.3, §F)."""
import math

import numpy as np
import pytest

from magica_py.params import (
    PARAMETERS,
    PRESETS,
    Curve,
    ParameterError,
    evaluate_curve,
    evaluate_curve_clamp01,
    resolve_parameters,
)


def test_flat_curve_table_is_the_value_everywhere():
    assert np.array_equal(Curve.flat(0.05).samples, np.full(16, 0.05))


def test_linear_curve_table_matches_hand_values():
    # CurveSerializeData(0.2, 1, 0.2): S[i] = 0.2 * (1 - 0.8 * i / 15)
    expected = [0.2 * (1.0 - 0.8 * i / 15.0) for i in range(16)]
    np.testing.assert_allclose(Curve.linear(0.2, 1.0, 0.2).samples, expected, rtol=0, atol=1e-15)


def test_hermite_curve_follows_unity_formula_at_midpoint():
    # keys (0, 1, out -1.5033) and (1, 0.09733, in -0.17397), s = 0.5:
    # v = 0.5*v0 + 0.125*m0 - 0.125*m1 + 0.5*v1
    c = Curve.hermite(1.0, (1.0, -1.5033), (0.09733, -0.17397))
    expected = 0.5 * 1.0 + 0.125 * -1.5033 - 0.125 * -0.17397 + 0.5 * 0.09733
    assert c.shape(0.5) == pytest.approx(expected, abs=1e-12)
    assert c.samples[0] == 1.0 and c.samples[15] == pytest.approx(0.09733)


def test_evaluate_curve_interpolates_samples_piecewise_linearly():
    table = np.arange(16, dtype=np.float64) ** 2
    # depth 0.5: i = 7, u = (0.5 - 7/15) * 15 = 0.5 → lerp(49, 64, 0.5)
    assert evaluate_curve(table, 0.5) == pytest.approx(56.5)
    assert evaluate_curve(table, 1.0) == 225.0
    assert evaluate_curve(table, 0.0) == 0.0
    assert evaluate_curve_clamp01(table, 0.5) == 1.0


def test_defaults_match_reference_table():
    p = resolve_parameters()
    assert p["gravity"] == 5.0
    assert p["inertia.movement_inertia_smoothing"] == 0.4
    assert p["tether.distance_compression"] == 0.4
    assert p["inertia.particle_speed_limit"] == 4.0
    assert p["inertia.local_movement_speed_limit"] == -1.0  # check slider off
    assert p["angle_restoration.stiffness"].use_curve
    assert not p["distance.stiffness"].use_curve
    np.testing.assert_allclose(p["angle_limit.limit_angle"].samples, [60.0 * i / 15 for i in range(16)], atol=1e-12)
    assert set(p) == set(PARAMETERS)


def test_eleven_presets_resolve_and_differ_from_defaults():
    assert len(PRESETS) == 11
    for name in PRESETS:
        p = resolve_parameters(name)
        assert 0.0 <= p["damping"].value <= 1.0
    assert resolve_parameters("Skirt")["inertia.depth_inertia"] == 0.7
    assert resolve_parameters("ShortHair")["angle_limit.use"] is True
    assert resolve_parameters("hard_spring")["collider_collision.friction"] == 0.2


def test_overrides_nested_and_dotted_are_equivalent():
    a = resolve_parameters("tail", {"inertia": {"world_inertia": 0.25}})
    b = resolve_parameters("tail", {"inertia.world_inertia": 0.25})
    assert a == b and a["inertia.world_inertia"] == 0.25


def test_bare_number_rescales_an_active_curve():
    p = resolve_parameters(None, {"angle_restoration": {"stiffness": 0.4}})
    np.testing.assert_allclose(p["angle_restoration.stiffness"].samples, 2 * resolve_parameters()["angle_restoration.stiffness"].samples)


def test_limits_accept_numbers_and_off():
    p = resolve_parameters(None, {"inertia": {"movement_speed_limit": False, "local_rotation_speed_limit": 90}})
    assert p["inertia.movement_speed_limit"] == -1.0
    assert p["inertia.local_rotation_speed_limit"] == 90.0


@pytest.mark.parametrize(
    "overrides, path, fragment",
    [
        ({"dampin": 0.1}, "cloths[1].parameters.dampin", "did you mean 'damping'"),
        ({"inertia": {"world_inertai": 1}}, "cloths[1].parameters.inertia.world_inertai", "did you mean 'inertia.world_inertia'"),
        ({"gravity": 30}, "cloths[1].parameters.gravity", "out of range [0, 20]"),
        ({"damping": math.nan}, "cloths[1].parameters.damping", "finite"),
        ({"gravity": "strong"}, "cloths[1].parameters.gravity", "expected a number"),
        ({"angle_limit": {"use": "yes"}}, "cloths[1].parameters.angle_limit.use", "true or false"),
        ({"inertia": {"teleport_mode": "jump"}}, "cloths[1].parameters.inertia.teleport_mode", "none, reset, keep"),
        ({"radius": {"value": 0.1, "curv": [1, 0]}}, "cloths[1].parameters.radius", "unknown curve keys"),
    ],
)
def test_bad_parameters_name_the_path_and_the_expectation(overrides, path, fragment):
    with pytest.raises(ParameterError) as info:
        resolve_parameters(None, overrides, "cloths[1].parameters")
    assert info.value.path == path
    assert fragment in str(info.value)


def test_unknown_preset_suggests_the_closest():
    with pytest.raises(ParameterError, match="did you mean 'skirt'"):
        resolve_parameters("skrit")


def test_with_changes_keeps_other_values():
    p = resolve_parameters("cape")
    q = p.with_changes({"gravity": 2.0})
    assert q["gravity"] == 2.0 and p["gravity"] == 7.0
    assert all(q[k] == p[k] for k in p if k != "gravity")
