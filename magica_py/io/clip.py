"""Animation clips as per-node keyframe tracks, and a numba sampler that drives a hierarchy.

A ``Clip`` is plain data in Unity convention (converted at load): a list of ``Track``s,
each one channel (``translation``, ``rotation`` or ``scale``) of one named node, with key
times (k,) in seconds, values (k, 3) metres / (k, 4) quaternions xyzw / (k, 3) scale factors,
an interpolation (``linear`` — slerp for rotations, as glTF requires —, ``step`` or
``cubicspline`` with in/out tangents per key, glTF semantics) and optional tangents.

``ClipDriver`` packs the tracks of one clip against a ``TransformHierarchy`` once, then
``apply(hierarchy, t)`` samples every track in one numba call (no per-bone Python loop in
the frame path) and writes the local poses (UPDATE phase). ``Clip.without(...)`` drops the
channels of bones the simulation should move (a keyframed tail).
"""
from __future__ import annotations

import fnmatch
import math
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels.math3d import q_normalize, q_slerp
from magica_py.kernels import portable

PATHS = ("translation", "rotation", "scale")
INTERPOLATIONS = ("linear", "step", "cubicspline")


@dataclass(frozen=True)
class Track:
    """One animated channel of one node (Unity convention, seconds)."""

    node: str
    path: str                      # translation | rotation | scale
    times: np.ndarray              # (k,) s, strictly increasing
    values: np.ndarray             # (k, 3) or (k, 4) xyzw
    interpolation: str = "linear"  # linear | step | cubicspline
    in_tangents: np.ndarray | None = None   # (k, width) cubicspline only (per second)
    out_tangents: np.ndarray | None = None

    @property
    def width(self) -> int:
        return 4 if self.path == "rotation" else 3

    def sample(self, t: float) -> np.ndarray:
        """Reference (pure numpy) evaluation at time t, clamped to the key range."""
        times, values = self.times, self.values
        if len(times) == 1 or t <= times[0]:
            return values[0].copy()
        if t >= times[-1]:
            return values[-1].copy()
        k = int(np.searchsorted(times, t, side="right")) - 1
        td = times[k + 1] - times[k]
        s = (t - times[k]) / td
        if self.interpolation == "step":
            return values[k].copy()
        if self.interpolation == "cubicspline":
            s2, s3 = s * s, s * s * s
            v = ((2 * s3 - 3 * s2 + 1) * values[k] + (s3 - 2 * s2 + s) * td * self.out_tangents[k]
                 + (-2 * s3 + 3 * s2) * values[k + 1] + (s3 - s2) * td * self.in_tangents[k + 1])
        elif self.path == "rotation":
            from magica_py.io.quat import slerp
            return slerp(values[k], values[k + 1], s)
        else:
            v = values[k] + (values[k + 1] - values[k]) * s
        if self.path == "rotation":
            v = v / np.asarray(portable.norm(v))[..., None]
        return v


def sample_track_many(track: Track, times) -> np.ndarray:
    """Vectorised evaluation of one track at many times (clamped): (n, width)."""
    from magica_py.io.quat import qnormalize, slerp
    t = np.asarray(times, dtype=np.float64)
    kt, kv = track.times, track.values
    if len(kt) == 1:
        return np.repeat(kv[:1], len(t), axis=0)
    tc = np.clip(t, kt[0], kt[-1])
    k = np.clip(np.searchsorted(kt, tc, side="right") - 1, 0, len(kt) - 2)
    td = kt[k + 1] - kt[k]
    u = ((tc - kt[k]) / td)[:, None]
    if track.interpolation == "step":
        out = np.where(u >= 1.0, kv[k + 1], kv[k])
    elif track.interpolation == "cubicspline":
        u2, u3, d = u * u, u * u * u, td[:, None]
        out = ((2 * u3 - 3 * u2 + 1) * kv[k] + (u3 - 2 * u2 + u) * d * track.out_tangents[k]
               + (-2 * u3 + 3 * u2) * kv[k + 1] + (u3 - u2) * d * track.in_tangents[k + 1])
    elif track.path == "rotation":
        out = slerp(kv[k], kv[k + 1], u[:, 0])
    else:
        out = kv[k] + (kv[k + 1] - kv[k]) * u
    return qnormalize(out) if track.path == "rotation" else out


