"""Classic 2-D Perlin noise as Unity.Mathematics ``noise.cnoise(float2)`` defines it.

MagicaCloth2's wind (docs/solver.md §D.1) samples Unity.Mathematics' classic Perlin noise,
itself a port of Stefan Gustavson's and Ashima Arts' ``cnoise`` (webgl-noise, MIT licence).
This is that public algorithm written from its definition, in float64:

* the lattice cell ``Pi = floor(P)`` and the offsets ``Pf = P - Pi`` to its four corners;
* each corner's hash ``permute(permute(ix) + iy)`` with ``permute(x) = mod289((34 x + 1) x)``
  and ``mod289(x) = x - floor(x / 289) 289`` (the corner indices are reduced mod 289 first);
* the gradient of a corner from its hash h: ``gx = 2 frac(h / 41) - 1``, ``gy = |gx| - 0.5``,
  ``gx -= floor(gx + 0.5)``, normalised by ``taylorInvSqrt(r) = 1.79284291400159 -
  0.85373472095314 r`` (a first-order approximation of ``1/sqrt(r)``, as in the original);
* the four corner ramps ``dot(g, Pf_corner)`` blended with the quintic fade
  ``6t^5 - 15t^4 + 10t^3``, first along x, then along y, and scaled by 2.3.

Only +, -, *, /, abs and floor: the bits do not depend on the CPU (``kernels/portable.py``).
The value is 0 at every integer lattice point and stays within about [-1, 1].
``tests/test_wind_noise.py`` checks it against a separate slow transcription.
"""
from __future__ import annotations

import math

from magica_py.jit import kernel

INV_289 = 1.0 / 289.0
INV_41 = 1.0 / 41.0
TAYLOR_A = 1.79284291400159
TAYLOR_B = 0.85373472095314
CNOISE_SCALE = 2.3


@kernel
def mod289(x):
    return x - math.floor(x * INV_289) * 289.0


@kernel
def permute(x):
    return mod289((x * 34.0 + 1.0) * x)


@kernel
def fade(t):
    return t * t * t * (t * (t * 6.0 - 15.0) + 10.0)


@kernel
def _corner(hash_value, fx, fy):
    """The ramp ``dot(g, (fx, fy))`` of one corner with hash ``hash_value``."""
    gx = (hash_value * INV_41 - math.floor(hash_value * INV_41)) * 2.0 - 1.0
    gy = abs(gx) - 0.5
    gx = gx - math.floor(gx + 0.5)
    norm = TAYLOR_A - TAYLOR_B * (gx * gx + gy * gy)
    return (gx * norm) * fx + (gy * norm) * fy


@kernel
def cnoise(x, y):
    """Unity.Mathematics ``noise.cnoise(float2(x, y))`` (classic Perlin noise, 2-D)."""
    ix0 = math.floor(x)
    iy0 = math.floor(y)
    fx0 = x - ix0
    fy0 = y - iy0
    fx1 = fx0 - 1.0
    fy1 = fy0 - 1.0
    ix1 = mod289(ix0 + 1.0)
    iy1 = mod289(iy0 + 1.0)
    ix0 = mod289(ix0)
    iy0 = mod289(iy0)
    n00 = _corner(permute(permute(ix0) + iy0), fx0, fy0)
    n10 = _corner(permute(permute(ix1) + iy0), fx1, fy0)
    n01 = _corner(permute(permute(ix0) + iy1), fx0, fy1)
    n11 = _corner(permute(permute(ix1) + iy1), fx1, fy1)
    u = fade(fx0)
    v = fade(fy0)
    nx0 = n00 + (n10 - n00) * u
    nx1 = n01 + (n11 - n01) * u
    return CNOISE_SCALE * (nx0 + (nx1 - nx0) * v)
