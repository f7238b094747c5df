"""Vector and quaternion helpers for numba kernels (docs/solver.md §0.2, Unity.Mathematics semantics).

Conventions: Y up, left-handed (Unity). Vectors are 3-tuples, quaternions are 4-tuples
``(x, y, z, w)``; ``q_mul(a, b)`` applies ``b`` first. Helpers take and return tuples so that
values stay in registers (docs/tech-notes.md §10): never allocate inside these functions.
``load3``/``store3`` move tuples in and out of ``(n, 3)`` arrays.

Every function here is also callable from plain Python (numba dispatches), which the tests
use to compare against independent numpy computations.
"""
from __future__ import annotations

import math

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels import trig

EPSILON = 1e-8  # SystemDefine.Epsilon


# ----------------------------------------------------------------------------- array access
@kernel
def load3(a, i):
    return (a[i, 0], a[i, 1], a[i, 2])


@kernel
def store3(a, i, v):
    a[i, 0] = v[0]
    a[i, 1] = v[1]
    a[i, 2] = v[2]


@kernel
def load4(a, i):
    return (a[i, 0], a[i, 1], a[i, 2], a[i, 3])


@kernel
def store4(a, i, q):
    a[i, 0] = q[0]
    a[i, 1] = q[1]
    a[i, 2] = q[2]
    a[i, 3] = q[3]


# ----------------------------------------------------------------------------- vectors
@kernel
def v_add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


@kernel
def v_sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@kernel
def v_scale(a, s):
    return (a[0] * s, a[1] * s, a[2] * s)


@kernel
def v_mul(a, b):
    """Component-wise product."""
    return (a[0] * b[0], a[1] * b[1], a[2] * b[2])


@kernel
def v_dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@kernel
def v_cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@kernel
def v_length(a):
    return np.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


@kernel
def v_length_sq(a):
    return a[0] * a[0] + a[1] * a[1] + a[2] * a[2]


@kernel
def v_normalize(a):
    """Unit vector, or the zero vector when ``|a|`` is below 1e-12 (normalizesafe)."""
    n = np.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    if n < 1e-12:
        return (0.0, 0.0, 0.0)
    inv = 1.0 / n
    return (a[0] * inv, a[1] * inv, a[2] * inv)


@kernel
def v_lerp(a, b, t):
    """``a + (b - a) t`` with no clamp on t (Unity.Mathematics lerp)."""
    return (a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t, a[2] + (b[2] - a[2]) * t)


@kernel
def saturate(x):
    if x < 0.0:
        return 0.0
    if x > 1.0:
        return 1.0
    return x


@kernel
def lerp(a, b, t):
    return a + (b - a) * t


@kernel
def unlerp(a, b, x):
    """Inverse of lerp: the t with ``lerp(a, b, t) == x`` (0 when a == b)."""
    if b == a:
        return 0.0
    return (x - a) / (b - a)


@kernel
def clamp_length(v, max_length):
    """``clamp_len`` of §0.2: scale v down to max_length when it is longer (and |v| > 1e-9)."""
    n = v_length(v)
    if n > 1e-9 and n > max_length:
        return v_scale(v, max_length / n)
    return v


@kernel
def project_on_plane(v, n):
    """Remove the component of v along the plane normal n (n need not be unit)."""
    nn = v_dot(n, n)
    if nn < 1e-12:
        return v
    return v_sub(v, v_scale(n, v_dot(v, n) / nn))


@kernel
def orthogonal_axis(a):
    """A unit vector orthogonal to the unit vector a (fallback axis for opposite vectors).

    Follows MathUtility.FromToRotation's choice and falls back to another basis axis when
    that choice is degenerate (Appendix 3.11: a documented guard, never NaN).
    """
    if a[0] > a[1] and a[0] > a[2]:
        axis = v_cross(a, (0.0, 1.0, 0.0))
    else:
        axis = v_cross(a, (1.0, 0.0, 0.0))
    if v_length_sq(axis) < 1e-12:
        axis = v_cross(a, (0.0, 1.0, 0.0))
        if v_length_sq(axis) < 1e-12:
            axis = v_cross(a, (0.0, 0.0, 1.0))
    return v_normalize(axis)


# ----------------------------------------------------------------------------- quaternions


