"""BVH motion capture: our own parser (hierarchy, any channel order, position channels on
any joint, frame time) and its conversion to a Unity-convention skeleton and clip.

Semantics (Biovision BVH as CMU / cgspeed, Mixamo and Blender write it):

* Rotation channels compose in the order listed, first listed outermost: channels
  ``Zrotation Xrotation Yrotation`` give ``R = Rz · Rx · Ry`` (degrees, right-handed).
* Position channels set the joint's local translation on their axes, replacing the OFFSET
  component (axes without a channel keep the OFFSET). The root usually has them; any joint
  may.
* The file is right-handed Y up, facing +Z; ``coords`` mirrors X into Unity's convention.
* Units: ``units`` = ``"m"``, ``"cm"``, ``"mm"``, ``"inch"``, ``"cmu"`` (the CMU/cgspeed
  unit, 1/0.45 inch), a number (metres per file unit), or ``"auto"``: the named unit that
  makes the rest skeleton closest to a 1.7 m human (logged in ``clip.notes``).

``End Site`` offsets become leaf bones named ``<joint>_end`` when ``end_sites=True``.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from magica_py.io import coords
from magica_py.io.clip import Clip, Track
from magica_py.io.errors import AssetError
from magica_py.io.quat import qaxis_angle, qmul
from magica_py.scene.hierarchy import BoneSpec
from magica_py.kernels import portable

UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "inch": 0.0254, "cmu": 0.0254 / 0.45}
HUMAN_HEIGHT = 1.7
AUTO_UNITS_SPREAD = 3.0   # an automatic unit giving a skeleton outside [1.7 / 3, 1.7 x 3] m is warned about
_CHANNELS = ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")
_AXIS = {"X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}


@dataclass
class BvhFile:
    """The parsed file, in file units and file axes."""

    source: Path
    names: list[str]
    parents: list[int]                  # -1 for the root(s)
    offsets: np.ndarray                 # (J, 3) file units
    channels: list[list[str]]           # per joint, in file order
    channel_start: list[int]            # per joint: first column in ``motion``
    end_sites: dict[int, np.ndarray]    # joint → End Site offset
    frame_count: int
    frame_time: float                   # s
    motion: np.ndarray                  # (F, C)


@dataclass
class BvhAnimation:
    """A BVH converted to Unity convention: skeleton bones (rest = OFFSETs, no rotation) and clip."""

    source: Path
    bones: list[BoneSpec]
    clip: Clip
    unit_scale: float                   # metres per file unit
    file: BvhFile
    notes: list[str] = field(default_factory=list)

    @property
    def frame_count(self) -> int:
        return self.file.frame_count

    def local_rotations(self) -> np.ndarray:
        """(F, J, 4) per-frame local rotations xyzw of the joints (``bones`` order, end sites
        excluded); identity for a joint without rotation channels."""
        joints = [b for b in self.bones if "bvh_joint" in b.tags]
        out = np.zeros((self.frame_count, len(joints), 4))
        out[..., 3] = 1.0
        for tr in self.clip.tracks:
            if tr.path == "rotation":
                out[:, next(j for j, b in enumerate(joints) if b.name == tr.node)] = tr.values
        return out

    def root_positions(self) -> np.ndarray:
        """(F, 3) per-frame local position of the first root (metres, Unity axes)."""
        root = self.bones[0]
        try:
            return self.clip.track(root.name, "translation").values.copy()
        except KeyError:
            return np.repeat(np.asarray(root.position)[None], self.frame_count, axis=0)

    @property
    def frame_time(self) -> float:
        return self.file.frame_time


class _Tokens:
    def __init__(self, path: Path, lines: list[str]):
        self.path = path
        self.items = [(tok, n + 1) for n, line in enumerate(lines) for tok in line.split()]
        self.i = 0

    def peek(self):
        return self.items[self.i][0] if self.i < len(self.items) else None

    def line(self) -> int:
        return self.items[min(self.i, len(self.items) - 1)][1] if self.items else 1

    def next(self, expected: str | None = None) -> str:
        if self.i >= len(self.items):
            raise AssetError(self.path, f"line {self.line()}", f"unexpected end of file{f', expected {expected!r}' if expected else ''}")
        tok, _ = self.items[self.i]
        if expected is not None and tok != expected:
            raise AssetError(self.path, f"line {self.items[self.i][1]}", f"expected {expected!r}, got {tok!r}")
        self.i += 1
        return tok

    def number(self, what: str) -> float:
        line = self.line()
        tok = self.next()
        try:
            value = float(tok)
        except ValueError:
            raise AssetError(self.path, f"line {line}", f"expected a number for {what}, got {tok!r}") from None
        if not np.isfinite(value):
            raise AssetError(self.path, f"line {line}", f"expected a finite number for {what}, got {tok!r}")
        return value


def parse_bvh(path) -> BvhFile:
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig", errors="replace")   # -sig: a byte-order mark is skipped
    except OSError as exc:
        raise AssetError(path, "", f"cannot read the file ({exc.strerror or exc})") from None
    lines = text.splitlines()
    motion_line = next((n for n, l in enumerate(lines) if l.strip().upper().startswith("MOTION")), None)
    if motion_line is None:
        raise AssetError(path, "", "no MOTION section")
    tokens = _Tokens(path, lines[:motion_line])
    tokens.next("HIERARCHY")
    names, parents, offsets, channels, starts, ends = [], [], [], [], [], {}
    column = 0

    def joint(parent: int):
        nonlocal column
        line = tokens.line()
        name = tokens.next()
        if name in names:
            raise AssetError(path, f"line {line}", f"duplicate joint name {name!r}")
        index = len(names)
        names.append(name)
        parents.append(parent)
        tokens.next("{")
        tokens.next("OFFSET")
        offsets.append([tokens.number(f"{name} OFFSET") for _ in range(3)])
        line = tokens.line()
        tokens.next("CHANNELS")
        count_tok = tokens.next()
        if not count_tok.isdigit():
            raise AssetError(path, f"line {line}", f"{name}: expected a channel count, got {count_tok!r}")
        chans = [tokens.next() for _ in range(int(count_tok))]
        for c in chans:
            if c not in _CHANNELS:
                raise AssetError(path, f"line {line}", f"{name}: unknown channel {c!r} (expected {', '.join(_CHANNELS)})")
        channels.append(chans)
        starts.append(column)
        column += len(chans)
        while True:
            tok = tokens.peek()
            if tok == "JOINT":
                tokens.next()
                joint(index)
            elif tok == "End":
                tokens.next()
                tokens.next("Site")
                tokens.next("{")
                tokens.next("OFFSET")
                ends[index] = np.array([tokens.number(f"{name} End Site OFFSET") for _ in range(3)])
                tokens.next("}")
            elif tok == "}":
                tokens.next()
                return
            elif tok is None:
                raise AssetError(path, f"line {tokens.line()}", f"unexpected end of file before MOTION: joint {name!r} is missing its closing '}}'")
            else:
                raise AssetError(path, f"line {tokens.line()}", f"inside joint {name!r}: expected JOINT, End Site or '}}', got {tok!r}")

    while tokens.peek() == "ROOT":
        tokens.next()
        joint(-1)
    if not names:
        raise AssetError(path, f"line {tokens.line()}", "expected ROOT after HIERARCHY")
    if tokens.peek() is not None:
        raise AssetError(path, f"line {tokens.line()}", f"unexpected {tokens.peek()!r} after the hierarchy")

    # the two header lines after MOTION (blank lines between them are skipped)
    header = [n for n in range(motion_line + 1, len(lines)) if lines[n].strip()][:2]
    frames_line = header[0] if header else motion_line + 1
    try:
        key, value = lines[header[0]].split(":", 1)
        assert key.strip().lower() == "frames"
        frame_count = int(value)
    except (IndexError, ValueError, AssertionError):
        raise AssetError(path, f"line {frames_line + 1}", "expected 'Frames: <count>'") from None
    time_line = header[1] if len(header) > 1 else frames_line + 1
    try:
        key, value = lines[header[1]].split(":", 1)
        assert key.strip().lower() == "frame time"
        frame_time = float(value)
    except (IndexError, ValueError, AssertionError):
        raise AssetError(path, f"line {time_line + 1}", "expected 'Frame Time: <seconds>'") from None
    if not 0.0 < frame_time < np.inf:
        raise AssetError(path, f"line {time_line + 1}", f"frame time must be a positive finite number of seconds, got {frame_time}")
    first = time_line + 1
    rows, row_lines = [], []
    for n in range(first, len(lines)):
        values = lines[n].split()
        if not values:
            continue
        if len(values) != column:
            raise AssetError(path, f"line {n + 1}", f"frame {len(rows)} has {len(values)} values but the hierarchy declares {column} channels")
        rows.append(values)
        row_lines.append(n + 1)
    if len(rows) != frame_count:
        if abs(len(rows) - frame_count) != 1 or not rows:
            raise AssetError(path, f"line {frames_line + 1}",
                             f"header declares {frame_count} frames but the file has {len(rows)}")
        # exporters commonly count the T-pose frame or not: one frame off is read as written
        warnings.warn(f"{path}: line {frames_line + 1}: header declares {frame_count} frames but the file has "
                      f"{len(rows)}; all {len(rows)} frames are read", UserWarning, stacklevel=2)
        frame_count = len(rows)
    try:
        motion = np.array(rows, dtype=np.float64).reshape(frame_count, column)
    except ValueError:
        for f, row in enumerate(rows):
            for c, tok in enumerate(row):
                try:
                    float(tok)
                except ValueError:
                    raise AssetError(path, f"line {row_lines[f]}", f"frame {f}, channel {c + 1}: expected a number, "
                                     f"got {tok!r}") from None
        raise AssetError(path, "MOTION", "frame data contains a value that is not a number") from None
    bad = np.argwhere(~np.isfinite(motion))
    if bad.size:
        f, c = (int(x) for x in bad[0])
        raise AssetError(path, f"line {row_lines[f]}", f"frame {f}, channel {c + 1}: expected a finite number, "
                         f"got {rows[f][c]!r}")
    return BvhFile(path, names, parents, np.array(offsets, dtype=np.float64), channels, starts, ends,
                   frame_count, frame_time, motion)


def euler_channels_to_quaternion(angles_deg: np.ndarray, order: list[str]) -> np.ndarray:
    """(F, k) angles in degrees for the rotation channels ``order`` → (F, 4) quaternions.

    First listed channel outermost: ``q = q_0 · q_1 · q_2`` (right-handed file axes).
    """
    q = np.zeros((angles_deg.shape[0], 4))
    q[:, 3] = 1.0
    for k, ch in enumerate(order):
        q = qmul(q, qaxis_angle(_AXIS[ch[0]], np.radians(angles_deg[:, k])))
    return q


def resolve_units(units, bvh: BvhFile) -> tuple[float, str]:
    if isinstance(units, (int, float)) and not isinstance(units, bool):
        if not units > 0:
            raise ValueError(f"unit scale must be positive, got {units}")
        return float(units), f"unit scale {units:g} m per file unit"
    if units in UNITS:
        return UNITS[units], f"units {units}"
    if units != "auto":
        raise ValueError(f"units must be a number, 'auto' or one of {sorted(UNITS)}, got {units!r}")
    world = np.zeros_like(bvh.offsets)
    for j, p in enumerate(bvh.parents):
        world[j] = bvh.offsets[j] + (world[p] if p >= 0 else 0.0)
    points = np.concatenate([world] + [np.atleast_2d(world[j] + e) for j, e in bvh.end_sites.items()])
    # the rest skeleton's largest extent along a file axis: its height standing (a T-pose's arm
    # span is about the same), or its length if the file has it lying along Z or X
    extents = points.max(axis=0) - points.min(axis=0)
    axis = int(np.argmax(extents))
    height = float(extents[axis])
    if height <= 0:
        return 1.0, "units auto: a skeleton of one point, metres assumed"
    name = min(UNITS, key=lambda u: abs(portable.log(height * UNITS[u] / HUMAN_HEIGHT)))
    size = height * UNITS[name]
    note = f"units auto: rest size {height:.4g} file units along {'XYZ'[axis]} → {name} ({size:.3g} m)"
    if not HUMAN_HEIGHT / AUTO_UNITS_SPREAD <= size <= HUMAN_HEIGHT * AUTO_UNITS_SPREAD:
        warnings.warn(f"{bvh.source}: {note}, far from a human's {HUMAN_HEIGHT:g} m whatever the unit; "
                      "give the units (units: m, cm, mm, inch, cmu or a number of m per file unit)",
                      UserWarning, stacklevel=3)
    return UNITS[name], note


def load_bvh(path, *, units="auto", mirror_axis: str = "x", prefix: str = "", end_sites: bool = False,
             name: str | None = None) -> BvhAnimation:
    """Parse a BVH file and convert it to Unity-convention bones and a clip (metres)."""
    bvh = parse_bvh(path)
    scale, unit_note = resolve_units(units, bvh)
    names = [prefix + n for n in bvh.names]
    bones = []
    for j, n in enumerate(names):
        p = bvh.parents[j]
        offset = coords.position_to_unity(bvh.offsets[j] * scale, mirror_axis)
        bones.append(BoneSpec(name=n, parent=None if p < 0 else names[p], position=tuple(float(x) for x in offset),
                              tags={"bvh_joint": j}))
    if end_sites:
        for j, e in bvh.end_sites.items():
            offset = coords.position_to_unity(e * scale, mirror_axis)
            bones.append(BoneSpec(name=f"{names[j]}_end", parent=names[j], position=tuple(float(x) for x in offset),
                                  tags={"bvh_end_site": j}))
    times = np.arange(bvh.frame_count) * bvh.frame_time
    tracks = []
    for j, n in enumerate(names):
        chans, start = bvh.channels[j], bvh.channel_start[j]
        rot_cols = [start + k for k, c in enumerate(chans) if c.endswith("rotation")]
        pos_cols = {c[0]: start + k for k, c in enumerate(chans) if c.endswith("position")}
        if pos_cols:
            pos = np.repeat(bvh.offsets[j][None, :], bvh.frame_count, axis=0)
            for axis, col in pos_cols.items():
                pos[:, "XYZ".index(axis)] = bvh.motion[:, col]
            tracks.append(Track(n, "translation", times, coords.position_to_unity(pos * scale, mirror_axis)))
        if rot_cols:
            order = [c for c in chans if c.endswith("rotation")]
            q = euler_channels_to_quaternion(bvh.motion[:, rot_cols], order)
            tracks.append(Track(n, "rotation", times, coords.rotation_to_unity(q, mirror_axis)))
    clip = Clip(name=name or Path(path).stem, tracks=tracks, source=Path(path), frame_time=bvh.frame_time,
                notes=[unit_note])
    return BvhAnimation(source=Path(path), bones=bones, clip=clip, unit_scale=scale, file=bvh, notes=[unit_note])
