"""kernels/portable.py: CPU-independent maths, against libm (the oracle for accuracy) and
against hand-written values; the array forms give the same bits as the scalar kernels."""
import math

import numpy as np
import pytest

from magica_py.kernels import portable

EPS = np.finfo(np.float64).eps


def ulps(got, want):
    got = np.asarray(got, dtype=np.float64)
    want = np.asarray(want, dtype=np.float64)
    return np.abs(got - want) / np.spacing(np.maximum(np.abs(want), np.finfo(np.float64).tiny))


def libm(fn, *arrays):
    return np.array([fn(*args) for args in zip(*arrays)])


RNG = np.random.default_rng(20261126)


def test_sin_and_cos_match_libm_within_a_few_ulp_of_one():
    x = np.concatenate([RNG.uniform(-1e4, 1e4, 20000), RNG.uniform(-4.0, 4.0, 20000)])
    assert np.max(np.abs(portable.sin_array(x) - np.array([math.sin(v) for v in x]))) <= 2.3e-16
    assert np.max(np.abs(portable.cos_array(x) - np.array([math.cos(v) for v in x]))) <= 2.3e-16


def test_acos_and_asin_match_libm_within_4_ulp():
    x = np.concatenate([RNG.uniform(-1.0, 1.0, 40000), [-1.0, -0.5, 0.0, 0.5, 1.0]])
    assert np.max(ulps(portable.acos_array(x), libm(math.acos, x))) <= 4.0
    inner = x[np.abs(x) > 1e-300]
    assert np.max(ulps(portable.asin_array(inner), libm(math.asin, inner))) <= 4.0


def test_acos_and_asin_clamp_out_of_range_arguments():
    assert portable.acos(1.0 + 1e-12) == 0.0
    assert portable.acos(-1.0 - 1e-12) == math.pi
    assert portable.asin(2.0) == 0.5 * math.pi
    assert math.isnan(portable.acos(math.nan))


def test_atan2_matches_libm_within_4_ulp_in_every_quadrant():
    y = RNG.normal(size=40000) * RNG.choice([1e-8, 1.0, 1e8], 40000)
    x = RNG.normal(size=40000) * RNG.choice([1e-8, 1.0, 1e8], 40000)
    assert np.max(ulps(portable.atan2_array(y, x), libm(math.atan2, y, x))) <= 4.0


@pytest.mark.parametrize("y, x, expected", [
    (0.0, 1.0, 0.0), (1.0, 0.0, 0.5 * math.pi), (0.0, -1.0, math.pi), (-1.0, 0.0, -0.5 * math.pi),
    (1.0, 1.0, 0.25 * math.pi), (-1.0, -1.0, -0.75 * math.pi), (0.0, 0.0, 0.0),
    (math.inf, math.inf, 0.25 * math.pi), (1.0, math.inf, 0.0), (1.0, -math.inf, math.pi),
])
def test_atan2_special_points(y, x, expected):
    assert portable.atan2(y, x) == pytest.approx(expected, abs=1e-15)


def test_exp_and_log_match_libm_within_2_ulp():
    x = RNG.uniform(-700.0, 700.0, 40000)
    assert np.max(ulps(portable.exp_array(x), libm(math.exp, x))) <= 2.0
    y = np.exp(RNG.uniform(-700.0, 700.0, 40000))
    near_one = RNG.uniform(0.5, 2.0, 40000)
    assert np.max(ulps(portable.log_array(y), libm(math.log, y))) <= 2.0
    assert np.max(np.abs(portable.log_array(near_one) - libm(math.log, near_one))) <= 2.0 * EPS


def test_exp_and_log_edges():
    assert portable.exp(0.0) == 1.0 and portable.log(1.0) == 0.0
    assert portable.exp(1000.0) == math.inf and portable.exp(-1000.0) == 0.0
    assert portable.log(0.0) == -math.inf and math.isnan(portable.log(-1.0))
    assert portable.log(5e-324) == pytest.approx(math.log(5e-324), rel=1e-15)   # subnormal
    assert portable.exp(-740.0) == pytest.approx(math.exp(-740.0), rel=1e-3)    # subnormal result


def test_pow_relative_error_grows_only_with_the_exponent_of_the_result():
    x = RNG.uniform(1e-3, 4.0, 40000)
    y = RNG.uniform(0.0, 3.0, 40000)
    bound = (2.0 + np.abs(y * np.log(x))) * 1.5
    assert np.all(ulps(portable.pow_array(x, y), libm(math.pow, x, y)) <= bound)


def test_pow_is_exact_where_the_result_is():
    for x in (0.3, 1.7, 1e-9):
        assert portable.pow(x, 0.0) == 1.0 and portable.pow(x, 1.0) == x
    assert portable.pow(1.0, 0.37) == 1.0 and portable.pow(0.0, 2.5) == 0.0
    assert portable.pow(-2.0, 3.0) == pytest.approx(-8.0, rel=4 * EPS)
    assert math.isnan(portable.pow(-2.0, 0.5))


def test_array_forms_give_the_scalar_kernels_bits():
    x = RNG.uniform(-3.0, 3.0, 257)
    for array_fn, scalar_fn in ((portable.sin_array, portable.sin), (portable.cos_array, portable.cos),
                                (portable.acos_array, portable.acos), (portable.exp_array, portable.exp)):
        assert array_fn(x).tobytes() == np.array([scalar_fn(v) for v in x]).tobytes()
    grid = x.reshape(-1, 1)[:16] * np.ones((1, 3))
    assert portable.atan2_array(grid, 2.0).shape == (16, 3)


def test_dot_and_norm_sum_left_to_right():
    a = RNG.normal(size=(100, 3))
    b = RNG.normal(size=(100, 3))
    by_hand = (a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1]) + a[:, 2] * b[:, 2]
    assert portable.dot3(a, b).tobytes() == by_hand.tobytes()
    assert portable.norm(a).tobytes() == np.sqrt((a[:, 0] * a[:, 0] + a[:, 1] * a[:, 1]) + a[:, 2] * a[:, 2]).tobytes()
    assert portable.norm([3.0, 4.0, 12.0]) == 13.0
    assert isinstance(portable.norm([1.0, 0.0, 0.0]), float)


def test_inverse4_of_a_trs_matrix_is_its_hand_written_inverse():
    c, s = math.cos(0.3), math.sin(0.3)
    r = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    scale = np.array([2.0, 0.5, 4.0])
    t = np.array([1.0, -2.0, 3.0])
    m = np.eye(4)
    m[:3, :3] = r * scale
    m[:3, 3] = t
    expected = np.eye(4)
    expected[:3, :3] = (r * scale).T / (scale * scale)[:, None]
    expected[:3, 3] = -expected[:3, :3] @ t
    np.testing.assert_allclose(portable.inverse4(m), expected, atol=1e-14)
    assert np.all(np.isnan(portable.inverse4(np.zeros((4, 4)))))


def test_transform_points_and_rotate_vectors_apply_the_matrix():
    m = RNG.normal(size=(4, 4))
    p = RNG.normal(size=(10, 3))
    np.testing.assert_allclose(portable.transform_points(m, p), p @ m[:3, :3].T + m[:3, 3], atol=1e-13)
    stack = RNG.normal(size=(10, 3, 3))
    np.testing.assert_allclose(portable.rotate_vectors(stack, p), np.einsum("nij,nj->ni", stack, p), atol=1e-13)
    np.testing.assert_allclose(portable.inverse3(stack[0]) @ stack[0], np.eye(3), atol=1e-12)
    assert portable.determinant3(stack[0]) == pytest.approx(np.linalg.det(stack[0]), rel=1e-12)
