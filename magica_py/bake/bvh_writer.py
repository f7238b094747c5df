"""Write captured motion as a BVH file: the inverse of ``magica_py.io.bvh.load_bvh``.

* Axes and units: Unity (left-handed, metres) → the file's right-handed Y-up axes by the
  mirror of ``io.coords`` (its own inverse), lengths divided by ``unit_scale`` (metres per
  file unit: the rig's own for a BVH rig, 1 for generated rigs).
* Every joint's OFFSET is its rest local position; its rotation channels are
  ``Zrotation Xrotation Yrotation`` (``R = Rz·Rx·Ry``, degrees, first listed outermost, as
  CMU / cgspeed files and our reader use), each angle unwrapped over the frames so that no
  curve jumps by 360°. Roots, and joints whose local position moves away from the OFFSET
  (cloth bones stretch a little), also get ``Xposition Yposition Zposition``.
* BVH has no scale channel and no rest rotation: the rotation channels carry the whole
  local rotation every frame (exact); a scale other than 1 is not written (noted).
* Leaf joints end with an ``End Site`` half their own offset long (a bone length for tools
  that draw bones from joint to child); our reader ignores End Sites unless asked.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from magica_py import atomic
from magica_py.io import coords
from magica_py.io.quat import qto_matrix

ROTATION_ORDER = ("Zrotation", "Xrotation", "Yrotation")
POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")
MOVED_OFFSET = 1e-9      # m: a joint whose local position strays further from its OFFSET gets position channels
SCALE_TOLERANCE = 1e-9


def euler_zxy_degrees(q: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions → (..., 3) angles (z, x, y) in degrees with
    ``R(q) = Rz(z)·Rx(x)·Ry(y)``; at gimbal lock (x = ±90°) y is 0."""
    m = qto_matrix(q)
    sx = np.clip(m[..., 2, 1], -1.0, 1.0)
    cx = np.hypot(m[..., 2, 0], m[..., 2, 2])
    x = np.arctan2(sx, cx)
    regular = cx > 1e-12
    y = np.where(regular, np.arctan2(-m[..., 2, 0], m[..., 2, 2]), 0.0)
    z = np.where(regular, np.arctan2(-m[..., 0, 1], m[..., 1, 1]), np.arctan2(m[..., 1, 0], m[..., 0, 0]))
    return np.degrees(np.stack([z, x, y], axis=-1))


def bvh_names(names: list[str]) -> list[str]:
    """Joint names without whitespace (a BVH token ends at a space), unique."""
    out, used = [], set()
    for n in names:
        base = re.sub(r"\s+", "_", n) or "joint"
        name, k = base, 1
        while name in used:
            name, k = f"{base}_{k}", k + 1
        used.add(name)
        out.append(name)
    return out


def write_bvh(path, motion, *, unit_scale: float = 1.0, mirror_axis: str = "x") -> list[str]:
    """Write ``motion`` (a ``capture.CapturedMotion`` whose bones form whole chains: every
    captured bone's parent is captured or it is a root) to ``path``; returns notes."""
    if not unit_scale > 0:
        raise ValueError(f"unit scale must be positive, got {unit_scale}")
    notes = []
    f, b = motion.local_position.shape[:2]
    if f == 0:
        raise ValueError("nothing to write: the capture has no frame")
    offsets = coords.position_from_unity(motion.rest_position, mirror_axis) / unit_scale
    positions = coords.position_from_unity(motion.local_position, mirror_axis) / unit_scale
    angles = euler_zxy_degrees(coords.rotation_from_unity(motion.local_rotation, mirror_axis))
    angles = np.degrees(np.unwrap(np.radians(angles), axis=0))
    moved = np.abs(motion.local_position - motion.rest_position[None]).max(axis=(0, 2)) > MOVED_OFFSET
    roots = motion.parent < 0
    with_position = roots | moved
    scaled = np.abs(motion.local_scale - 1.0).max(axis=(0, 2)) > SCALE_TOLERANCE
    if scaled.any():
        notes.append(f"BVH has no scale channels: the scale of {int(scaled.sum())} bones is not written "
                     f"({', '.join(motion.names[j] for j in np.flatnonzero(scaled)[:5])}"
                     f"{' ...' if scaled.sum() > 5 else ''})")
    if f > 1:
        spread = float(motion.frame_times.max() - motion.frame_times.min())
        if spread > 1e-9:
            notes.append(f"frame times vary by {spread:.3g} s: BVH has one frame time, the mean "
                         f"{float(motion.frame_times.mean()):.6g} s is written")
    if int(roots.sum()) > 1:
        notes.append(f"{int(roots.sum())} root joints: written as several ROOT blocks")
    names = bvh_names(motion.names)
    if names != list(motion.names):
        notes.append("joint names with whitespace were written with underscores")
    children: dict[int, list[int]] = {}
    for j in range(b):
        children.setdefault(int(motion.parent[j]), []).append(j)

    lines = ["HIERARCHY"]
    columns: list[np.ndarray] = []

    def number(x: float) -> str:
        return f"{x + 0.0:.10g}"

    def joint(j: int, depth: int) -> None:
        pad = "  " * depth
        lines.append(f"{pad}{'ROOT' if motion.parent[j] < 0 else 'JOINT'} {names[j]}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}  OFFSET {' '.join(number(v) for v in offsets[j])}")
        channels = (POSITION_CHANNELS if with_position[j] else ()) + ROTATION_ORDER
        lines.append(f"{pad}  CHANNELS {len(channels)} {' '.join(channels)}")
        if with_position[j]:
            columns.append(positions[:, j, :])
        columns.append(angles[:, j, :])
        kids = children.get(j, [])
        for c in kids:
            joint(c, depth + 1)
        if not kids:
            end = offsets[j] * 0.5
            if not np.any(np.abs(end) > 0.0):
                end = np.array([0.0, 0.01 / unit_scale, 0.0])
            lines.append(f"{pad}  End Site")
            lines.append(f"{pad}  {{")
            lines.append(f"{pad}    OFFSET {' '.join(number(v) for v in end)}")
            lines.append(f"{pad}  }}")
        lines.append(f"{pad}}}")

    for r in children.get(-1, []):
        joint(r, 0)
    frame_time = float(motion.frame_times.mean()) if f else 1.0 / 60.0
    lines += ["MOTION", f"Frames: {f}", f"Frame Time: {frame_time:.10g}"]
    table = np.concatenate(columns, axis=1)
    body = "\n".join(" ".join(number(v) for v in row) for row in table)
    atomic.write_text(Path(path), "\n".join(lines) + "\n" + body + "\n")
    return notes
