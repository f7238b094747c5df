"""Vectorised numpy quaternion maths for the importers (load time, not the frame path).

Same conventions as ``magica_py.kernels.math3d`` (``(x, y, z, w)``, ``qmul(a, b)`` applies
``b`` first), but over arrays of shape (..., 4) so a whole clip converts in one call. The
numba helpers of math3d work on single tuples; these are their batched twins. Their
transcendental maths and sums go through ``kernels/portable`` so an imported clip has the
same bits on every CPU (docs/determinism.md).
"""
from __future__ import annotations

import numpy as np
from magica_py.kernels import portable


def qmul(a, b):
    """Hamilton product a * b over (..., 4) arrays."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack([
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ], axis=-1)


def qconj(q):
    q = np.asarray(q, dtype=np.float64)
    return q * np.array([-1.0, -1.0, -1.0, 1.0])


def qnormalize(q):
    q = np.asarray(q, dtype=np.float64)
    n = np.asarray(portable.norm(q))[..., None]
    return np.where(n > 1e-12, q / np.where(n > 1e-12, n, 1.0), np.array([0.0, 0.0, 0.0, 1.0]))


def qrotate(q, v):
    """Rotate vectors v (..., 3) by unit quaternions q (..., 4)."""
    q = np.asarray(q, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    u = q[..., :3]
    w = q[..., 3:4]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def qaxis_angle(axis, angle):
    """Quaternion for a rotation of ``angle`` radians about the unit ``axis`` (broadcasts)."""
    axis = np.asarray(axis, dtype=np.float64)
    half = 0.5 * np.asarray(angle, dtype=np.float64)[..., None]
    return np.concatenate([axis * portable.sin_array(half), portable.cos_array(half)], axis=-1)


def qcanonical(q):
    """The same rotations with w >= 0 (q and -q are one rotation): for comparing quaternions."""
    q = np.asarray(q, dtype=np.float64)
    return np.where(q[..., 3:4] < 0.0, -q, q)


def qangle(a, b):
    """Angle in radians between the rotations a and b (..., 4)."""
    d = np.abs(portable.dot3(qnormalize(a), qnormalize(b)))
    return 2.0 * portable.acos_array(d)


def qfrom_matrix(m):
    """Quaternion of a proper rotation matrix (3, 3) (Shepperd's method, w >= 0)."""
    m = np.asarray(m, dtype=np.float64)
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0.0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s]
    return qcanonical(qnormalize(np.array(q)))


def qto_matrix(q):
    """Rotation matrices (..., 3, 3) of unit quaternions (..., 4)."""
    q = np.asarray(q, dtype=np.float64)
    x, y, z, w = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], axis=-2)


def qfrom_to(a, b):
    """Shortest rotation taking direction a to direction b (3,) (identity if either is ~0)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    na, nb = portable.norm(a), portable.norm(b)
    if na < 1e-12 or nb < 1e-12:
        return np.array([0.0, 0.0, 0.0, 1.0])
    a, b = a / na, b / nb
    d = portable.dot3(a, b)
    if d < -1.0 + 1e-12:  # opposite: turn half a turn about any axis orthogonal to a
        axis = np.cross(a, [1.0, 0.0, 0.0])
        if portable.norm(axis) < 1e-6:
            axis = np.cross(a, [0.0, 1.0, 0.0])
        axis /= portable.norm(axis)
        return np.array([axis[0], axis[1], axis[2], 0.0])
    c = np.cross(a, b)
    q = np.array([c[0], c[1], c[2], 1.0 + d])
    return q / portable.norm(q)


def slerp(a, b, t):
    """Spherical interpolation between unit quaternions a and b (..., 4), shortest path."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)[..., None]
    d = np.asarray(portable.dot3(a, b))[..., None]
    b = np.where(d < 0.0, -b, b)
    d = np.abs(d)
    angle = portable.acos_array(d)
    s = portable.sin_array(angle)
    near = s < 1e-6
    safe = np.where(near, 1.0, s)
    w1 = np.where(near, 1.0 - t, portable.sin_array((1.0 - t) * angle) / safe)
    w2 = np.where(near, t, portable.sin_array(t * angle) / safe)
    return qnormalize(w1 * a + w2 * b)