@kernel
def q_mul(a, b):
    """Hamilton product ``a * b``: applies b first, then a."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


@kernel
def q_inverse(q):
    """Conjugate divided by |q|^2 (``qinv`` of §0.2)."""
    n = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]
    if n < 1e-30:
        return (0.0, 0.0, 0.0, 1.0)
    inv = 1.0 / n
    return (-q[0] * inv, -q[1] * inv, -q[2] * inv, q[3] * inv)


@kernel
def q_dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]


@kernel
def q_normalize(q):
    """Unit quaternion, or identity when |q| is (near) zero (normalizesafe)."""
    n = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    if n < 1e-12:
        return (0.0, 0.0, 0.0, 1.0)
    inv = 1.0 / n
    return (q[0] * inv, q[1] * inv, q[2] * inv, q[3] * inv)


@kernel
def q_rotate(q, v):
    """Rotate vector v by quaternion q (``q * v``)."""
    qx, qy, qz, qw = q
    tx = 2.0 * (qy * v[2] - qz * v[1])
    ty = 2.0 * (qz * v[0] - qx * v[2])
    tz = 2.0 * (qx * v[1] - qy * v[0])
    return (
        v[0] + qw * tx + (qy * tz - qz * ty),
        v[1] + qw * ty + (qz * tx - qx * tz),
        v[2] + qw * tz + (qx * ty - qy * tx),
    )


@kernel
def q_slerp(q1, q2, t):
    """Unity.Mathematics slerp (§0.2), normalized afterwards as the source usually does."""
    d = q_dot(q1, q2)
    b = q2
    if d < 0.0:
        d = -d
        b = (-q2[0], -q2[1], -q2[2], -q2[3])
    if d < 0.9995:
        angle = trig.acos(d)
        w1 = trig.sin((1.0 - t) * angle)
        w2 = trig.sin(t * angle)
        inv_s = 1.0 / trig.sin(angle)
        r = (
            (q1[0] * w1 + b[0] * w2) * inv_s,
            (q1[1] * w1 + b[1] * w2) * inv_s,
            (q1[2] * w1 + b[2] * w2) * inv_s,
            (q1[3] * w1 + b[3] * w2) * inv_s,
        )
        return q_normalize(r)
    return slerp_near(q1, q2, t)


@kernel(inline="always")
def slerp_near(q1, q2, t):
    """``q_slerp(q1, q2, t)`` where its normalised-lerp path applies (the rotations within about
    3.6 degrees, ``|q1 . q2| >= 0.9995``): that path alone (the same bits without the
    trigonometry)."""
    b = (-q2[0], -q2[1], -q2[2], -q2[3]) if q_dot(q1, q2) < 0.0 else q2
    return q_normalize((
        q1[0] + (b[0] - q1[0]) * t,
        q1[1] + (b[1] - q1[1]) * t,
        q1[2] + (b[2] - q1[2]) * t,
        q1[3] + (b[3] - q1[3]) * t,
    ))


@kernel
def q_axis_angle(axis, angle):
    """Rotation of ``angle`` radians about the unit vector ``axis``."""
    s, c = trig.sincos(0.5 * angle)
    return (axis[0] * s, axis[1] * s, axis[2] * s, c)


@kernel
def q_from_euler_degrees(x, y, z):
    """Unity's Quaternion.Euler: rotate about Z, then X, then Y (q = qy * qx * qz)."""
    d2r = math.pi / 180.0
    qx = q_axis_angle((1.0, 0.0, 0.0), x * d2r)
    qy = q_axis_angle((0.0, 1.0, 0.0), y * d2r)
    qz = q_axis_angle((0.0, 0.0, 1.0), z * d2r)
    return q_mul(qy, q_mul(qx, qz))


@kernel(inline="always")
def q_from_matrix(m00, m01, m02, m10, m11, m12, m20, m21, m22):
    """Quaternion of a rotation matrix (row r, column c = m{rc}), as Unity.Mathematics does.

    The branch depends on the sign of m00 and of m11 +/- m22, and the branch's major
    component is positive (Appendix 3.12); the sign matters for ToAngleAxis.
    """
    if math.copysign(1.0, m00) >= 0.0:
        t = m11 + m22
        if math.copysign(1.0, t) >= 0.0:
            q = (m21 - m12, m02 - m20, m10 - m01, 1.0 + m00 + t)
        else:
            q = (1.0 + m00 - t, m01 + m10, m02 + m20, m21 - m12)
    else:
        t = m11 - m22
        if math.copysign(1.0, t) >= 0.0:
            q = (m01 + m10, 1.0 - m00 + t, m12 + m21, m02 - m20)
        else:
            q = (m02 + m20, m12 + m21, 1.0 - m00 - t, m10 - m01)
    return q_normalize(q)


