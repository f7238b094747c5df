"""Unity.Mathematics classic Perlin noise (``wind.noise.cnoise``) against a separate slow
transcription of Gustavson's / Ashima's ``cnoise`` (vectors as lists, the corners in the
original's float4 layout), and its defining properties."""
from __future__ import annotations

import math

import numpy as np
import pytest

from magica_py.wind.noise import cnoise


def _reference_cnoise(px: float, py: float) -> float:
    """The published algorithm, written independently of ``wind/noise.py``: float4 swizzles
    as lists, ``frac`` and ``mod289`` spelled out."""
    def floor4(v):
        return [math.floor(x) for x in v]

    def frac4(v):
        return [x - math.floor(x) for x in v]

    def mod289_4(v):
        return [x - math.floor(x * (1.0 / 289.0)) * 289.0 for x in v]

    def permute4(v):
        return mod289_4([((x * 34.0) + 1.0) * x for x in v])

    pxyxy = [px, py, px, py]
    pi = [a + b for a, b in zip(floor4(pxyxy), [0.0, 0.0, 1.0, 1.0])]
    pf = [a - b for a, b in zip(frac4(pxyxy), [0.0, 0.0, 1.0, 1.0])]
    pi = mod289_4(pi)
    ix = [pi[0], pi[2], pi[0], pi[2]]        # Pi.xzxz
    iy = [pi[1], pi[1], pi[3], pi[3]]        # Pi.yyww
    fx = [pf[0], pf[2], pf[0], pf[2]]
    fy = [pf[1], pf[1], pf[3], pf[3]]
    i = permute4([a + b for a, b in zip(permute4(ix), iy)])
    gx = [f * 2.0 - 1.0 for f in frac4([x * (1.0 / 41.0) for x in i])]
    gy = [abs(x) - 0.5 for x in gx]
    tx = [math.floor(x + 0.5) for x in gx]
    gx = [a - b for a, b in zip(gx, tx)]
    g00, g10, g01, g11 = [(gx[k], gy[k]) for k in range(4)]
    r = [g00[0] ** 2 + g00[1] ** 2, g01[0] ** 2 + g01[1] ** 2, g10[0] ** 2 + g10[1] ** 2, g11[0] ** 2 + g11[1] ** 2]
    norm = [1.79284291400159 - 0.85373472095314 * x for x in r]
    g00 = (g00[0] * norm[0], g00[1] * norm[0])
    g01 = (g01[0] * norm[1], g01[1] * norm[1])
    g10 = (g10[0] * norm[2], g10[1] * norm[2])
    g11 = (g11[0] * norm[3], g11[1] * norm[3])
    n00 = g00[0] * fx[0] + g00[1] * fy[0]
    n10 = g10[0] * fx[1] + g10[1] * fy[1]
    n01 = g01[0] * fx[2] + g01[1] * fy[2]
    n11 = g11[0] * fx[3] + g11[1] * fy[3]

    def fade(t):
        return t * t * t * (t * (t * 6.0 - 15.0) + 10.0)

    fade_x, fade_y = fade(pf[0]), fade(pf[1])
    nx = (n00 + (n10 - n00) * fade_x, n01 + (n11 - n01) * fade_x)
    return 2.3 * (nx[0] + (nx[1] - nx[0]) * fade_y)


POINTS = [(0.3, 0.7), (-1.25, 3.5), (12.75, -0.1), (100.1, 200.2), (-23132.5, -23132.5), (8.384, 8.384),
          (0.5, 0.5), (288.9, -288.9), (1e4 + 0.37, 2.0)]


@pytest.mark.parametrize("x,y", POINTS)
def test_cnoise_matches_the_independent_transcription(x, y):
    assert cnoise(x, y) == pytest.approx(_reference_cnoise(x, y), abs=1e-12)


def test_cnoise_is_zero_at_every_lattice_point():
    for x in range(-5, 6):
        for y in (-300, -1, 0, 7, 289, 1000):
            assert cnoise(float(x), float(y)) == 0.0


def test_cnoise_is_bounded_smooth_and_not_constant():
    rng = np.random.default_rng(3)
    pts = rng.uniform(-500.0, 500.0, size=(4000, 2))
    values = np.array([cnoise(float(x), float(y)) for x, y in pts])
    assert np.abs(values).max() <= 1.2           # classic 2-D Perlin x 2.3 stays near [-1, 1]
    assert values.std() > 0.15                   # it does vary
    # continuous: a 1e-6 step changes the value by at most a few 1e-6 (the gradient is bounded)
    steps = np.array([cnoise(float(x) + 1e-6, float(y)) for x, y in pts[:200]])
    assert np.abs(steps - values[:200]).max() < 1e-5


def test_cnoise_is_deterministic():
    a = [cnoise(x, y) for x, y in POINTS]
    b = [cnoise(x, y) for x, y in POINTS]
    assert a == b
    assert [_reference_cnoise(x, y) for x, y in POINTS[:3]] == pytest.approx(a[:3], abs=1e-12)
