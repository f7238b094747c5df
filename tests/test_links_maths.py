"""The distance link and the bending dihedral in their shared-reciprocal forms
(``distance_link``: one division by ``L (w_p + w_q)``; ``solve_dihedral``: 1/|e| once,
1/|n|^2 = (1/|n|)^2, the cosine from the unnormalised normals, ``trig.acos_fma``) against the
forms they replaced (copied below as the oracle): the same ``ok`` on every input and the same
corrections up to round-off, per call, on random, skewed and degenerate inputs
(docs/distance_bending_maths.md)."""
import math

import numba
import numpy as np

from magica_py.kernels import trig
from magica_py.kernels.math3d import v_cross, v_dot, v_length, v_length_sq, v_scale, v_sub
from magica_py.solver.constraints.bending import solve_dihedral
from magica_py.solver.constraints.distance import distance_link

ZERO3 = (0.0, 0.0, 0.0)


# ----------------------------------------------------------------------------- the replaced forms
@numba.njit(cache=False, error_model="numpy")
def old_distance_link(p_pos, q_pos, rest, w_p, w_q, stiffness):
    v = v_sub(q_pos, p_pos)
    length = v_length(v)
    ok = not (length < 1e-8)
    corr = v_scale(v, (length - rest) * stiffness / length * w_p / (w_p + w_q))
    return (corr if ok else ZERO3), ok


@numba.njit(cache=False, error_model="numpy")
def old_solve_dihedral(p0, p1, p2, p3, w0, w1, w2, w3, rest_angle, sign, stiffness):
    e = v_sub(p3, p2)
    el = v_length(e)
    n1 = v_cross(v_sub(p2, p0), v_sub(p3, p0))
    n2 = v_cross(v_sub(p3, p1), v_sub(p2, p1))
    l1 = v_length_sq(n1)
    l2 = v_length_sq(n2)
    n1u = v_scale(n1, 1.0 / math.sqrt(l1))
    n2u = v_scale(n2, 1.0 / math.sqrt(l2))
    n1 = v_scale(n1, 1.0 / l1)
    n2 = v_scale(n2, 1.0 / l2)
    d0 = v_scale(n1, el)
    d1 = v_scale(n2, el)
    a = v_dot(v_sub(p0, p3), e) / el
    b = v_dot(v_sub(p1, p3), e) / el
    d2 = (a * n1[0] + b * n2[0], a * n1[1] + b * n2[1], a * n1[2] + b * n2[2])
    a = v_dot(v_sub(p2, p0), e) / el
    b = v_dot(v_sub(p2, p1), e) / el
    d3 = (a * n1[0] + b * n2[0], a * n1[1] + b * n2[1], a * n1[2] + b * n2[2])
    c = v_dot(n1u, n2u)
    c = -1.0 if c < -1.0 else (1.0 if c > 1.0 else c)
    phi = trig.acos(c)
    phi = -phi if v_dot(v_cross(n1u, n2u), e) < 0.0 else phi
    denom = w0 * v_length_sq(d0) + w1 * v_length_sq(d1) + w2 * v_length_sq(d2) + w3 * v_length_sq(d3)
    lam = (sign * rest_angle - phi) / denom * stiffness
    ok = (not el < 1e-8) & (not (l1 == 0.0)) & (not (l2 == 0.0)) & (not denom == 0.0)
    c0 = v_scale(d0, -w0 * lam)
    c1 = v_scale(d1, -w1 * lam)
    c2 = v_scale(d2, -w2 * lam)
    c3 = v_scale(d3, -w3 * lam)
    return (ok, c0 if ok else ZERO3, c1 if ok else ZERO3, c2 if ok else ZERO3, c3 if ok else ZERO3)


def _t(a):
    return tuple(float(x) for x in a)


# ----------------------------------------------------------------------------- distance
def _link_inputs(rng, n):
    for _ in range(n):
        p = rng.normal(size=3) * rng.choice([0.01, 1.0, 10.0])
        v = rng.normal(size=3) * 10.0 ** rng.uniform(-7.9, 0.5)   # lengths from 1e-8 to a few metres
        yield (_t(p), _t(p + v), float(abs(rng.normal()) * 0.1), float(rng.uniform(0.01, 1.0)),
               float(rng.choice([0.02, rng.uniform(0.01, 1.0)])), float(rng.uniform(0.0, 1.0)))


def test_distance_link_matches_the_two_division_form_to_round_off():
    rng = np.random.default_rng(4)
    worst = 0.0
    for args in _link_inputs(rng, 20000):
        new, ok_new = distance_link(*args)
        old, ok_old = old_distance_link(*args)
        assert ok_new == ok_old
        scale = max(abs(x) for x in old)
        if scale > 0.0:
            worst = max(worst, max(abs(a - b) for a, b in zip(new, old)) / scale)
        else:
            assert new == old
    assert worst < 1e-15, worst   # measured: 5.2e-16 (a few roundings of the factor)


