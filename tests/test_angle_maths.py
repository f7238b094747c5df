"""The angle stage's per-element maths in their edge form (``angle_limit_entry`` returning the
edge it leaves, ``restoration_offset``, ``trig.acos_fma`` / ``trig.sincos_fma``) against the
forms they replaced (the quaternion from-to rotation applied to the edge and
``solve_pivot_pair`` on world positions, copied below as the oracle): the same results up to
round-off, per call, on random and degenerate inputs, and the same path on every input."""
import math

import numba
import numpy as np
import pytest

from magica_py.kernels import trig
from magica_py.kernels.math3d import (
    lerp, orthogonal_axis, q_axis_angle, q_mul, q_rotate, v_add, v_cross,
    v_dot, v_length, v_normalize, v_scale, v_sub,
)
from magica_py.solver.constraints.angle import (
    LIMIT_PIVOT, angle_limit_entry, angle_restoration_entry, edge_of, restoration_offset,
)
from reference_solver.solver.maths import angle_between_vectors, clamp_angle

IDENTITY = (0.0, 0.0, 0.0, 1.0)
ZERO3 = (0.0, 0.0, 0.0)


# ----------------------------------------------------------------------------- the replaced forms
@numba.njit(cache=False, error_model="numpy")
def old_solve_pivot_pair(pp, cp, v, r, pivot_ratio, wp, wc):
    pivot = v_add(pp, v_scale(v, pivot_ratio))
    dp = v_scale(v_sub(v_sub(pivot, v_scale(r, pivot_ratio)), pp), wp)
    dc = v_scale(v_sub(v_add(pivot, v_scale(r, 1.0 - pivot_ratio)), cp), wc)
    return dp, dc


@numba.njit(cache=False, error_model="numpy")
def old_swing(a, b):
    c = v_dot(a, b)
    c = 1.0 if c > 1.0 else c
    c = -1.0 if c < -1.0 else c
    x = v_cross(a, b)
    w = 1.0 + c
    inv = 1.0 / math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2] + w * w)
    half_angle = (x[0] * inv, x[1] * inv, x[2] * inv, w * inv)
    opposite = abs(1.0 + c) < 1e-6
    flip = q_axis_angle(orthogonal_axis(a), math.pi * 1.0)
    return flip if opposite else (IDENTITY if abs(1.0 - c) < 1e-6 else half_angle)


@numba.njit(cache=False, error_model="numpy")
def old_from_to_fraction(a, b, t):
    c = v_dot(a, b)
    c = 1.0 if c > 1.0 else c
    c = -1.0 if c < -1.0 else c
    opposite = abs(1.0 + c) < 1e-6
    parallel = abs(1.0 - c) < 1e-6
    axis = v_normalize(v_cross(a, b))
    angle = trig.acos(c) * t
    axis = orthogonal_axis(a) if opposite else axis
    angle = math.pi * t if opposite else angle
    q = q_axis_angle(axis, angle)
    return IDENTITY if (not opposite) & parallel else q


@numba.njit(cache=False, error_model="numpy")
def old_limit(cp, pp, vel_c, vel_p, rot_c, rot_p, local_pos, local_rot, length, max_angle, max_angle_cos, wc, wp,
              p_move, stiffness, attenuation):
    v = v_sub(cp, pp)
    vl = v_length(v)
    tv = q_rotate(rot_p, local_pos)
    tl = v_length(tv)
    rest_rot = q_mul(rot_p, local_rot)
    vn = v_scale(v, 1.0 / vl)
    tn = v_scale(tv, 1.0 / tl)
    lc = (vl + length) * 0.5
    v = v_scale(vn, lc)
    r = v
    if v_dot(vn, tn) < max_angle_cos:
        alpha = angle_between_vectors(v, tn)
        if alpha > max_angle:
            r = clamp_angle(v, tn, lerp(alpha, max_angle, stiffness))
    dp, dc = old_solve_pivot_pair(pp, cp, v, r, LIMIT_PIVOT, wp, wc)
    solved_c = v_add(cp, dc)
    solved_vel_c = v_add(vel_c, v_scale(dc, attenuation))
    solved_p = v_add(pp, dp) if p_move else pp
    solved_vel_p = v_add(vel_p, v_scale(dp, attenuation)) if p_move else vel_p
    u = v_sub(solved_c, solved_p)
    ul = v_length(u)
    swung = q_mul(old_swing(tn, v_scale(u, 1.0 / ul)), rest_rot)
    solved_rot = rot_c if ul < 1e-8 else swung
    skip = vl < 1e-8
    snap = (not skip) & (tl < 1e-8)
    solve = (not skip) & (not (tl < 1e-8)) & (not ((length < 1e-8) | (lc < 1e-8)))
    snapped_vel_c = v_add(vel_c, v_sub(pp, cp))
    next_c = solved_c if solve else (pp if snap else cp)
    vel_c = solved_vel_c if solve else (snapped_vel_c if snap else vel_c)
    vel_p = solved_vel_p if solve else vel_p
    rot_c = solved_rot if solve else (rest_rot if snap else rot_c)
    cp = solved_c if solve else cp
    pp = solved_p if solve else pp
    return cp, pp, next_c, vel_c, vel_p, rot_c


