"""The branching forms of three helpers whose branch-free forms the package's lane stages use
(``magica_py.kernels.math3d``: ``angle_between_vectors_select``, ``clamp_angle_select``; the
skinning's matrix rows are read in place there). The per-team reference solver keeps its own
arithmetic, so it keeps these (docs/solver.md §0.2: ``angle_v``, ``MathUtility.ClampAngle``);
tests/test_angle_maths.py uses them too."""
from __future__ import annotations

from magica_py.jit import kernel
from magica_py.kernels import trig
from magica_py.kernels.math3d import (orthogonal_axis, q_axis_angle, q_rotate, v_cross, v_dot, v_length,
                                      v_normalize)


@kernel
def angle_between_vectors(a, b):
    """``angle_v``: the unsigned angle in radians, 0 when either vector is zero."""
    la = v_length(a)
    lb = v_length(b)
    if la < 1e-12 or lb < 1e-12:
        return 0.0
    c = v_dot(a, b) / (la * lb)
    if c > 1.0:
        c = 1.0
    elif c < -1.0:
        c = -1.0
    return trig.acos(c)


@kernel
def clamp_angle(direction, base, max_angle):
    """``MathUtility.ClampAngle``: rotate ``direction`` towards ``base`` until their angle is max_angle."""
    d = v_normalize(direction)
    b = v_normalize(base)
    c = v_dot(d, b)
    if c > 1.0:
        c = 1.0
    elif c < -1.0:
        c = -1.0
    alpha = trig.acos(c)
    if alpha <= max_angle:
        return direction
    if abs(1.0 + c) < 1e-6:
        axis = orthogonal_axis(d)
    elif abs(1.0 - c) < 1e-6:
        return direction
    else:
        axis = v_normalize(v_cross(d, b))
    return q_rotate(q_axis_angle(axis, alpha - max_angle), direction)


@kernel
def matrix_row(a, i, k):
    """Row k of matrix i of a ``(n, 4, 4)`` array, as a tuple."""
    return (a[i, k, 0], a[i, k, 1], a[i, k, 2], a[i, k, 3])
