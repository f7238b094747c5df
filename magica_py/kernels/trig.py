"""Branch-free polynomial acos / sin / cos for the solver's kernels.

Why not ``math.acos`` and ``math.sin``: numba lowers them to libm, whose bits differ between
CPUs (glibc picks FMA or non-FMA code paths at run time, docs/determinism.md); these
polynomials give the same bits on every x86-64 machine, and a loop calling them can vectorise
(no opaque call).

Accuracy (``tests/test_trig.py``, against libm on dense grids): acos within 2 ulp of the
result plus 1e-16 absolute near x = +-1; sin and cos within 2.3e-16 absolute for |x| <= 1e4 rad.

- ``acos``: ``asin(z) = z + z^3 P(z^2)`` on |z| <= 1/2 (P: degree-11 least-squares
  Chebyshev fit of the arcsine series, max error 3.3e-16 on [0, 1/4]); outside,
  ``acos(x) = 2 asin(sqrt((1 - x) / 2))`` (x > 1/2) and ``pi - 2 asin(sqrt((1 + x) / 2))``
  (x < -1/2). Arguments are clamped to [-1, 1]; NaN gives NaN.
- ``sin`` / ``cos``: Cody-Waite reduction by pi/2 (three-part constant), Taylor polynomials
  to degree 17 / 18 on [-pi/4, pi/4] (truncation below 1e-19), quadrant chosen by selects.
"""
from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
from llvmlite import ir
from numba import config
from numba.core import cgutils, types
from numba.extending import intrinsic

from magica_py.jit import kernel

PI = math.pi
HALF_PI = 0.5 * math.pi
TWO_OVER_PI = 2.0 / math.pi
# pi/2 split so that k * PIO2_1 and k * PIO2_2 are exact for |k| < 2^20 (fdlibm's split)
PIO2_1 = 1.57079632673412561417e+00
PIO2_2 = 6.07710050650619224932e-11
PIO2_3 = 2.02226624879595063154e-21

_A0 = 0.16666666666666657
_A1 = 0.07500000000021258
_A2 = 0.04464285710207024
_A3 = 0.03038194747268177
_A4 = 0.0223720437655528
_A5 = 0.017355339382066973
_A6 = 0.013928657182645604
_A7 = 0.011883404249107542
_A8 = 0.007762952658098213
_A9 = 0.01616027023227435
_A10 = -0.010967863951453709
_A11 = 0.02833431020888856


@kernel
def _asin_small(z):
    """asin(z) for |z| <= 1/2."""
    u = z * z
    p = _A11
    p = p * u + _A10
    p = p * u + _A9
    p = p * u + _A8
    p = p * u + _A7
    p = p * u + _A6
    p = p * u + _A5
    p = p * u + _A4
    p = p * u + _A3
    p = p * u + _A2
    p = p * u + _A1
    p = p * u + _A0
    return z + z * u * p


@kernel
def acos(x):
    """arccos in radians; x is clamped to [-1, 1]. No branches (selects only)."""
    x = 1.0 if x > 1.0 else x      # selects, not min/max: a NaN stays NaN (the guards see it)
    x = -1.0 if x < -1.0 else x
    ax = abs(x)
    big = ax > 0.5
    # |x| > 1/2: asin of sqrt((1 - |x|) / 2), exact argument (1 - |x| is exact there); the
    # root is taken either way and selected (a conditional root is a call, not an instruction)
    root = np.sqrt((1.0 - ax) * 0.5)
    z = root if big else x
    a = _asin_small(z)
    r = 2.0 * a
    return (r if x > 0.0 else PI - r) if big else HALF_PI - a


@kernel
def _sin_poly(r):
    """sin(r) for |r| <= pi/4 (Taylor to r^17)."""
    u = r * r
    p = 1.0 / 355687428096000.0
    p = p * u - 1.0 / 1307674368000.0
    p = p * u + 1.0 / 6227020800.0
    p = p * u - 1.0 / 39916800.0
    p = p * u + 1.0 / 362880.0
    p = p * u - 1.0 / 5040.0
    p = p * u + 1.0 / 120.0
    p = p * u - 1.0 / 6.0
    return r + r * u * p


@kernel
def _cos_poly(r):
    """cos(r) for |r| <= pi/4 (Taylor to r^18)."""
    u = r * r
    p = -1.0 / 6402373705728000.0
    p = p * u + 1.0 / 20922789888000.0
    p = p * u - 1.0 / 87178291200.0
    p = p * u + 1.0 / 479001600.0
    p = p * u - 1.0 / 3628800.0
    p = p * u + 1.0 / 40320.0
    p = p * u - 1.0 / 720.0
    p = p * u + 1.0 / 24.0
    return 1.0 - 0.5 * u + u * u * p


@kernel
def sincos(x):
    """(sin x, cos x). Accurate for |x| <= 1e4 (the reduction's constant is exact to 2^20 k)."""
    k = np.floor(x * TWO_OVER_PI + 0.5)   # float floor (math.floor returns an int in numba)
    r = ((x - k * PIO2_1) - k * PIO2_2) - k * PIO2_3
    s = _sin_poly(r)
    c = _cos_poly(r)
    q = k - 4.0 * np.floor(k * 0.25)   # quadrant 0..3 as a float (an int select does not vectorise)
    odd = q == 1.0 or q == 3.0
    sin_x = c if odd else s
    cos_x = s if odd else c
    sin_x = -sin_x if q >= 2.0 else sin_x
    cos_x = -cos_x if (q == 1.0 or q == 2.0) else cos_x
    return sin_x, cos_x