@numba.njit(cache=False, error_model="numpy")
def old_restoration(cp, pp, next_c, vel_c, next_p, vel_p, rest_length, rest_direction, stiffness, pivot, wc, wp,
                    p_move, attenuation):
    v = v_sub(cp, pp)
    vl = v_length(v)
    q = old_from_to_fraction(v_scale(v, 1.0 / vl), rest_direction, stiffness)
    dp, dc = old_solve_pivot_pair(pp, cp, v, q_rotate(q, v), pivot, wp, wc)
    snap = rest_length < 1e-8
    solve = (not snap) & (not (vl < 1e-8))
    move_p = solve & p_move
    next_c_out = v_add(next_c, dc) if solve else (pp if snap else next_c)
    vel_c_out = v_add(vel_c, v_scale(dc, attenuation)) if solve else (v_add(vel_c, v_sub(pp, cp)) if snap else vel_c)
    next_p = v_add(next_p, dp) if move_p else next_p
    vel_p = v_add(vel_p, v_scale(dp, attenuation)) if move_p else vel_p
    return next_c_out, vel_c_out, next_p, vel_p


# ----------------------------------------------------------------------------- inputs and runs
def _t(a, i):
    return (float(a[i, 0]), float(a[i, 1]), float(a[i, 2]))


def _t4(a, i):
    return (float(a[i, 0]), float(a[i, 1]), float(a[i, 2]), float(a[i, 3]))


@numba.njit(cache=False, error_model="numpy")
def _run_restoration(cp, pp, rest_direction, rest_length, t, pivot, wc, wp, p_move, new_out, old_out):
    for i in range(cp.shape[0]):
        c = (cp[i, 0], cp[i, 1], cp[i, 2])
        p = (pp[i, 0], pp[i, 1], pp[i, 2])
        rd = (rest_direction[i, 0], rest_direction[i, 1], rest_direction[i, 2])
        vel = (0.01, -0.02, 0.03)
        got = angle_restoration_entry(c, p, edge_of(c, p), c, vel, p, vel, rest_length[i], rd, t[i], pivot[i],
                                      wc[i], wp[i], p_move[i], 0.8)
        want = old_restoration(c, p, c, vel, p, vel, rest_length[i], rd, t[i], pivot[i], wc[i], wp[i], p_move[i], 0.8)
        for j in range(3):
            new_out[i, 0, j], old_out[i, 0, j] = got[0][j], want[0][j]
            new_out[i, 1, j], old_out[i, 1, j] = got[1][j], want[1][j]
            new_out[i, 2, j], old_out[i, 2, j] = got[2][j], want[2][j]
            new_out[i, 3, j], old_out[i, 3, j] = got[3][j], want[3][j]