@dataclass
class Clip:
    """A named set of tracks; ``duration`` is the last key time over all tracks."""

    name: str
    tracks: list[Track]
    source: Path | None = None
    frame_time: float | None = None      # sampling period of the source (BVH), if any
    notes: list[str] = field(default_factory=list)

    @property
    def duration(self) -> float:
        return max((float(tr.times[-1]) for tr in self.tracks), default=0.0)

    def nodes(self) -> list[str]:
        seen: dict[str, None] = {}
        for tr in self.tracks:
            seen.setdefault(tr.node, None)
        return list(seen)

    def track(self, node: str, path: str) -> Track:
        for tr in self.tracks:
            if tr.node == node and tr.path == path:
                return tr
        raise KeyError(f"clip {self.name!r} has no {path} track for {node!r}")

    def without(self, patterns, paths=PATHS) -> "Clip":
        """A copy without the channels ``paths`` of nodes matching any glob in ``patterns``.

        Use it for bones the simulation moves (``clip.without(["b_Tail*"])``): a keyframed
        tail would otherwise be overwritten by the clip every frame before the cloth runs. A
        glob that matches no animated bone is warned about: the bone it meant stays keyframed.
        """
        pats = [patterns] if isinstance(patterns, str) else list(patterns)
        animated = sorted(self.nodes())
        for p in pats:
            if not any(fnmatch.fnmatchcase(n, p) for n in animated):
                warnings.warn(f"{self.source or self.name}: drop {p!r} matches no bone the clip animates "
                              f"({len(animated)} bones: {animated[:6]}{' ...' if len(animated) > 6 else ''})",
                              UserWarning, stacklevel=2)
        keep = [tr for tr in self.tracks
                if not (tr.path in paths and any(fnmatch.fnmatchcase(tr.node, p) for p in pats))]
        return replace(self, tracks=keep, notes=self.notes + [f"dropped {paths} of {pats}"])

    def trimmed(self, start: float, end: float | None = None) -> "Clip":
        """The part [start, end] of the clip, re-timed to begin at 0 (end values sampled); an
        end past the clip's last key is its end (the source has nothing after it)."""
        end = self.duration if end is None else min(float(end), self.duration)
        if not 0.0 <= start < end:
            raise ValueError(f"clip {self.name!r}: expected 0 <= start < end, got [{start}, {end}]")
        tracks = []
        for tr in self.tracks:
            inside = (tr.times > start) & (tr.times < end)
            times = np.concatenate([[start], tr.times[inside], [end]])
            if tr.interpolation == "cubicspline":   # keep it simple and exact at the keys: resample
                times = np.union1d(times, np.linspace(start, end, max(2, int((end - start) * 60) + 1)))
                values, interp = sample_track_many(tr, times), "linear"
                tracks.append(Track(tr.node, tr.path, times - start, values, interp))
                continue
            values = sample_track_many(tr, times)
            if tr.interpolation == "step":   # the value holding at start, then the keys inside
                values[0] = sample_track_many(tr, [start])[0]
            tracks.append(Track(tr.node, tr.path, times - start, values, tr.interpolation))
        return replace(self, tracks=tracks, notes=self.notes + [f"trimmed to [{start:g}, {end:g}] s"])

    def pose_at(self, t: float) -> "Clip":
        """A one-key clip holding the pose at time ``t`` (every track sampled there, at time 0)."""
        tracks = [Track(tr.node, tr.path, np.zeros(1), sample_track_many(tr, [float(t)]), "linear")
                  for tr in self.tracks]
        return replace(self, tracks=tracks, notes=self.notes + [f"the pose at {t:g} s"])

    def frame_times(self) -> np.ndarray:
        """Times (s) of the source's frames: multiples of ``frame_time`` (BVH) up to the
        duration, else every distinct key time of the tracks (glTF has no frame rate)."""
        if self.frame_time:
            return np.arange(int(round(self.duration / self.frame_time)) + 1) * self.frame_time
        return np.unique(np.concatenate([tr.times for tr in self.tracks])) if self.tracks else np.zeros(1)

    def frame_span(self, first: int, last: int | None = None) -> tuple[float, float | None]:
        """Seconds [start, end] of frames ``first`` .. ``last`` (inclusive; None: to the end)."""
        times = self.frame_times()
        n = len(times)
        if not 0 <= first < n or (last is not None and not first < last < n):
            raise ValueError(f"clip {self.name!r}: frames [{first}, {last}] outside its {n} frames "
                             f"(expected 0 <= first < last <= {n - 1})")
        return float(times[first]), None if last is None else float(times[last])

    def resampled(self, rate: float) -> "Clip":
        """Linear tracks sampled at ``rate`` Hz (fewer keys for YAML entries; exact at the ends)."""
        duration = self.duration
        times = np.linspace(0.0, duration, max(2, int(round(duration * rate)) + 1))
        tracks = [tr if len(tr.times) == 1 else Track(tr.node, tr.path, times, sample_track_many(tr, times), "linear")
                  for tr in self.tracks]   # a constant channel stays one key
        return replace(self, tracks=tracks, frame_time=1.0 / rate, notes=self.notes + [f"resampled at {rate:g} Hz"])

    def renamed(self, mapping: dict[str, str]) -> "Clip":
        """A copy whose tracks target ``mapping.get(node, node)`` (prefixing, instancing)."""
        return replace(self, tracks=[replace(tr, node=mapping.get(tr.node, tr.node)) for tr in self.tracks])

    def sample(self, t: float) -> dict[tuple[str, str], np.ndarray]:
        """Reference evaluation of every track at t: {(node, path): value}."""
        return {(tr.node, tr.path): tr.sample(t) for tr in self.tracks}

    def to_animation_entries(self, loop: bool = True, resample_rate: float = 30.0) -> list[dict]:
        """The clip as YAML ``animation`` keyframe entries (one per node and channel).

        Shape: ``{target, keyframes: {interpolation, loop, keys: [{time, position |
        rotation | scale}]}}`` with rotations as ``[x, y, z, w]``. Cubic-spline tracks are
        resampled to linear keys at ``resample_rate`` Hz since the YAML keyframes have no
        tangents. For large clips prefer handing the ``Clip`` itself to ``ClipDriver``.
        """
        key_name = {"translation": "position", "rotation": "rotation", "scale": "scale"}
        duration = self.duration
        out = []
        for tr in self.tracks:
            times, values, interp = tr.times, tr.values, tr.interpolation
            if interp == "cubicspline":
                n = max(2, int(math.ceil((times[-1] - times[0]) * resample_rate)) + 1)
                times = np.linspace(times[0], times[-1], n)
                values = sample_track_many(tr, times)
                interp = "linear"
            # the scene's keyframes loop each entry over its own keys: pad every track to the
            # clip's [0, duration] (holding its end values) so all tracks loop together
            if times[0] > 0.0:
                times, values = np.concatenate([[0.0], times]), np.concatenate([values[:1], values])
            if times[-1] < duration:
                times, values = np.concatenate([times, [duration]]), np.concatenate([values, values[-1:]])
            keys = [{"time": float(t), key_name[tr.path]: [float(x) for x in v]} for t, v in zip(times, values)]
            out.append({"target": tr.node, "keyframes": {"interpolation": interp, "loop": loop, "keys": keys}})
        return out


