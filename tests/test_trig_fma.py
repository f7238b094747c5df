"""The fma / Estrin forms of the solver's trigonometry (``trig.acos_fma``, ``trig.sincos_fma``,
used by the angle restoration) hold the bounds of ``acos`` / ``sincos`` against libm on the
same dense grids, and differ from them by round-off only."""
import math

import numpy as np
from numba import njit

from magica_py.kernels import trig


@njit(cache=False)
def _acos_both(x):
    new = np.empty_like(x)
    old = np.empty_like(x)
    for i in range(x.shape[0]):
        new[i] = trig.acos_fma(x[i])
        old[i] = trig.acos(x[i])
    return new, old


@njit(cache=False)
def _sincos_both(x):
    s = np.empty_like(x)
    c = np.empty_like(x)
    s0 = np.empty_like(x)
    c0 = np.empty_like(x)
    for i in range(x.shape[0]):
        s[i], c[i] = trig.sincos_fma(x[i])
        s0[i], c0[i] = trig.sincos(x[i])
    return s, c, s0, c0


@njit(cache=False)
def _fma(a, b, c):
    return trig.fma(a, b, c)


def test_fma_rounds_once():
    # (1 + 2^-30)^2 - 1 = 2^-29 + 2^-60: the separate product rounds the 2^-60 away
    a = 1.0 + 2.0 ** -30
    assert _fma(a, a, -1.0) == 2.0 ** -29 + 2.0 ** -60
    assert a * a - 1.0 == 2.0 ** -29


def test_acos_fma_is_within_two_ulp_of_libm_and_round_off_of_acos():
    x = np.concatenate([np.linspace(-1.0, 1.0, 400001), 1.0 - np.logspace(-17, -1, 4000),
                        -1.0 + np.logspace(-17, -1, 4000), [-1.0, -0.5, 0.0, 0.5, 1.0]])
    new, old = _acos_both(x)
    ref = np.arccos(x)
    assert np.all(np.abs(new - ref) <= 2.0 * np.spacing(np.abs(ref)) + 1e-300)
    assert np.all(np.abs(new - old) <= 2.0 * np.spacing(np.abs(ref)) + 1e-300)
    assert _acos_both(np.array([1.0]))[0][0] == 0.0 and _acos_both(np.array([-1.0]))[0][0] == math.pi
    out = _acos_both(np.array([1.0 + 1e-12, -1.0 - 1e-12, np.nan]))[0]
    assert out[0] == 0.0 and out[1] == math.pi and np.isnan(out[2])


def test_sincos_fma_is_within_2e_16_of_libm_up_to_1e4_rad():
    for limit in (math.pi, 100.0, 1e4):
        x = np.linspace(-limit, limit, 400001)
        s, c, s0, c0 = _sincos_both(x)
        assert np.max(np.abs(s - np.sin(x))) <= 2.3e-16
        assert np.max(np.abs(c - np.cos(x))) <= 2.3e-16
        assert np.max(np.abs(s - s0)) <= 2.3e-16 and np.max(np.abs(c - c0)) <= 2.3e-16
    s, c, _, _ = _sincos_both(np.array([0.0, math.pi / 2, math.pi, np.nan]))
    assert s[0] == 0.0 and c[0] == 1.0 and abs(c[1]) < 1e-16 and abs(s[2]) < 2e-16
    assert np.isnan(s[3]) and np.isnan(c[3])