@numba.njit(cache=False, error_model="numpy")
def _run_limit(cp, pp, rot_c, rot_p, local_pos, local_rot, length, max_angle, stiffness, wc, wp, p_move, new_out,
               old_out, new_edge, new_rot, old_rot):
    for i in range(cp.shape[0]):
        c = (cp[i, 0], cp[i, 1], cp[i, 2])
        p = (pp[i, 0], pp[i, 1], pp[i, 2])
        rc = (rot_c[i, 0], rot_c[i, 1], rot_c[i, 2], rot_c[i, 3])
        rp = (rot_p[i, 0], rot_p[i, 1], rot_p[i, 2], rot_p[i, 3])
        lp = (local_pos[i, 0], local_pos[i, 1], local_pos[i, 2])
        lr = (local_rot[i, 0], local_rot[i, 1], local_rot[i, 2], local_rot[i, 3])
        vel = (0.01, -0.02, 0.03)
        max_cos = trig.cos(max_angle[i])
        got = angle_limit_entry(c, p, vel, vel, rc, rp, lp, lr, length[i], max_angle[i], max_cos, wc[i], wp[i],
                                p_move[i], stiffness[i], 0.9)
        want = old_limit(c, p, vel, vel, rc, rp, lp, lr, length[i], max_angle[i], max_cos, wc[i], wp[i],
                         p_move[i], stiffness[i], 0.9)
        for j in range(3):
            new_out[i, 0, j], old_out[i, 0, j] = got[0][j], want[0][j]
            new_out[i, 1, j], old_out[i, 1, j] = got[1][j], want[1][j]
            new_out[i, 2, j], old_out[i, 2, j] = got[2][j], want[2][j]
            new_out[i, 3, j], old_out[i, 3, j] = got[3][j], want[3][j]
            new_out[i, 4, j], old_out[i, 4, j] = got[4][j], want[4][j]
        edge, edge_length, edge_unit = got[6]
        for j in range(3):
            new_edge[i, 0, j] = edge[j]
            new_edge[i, 1, j] = edge_unit[j]
        new_edge[i, 2, 0] = edge_length
        for j in range(4):
            new_rot[i, j] = got[5][j]
            old_rot[i, j] = want[5][j]


def _unit(rng, n):
    x = rng.normal(size=(n, 3))
    return x / np.linalg.norm(x, axis=1)[:, None]


def _rotate_towards(a, axis_seed, angle):
    """Unit vectors at ``angle`` from the unit vectors a (about a random axis orthogonal to a)."""
    k = np.cross(a, axis_seed)
    k /= np.linalg.norm(k, axis=1)[:, None]
    return a * np.cos(angle)[:, None] + np.cross(k, a) * np.sin(angle)[:, None]


def _quats(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1)[:, None]


N = 20000
EPS = np.finfo(float).eps


@pytest.fixture(scope="module")
def restoration_inputs():
    rng = np.random.default_rng(11)
    pp = rng.uniform(-10.0, 10.0, (N, 3))
    a = _unit(rng, N)
    vl = rng.uniform(0.01, 0.3, N)
    # angle between the edge and its rest direction: general, small, at the parallel and the
    # opposite thresholds (1 -+ cos = 1e-6), exactly parallel and exactly opposite
    kind = np.arange(N) % 8
    angle = rng.uniform(0.0, math.pi, N)
    angle[kind == 1] = 10.0 ** rng.uniform(-7.0, -1.0, (kind == 1).sum())
    angle[kind == 2] = math.sqrt(2e-6) * rng.uniform(0.5, 2.0, (kind == 2).sum())
    angle[kind == 3] = math.pi - math.sqrt(2e-6) * rng.uniform(0.5, 2.0, (kind == 3).sum())
    angle[kind == 4] = math.pi - 10.0 ** rng.uniform(-2.0, 0.0, (kind == 4).sum())
    rd = _rotate_towards(a, _unit(rng, N), angle)
    rd[kind == 5] = a[kind == 5]
    rd[kind == 6] = -a[kind == 6]
    cp = pp + a * vl[:, None]
    cp[kind == 7] = pp[kind == 7]            # zero-length edge: nothing happens
    rest_length = np.where(rng.uniform(size=N) < 0.03, 0.0, 0.1)   # degenerate rest edge: snap
    t = rng.uniform(0.0, 1.0, N)
    t[:100] = 0.0
    pivot = rng.choice([0.1, 0.3, 0.5], N)
    wc = 1.0 / (1.0 + 3.0 * rng.uniform(0.0, 0.3, N))
    wp = 1.0 / (1.0 + 3.0 * rng.uniform(0.0, 0.3, N))
    p_move = rng.uniform(size=N) < 0.7
    return cp, pp, rd, rest_length, t, pivot, wc, wp, p_move