# ----------------------------------------------------------------------------- packed sampler
@kernel
def _find_key(key_time, start, count, t):
    """Index k in [start, start+count-2] with key_time[k] <= t < key_time[k+1] (binary search)."""
    lo = start
    hi = start + count - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if key_time[mid] <= t:
            lo = mid
        else:
            hi = mid
    return lo


@kernel
def sample_tracks(t, track_node, track_path, track_interp, key_start, key_count,
                  key_time, key_value, key_in, key_out,
                  local_position, local_rotation, local_scale):
    """Evaluate every packed track at time t and write the node's local channel.

    track_path: 0 translation, 1 rotation, 2 scale; track_interp: 0 linear, 1 step, 2 cubic.
    Times outside the key range clamp to the first/last key (looping is done by the caller).
    """
    for j in range(track_node.shape[0]):
        s0 = key_start[j]
        n = key_count[j]
        path = track_path[j]
        if n == 1 or t <= key_time[s0]:
            k = s0
            u = 0.0
        elif t >= key_time[s0 + n - 1]:
            k = s0 + n - 2
            u = 1.0
        else:
            k = _find_key(key_time, s0, n, t)
            u = (t - key_time[k]) / (key_time[k + 1] - key_time[k])
        if n == 1:
            v0 = key_value[k, 0]; v1 = key_value[k, 1]; v2 = key_value[k, 2]; v3 = key_value[k, 3]
        elif track_interp[j] == 1:  # step: hold the key at or before t
            kk = k + 1 if u >= 1.0 else k
            v0 = key_value[kk, 0]; v1 = key_value[kk, 1]; v2 = key_value[kk, 2]; v3 = key_value[kk, 3]
        elif track_interp[j] == 2:  # glTF cubic spline (Hermite with tangents scaled by the key gap)
            td = key_time[k + 1] - key_time[k]
            u2 = u * u
            u3 = u2 * u
            h00 = 2.0 * u3 - 3.0 * u2 + 1.0
            h10 = (u3 - 2.0 * u2 + u) * td
            h01 = -2.0 * u3 + 3.0 * u2
            h11 = (u3 - u2) * td
            v0 = h00 * key_value[k, 0] + h10 * key_out[k, 0] + h01 * key_value[k + 1, 0] + h11 * key_in[k + 1, 0]
            v1 = h00 * key_value[k, 1] + h10 * key_out[k, 1] + h01 * key_value[k + 1, 1] + h11 * key_in[k + 1, 1]
            v2 = h00 * key_value[k, 2] + h10 * key_out[k, 2] + h01 * key_value[k + 1, 2] + h11 * key_in[k + 1, 2]
            v3 = h00 * key_value[k, 3] + h10 * key_out[k, 3] + h01 * key_value[k + 1, 3] + h11 * key_in[k + 1, 3]
        elif path == 1:
            q = q_slerp((key_value[k, 0], key_value[k, 1], key_value[k, 2], key_value[k, 3]),
                        (key_value[k + 1, 0], key_value[k + 1, 1], key_value[k + 1, 2], key_value[k + 1, 3]), u)
            v0 = q[0]; v1 = q[1]; v2 = q[2]; v3 = q[3]
        else:
            v0 = key_value[k, 0] + (key_value[k + 1, 0] - key_value[k, 0]) * u
            v1 = key_value[k, 1] + (key_value[k + 1, 1] - key_value[k, 1]) * u
            v2 = key_value[k, 2] + (key_value[k + 1, 2] - key_value[k, 2]) * u
            v3 = 0.0
        i = track_node[j]
        if path == 0:
            local_position[i, 0] = v0; local_position[i, 1] = v1; local_position[i, 2] = v2
        elif path == 1:
            q = q_normalize((v0, v1, v2, v3))
            local_rotation[i, 0] = q[0]; local_rotation[i, 1] = q[1]
            local_rotation[i, 2] = q[2]; local_rotation[i, 3] = q[3]
        else:
            local_scale[i, 0] = v0; local_scale[i, 1] = v1; local_scale[i, 2] = v2


