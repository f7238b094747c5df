"""Maths whose bits do not depend on the CPU, the numpy build or the C library.

Every value that feeds a cloth model or the simulation state (the build, rig generators,
animation drivers, importers, parameter conversions) is computed with these functions or
with IEEE-exact operations (+ - * / sqrt, floor, comparisons), never with:

* numpy's transcendental ufuncs (``np.sin``, ``np.arccos``, ``np.arctan2`` ...): numpy picks a
  SIMD implementation at run time (AVX-512, AVX2, baseline) and their last bits differ;
* BLAS / LAPACK (``np.dot``, ``@``, ``np.linalg.inv`` / ``solve`` / ``det``, ``np.linalg.norm``
  of a 1-D vector, which is a dot product): OpenBLAS picks a kernel per CPU;
* the C library's ``sin``, ``exp``, ``pow`` ... (Python's ``math`` module, numba's ``math.*``,
  a numpy scalar's ``** 2``): glibc selects an FMA or an SSE2 variant per CPU, and their bits
  differ (measured: every function of glibc 2.36 changes bits with
  ``GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA``).

The functions are polynomials evaluated with plain multiplies and adds (no fused
multiply-add: numba does not contract without fastmath), so they give the same bits in a
scalar register and a vector lane on any x86-64 or arm64 machine. ``tests/test_portable.py``
pins their accuracy against libm and ``tests/test_cpu_independence.py`` runs the showcases under
other numpy / OpenBLAS / glibc dispatch choices (docs/determinism.md).

Accuracy: ``sin`` / ``cos`` / ``acos`` as ``kernels/trig.py`` (2 ulp; |x| <= 1e4 for sin / cos);
``asin`` / ``atan`` / ``atan2`` within 4 ulp; ``exp`` / ``log`` within 2 ulp; ``pow(x, y)``
(x >= 0) = exp(y log x), relative error about (1 + |y log x|) ulp.

Scalar kernels (``acos`` ... ``pow``) are for numba kernels and Python scalars alike; the
``*_array`` functions apply them element-wise to arrays of any shape (the build's vectorised
numpy code). ``norm``, ``dot3``, ``transform_points`` and ``inverse4`` replace the BLAS-backed
numpy calls.
"""
from __future__ import annotations

import math

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels import trig

PI = math.pi
HALF_PI = 0.5 * math.pi
QUARTER_PI = 0.25 * math.pi
LN2_HI = 6.93147180369123816490e-01   # fdlibm's split of ln 2: k * LN2_HI is exact for |k| < 2^11
LN2_LO = 1.90821492927058770002e-10
INV_LN2 = 1.44269504088896338700e+00
EXP_OVERFLOW = 709.782712893383973096
EXP_UNDERFLOW = -745.13321910194110842
SQRT_HALF = 0.70710678118654752440


# ----------------------------------------------------------------------------- circular
@kernel
def sin(x):
    return trig.sincos(x)[0]


@kernel
def cos(x):
    return trig.sincos(x)[1]


@kernel
def sincos(x):
    return trig.sincos(x)


@kernel
def acos(x):
    """arccos in radians, x clamped to [-1, 1]."""
    return trig.acos(x)


@kernel
def asin(x):
    """arcsin in radians, x clamped to [-1, 1]."""
    x = 1.0 if x > 1.0 else x
    x = -1.0 if x < -1.0 else x
    ax = abs(x)
    if ax <= 0.5:
        return trig._asin_small(x)
    r = HALF_PI - 2.0 * trig._asin_small(np.sqrt((1.0 - ax) * 0.5))
    return r if x > 0.0 else -r


