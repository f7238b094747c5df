"""Vector/quaternion helpers (magica_py/kernels/math3d.py) against independent numpy versions.

The oracle works with rotation matrices (Rodrigues' formula), never with the helpers' own
quaternion algebra, so a sign or order mistake in a helper shows up as a matrix mismatch.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from magica_py.kernels import math3d as m

RNG = np.random.default_rng(1234)


# ----------------------------------------------------------------------------- numpy oracle
def rodrigues(axis, angle):
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) * math.cos(angle) + math.sin(angle) * kx + (1 - math.cos(angle)) * np.outer(k, k)


def quat_of(axis, angle):
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    return tuple(np.append(k * math.sin(angle / 2), math.cos(angle / 2)))


def matrix_of(q):
    """Rotation matrix of a unit quaternion via the rotation it applies to the basis vectors,
    computed with the sandwich product in 4-vectors (independent of q_to_matrix)."""
    x, y, z, w = q

    def hamilton(a, b):
        a1, b1, c1, d1 = a[3], a[0], a[1], a[2]
        a2, b2, c2, d2 = b[3], b[0], b[1], b[2]
        return np.array([a1 * b2 + b1 * a2 + c1 * d2 - d1 * c2,
                         a1 * c2 - b1 * d2 + c1 * a2 + d1 * b2,
                         a1 * d2 + b1 * c2 - c1 * b2 + d1 * a2,
                         a1 * a2 - b1 * b2 - c1 * c2 - d1 * d2])

    conj = np.array([-x, -y, -z, w])
    cols = [hamilton(hamilton(np.array(q), np.append(e, 0.0)), conj)[:3] for e in np.eye(3)]
    return np.column_stack(cols)


def random_axis():
    v = RNG.normal(size=3)
    return v / np.linalg.norm(v)


def random_quat():
    return quat_of(random_axis(), RNG.uniform(-math.pi, math.pi))


def same_rotation(q1, q2, atol=1e-12):
    return np.allclose(matrix_of(q1), matrix_of(q2), atol=atol)


# ----------------------------------------------------------------------------- basics
def test_oracle_matrix_matches_rodrigues():
    axis, angle = random_axis(), 0.7
    np.testing.assert_allclose(matrix_of(quat_of(axis, angle)), rodrigues(axis, angle), atol=1e-14)


def test_q_rotate_and_q_to_matrix_match_rodrigues():
    for _ in range(50):
        axis, angle = random_axis(), RNG.uniform(-4, 4)
        q = quat_of(axis, angle)
        v = RNG.normal(size=3)
        np.testing.assert_allclose(m.q_rotate(q, tuple(v)), rodrigues(axis, angle) @ v, atol=1e-12)
        np.testing.assert_allclose(np.array(m.q_to_matrix(q)), rodrigues(axis, angle), atol=1e-12)
        np.testing.assert_allclose(m.q_rotate(m.q_inverse(q), tuple(v)), rodrigues(axis, angle).T @ v,
                                   atol=1e-12)


def test_q_mul_applies_the_right_operand_first():
    for _ in range(50):
        a, b = random_quat(), random_quat()
        np.testing.assert_allclose(matrix_of(m.q_mul(a, b)), matrix_of(a) @ matrix_of(b), atol=1e-12)


def test_q_inverse_divides_by_the_squared_norm():
    q = tuple(2.0 * np.array(random_quat()))
    inv = m.q_inverse(q)
    np.testing.assert_allclose(m.q_mul(q, inv), (0, 0, 0, 1), atol=1e-12)
    assert m.q_inverse((0.0, 0.0, 0.0, 0.0)) == (0.0, 0.0, 0.0, 1.0)


def test_normalize_of_zero_is_safe():
    assert m.v_normalize((0.0, 0.0, 0.0)) == (0.0, 0.0, 0.0)
    assert m.q_normalize((0.0, 0.0, 0.0, 0.0)) == (0.0, 0.0, 0.0, 1.0)
    np.testing.assert_allclose(m.v_normalize((3.0, 0.0, 4.0)), (0.6, 0.0, 0.8))


def test_unity_euler_order_is_z_then_x_then_y():
    right, forward = (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)
    np.testing.assert_allclose(m.q_rotate(m.q_from_euler_degrees(0, 90, 0), right), (0, 0, -1), atol=1e-15)
    np.testing.assert_allclose(m.q_rotate(m.q_from_euler_degrees(90, 0, 0), forward), (0, -1, 0), atol=1e-15)
    np.testing.assert_allclose(m.q_rotate(m.q_from_euler_degrees(0, 0, 90), right), (0, 1, 0), atol=1e-15)
    # Z, X, Y order: X first would send forward to (1,0,0)
    np.testing.assert_allclose(m.q_rotate(m.q_from_euler_degrees(90, 90, 0), forward), (0, -1, 0), atol=1e-15)
    x, y, z = 30.0, -50.0, 70.0
    expected = rodrigues((0, 1, 0), math.radians(y)) @ rodrigues((1, 0, 0), math.radians(x)) @ \
        rodrigues((0, 0, 1), math.radians(z))
    np.testing.assert_allclose(matrix_of(m.q_from_euler_degrees(x, y, z)), expected, atol=1e-12)


# ----------------------------------------------------------------------------- slerp
def slerp_oracle(q1, q2, t):
    """Rotation matrix that moves fraction t along the shortest rotation from q1 to q2."""
    r1, r2 = matrix_of(q1), matrix_of(q2)
    rel = r1.T @ r2
    angle = math.acos(np.clip((np.trace(rel) - 1) / 2, -1, 1))
    if angle < 1e-12:
        return r1
    axis = np.array([rel[2, 1] - rel[1, 2], rel[0, 2] - rel[2, 0], rel[1, 0] - rel[0, 1]])
    return r1 @ rodrigues(axis, angle * t)


@pytest.mark.parametrize("t", [0.0, 0.25, 0.5, 0.9, 1.0])
def test_slerp_follows_the_shortest_arc(t):
    for _ in range(30):
        q1, q2 = random_quat(), random_quat()
        if RNG.random() < 0.5:
            q2 = tuple(-c for c in q2)  # the other hemisphere: same rotation
        out = m.q_slerp(q1, q2, t)
        assert abs(np.linalg.norm(out) - 1) < 1e-12
        np.testing.assert_allclose(matrix_of(out), slerp_oracle(q1, q2, t), atol=1e-9)


def test_slerp_of_nearly_equal_quaternions_uses_normalized_lerp():
    q1 = quat_of((0, 1, 0), 0.2)
    q2 = quat_of((0, 1, 0), 0.2 + 1e-3)
    out = m.q_slerp(q1, q2, 0.5)
    np.testing.assert_allclose(out, quat_of((0, 1, 0), 0.2 + 5e-4), atol=1e-9)


def test_slerp_from_a_precomputed_path_is_the_branch_free_slerp_bit_for_bit():
    """``q_slerp_path`` (once per pair) and ``q_slerp_along`` (per t) give ``q_slerp_select``'s
    bits, on both of its paths (far apart, nearly equal) and both hemispheres, and match the
    rotation oracle."""
    pairs = [(random_quat(), random_quat()) for _ in range(40)]
    pairs += [(quat_of((0, 1, 0), 0.2), quat_of((0, 1, 0), 0.2 + 1e-3))]   # the lerp path
    pairs += [(q1, tuple(-c for c in q2)) for q1, q2 in pairs[:10]]
    for q1, q2 in pairs:
        path = m.q_slerp_path(q1, q2)
        for t in (0.0, 0.3, 0.75, 1.0):
            along = m.q_slerp_along(q1, *path, t)
            assert np.array(along).tobytes() == np.array(m.q_slerp_select(q1, q2, t)).tobytes()
            np.testing.assert_allclose(matrix_of(along), slerp_oracle(q1, q2, t), atol=1e-9)


# ----------------------------------------------------------------------------- from-to
def test_from_to_rotation_maps_a_onto_b_and_scales_the_angle_by_t():
    for _ in range(50):
        a, b = RNG.normal(size=3), RNG.normal(size=3)
        q = m.from_to_rotation(tuple(a), tuple(b), 1.0)
        np.testing.assert_allclose(m.q_rotate(q, tuple(a / np.linalg.norm(a))), b / np.linalg.norm(b),
                                   atol=1e-10)
        half = m.from_to_rotation(tuple(a), tuple(b), 0.5)
        full_angle = math.acos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1))
        assert 2 * math.acos(min(1.0, abs(half[3]))) == pytest.approx(full_angle / 2, abs=1e-9)


@pytest.mark.parametrize("a", [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1),
                               (1, 1, 0), (-1, -1, -1), (0.3, -0.2, 0.9)])
def test_from_to_rotation_of_opposite_vectors_is_a_half_turn_never_nan(a):
    a = np.asarray(a, float)
    q = m.from_to_rotation(tuple(a), tuple(-a), 1.0)
    assert np.all(np.isfinite(q))
    assert abs(np.linalg.norm(q) - 1) < 1e-12
    np.testing.assert_allclose(m.q_rotate(q, tuple(a / np.linalg.norm(a))), -a / np.linalg.norm(a),
                               atol=1e-12)
    assert m.from_to_rotation(tuple(a), tuple(2 * a), 1.0) == (0.0, 0.0, 0.0, 1.0)


def test_q_from_to_takes_orientation_a_to_b():
    a, b = random_quat(), random_quat()
    d = m.q_from_to(a, b)
    assert same_rotation(m.q_mul(d, a), b)


# ----------------------------------------------------------------------------- matrix -> quaternion
def test_q_from_matrix_round_trip():
    for _ in range(200):
        q = random_quat()
        r = matrix_of(q)
        out = m.q_from_matrix(*r.ravel())
        assert same_rotation(out, q, atol=1e-10)
        assert abs(abs(np.dot(out, q)) - 1) < 1e-10


@pytest.mark.parametrize("axis, angle, major", [
    ((0, 0, 1), 0.3, 3),           # m00 >= 0, m11 + m22 >= 0 -> w branch
    ((1, 0, 0), 3.0, 0),           # m00 >= 0, m11 + m22 < 0  -> x branch
    ((0, 1, 0), 3.0, 1),           # m00 < 0,  m11 - m22 >= 0 -> y branch
    ((0, 0, 1), 3.0, 2),           # m00 < 0,  m11 - m22 < 0  -> z branch
])
def test_q_from_matrix_branch_makes_its_major_component_positive(axis, angle, major):
    for sign in (1.0, -1.0):  # the input quaternion's sign must not matter
        q = tuple(sign * c for c in quat_of(axis, angle))
        out = m.q_from_matrix(*matrix_of(q).ravel())
        assert out[major] > 0
        assert same_rotation(out, q)


def test_look_rotation_points_z_forward_and_y_up():
    for _ in range(30):
        f = random_axis()
        up = random_axis()
        q = m.q_look_rotation(tuple(f), tuple(up))
        np.testing.assert_allclose(m.q_rotate(q, (0.0, 0.0, 1.0)), f, atol=1e-10)
        y = np.array(m.q_rotate(q, (0.0, 1.0, 0.0)))
        ortho_up = up - (up @ f) * f
        np.testing.assert_allclose(y, ortho_up / np.linalg.norm(ortho_up), atol=1e-10)
        # rot_from(n, t) == LookRotation(t, n)
        assert m.rot_from_normal_tangent(tuple(up), tuple(f)) == q
        np.testing.assert_allclose(m.q_tangent_axis(q), f, atol=1e-10)


# ----------------------------------------------------------------------------- angles
def test_angle_between_vectors_and_quaternions():
    for _ in range(50):
        a, b = RNG.normal(size=3), RNG.normal(size=3)
        expected = math.acos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1))
        assert m.angle_between_vectors_select(tuple(a), tuple(b)) == pytest.approx(expected, abs=1e-12)
        qa, qb = random_quat(), random_quat()
        rel = matrix_of(qa).T @ matrix_of(qb)
        rel_angle = math.acos(np.clip((np.trace(rel) - 1) / 2, -1, 1))
        assert m.q_angle(qa, qb) == pytest.approx(rel_angle, abs=1e-7)
    assert m.angle_between_vectors_select((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)) == 0.0
    assert m.q_angle(quat_of((0, 1, 0), 0.001), quat_of((0, 1, 0), 0.002)) == 0.0  # |d| >= 0.9999


def test_to_angle_axis_inverts_axis_angle():
    axis = random_axis()
    angle, out_axis = m.q_to_angle_axis(quat_of(axis, 1.1))
    assert angle == pytest.approx(1.1)
    np.testing.assert_allclose(out_axis, axis, atol=1e-12)
    angle, out_axis = m.q_to_angle_axis((0.0, 0.0, 0.0, 1.0))
    assert angle == 0.0 and out_axis == (0.0, 0.0, 0.0)


def test_clamp_angle_limits_the_angle_and_keeps_the_length():
    for _ in range(50):
        d, b = RNG.normal(size=3) * 2, RNG.normal(size=3)
        limit = RNG.uniform(0.05, 1.5)
        out = np.array(m.clamp_angle_select(tuple(d), tuple(b), limit))
        before = math.acos(np.clip(d @ b / np.linalg.norm(d) / np.linalg.norm(b), -1, 1))
        after = math.acos(np.clip(out @ b / np.linalg.norm(out) / np.linalg.norm(b), -1, 1))
        assert np.linalg.norm(out) == pytest.approx(np.linalg.norm(d))
        assert after == pytest.approx(min(before, limit), abs=1e-9)
        # the clamped direction stays in the plane of d and b
        assert abs(np.cross(d, b) @ out) < 1e-9
    opposite = m.clamp_angle_select((-1.0, 0.0, 0.0), (1.0, 0.0, 0.0), 0.5)
    assert np.all(np.isfinite(opposite))
    assert math.acos(opposite[0]) == pytest.approx(0.5)



def test_the_branch_free_angle_helpers_give_the_branching_forms_bits():
    """The solver's branch-free ``angle_between_vectors_select``, ``clamp_angle_select`` and
    ``rotations.swing_select`` against the branching forms the per-team reference solver keeps
    (tests/reference_solver): the same bits on random inputs and on each degenerate path (a zero
    vector, parallel and opposite vectors, an angle within the limit)."""
    from magica_py.solver.rotations import swing_select
    from reference_solver.solver.maths import angle_between_vectors, clamp_angle
    from reference_solver.solver.rotations import full_swing

    x = (1.0, 0.0, 0.0)
    pairs = [(tuple(RNG.normal(size=3)), tuple(RNG.normal(size=3))) for _ in range(40)]
    pairs += [(x, x), (x, (-1.0, 0.0, 0.0)), (x, (1.0, 1e-9, 0.0)), (x, (-1.0, 1e-9, 0.0)),
              ((0.0, 2.0, 0.0), (0.0, 0.0, 3.0))]
    for a, b in pairs:
        assert m.angle_between_vectors_select(a, b) == angle_between_vectors(a, b)
        for limit in (0.05, 0.7, 3.0):
            assert np.array(m.clamp_angle_select(a, b, limit)).tobytes() == \
                np.array(clamp_angle(a, b, limit)).tobytes()
        ua, ub = m.v_normalize(a), m.v_normalize(b)
        assert np.array(swing_select(ua, ub)).tobytes() == np.array(full_swing(ua, ub)).tobytes()
    assert m.angle_between_vectors_select((0.0, 0.0, 0.0), x) == angle_between_vectors((0.0, 0.0, 0.0), x) == 0.0

def test_clamp_length_and_project_on_plane_and_shift():
    np.testing.assert_allclose(m.clamp_length((3.0, 4.0, 0.0), 1.0), (0.6, 0.8, 0.0))
    assert m.clamp_length((3.0, 4.0, 0.0), 10.0) == (3.0, 4.0, 0.0)
    np.testing.assert_allclose(m.project_on_plane((1.0, 2.0, 3.0), (0.0, 2.0, 0.0)), (1.0, 0.0, 3.0))
    q = quat_of((0, 1, 0), math.pi / 2)
    # shift(p, pivot, dv, dq) = pivot + dq (p - pivot) + dv
    np.testing.assert_allclose(m.shift_position((2.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), q),
                               (1.0, 1.0, -1.0), atol=1e-15)


def test_mass_helpers_match_reference_formulas():
    assert m.depth_mass(0.0) == 6.0 and m.depth_mass(1.0) == 1.0
    assert m.inverse_mass_friction(1.0) == 0.25
    assert m.inverse_mass_friction_depth(0.5, 0.5) == pytest.approx(1 / (1 + 1.5 + 1.25))
    assert m.saturate(-1.0) == 0.0 and m.saturate(2.0) == 1.0 and m.saturate(0.3) == 0.3
    assert m.unlerp(2.0, 4.0, 3.0) == 0.5 and m.unlerp(1.0, 1.0, 5.0) == 0.0


def unity_mathematics_quaternion(r):
    """Transcription of Unity.Mathematics ``quaternion(float3x3)`` (sign-bit masks -> branches)."""
    u, v, w = r[:, 0], r[:, 1], r[:, 2]
    u_neg = math.copysign(1.0, u[0]) < 0
    t = v[1] + (-w[2] if u_neg else w[2])
    t_neg = math.copysign(1.0, t) < 0
    tr = 1.0 + abs(u[0])
    flips = np.array([0, 1, 1, 1])
    if u_neg:
        flips ^= np.array([0, 1, 0, 1])
    if t_neg:
        flips ^= np.array([1, 1, 1, 0])
    signs = np.where(flips == 1, -1.0, 1.0)
    value = np.array([tr, u[1], w[0], v[2]]) + np.array([t, v[0], u[2], w[1]]) * signs
    if u_neg:
        value = value[[2, 3, 0, 1]]  # .zwxy
    if not t_neg:
        value = value[[3, 2, 1, 0]]  # .wzyx
    return value / np.linalg.norm(value)


def test_q_from_matrix_matches_unity_mathematics_signs_exactly():
    seen_branches = set()
    for _ in range(400):
        q = random_quat()
        r = matrix_of(q)
        expected = unity_mathematics_quaternion(r)
        np.testing.assert_allclose(m.q_from_matrix(*r.ravel()), expected, atol=1e-12)
        u_neg = r[0, 0] < 0
        seen_branches.add((u_neg, (r[1, 1] - r[2, 2] if u_neg else r[1, 1] + r[2, 2]) < 0))
    assert len(seen_branches) == 4


def test_closest_segment_segment_matches_hand_computed_cases():
    from magica_py.kernels.math3d import closest_segment_segment

    # crossing segments: closest points at both midpoints
    s, t, c1, c2 = closest_segment_segment((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.5, 1.0, -1.0), (0.5, 1.0, 1.0))
    assert (s, t) == (0.5, 0.5)
    np.testing.assert_allclose(c1, (0.5, 0.0, 0.0)) and np.testing.assert_allclose(c2, (0.5, 1.0, 0.0))
    # the second segment lies beyond the first one's end: s clamps to 1
    s, t, c1, _ = closest_segment_segment((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (3.0, 1.0, -1.0), (3.0, 1.0, 1.0))
    assert (s, t) == (1.0, 0.5) and c1 == (1.0, 0.0, 0.0)
    # a point (degenerate first segment) against a segment: its projection, clamped
    s, t, _, c2 = closest_segment_segment((0.25, 2.0, 0.0), (0.25, 2.0, 0.0), (0.0, 0.0, 0.0), (1.0, 0.0, 0.0))
    assert (s, t) == (0.0, 0.25) and c2 == (0.25, 0.0, 0.0)
    # both degenerate: parameters 0, never NaN
    s, t, _, _ = closest_segment_segment((1.0, 1.0, 1.0), (1.0, 1.0, 1.0), (2.0, 2.0, 2.0), (2.0, 2.0, 2.0))
    assert (s, t) == (0.0, 0.0)
