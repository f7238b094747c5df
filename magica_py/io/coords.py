"""glTF / BVH (right-handed, Y up) → Unity (left-handed, Y up), converted once at load.

Derivation. Both systems are Y up; they differ by the handedness of the axis triple. The
change of basis is a mirror ``M = diag(±1, 1, ±1)`` with one axis negated (det M = -1):

* a point or a displacement p becomes ``M p`` (negate one component);
* a rotation matrix R becomes ``M R M`` (conjugation by the mirror). For a quaternion
  ``(v, w)`` the rotation axis v is an *axial* vector, which under a reflection transforms
  as ``det(M) M v = -M v`` while the angle w is unchanged: mirroring X gives
  ``(x, y, z, w) → (x, -y, -z, w)``, mirroring Z gives ``(x, y, z, w) → (-x, -y, z, w)``;
* scales are unchanged (``M S M = S`` for a diagonal S);
* a full matrix A becomes ``M A M``.

Because the conversion is a conjugation, it commutes with composition: converting every
node's local TRS gives exactly the converted world poses (``tests/test_io_coords.py`` checks
this and that a known point lands where it should).

Which axis: glTF 2.0 assets face +Z (spec "the front of an asset faces +Z"); mirroring X
keeps the front at Unity's +Z and puts the character's left at -X, as in Unity. This is
UniVRM's ``ReverseX`` (VRM 1.0 and plain glTF). VRM 0.x files were exported from Unity
with ``ReverseZ`` (the avatar faces -Z inside the file), so a VRM 0.x file is converted by
mirroring Z, which again puts the face at +Z and the left hand at -X. BVH files (CMU,
Mixamo) are right-handed Y up facing +Z, converted like glTF.
"""
from __future__ import annotations

import numpy as np

MIRROR_AXES = ("x", "z")

_POSITION_SIGN = {"x": np.array([-1.0, 1.0, 1.0]), "z": np.array([1.0, 1.0, -1.0])}
_ROTATION_SIGN = {"x": np.array([1.0, -1.0, -1.0, 1.0]), "z": np.array([-1.0, -1.0, 1.0, 1.0])}


def _check(axis: str) -> str:
    if axis not in MIRROR_AXES:
        raise ValueError(f"mirror axis must be one of {MIRROR_AXES}, got {axis!r}")
    return axis


def position_to_unity(p, axis: str = "x") -> np.ndarray:
    """Points or displacements (..., 3) from a right-handed file to Unity."""
    return np.asarray(p, dtype=np.float64) * _POSITION_SIGN[_check(axis)]


def rotation_to_unity(q, axis: str = "x") -> np.ndarray:
    """Quaternions (..., 4) ``(x, y, z, w)`` from a right-handed file to Unity."""
    return np.asarray(q, dtype=np.float64) * _ROTATION_SIGN[_check(axis)]


def scale_to_unity(s, axis: str = "x") -> np.ndarray:
    """Scales are unchanged by the mirror (kept for symmetry of the call sites)."""
    _check(axis)
    return np.asarray(s, dtype=np.float64).copy()


def matrix_to_unity(m, axis: str = "x") -> np.ndarray:
    """A 4x4 (or 3x3) matrix ``A`` becomes ``M A M``."""
    m = np.asarray(m, dtype=np.float64)
    n = m.shape[-1]
    sign = np.ones(n)
    sign[:3] = _POSITION_SIGN[_check(axis)]
    return m * sign[:, None] * sign[None, :]


# The conversion is its own inverse (M M = I); these names make call sites read right.
position_from_unity = position_to_unity
rotation_from_unity = rotation_to_unity