@kernel
def atan2(y, x):
    """The angle of (x, y) in (-pi, pi], as C's atan2 (signed zeros aside). The first
    octant angle comes from asin or acos of an argument <= 1/sqrt(2), where both are well
    conditioned."""
    if math.isnan(x) or math.isnan(y):
        return math.nan
    ax = abs(x)
    ay = abs(y)
    if ax == 0.0 and ay == 0.0:
        base = 0.0
    elif math.isinf(ax) or math.isinf(ay):
        if math.isinf(ax) and math.isinf(ay):
            base = QUARTER_PI
        elif math.isinf(ax):
            base = 0.0
        else:
            base = HALF_PI
    else:
        scale = ax if ax > ay else ay        # no overflow or underflow in the squares
        sx = ax / scale
        sy = ay / scale
        r = np.sqrt(sx * sx + sy * sy)
        if sy <= sx:
            base = asin(sy / r)
        else:
            base = acos(sx / r)
    if x < 0.0:
        base = PI - base
    return -base if y < 0.0 else base


@kernel
def atan(x):
    return atan2(x, 1.0)


# ----------------------------------------------------------------------------- exponential
@kernel
def exp(x):
    """e^x: x = k ln2 + r with |r| <= ln2 / 2, e^r by its Taylor series to r^13."""
    if math.isnan(x):
        return x
    if x > EXP_OVERFLOW:
        return math.inf
    if x < EXP_UNDERFLOW:
        return 0.0
    k = np.floor(x * INV_LN2 + 0.5)
    r = (x - k * LN2_HI) - k * LN2_LO
    p = 1.0 / 6227020800.0
    p = p * r + 1.0 / 479001600.0
    p = p * r + 1.0 / 39916800.0
    p = p * r + 1.0 / 3628800.0
    p = p * r + 1.0 / 362880.0
    p = p * r + 1.0 / 40320.0
    p = p * r + 1.0 / 5040.0
    p = p * r + 1.0 / 720.0
    p = p * r + 1.0 / 120.0
    p = p * r + 1.0 / 24.0
    p = p * r + 1.0 / 6.0
    p = p * r + 0.5
    e = 1.0 + (r + r * r * p)
    return math.ldexp(e, int(k))


@kernel
def log(x):
    """Natural logarithm: x = m 2^e with m in [sqrt(1/2), sqrt(2)), log m = 2 atanh(s),
    s = (m - 1) / (m + 1), by its series to s^23."""
    if math.isnan(x) or x < 0.0:
        return math.nan
    if x == 0.0:
        return -math.inf
    if math.isinf(x):
        return x
    m, e = math.frexp(x)        # m in [1/2, 1)
    if m < SQRT_HALF:
        m = m * 2.0
        e = e - 1
    f = m - 1.0
    s = f / (2.0 + f)
    z = s * s
    p = 1.0 / 23.0
    p = p * z + 1.0 / 21.0
    p = p * z + 1.0 / 19.0
    p = p * z + 1.0 / 17.0
    p = p * z + 1.0 / 15.0
    p = p * z + 1.0 / 13.0
    p = p * z + 1.0 / 11.0
    p = p * z + 1.0 / 9.0
    p = p * z + 1.0 / 7.0
    p = p * z + 1.0 / 5.0
    p = p * z + 1.0 / 3.0
    # log(1 + f) = f - f^2/2 + 2 s (f^2/2 + z p) keeps the leading term exact
    hf = 0.5 * f * f
    log_m = f - (hf - s * (hf + z * p * 2.0))
    k = float(e)
    return k * LN2_HI + (log_m + k * LN2_LO)


@kernel
def pow(x, y):
    """x^y for x >= 0 (the solver's rates and attenuations); NaN for x < 0 unless y is an
    integer. Exact where the result is: x^0 = 1, 1^y = 1, x^1 = x."""
    if y == 0.0 or x == 1.0:
        return 1.0
    if y == 1.0:
        return x
    if math.isnan(x) or math.isnan(y):
        return math.nan
    if x < 0.0:
        if y != np.floor(y):
            return math.nan
        r = exp(y * log(-x))
        odd = (y * 0.5) != np.floor(y * 0.5)
        return -r if odd else r
    if x == 0.0:
        return 0.0 if y > 0.0 else math.inf
    return exp(y * log(x))


