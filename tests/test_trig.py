"""The solver's polynomial trigonometry (``kernels/trig.py``) against libm on dense grids."""
import math

import numpy as np
from numba import njit

from magica_py.kernels import trig


@njit(cache=False)
def _acos_all(x):
    out = np.empty_like(x)
    for i in range(x.shape[0]):
        out[i] = trig.acos(x[i])
    return out


@njit(cache=False)
def _sincos_all(x):
    s = np.empty_like(x)
    c = np.empty_like(x)
    for i in range(x.shape[0]):
        s[i], c[i] = trig.sincos(x[i])
    return s, c


def test_acos_is_within_two_ulp_of_libm_including_near_plus_minus_one():
    x = np.concatenate([np.linspace(-1.0, 1.0, 400001), 1.0 - np.logspace(-17, -1, 4000),
                        -1.0 + np.logspace(-17, -1, 4000), [-1.0, -0.5, 0.0, 0.5, 1.0]])
    ref = np.arccos(x)
    err = np.abs(_acos_all(x) - ref)
    assert np.all(err <= 2.0 * np.spacing(np.abs(ref)) + 1e-300)
    assert _acos_all(np.array([1.0]))[0] == 0.0
    assert _acos_all(np.array([-1.0]))[0] == math.pi


def test_acos_clamps_arguments_outside_minus_one_one():
    out = _acos_all(np.array([1.0 + 1e-12, -1.0 - 1e-12, 7.0]))
    assert out[0] == 0.0 and out[1] == math.pi and out[2] == 0.0


def test_sin_and_cos_are_within_2e_16_of_libm_up_to_1e4_rad():
    for limit in (math.pi, 100.0, 1e4):
        x = np.linspace(-limit, limit, 400001)
        s, c = _sincos_all(x)
        assert np.max(np.abs(s - np.sin(x))) <= 2.3e-16
        assert np.max(np.abs(c - np.cos(x))) <= 2.3e-16
    s, c = _sincos_all(np.array([0.0, math.pi / 2, math.pi]))
    assert s[0] == 0.0 and c[0] == 1.0 and abs(c[1]) < 1e-16 and abs(s[2]) < 2e-16


def test_non_finite_input_gives_nan_not_a_number_that_looks_valid():
    s, c = _sincos_all(np.array([np.nan, np.inf]))
    assert np.all(np.isnan(s)) and np.all(np.isnan(c))
    assert np.isnan(_acos_all(np.array([np.nan]))[0])
