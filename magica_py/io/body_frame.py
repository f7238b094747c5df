"""Which way a skeleton faces, read from its rest pose; the turn from one skeleton's facing
to another's; the floor and hips height that root motion is measured against.

Axes are the project's (Unity: left-handed, X right, Y up, Z forward), so for a body
``forward = across × up`` with ``across`` pointing from its left to its right side:

* **up**: from the hips towards the head (the highest of head, neck, upperChest, chest,
  spine that is mapped);
* **across**: the mean of right minus left over the mapped pairs of upper legs, upper arms
  and shoulders, made perpendicular to up;
* **forward**: ``across × up``, checked against the direction the feet point (foot → toes,
  horizontal part): ``feet`` says whether they agree.

A detected up or forward within 20° of a coordinate axis is snapped to it (files face an
axis; a slouch or a head held forward must not tilt the whole motion).

A frame given by the user (``forward`` and/or ``up``) replaces the detected axis; the
missing one is detected and made perpendicular. No numpy transcendental functions or BLAS
here: the results feed the simulation (square roots and cross products only).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from magica_py.io.quat import qfrom_matrix

_UP_CHAIN = ("head", "neck", "upperChest", "chest", "spine")
_PAIRS = ("UpperLeg", "UpperArm", "Shoulder")
AXIS_NAMES = {"+X": (1.0, 0.0, 0.0), "-X": (-1.0, 0.0, 0.0), "+Y": (0.0, 1.0, 0.0), "-Y": (0.0, -1.0, 0.0),
              "+Z": (0.0, 0.0, 1.0), "-Z": (0.0, 0.0, -1.0)}


def norm(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return np.sqrt(np.sum(v * v, axis=-1))


def unit(v) -> np.ndarray | None:
    n = float(norm(v))
    return None if n < 1e-9 else np.asarray(v, dtype=np.float64) / n


def axis_label(v) -> str:
    """``+Z`` for a vector within 1e-3 of an axis, else the rounded components."""
    for name, axis in AXIS_NAMES.items():
        if float(norm(np.asarray(v) - axis)) < 1e-3:
            return name
    return "(" + ", ".join(f"{x:+.3f}" for x in v) + ")"


@dataclass
class BodyFrame:
    """A skeleton's forward / up / across (unit vectors, project axes) or why it is unknown."""

    forward: np.ndarray | None
    up: np.ndarray | None
    across: np.ndarray | None
    how: str                         # "detected", "given", "given up, detected forward", ...
    feet: str                        # "agree", "disagree", "not checked (no toes mapped)"
    problem: str | None = None       # why the frame could not be determined

    @property
    def determined(self) -> bool:
        return self.forward is not None

    def describe(self) -> str:
        if not self.determined:
            return f"undetermined ({self.problem})"
        return f"forward {axis_label(self.forward)}, up {axis_label(self.up)} ({self.how}; feet {self.feet})"

    def matrix(self) -> np.ndarray:
        """(3, 3) columns across, up, forward."""
        return np.stack([self.across, self.up, self.forward], axis=1)


SNAP_DEG = 20.0     # a detected axis this close to a coordinate axis is that axis


def snap(v: np.ndarray) -> np.ndarray:
    """The coordinate axis nearest to unit ``v`` if within ``SNAP_DEG``, else ``v``: files are
    authored facing an axis, and a slouch or a head held forward must not tilt the motion."""
    best = max(AXIS_NAMES.values(), key=lambda a: float(np.sum(v * np.asarray(a))))
    cos_limit = 0.9396926207859083      # cos(20 deg), a constant: no transcendental call
    return np.asarray(best, dtype=np.float64) if float(np.sum(v * np.asarray(best))) >= cos_limit else v


def _position(mapping, index_of, positions, human):
    bone = mapping.get(human)
    return None if bone is None or bone not in index_of else positions[index_of[bone]]