# ----------------------------------------------------------------------------- arrays
@kernel
def _map1(code, x, out):
    for i in range(x.shape[0]):
        v = x[i]
        if code == 0:
            out[i] = sin(v)
        elif code == 1:
            out[i] = cos(v)
        elif code == 2:
            out[i] = acos(v)
        elif code == 3:
            out[i] = asin(v)
        elif code == 4:
            out[i] = exp(v)
        else:
            out[i] = log(v)


@kernel
def _map2(code, a, b, out):
    for i in range(a.shape[0]):
        if code == 0:
            out[i] = atan2(a[i], b[i])
        else:
            out[i] = pow(a[i], b[i])


def _apply1(code: int, x) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    flat = np.ascontiguousarray(x).reshape(-1)
    out = np.empty_like(flat)
    _map1(code, flat, out)
    return out.reshape(x.shape)


def _apply2(code: int, a, b) -> np.ndarray:
    a, b = np.broadcast_arrays(np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64))
    fa = np.ascontiguousarray(a).reshape(-1)
    fb = np.ascontiguousarray(b).reshape(-1)
    out = np.empty_like(fa)
    _map2(code, fa, fb, out)
    return out.reshape(a.shape)


def sin_array(x) -> np.ndarray:
    return _apply1(0, x)


def cos_array(x) -> np.ndarray:
    return _apply1(1, x)


def acos_array(x) -> np.ndarray:
    return _apply1(2, x)


def asin_array(x) -> np.ndarray:
    return _apply1(3, x)


def exp_array(x) -> np.ndarray:
    return _apply1(4, x)


def log_array(x) -> np.ndarray:
    return _apply1(5, x)


def atan2_array(y, x) -> np.ndarray:
    return _apply2(0, y, x)


def pow_array(x, y) -> np.ndarray:
    return _apply2(1, x, y)


# ----------------------------------------------------------------------------- linear algebra
def dot3(a, b) -> np.ndarray | float:
    """Dot product over the last axis of length 3 (or 4), summed left to right."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    s = a[..., 0] * b[..., 0]
    for c in range(1, a.shape[-1]):
        s = s + a[..., c] * b[..., c]
    return float(s) if s.ndim == 0 else s


def norm(v) -> np.ndarray | float:
    """Euclidean length over the last axis, summed left to right (a float for a 1-D vector)."""
    v = np.asarray(v, dtype=np.float64)
    return np.sqrt(dot3(v, v)) if v.ndim > 1 else float(math.sqrt(dot3(v, v)))


def transform_points(m: np.ndarray, points) -> np.ndarray:
    """``points @ m[:3, :3].T + m[:3, 3]`` for (..., 3) points and a (4, 4) or (3, 4) matrix,
    each coordinate summed left to right."""
    p = np.asarray(points, dtype=np.float64)
    m = np.asarray(m, dtype=np.float64)
    out = np.empty(p.shape, dtype=np.float64)
    for r in range(3):
        out[..., r] = ((p[..., 0] * m[r, 0] + p[..., 1] * m[r, 1]) + p[..., 2] * m[r, 2]) + m[r, 3]
    return out


def rotate_vectors(m: np.ndarray, vectors) -> np.ndarray:
    """``vectors @ m[:3, :3].T`` (no translation), each coordinate summed left to right.
    ``m`` may also be a stack (..., 3, 3) matching the vectors' leading axes."""
    v = np.asarray(vectors, dtype=np.float64)
    m = np.asarray(m, dtype=np.float64)
    out = np.empty(np.broadcast_shapes(v.shape, m.shape[:-1]), dtype=np.float64)
    for r in range(3):
        out[..., r] = (v[..., 0] * m[..., r, 0] + v[..., 1] * m[..., r, 1]) + v[..., 2] * m[..., r, 2]
    return out