def test_restoration_edge_form_equals_the_quaternion_form_up_to_round_off(restoration_inputs):
    cp, pp, rd, rest_length, t, pivot, wc, wp, p_move = restoration_inputs
    new = np.zeros((N, 4, 3))
    old = np.zeros((N, 4, 3))
    _run_restoration(cp, pp, rd, rest_length, t, pivot, wc, wp, p_move, new, old)
    assert np.all(np.isfinite(new)) and np.all(np.isfinite(old))
    # the old form rounds on world positions (|x| <= 17 m: ulp 3.6e-15 m), the new one on the
    # edge; near the opposite threshold both turn about a direction known to eps / sin(angle)
    # (|a x b| there, |b - (a.b) a| here), an error the rotation carries to |v| eps / sin
    vl = np.linalg.norm(cp - pp, axis=1)
    a = (cp - pp) / np.where(vl > 0.0, vl, 1.0)[:, None]
    sin = np.sqrt(np.maximum(1.0 - np.einsum("ij,ij->i", a, rd) ** 2, 0.0))
    scale = np.maximum(np.abs(cp).max(axis=1), np.abs(pp).max(axis=1))
    round_off = EPS * (scale + vl / np.maximum(sin, 1.4e-3))
    err = np.abs(new - old).max(axis=(1, 2))
    ratio = err / round_off
    assert ratio.max() < 8.0, ratio.max()
    assert err.max() < 1e-13, err.max()
    # the snap (degenerate rest edge) and skip (zero-length edge) paths: the same bits
    exact = (rest_length < 1e-8) | (vl < 1e-8)
    assert exact.sum() > 500 and np.array_equal(new[exact], old[exact])
    print(f"restoration: max abs {err.max():.2e} m, max error / round-off bound {ratio.max():.2f}, "
          f"median error / ulp(|x|) {np.median(err / (EPS * scale)):.2f}")


def test_restoration_offset_turns_the_edge_by_the_fraction_of_the_angle():
    a = (1.0, 0.0, 0.0)
    b = (0.0, 1.0, 0.0)
    v = (0.2, 0.0, 0.0)
    d, opposite = restoration_offset(a, v, 0.2, b, 0.5)
    r = v_add(v, d)
    assert not opposite
    assert np.allclose(r, (0.2 * math.cos(math.pi / 4), 0.2 * math.sin(math.pi / 4), 0.0), rtol=0, atol=1e-16)
    d, opposite = restoration_offset(a, v, 0.2, (-1.0, 0.0, 0.0), 0.5)
    assert opposite and abs(v_length(v_add(v, d)) - 0.2) < 1e-16 and abs(v_dot(v_add(v, d), a)) < 1e-16
    d, _ = restoration_offset(a, v, 0.2, a, 0.7)
    assert d == (0.0, 0.0, 0.0)