@kernel
def q_to_matrix(q):
    """Rotation matrix rows of a unit quaternion: returns (r0, r1, r2) 3-tuples."""
    x, y, z, w = q
    return (
        (1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w)),
        (2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w)),
        (2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y)),
    )


@kernel
def q_look_rotation(forward, up):
    """Unity.Mathematics quaternion.LookRotation: +Z = forward, +Y towards up (both unit)."""
    x_axis = v_normalize(v_cross(up, forward))
    y_axis = v_cross(forward, x_axis)
    return q_from_matrix(
        x_axis[0], y_axis[0], forward[0],
        x_axis[1], y_axis[1], forward[1],
        x_axis[2], y_axis[2], forward[2],
    )


@kernel
def rot_from_normal_tangent(normal, tangent):
    """``rot_from(n, t)`` of §0.2 (MathUtility.ToRotation): forward = t, up = n."""
    return q_look_rotation(tangent, normal)


@kernel(inline="always")
def q_normal_axis(q):
    """``nor(q) = q * up``."""
    return q_rotate(q, (0.0, 1.0, 0.0))


@kernel(inline="always")
def q_tangent_axis(q):
    """``tan(q) = q * forward``."""
    return q_rotate(q, (0.0, 0.0, 1.0))


@kernel
def from_to_rotation_unit(a, b, t):
    """``fromto_v`` for unit inputs (the WithoutNormalize variant), scaled by the fraction t."""
    c = v_dot(a, b)
    if c > 1.0:
        c = 1.0
    elif c < -1.0:
        c = -1.0
    if abs(1.0 + c) < 1e-6:
        return q_axis_angle(orthogonal_axis(a), math.pi * t)
    if abs(1.0 - c) < 1e-6:
        return (0.0, 0.0, 0.0, 1.0)
    axis = v_normalize(v_cross(a, b))
    return q_axis_angle(axis, trig.acos(c) * t)


@kernel
def from_to_rotation(a, b, t):
    """``fromto_v(a, b, t)`` of §0.2: the rotation taking direction a towards b by fraction t."""
    return from_to_rotation_unit(v_normalize(a), v_normalize(b), t)


@kernel
def q_from_to(a, b):
    """``fromto_q(a, b) = b * qinv(a)``: the rotation taking orientation a to orientation b."""
    return q_mul(b, q_inverse(a))


@kernel
def q_angle(a, b):
    """``angle_q`` of §0.2, in radians."""
    d = q_dot(a, b)
    if abs(d) < 0.9999:
        if d > 1.0:
            d = 1.0
        elif d < -1.0:
            d = -1.0
        ang = 2.0 * trig.acos(d)
        if ang > math.pi:
            ang = 2.0 * math.pi - ang
        return ang
    return 0.0


@kernel(inline="always")
def q_to_angle_axis(q):
    """``ToAngleAxis`` of §0.2: returns (angle radians, axis 3-tuple; zero axis when degenerate)."""
    a = trig.acos(q[3]) if abs(q[3]) < 0.9999 else 0.0
    s = trig.sin(a)
    if abs(s) < 1e-6:
        return 2.0 * a, (0.0, 0.0, 0.0)
    return 2.0 * a, (q[0] / s, q[1] / s, q[2] / s)


@kernel
def shift_position(p, pivot, delta, rotation):
    """``shift(p, pivot, dv, dq) = pivot + dq (p - pivot) + dv`` (MathUtility.ShiftPosition)."""
    return v_add(v_add(pivot, q_rotate(rotation, v_sub(p, pivot))), delta)