def test_distance_link_degenerate_and_extreme_links_as_before():
    cases = [
        ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.1, 1.0, 1.0, 1.0),          # coincident: not ok
        ((0.0, 0.0, 0.0), (5e-9, 0.0, 0.0), 0.1, 1.0, 1.0, 1.0),         # below 1e-8: not ok
        ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 1.0, 1.0, 1.0, 1.0),          # at rest: zero
        ((0.0, 0.0, 0.0), (2e-8, 0.0, 0.0), 0.0, 0.01, 0.02, 1.0),       # tiny, zero rest
        ((1e3, 1e3, 1e3), (1e3 + 1e-3, 1e3, 1e3), 2e-3, 1e-3, 1.0, 0.5),  # far from the origin
        ((0.0, 0.0, 0.0), (math.nan, 0.0, 0.0), 0.1, 1.0, 1.0, 1.0),     # NaN passes as it did
    ]
    for args in cases:
        new, ok_new = distance_link(*args)
        old, ok_old = old_distance_link(*args)
        assert ok_new == ok_old
        for a, b in zip(new, old):
            assert (math.isnan(a) and math.isnan(b)) or abs(a - b) <= 1e-15 * max(1.0, abs(b)), (args, new, old)
    assert distance_link(*cases[2])[0] == (0.0, 0.0, 0.0)
    corr, ok = distance_link((0.0, 0.0, 0.0), (2.0, 0.0, 0.0), 1.0, 1.0, 1.0, 0.5)
    assert ok and corr == (0.25, 0.0, 0.0)   # (2 - 1) 0.5 (1/2) w 1/2


# ----------------------------------------------------------------------------- dihedral
def _pair(rng, fold, edge_scale):
    """A bend pair around the edge p2-p3 (length edge_scale), the opposite vertices at a
    fold angle ``fold`` from flat, randomly placed and oriented."""
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    origin = rng.normal(size=3) * 2.0
    h0, h1 = rng.uniform(0.2, 2.0, 2) * edge_scale
    s0, s1 = rng.uniform(-0.5, 1.5, 2) * edge_scale
    p2 = np.zeros(3)
    p3 = np.array([edge_scale, 0.0, 0.0])
    p0 = np.array([s0, h0, 0.0])
    p1 = np.array([s1, -h1 * math.cos(fold), h1 * math.sin(fold)])
    return [_t(origin + q @ x) for x in (p0, p1, p2, p3)]


def _compare(points, w, rest, sign, k):
    """max |new - old| over the four corrections, in units of the corrections' gradient per
    radian of ``sign rest - phi`` (old(rest + 1) - old(rest)): the corrections are
    ``G (sign rest - phi)``, so where that difference nearly cancels a relative measure would
    only see the angle's round-off magnified; per radian it is the round-off of G and phi."""
    ok_new, *new = solve_dihedral(*points, *w, rest, sign, k)
    ok_old, *old = old_solve_dihedral(*points, *w, rest, sign, k)
    assert ok_new == ok_old
    new, old = np.array(new), np.array(old)
    per_radian = np.abs(np.array(old_solve_dihedral(*points, *w, rest + sign, sign, k)[1:]) - old).max()
    if per_radian == 0.0:
        assert (new == old).all()
        return 0.0
    return float(np.abs(new - old).max() / per_radian)


def test_solve_dihedral_matches_the_nine_division_form_to_round_off():
    rng = np.random.default_rng(7)
    worst = 0.0
    for _ in range(20000):
        fold = rng.uniform(-3.0, 3.0)          # away from +-pi, where the sign of phi is round-off
        points = _pair(rng, fold, 10.0 ** rng.uniform(-3.0, 0.5))
        w = _t(rng.uniform(0.01, 1.0, 4))
        worst = max(worst, _compare(points, w, float(rng.uniform(-1.0, 1.0)), float(rng.choice([-1.0, 1.0])),
                                    float(rng.uniform(0.0, 1.0))))
    assert worst < 1e-14, worst   # measured: 5.1e-15 (docs/distance_bending_maths.md)


def test_solve_dihedral_near_flat_and_at_rest_pairs_agree_per_radian():
    """Flat and nearly flat pairs at (or near) their rest angle: ``sign rest - phi`` cancels,
    the corrections are round-off themselves; new and old differ by round-off per radian."""
    rng = np.random.default_rng(11)
    worst = 0.0
    for _ in range(5000):
        fold = float(rng.choice([0.0, 1e-12, -1e-9, 1e-6, 0.3, -2.5]))
        points = _pair(rng, fold, float(rng.choice([0.05, 1e-3])))
        w = _t(rng.uniform(0.01, 1.0, 4))
        worst = max(worst, _compare(points, w, abs(fold), float(np.sign(fold) or 1.0), 1.0))
    assert worst < 1e-14, worst


def test_solve_dihedral_degenerate_pairs_not_ok_in_both_forms():
    p = (0.0, 0.0, 0.0)
    cases = [
        [(0.0, 1.0, 0.0), (0.0, -1.0, 0.0), p, p],                            # zero edge
        [(0.5, 0.0, 0.0), (0.0, -1.0, 0.0), p, (1.0, 0.0, 0.0)],              # collinear triangle
        [(0.0, 1.0, 0.0), (0.5, 0.0, 0.0), p, (1.0, 0.0, 0.0)],               # the other one
        [(0.0, 1.0, 0.0), (0.0, -1.0, 0.0), p, (5e-9, 0.0, 0.0)],             # edge below 1e-8
        [(0.0, 1e-150, 0.0), (0.0, -1e-150, 0.0), p, (1e-150, 0.0, 0.0)],     # l1 underflows to 0
    ]
    for points in cases:
        ok_new, *new = solve_dihedral(*points, 1.0, 1.0, 1.0, 1.0, 0.3, 1.0, 1.0)
        ok_old, *old = old_solve_dihedral(*points, 1.0, 1.0, 1.0, 1.0, 0.3, 1.0, 1.0)
        assert not ok_new and not ok_old
        assert all(c == ZERO3 for c in new)
    # a tiny but valid pair (1 mm): ok in both, the same corrections to round-off
    assert _compare(_pair(np.random.default_rng(1), 0.7, 1e-3), (1.0, 1.0, 0.5, 0.5), 0.0, 1.0, 1.0) < 1e-12