def detect_frame(mapping: dict[str, str], index_of: dict[str, int], positions: np.ndarray,
                 forward=None, up=None) -> BodyFrame:
    """The body frame of a skeleton posed at ``positions`` (J, 3), from its humanoid map;
    ``forward`` / ``up`` (project axes) override the detected axes."""
    given_up = unit(up) if up is not None else None
    given_forward = unit(forward) if forward is not None else None
    hips = _position(mapping, index_of, positions, "hips")
    detected_up = None
    if hips is not None:
        for human in _UP_CHAIN:
            top = _position(mapping, index_of, positions, human)
            if top is not None and float(norm(top - hips)) > 1e-6:
                detected_up = snap(unit(top - hips))
                break
    across = np.zeros(3)
    for part in _PAIRS:
        left = _position(mapping, index_of, positions, f"left{part}")
        right = _position(mapping, index_of, positions, f"right{part}")
        if left is not None and right is not None:
            d = unit(right - left)
            if d is not None:
                across = across + d
    up_axis = given_up if given_up is not None else detected_up
    if given_forward is not None and up_axis is None:
        return BodyFrame(None, None, None, "given forward", "not checked", "no up: source_up not given and the "
                         "hips or the spine / head are not mapped")
    if given_forward is not None:
        f = unit(given_forward - up_axis * float(np.sum(given_forward * up_axis)))
        if f is None:
            return BodyFrame(None, None, None, "given", "not checked", "the given forward is parallel to up")
        a = np.cross(up_axis, f)         # across = up x forward in left-handed axes (X = Y x Z)
        how = "given" if given_up is not None else "given forward, detected up"
        return BodyFrame(f, up_axis, a, how, _feet(mapping, index_of, positions, f, up_axis))
    if up_axis is None:
        return BodyFrame(None, None, None, "detected", "not checked",
                         "the hips or the spine / head are not mapped, so up is unknown")
    a = unit(across - up_axis * float(np.sum(across * up_axis)))
    if a is None:
        return BodyFrame(None, None, None, "detected", "not checked",
                         "no left/right pair of upper legs, upper arms or shoulders is mapped, so across is unknown")
    f = snap(np.cross(a, up_axis))
    f = unit(f - up_axis * float(np.sum(f * up_axis)))
    a = np.cross(up_axis, f)
    how = "detected" if given_up is None else "given up, detected forward"
    return BodyFrame(f, up_axis, a, how, _feet(mapping, index_of, positions, f, up_axis))


def _feet(mapping, index_of, positions, forward, up) -> str:
    votes = []
    for side in ("left", "right"):
        foot = _position(mapping, index_of, positions, f"{side}Foot")
        toes = _position(mapping, index_of, positions, f"{side}Toes")
        if foot is None or toes is None:
            continue
        d = toes - foot
        d = d - up * float(np.sum(d * up))
        if float(norm(d)) > 1e-4:
            votes.append(float(np.sum(d * forward)) / float(norm(d)))
    if not votes:
        return "not checked (no foot and toes mapped)"
    return "agree" if min(votes) > 0.5 else "disagree"


def frame_rotation(source: BodyFrame, target: BodyFrame) -> np.ndarray:
    """Quaternion turning the source body frame onto the target's (``R · src = tgt``)."""
    s, t = source.matrix(), target.matrix()
    m = np.sum(t[:, None, :] * s[None, :, :], axis=-1)      # T · Sᵀ without BLAS
    return qfrom_matrix(m)


def floor_level(mapping: dict[str, str], index_of: dict[str, int], positions: np.ndarray, up) -> float | None:
    """Lowest height along ``up`` of the mapped feet and toes over ``positions`` (..., J, 3)."""
    idx = [index_of[mapping[h]] for h in ("leftFoot", "rightFoot", "leftToes", "rightToes")
           if h in mapping and mapping[h] in index_of]
    if not idx:
        return None
    heights = np.sum(positions[..., idx, :] * np.asarray(up), axis=-1)
    return float(heights.min())