@kernel
def closest_segment_segment(p1, q1, p2, q2):
    """Ericson's ClosestPtSegmentSegment (§0.2, degeneracy threshold 1e-8): the parameters
    (s, t) of the closest points on segments p1q1 and p2q2, and the points themselves."""
    eps = 1e-8
    d1 = v_sub(q1, p1)
    d2 = v_sub(q2, p2)
    r = v_sub(p1, p2)
    a = v_dot(d1, d1)
    e = v_dot(d2, d2)
    f = v_dot(d2, r)
    if a <= eps and e <= eps:
        s = 0.0
        t = 0.0
    elif a <= eps:
        s = 0.0
        t = saturate(f / e)
    else:
        c = v_dot(d1, r)
        if e <= eps:
            t = 0.0
            s = saturate(-c / a)
        else:
            b = v_dot(d1, d2)
            denom = a * e - b * b
            s = saturate((b * f - c * e) / denom) if denom != 0.0 else 0.0
            t = (b * s + f) / e
            if t < 0.0:
                t = 0.0
                s = saturate(-c / a)
            elif t > 1.0:
                t = 1.0
                s = saturate((b - c) / a)
    return s, t, v_add(p1, v_scale(d1, s)), v_add(p2, v_scale(d2, t))


# ----------------------------------------------------------------------------- masses (§0.2)
FRICTION_MASS = 3.0
DEPTH_MASS = 5.0


@kernel
def depth_mass(depth):
    return 1.0 + DEPTH_MASS * (1.0 - depth) * (1.0 - depth)


@kernel
def inverse_mass_friction(friction):
    """``w_f(f) = 1 / (1 + 3 f)``."""
    return 1.0 / (1.0 + FRICTION_MASS * friction)


@kernel
def inverse_mass_friction_depth(friction, depth):
    """``w_fd(f, depth) = 1 / (1 + 3 f + 5 (1 - depth)^2)``."""
    return 1.0 / (1.0 + FRICTION_MASS * friction + DEPTH_MASS * (1.0 - depth) * (1.0 - depth))


# ----------------------------------------------------------------------------- select forms
# Functions of the kind above with every path computed and the answer selected (no branch): the
# same bits on every path as the branching forms, and a lane loop calling them vectorises. They
# cost every path's work, so the lane-inner stages use them where the paths are cheap or the
# expensive one is the common one; scalar code keeps the branching forms. Where the solver uses
# only the branch-free form (the angle between vectors, the angle clamp), the branching one lives
# with the test-only reference solver (tests/reference_solver/solver/maths.py).

@kernel
def v_normalize_select(a):
    """``v_normalize`` without a branch."""
    n = np.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    inv = 1.0 / max(n, 1e-300)   # a zero vector: discarded below (and no 1/0 with the JIT off)
    small = n < 1e-12
    return (0.0 if small else a[0] * inv, 0.0 if small else a[1] * inv, 0.0 if small else a[2] * inv)


@kernel
def q_normalize_select(q):
    """``q_normalize`` without a branch."""
    n = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    inv = 1.0 / max(n, 1e-300)   # a zero quaternion: discarded below
    small = n < 1e-12
    return (0.0 if small else q[0] * inv, 0.0 if small else q[1] * inv,
            0.0 if small else q[2] * inv, 1.0 if small else q[3] * inv)


@kernel
def orthogonal_axis_select(a):
    """``orthogonal_axis`` without a branch."""
    first = v_cross(a, (0.0, 1.0, 0.0)) if (a[0] > a[1] and a[0] > a[2]) else v_cross(a, (1.0, 0.0, 0.0))
    second = v_cross(a, (0.0, 1.0, 0.0))
    third = v_cross(a, (0.0, 0.0, 1.0))
    fallback = third if v_length_sq(second) < 1e-12 else second
    return v_normalize_select(fallback if v_length_sq(first) < 1e-12 else first)


@kernel
def q_slerp_select(q1, q2, t):
    """``q_slerp`` without a branch (both of its paths computed)."""
    to, angle, inv_sin, far = q_slerp_path(q1, q2)
    return q_slerp_along(q1, to, angle, inv_sin, far, t)