@pytest.fixture(scope="module")
def limit_inputs():
    rng = np.random.default_rng(12)
    pp = rng.uniform(-10.0, 10.0, (N, 3))
    a = _unit(rng, N)
    vl = rng.uniform(0.01, 0.3, N)
    cp = pp + a * vl[:, None]
    rot_p = _quats(rng, N)
    rot_c = _quats(rng, N)
    local_rot = _quats(rng, N)
    # the rest direction tn at an angle from the edge: within the limit, beyond it (clamp),
    # near opposite; local_pos is tn in the parent's frame
    kind = np.arange(N) % 8
    angle = rng.uniform(0.0, math.pi, N)
    angle[kind == 1] = 10.0 ** rng.uniform(-7.0, -1.0, (kind == 1).sum())
    angle[kind == 2] = math.pi - 10.0 ** rng.uniform(-7.0, -1.0, (kind == 2).sum())
    tn = _rotate_towards(a, _unit(rng, N), angle)
    inv = rot_p * np.array([-1.0, -1.0, -1.0, 1.0])
    local_pos = np.array([q_rotate(_t4(inv, i), _t(tn, i)) for i in range(N)])
    local_pos[kind == 3] = 0.0               # degenerate rest direction: snap
    cp[kind == 4] = pp[kind == 4]            # zero-length segment: skip
    length = vl * rng.uniform(0.5, 1.5, N)
    length[kind == 5] = 0.0                  # degenerate rest length: nothing
    max_angle = rng.uniform(0.1, 1.5, N)
    stiffness = rng.uniform(0.0, 1.0, N)
    wc = 1.0 / (1.0 + 3.0 * rng.uniform(0.0, 0.3, N))
    wp = 1.0 / (1.0 + 3.0 * rng.uniform(0.0, 0.3, N))
    p_move = rng.uniform(size=N) < 0.7
    return cp, pp, rot_c, rot_p, local_pos, local_rot, length, max_angle, stiffness, wc, wp, p_move


def test_limit_edge_form_equals_the_world_position_form_up_to_round_off(limit_inputs):
    cp, pp, rot_c, rot_p, local_pos, local_rot, length, max_angle, stiffness, wc, wp, p_move = limit_inputs
    new, old = np.zeros((N, 5, 3)), np.zeros((N, 5, 3))
    new_edge = np.zeros((N, 3, 3))
    new_rot, old_rot = np.zeros((N, 4)), np.zeros((N, 4))
    _run_limit(cp, pp, rot_c, rot_p, local_pos, local_rot, length, max_angle, stiffness, wc, wp, p_move, new, old,
               new_edge, new_rot, old_rot)
    assert np.all(np.isfinite(new)) and np.all(np.isfinite(old))
    scale = np.maximum(np.abs(cp).max(axis=1), np.abs(pp).max(axis=1))
    err = np.abs(new - old).max(axis=(1, 2))
    assert (err / (EPS * scale)).max() < 8.0, (err / (EPS * scale)).max()
    # the edge handed to the restoration: the old form's returned cp - pp, its length and
    # direction, up to the old form's round-off on world positions
    vl = np.linalg.norm(cp - pp, axis=1)
    ok = vl > 1e-8
    old_edge = old[:, 0] - old[:, 1]
    old_length = np.linalg.norm(old_edge, axis=1)
    edge_err = np.abs(new_edge[:, 0] - old_edge).max(axis=1)
    assert (edge_err / (EPS * scale)).max() < 8.0
    assert (np.abs(new_edge[ok, 2, 0] - old_length[ok]) / (EPS * scale[ok])).max() < 8.0
    unit_err = np.abs(new_edge[ok, 1] - old_edge[ok] / old_length[ok, None]).max(axis=1)
    assert (unit_err / (EPS * scale[ok] / vl[ok])).max() < 8.0
    # rotations: the swing from tn to the edge direction, whose old error eps |x| / |v| the
    # half-angle quaternion amplifies by 1 / sqrt(1 + cos) near opposite directions
    tv = np.array([q_rotate(_t4(rot_p, i), _t(local_pos, i)) for i in range(N)])
    tl = np.linalg.norm(tv, axis=1)
    swing = ok & (tl > 1e-8) & (length >= 1e-8)
    cos = np.einsum("ij,ij->i", tv[swing] / tl[swing, None], old_edge[swing] / old_length[swing, None])
    bound = EPS * scale[swing] / vl[swing] / np.sqrt(np.maximum(1.0 + cos, 1e-12))
    rot_err = np.abs(new_rot - old_rot).max(axis=1)
    rot_ratio = rot_err[swing] / bound
    assert rot_ratio.max() < 8.0, rot_ratio.max()
    assert np.array_equal(new_rot[~swing], old_rot[~swing])
    print(f"limit: positions max abs {err.max():.2e} m ({(err / (EPS * scale)).max():.2f} ulp of |x|), rotations "
          f"max abs {rot_err.max():.2e} (median {np.median(rot_err):.1e}; error / round-off bound {rot_ratio.max():.2f})")