@kernel
def _inverse4(m, out):
    """Inverse of a 4x4 matrix by cofactors (fixed operation order); NaN when singular."""
    a = m
    s0 = a[0, 0] * a[1, 1] - a[1, 0] * a[0, 1]
    s1 = a[0, 0] * a[1, 2] - a[1, 0] * a[0, 2]
    s2 = a[0, 0] * a[1, 3] - a[1, 0] * a[0, 3]
    s3 = a[0, 1] * a[1, 2] - a[1, 1] * a[0, 2]
    s4 = a[0, 1] * a[1, 3] - a[1, 1] * a[0, 3]
    s5 = a[0, 2] * a[1, 3] - a[1, 2] * a[0, 3]
    c5 = a[2, 2] * a[3, 3] - a[3, 2] * a[2, 3]
    c4 = a[2, 1] * a[3, 3] - a[3, 1] * a[2, 3]
    c3 = a[2, 1] * a[3, 2] - a[3, 1] * a[2, 2]
    c2 = a[2, 0] * a[3, 3] - a[3, 0] * a[2, 3]
    c1 = a[2, 0] * a[3, 2] - a[3, 0] * a[2, 2]
    c0 = a[2, 0] * a[3, 1] - a[3, 0] * a[2, 1]
    det = s0 * c5 - s1 * c4 + s2 * c3 + s3 * c2 - s4 * c1 + s5 * c0
    inv = 1.0 / det if det != 0.0 else math.nan
    out[0, 0] = (a[1, 1] * c5 - a[1, 2] * c4 + a[1, 3] * c3) * inv
    out[0, 1] = (-a[0, 1] * c5 + a[0, 2] * c4 - a[0, 3] * c3) * inv
    out[0, 2] = (a[3, 1] * s5 - a[3, 2] * s4 + a[3, 3] * s3) * inv
    out[0, 3] = (-a[2, 1] * s5 + a[2, 2] * s4 - a[2, 3] * s3) * inv
    out[1, 0] = (-a[1, 0] * c5 + a[1, 2] * c2 - a[1, 3] * c1) * inv
    out[1, 1] = (a[0, 0] * c5 - a[0, 2] * c2 + a[0, 3] * c1) * inv
    out[1, 2] = (-a[3, 0] * s5 + a[3, 2] * s2 - a[3, 3] * s1) * inv
    out[1, 3] = (a[2, 0] * s5 - a[2, 2] * s2 + a[2, 3] * s1) * inv
    out[2, 0] = (a[1, 0] * c4 - a[1, 1] * c2 + a[1, 3] * c0) * inv
    out[2, 1] = (-a[0, 0] * c4 + a[0, 1] * c2 - a[0, 3] * c0) * inv
    out[2, 2] = (a[3, 0] * s4 - a[3, 1] * s2 + a[3, 3] * s0) * inv
    out[2, 3] = (-a[2, 0] * s4 + a[2, 1] * s2 - a[2, 3] * s0) * inv
    out[3, 0] = (-a[1, 0] * c3 + a[1, 1] * c1 - a[1, 2] * c0) * inv
    out[3, 1] = (a[0, 0] * c3 - a[0, 1] * c1 + a[0, 2] * c0) * inv
    out[3, 2] = (-a[3, 0] * s3 + a[3, 1] * s1 - a[3, 2] * s0) * inv
    out[3, 3] = (a[2, 0] * s3 - a[2, 1] * s1 + a[2, 2] * s0) * inv


def inverse4(m) -> np.ndarray:
    """Inverse of a (4, 4) matrix (replaces ``np.linalg.inv``, whose LAPACK kernel depends on the CPU)."""
    m = np.ascontiguousarray(m, dtype=np.float64)
    out = np.empty((4, 4), dtype=np.float64)
    _inverse4(m, out)
    return out


def inverse3(m) -> np.ndarray:
    """Inverse of a (3, 3) matrix, through ``inverse4`` of its homogeneous form."""
    h = np.eye(4)
    h[:3, :3] = m
    return inverse4(h)[:3, :3].copy()


def determinant3(m) -> float:
    """Determinant of a (3, 3) matrix by the rule of Sarrus, in a fixed order."""
    m = np.asarray(m, dtype=np.float64)
    return float((m[0, 0] * (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1])
                  - m[0, 1] * (m[1, 0] * m[2, 2] - m[1, 2] * m[2, 0]))
                 + m[0, 2] * (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]))