@kernel
def q_slerp_path(q1, q2):
    """The part of ``q_slerp_select(q1, q2, t)`` that does not depend on t: the target on q1's
    side of the double cover, the angle between them, 1 / its sine, and 1.0 where the slerp
    takes its far (sine-weighted) path, 0.0 where the normalised lerp. ``q_slerp_along`` finishes
    it for a t; computed once for many t, the acos and a sine are left out of each."""
    d = q_dot(q1, q2)
    negative = d < 0.0
    to = (-q2[0], -q2[1], -q2[2], -q2[3]) if negative else q2
    d = -d if negative else d
    angle = trig.acos(d)
    inv_sin = 1.0 / trig.sin(angle)
    return to, angle, inv_sin, 1.0 if d < 0.9995 else 0.0


@kernel
def q_slerp_along(q1, to, angle, inv_sin, far, t):
    """``q_slerp_select(q1, q2, t)`` from ``q_slerp_path(q1, q2)``'s values (the same bits)."""
    w1 = trig.sin((1.0 - t) * angle)
    w2 = trig.sin(t * angle)
    sine = q_normalize_select(((q1[0] * w1 + to[0] * w2) * inv_sin, (q1[1] * w1 + to[1] * w2) * inv_sin,
                               (q1[2] * w1 + to[2] * w2) * inv_sin, (q1[3] * w1 + to[3] * w2) * inv_sin))
    near = q_normalize_select((q1[0] + (to[0] - q1[0]) * t, q1[1] + (to[1] - q1[1]) * t,
                               q1[2] + (to[2] - q1[2]) * t, q1[3] + (to[3] - q1[3]) * t))
    use_far = far != 0.0
    return (sine[0] if use_far else near[0], sine[1] if use_far else near[1], sine[2] if use_far else near[2],
            sine[3] if use_far else near[3])


@kernel(inline="always")
def from_to_rotation_unit_select(a, b, t, with_opposite=True):
    """``from_to_rotation_unit`` without a branch. ``with_opposite`` False (a constant at the
    call site) leaves the path of opposite a and b out: the result is then not the
    reference's where ``opposite_unit(a, b)``, which the caller must detect and redo."""
    c = v_dot(a, b)
    c = 1.0 if c > 1.0 else c
    c = -1.0 if c < -1.0 else c
    general = q_axis_angle(v_normalize_select(v_cross(a, b)), trig.acos(c) * t)
    is_parallel = abs(1.0 - c) < 1e-6
    q = ((0.0, 0.0, 0.0, 1.0) if is_parallel else general)
    if not with_opposite:
        return q
    opposite = q_axis_angle(orthogonal_axis_select(a), math.pi * t)
    return opposite if opposite_unit(a, b) else q


@kernel(inline="always")
def opposite_unit(a, b):
    """Are the unit vectors a and b opposite in the sense of the from-to rotations and swings
    (``|1 + a.b| < 1e-6``, a.b clamped to [-1, 1])?"""
    c = v_dot(a, b)
    c = 1.0 if c > 1.0 else c
    c = -1.0 if c < -1.0 else c
    return abs(1.0 + c) < 1e-6


@kernel
def angle_between_vectors_select(a, b):
    """``angle_v`` (§0.2): the unsigned angle in radians between a and b, 0 when either is zero,
    without a branch (every path computed, the answer selected)."""
    la = v_length(a)
    lb = v_length(b)
    c = v_dot(a, b) / (la * lb)
    c = 1.0 if c > 1.0 else c
    c = -1.0 if c < -1.0 else c
    angle = trig.acos(c)
    return 0.0 if (la < 1e-12 or lb < 1e-12) else angle


@kernel
def clamp_angle_select(direction, base, max_angle):
    """``clamp_angle`` (§0.2, MathUtility.ClampAngle) without a branch: ``direction`` rotated
    towards ``base`` until their angle is ``max_angle`` (kept when within it or parallel;
    opposite vectors turn about ``orthogonal_axis``), its length kept."""
    d = v_normalize_select(direction)
    b = v_normalize_select(base)
    c = v_dot(d, b)
    c = 1.0 if c > 1.0 else c
    c = -1.0 if c < -1.0 else c
    alpha = trig.acos(c)
    axis = orthogonal_axis_select(d) if abs(1.0 + c) < 1e-6 else v_normalize_select(v_cross(d, b))
    turned = q_rotate(q_axis_angle(axis, alpha - max_angle), direction)
    keep = (alpha <= max_angle) or (not (abs(1.0 + c) < 1e-6) and abs(1.0 - c) < 1e-6)
    return direction if keep else turned