@kernel
def sin(x):
    return sincos(x)[0]


@kernel
def cos(x):
    return sincos(x)[1]


# ----------------------------------------------------------------------------- low latency
# The same functions evaluated for a short dependency chain (the angle restoration's lane loop
# is latency-bound: acos then sincos on its critical path): fused multiply-adds (``fma``,
# rounded once) and Estrin's scheme instead of Horner's (degree-11 asin polynomial: 5 dependent
# operations instead of 24). Results differ from ``acos`` / ``sincos`` by round-off only
# (tests/test_trig_fma.py: the same error bounds against libm).

@intrinsic
def _fma_llvm(typingctx, a, b, c):
    """``a * b + c`` rounded once (llvm.fma: one instruction on x86-64 since Haswell and on
    arm64, correctly rounded, so the same bits everywhere; vectorised in lane loops)."""
    if not all(isinstance(x, (types.Float, types.Integer)) for x in (a, b, c)):
        return None
    sig = types.float64(a, b, c)

    def codegen(context, builder, signature, args):
        values = [context.cast(builder, v, t, types.float64) for v, t in zip(args, signature.args)]
        double = ir.DoubleType()
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(double, [double] * 3), "llvm.fma.f64")
        return builder.call(fn, values)

    return sig, codegen


def _fma_exact(a, b, c):
    """``a * b + c`` rounded once, in Python (exact rational arithmetic): the JIT-off twin."""
    if not all(math.isfinite(x) for x in (a, b, c)):
        return float(a) * float(b) + float(c)
    return float(Fraction(float(a)) * Fraction(float(b)) + Fraction(float(c)))


# with NUMBA_DISABLE_JIT=1 the kernels run as Python and call the exact Python form
fma = _fma_exact if config.DISABLE_JIT else _fma_llvm


@kernel
def _asin_small_fma(z):
    """asin(z) for |z| <= 1/2 (``_asin_small``'s polynomial, Estrin's scheme)."""
    u = z * z
    u2 = u * u
    u4 = u2 * u2
    q0 = fma(fma(_A3, u, _A2), u2, fma(_A1, u, _A0))
    q1 = fma(fma(_A7, u, _A6), u2, fma(_A5, u, _A4))
    q2 = fma(fma(_A11, u, _A10), u2, fma(_A9, u, _A8))
    p = fma(fma(q2, u4, q1), u4, q0)
    return fma(z * u, p, z)


@kernel
def acos_fma(x):
    """``acos`` (clamped to [-1, 1], selects only), evaluated with fma and Estrin's scheme."""
    x = 1.0 if x > 1.0 else x
    x = -1.0 if x < -1.0 else x
    ax = abs(x)
    big = ax > 0.5
    root = np.sqrt((1.0 - ax) * 0.5)   # taken either way and selected (as in ``acos``)
    z = root if big else x
    a = _asin_small_fma(z)
    r = 2.0 * a
    return (r if x > 0.0 else PI - r) if big else HALF_PI - a


_S0, _S1, _S2, _S3 = -1.0 / 6.0, 1.0 / 120.0, -1.0 / 5040.0, 1.0 / 362880.0
_S4, _S5, _S6, _S7 = -1.0 / 39916800.0, 1.0 / 6227020800.0, -1.0 / 1307674368000.0, 1.0 / 355687428096000.0
_C0, _C1, _C2, _C3 = 1.0 / 24.0, -1.0 / 720.0, 1.0 / 40320.0, -1.0 / 3628800.0
_C4, _C5, _C6, _C7 = 1.0 / 479001600.0, -1.0 / 87178291200.0, 1.0 / 20922789888000.0, -1.0 / 6402373705728000.0


@kernel
def sincos_fma(x):
    """``sincos`` (same reduction, same Taylor polynomials, quadrant by selects), evaluated
    with fma and Estrin's scheme. Accurate for |x| <= 1e4."""
    k = np.floor(x * TWO_OVER_PI + 0.5)
    r = fma(-k, PIO2_3, fma(-k, PIO2_2, fma(-k, PIO2_1, x)))
    u = r * r
    u2 = u * u
    u4 = u2 * u2
    ps = fma(fma(fma(_S7, u, _S6), u2, fma(_S5, u, _S4)), u4, fma(fma(_S3, u, _S2), u2, fma(_S1, u, _S0)))
    pc = fma(fma(fma(_C7, u, _C6), u2, fma(_C5, u, _C4)), u4, fma(fma(_C3, u, _C2), u2, fma(_C1, u, _C0)))
    s = fma(r * u, ps, r)
    c = fma(u2, pc, fma(-0.5, u, 1.0))
    q = k - 4.0 * np.floor(k * 0.25)
    odd = q == 1.0 or q == 3.0
    sin_x = c if odd else s
    cos_x = s if odd else c
    sin_x = -sin_x if q >= 2.0 else sin_x
    cos_x = -cos_x if (q == 1.0 or q == 2.0) else cos_x
    return sin_x, cos_x