class ClipDriver:
    """Plays one clip on a hierarchy: ``apply(hierarchy, t)`` writes the sampled local poses.

    Tracks whose node is not in the hierarchy raise unless ``missing="skip"``. ``loop``
    wraps time into [0, duration); ``speed`` scales time; ``start`` offsets it.
    """

    def __init__(self, clip: Clip, hierarchy, *, loop: bool = True, speed: float = 1.0,
                 start: float = 0.0, missing: str = "raise"):
        tracks = []
        for tr in clip.tracks:
            if tr.node not in hierarchy.index_of:
                if missing == "skip":
                    continue
                raise KeyError(f"clip {clip.name!r}: track target {tr.node!r} is not in the hierarchy")
            tracks.append(tr)
        self.clip = clip
        self.loop = loop
        self.speed = float(speed)
        self.start = float(start)
        self.duration = clip.duration
        n = len(tracks)
        counts = np.array([len(tr.times) for tr in tracks], dtype=np.int32)
        self.track_node = np.array([hierarchy.index(tr.node) for tr in tracks], dtype=np.int32)
        self.track_path = np.array([PATHS.index(tr.path) for tr in tracks], dtype=np.int8)
        self.track_interp = np.array([INTERPOLATIONS.index(tr.interpolation) for tr in tracks], dtype=np.int8)
        self.key_count = counts
        self.key_start = np.zeros(n, dtype=np.int32)
        if n:
            self.key_start[1:] = np.cumsum(counts)[:-1]
        total = int(counts.sum())
        self.key_time = np.zeros(total)
        self.key_value = np.zeros((total, 4))
        self.key_in = np.zeros((total, 4))
        self.key_out = np.zeros((total, 4))
        for j, tr in enumerate(tracks):
            s, c, w = self.key_start[j], counts[j], tr.width
            self.key_time[s:s + c] = tr.times
            self.key_value[s:s + c, :w] = tr.values
            if tr.interpolation == "cubicspline":
                self.key_in[s:s + c, :w] = tr.in_tangents
                self.key_out[s:s + c, :w] = tr.out_tangents
        for a in (self.track_node, self.track_path, self.track_interp, self.key_start, self.key_count,
                  self.key_time, self.key_value, self.key_in, self.key_out):
            a.flags.writeable = False

    def clip_time(self, t: float) -> float:
        u = self.start + self.speed * t
        if self.loop and self.duration > 0.0:
            u = math.fmod(u, self.duration)
            if u < 0.0:
                u += self.duration
        return u

    def apply(self, hierarchy, t: float, dt: float = 0.0) -> None:
        sample_tracks(self.clip_time(t), self.track_node, self.track_path, self.track_interp,
                      self.key_start, self.key_count, self.key_time, self.key_value,
                      self.key_in, self.key_out,
                      hierarchy.local_position, hierarchy.local_rotation, hierarchy.local_scale)
