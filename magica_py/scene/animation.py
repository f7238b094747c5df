"""Animation drivers and timed events, applied in the UPDATE phase (docs/solver.md §A.2).

``Animation.from_specs(entries, hierarchy)`` builds it from the validated ``animation``
section after instance replication. Each entry is either a **driver**::

    {"target": name | index, "<kind>": {params}, "start": 0, "end": None,
     "phase_offset": 0, "fade": 0}
    # or the config package's normalised form {"kind": kind, "params": {...}, "target": ...}

or an **event** ``{"at": seconds, "<event kind>": payload}`` (normalised form
``{"kind": kind, "at": ..., "params": {...}}``). The Player calls
``apply(hierarchy, ctx)`` every frame (``ctx.time.time`` = scaled game time, ``ctx.events``
= list receiving ``(kind, payload)``) and then ``hierarchy.propagate()``.

Composition rule
----------------
Every frame each *driven* node (target of a driver or of a teleport) starts from its rest
local pose (``hierarchy.rest_local_*``); the drivers then run in list order:

* **keyframes** and **orbit** are absolute: they overwrite the channels they animate
  (keyframes: the position / rotation / scale tracks that have keys; orbit: the position,
  and the rotation when ``face_path``);
* **oscillate**, **spin** and **walk** are additive: positions are offset in the parent's
  space (``position += offset``), rotations turn about the node's own axes
  (``rotation = rotation * delta``), so they stack on whatever came before;
* finally a teleport offset (identity until a teleport fires) is composed in front:
  ``local = offset * local``, so motion continues relative to the place teleported to.

Time: driver time is ``tau = clamp(t, start, end) - start + phase_offset``. Keyframes,
orbit, spin and walk's forward travel are *progressive*: they hold their value at the window
edges (a walk that ends stays where it stopped). Oscillate and walk's bob / sway / twist are
*periodic*: they contribute nothing outside [start, end] and fade in / out linearly over
``fade`` seconds inside it (0 = hard edges).

Driver parameters (angles in degrees, lengths in metres, times in seconds)
--------------------------------------------------------------------------
* ``keyframes: {keys: [{time, position?, rotation? (xyzw) | euler?, scale?}], interpolation:
  linear | step | smooth | cubic, loop: false}``: local pose tracks; each channel uses the keys that
  have it; vectors lerp, rotations slerp (shortest arc: add intermediate keys for turns over
  180 degrees); ``smooth`` eases each segment (smoothstep: starts and stops at every key);
  ``cubic`` passes smoothly through the keys (Catmull-Rom tangents for uneven key times,
  one-sided at the ends; rotations slerp linearly); ``loop`` wraps over
  [first key, last key], otherwise the ends are held. Key times are relative to ``start``.
* ``orbit: {center, radius, period, axis=(0,1,0), phase=0, face_path=false}``: position on
  the circle ``center + rotate(axis, 360 tau/period + phase) * radius * u`` where ``u`` is
  the parent's +X made orthogonal to the axis (+Z when the axis is along X). The rotation
  is positive about ``axis`` as in Unity (clockwise seen from the tip of the axis, since
  Unity is left-handed), the same sense as a positive ``spin``; a negative ``period`` runs
  the other way. ``face_path`` sets the rotation to +Z along the velocity, +Y along the axis.
* ``oscillate: {property: position | rotation, axis, amplitude, frequency, phase=0}``:
  ``amplitude * sin(360 frequency tau + phase)`` metres along ``axis`` (parent space) or
  degrees about ``axis`` (the node's local axes).
* ``spin: {axis, speed}``: ``speed * tau`` degrees about ``axis`` (local axes).
* ``walk: {speed=0, stride_frequency=1.8, bob=0.03, sway=4, lateral=0, twist=0,
  direction=(0,0,1), up=(0,1,0)}``: one stride = two steps = one gait cycle, so the hips bob
  ``bob * sin(2 * 360 f tau)`` along ``up`` (once per step), roll ``sway * sin(360 f tau)``
  degrees about their local +Z, shift ``lateral * sin(360 f tau)`` metres along
  ``up x direction`` and yaw ``twist * sin(360 f tau)`` about local +Y; and travel
  ``speed * tau`` metres along ``direction`` (parent space).

Events fire once, on the first ``apply`` whose ``ctx.time.time >= at`` (in ``at`` order):
``teleport: {target, position?, rotation? | euler?}`` sets the target's world pose with
``hierarchy.set_world_pose`` (and appends ``("teleport", {...})``); ``time_scale: value``
appends ``("time_scale", value)``; ``set_parameter: {cloth, key, value}`` appends
``("set_parameter", {...})``; ``wind: {zone, enabled?, main?}`` appends ``("wind", {...})``
(applied by the cloth system's wind field). ``reset()`` re-arms the events and clears teleport offsets.

Cost: one numba kernel call per frame evaluates every driver of every target (crowds
included), writing local poses only (the player's UPDATE system then propagates the driven
subtrees, ``scene/propagation.py``); events are a pointer into a sorted list, and a frame
without a due event allocates nothing.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from magica_py.jit import kernel, stage_policy
from magica_py.kernels.math3d import (
    load3,
    load4,
    q_axis_angle,
    q_look_rotation,
    q_mul,
    q_normalize,
    q_rotate,
    q_slerp,
    store3,
    store4,
    v_cross,
    v_lerp,
    v_normalize,
)
from magica_py.kernels import portable

KEYFRAMES, ORBIT, OSCILLATE, SPIN, WALK = 0, 1, 2, 3, 4
DRIVER_KINDS = {"keyframes": KEYFRAMES, "orbit": ORBIT, "oscillate": OSCILLATE,
                "spin": SPIN, "walk": WALK}
EVENT_KINDS = ("teleport", "time_scale", "set_parameter", "wind")
INTERPOLATIONS = {"linear": 0, "step": 1, "smooth": 2, "cubic": 3}
CUBIC = 3
PARAM_WIDTH = 16
CHANNEL_POSITION, CHANNEL_ROTATION, CHANNEL_SCALE = 0, 1, 2

# parameter rows (PARAM_WIDTH floats per driver); the kernel reads these offsets
# keyframes: [interpolation, loop]
# orbit:     [center x3, radius, period, axis x3, u x3, phase rad, face_path]
# oscillate: [axis x3, amplitude (m | rad), frequency, phase rad, is_rotation]
# spin:      [axis x3, speed rad/s]
# walk:      [direction x3, speed, frequency, bob, sway rad, lateral, twist rad, up x3]


# ----------------------------------------------------------------------------- kernels
@kernel(inline="always")
def track_segment(key_time, first, count, tau, loop):
    """Keys (k0, k1) around tau in one track and the fraction between them."""
    last = first + count - 1
    t0 = key_time[first]
    t1 = key_time[last]
    if count == 1:
        return first, first, 0.0
    if loop and t1 > t0:
        tau = t0 + (tau - t0) % (t1 - t0)
    if tau <= t0:
        return first, first, 0.0
    if tau >= t1:
        return last, last, 0.0
    lo = first
    hi = last
    while hi - lo > 1:  # key_time[lo] <= tau < key_time[hi]
        mid = (lo + hi) // 2
        if key_time[mid] <= tau:
            lo = mid
        else:
            hi = mid
    return lo, hi, (tau - key_time[lo]) / (key_time[hi] - key_time[lo])


@kernel(inline="always")
def ease(f, interpolation):
    if interpolation == 1:
        return 0.0
    if interpolation == 2:
        return f * f * (3.0 - 2.0 * f)
    return f


@kernel(inline="always")
def cubic_segment(key_time, key_value, first, last, k0, k1, f):
    """Cubic Hermite between keys k0 and k1 with Catmull-Rom tangents for uneven key times
    (``(p[k+1] - p[k-1]) / (t[k+1] - t[k-1])``, one-sided at the track ends)."""
    if k0 == k1:
        return load3(key_value, k0)
    h = key_time[k1] - key_time[k0]
    a = k0 - 1 if k0 > first else k0
    b = k1 + 1 if k1 < last else k1
    f2 = f * f
    f3 = f2 * f
    h00 = 2.0 * f3 - 3.0 * f2 + 1.0
    h10 = (f3 - 2.0 * f2 + f) * h
    h01 = -2.0 * f3 + 3.0 * f2
    h11 = (f3 - f2) * h
    ta = key_time[k1] - key_time[a]
    tb = key_time[b] - key_time[k0]
    out0 = 0.0
    out1 = 0.0
    out2 = 0.0
    for c in range(3):
        m0 = (key_value[k1, c] - key_value[a, c]) / ta
        m1 = (key_value[b, c] - key_value[k0, c]) / tb
        v = h00 * key_value[k0, c] + h10 * m0 + h01 * key_value[k1, c] + h11 * m1
        if c == 0:
            out0 = v
        elif c == 1:
            out1 = v
        else:
            out2 = v
    return (out0, out1, out2)


@kernel
def window_weight(t, start, end, fade):
    """Envelope of periodic motions: 0 outside [start, end], linear ramps of ``fade`` s."""
    if t < start or t > end:
        return 0.0
    if fade <= 0.0:
        return 1.0
    w = min((t - start) / fade, (end - t) / fade)
    return min(w, 1.0)


@kernel(inline="always")
def orbit_radials(t, orbit_columns, orbit_radial):
    """The unit radial vector ``rotate(axis, 360 tau / period + phase) * u`` of every orbit
    driver at time t, one column per orbit (``Animation.orbit_columns`` rows: start, end,
    phase offset, period, phase, axis x3, u x3). A pure function of time, evaluated for all
    orbits in one loop that vectorises across them; ``apply_drivers`` reads the result at the
    driver's place in the list."""
    two_pi = 2.0 * math.pi
    for j in range(orbit_columns.shape[1]):
        start = orbit_columns[0, j]
        tau = min(max(t, start), orbit_columns[1, j]) - start + orbit_columns[2, j]
        angle = two_pi * tau / orbit_columns[3, j] + orbit_columns[4, j]
        turn = q_axis_angle((orbit_columns[5, j], orbit_columns[6, j], orbit_columns[7, j]), angle)
        radial = q_rotate(turn, (orbit_columns[8, j], orbit_columns[9, j], orbit_columns[10, j]))
        orbit_radial[0, j] = radial[0]
        orbit_radial[1, j] = radial[1]
        orbit_radial[2, j] = radial[2]


@kernel
def apply_drivers(t, kind, target, start, end, phase_offset, fade, params, key_first,
                  key_count, key_time, key_value, driven, offset_position, offset_rotation,
                  rest_position, rest_rotation, rest_scale,
                  local_position, local_rotation, local_scale,
                  orbit_slot, orbit_columns, orbit_radial, keyframes, orbit, oscillate, spin, walk):
    """UPDATE phase: rest pose of every driven node, then each driver in list order, then
    the teleport offsets (see the module docstring for the composition rule). The orbits'
    radial vectors are evaluated first, all at once (``orbit_radials``).

    ``keyframes`` ... ``walk`` (``Animation.kinds_used``): 1 where a driver of that kind
    exists, None where none does; numba removes an ``if switch is not None`` branch whose
    argument is None before typing it, so a scene compiles only the driver kinds it uses
    (every kind under ``MAGICA_STAGES=all``)."""
    if orbit is not None:
        orbit_radials(t, orbit_columns, orbit_radial)
    for m in range(driven.shape[0]):
        i = np.int64(driven[m])   # int64 node ids: one signature of the row helpers (docs/tech-notes.md §7)
        store3(local_position, i, load3(rest_position, i))
        store4(local_rotation, i, load4(rest_rotation, i))
        store3(local_scale, i, load3(rest_scale, i))
    two_pi = 2.0 * math.pi
    for d in range(kind.shape[0]):
        i = np.int64(target[d])
        k = kind[d]
        tau = min(max(t, start[d]), end[d]) - start[d] + phase_offset[d]
        if keyframes is not None:
            if k == KEYFRAMES:
                interpolation = int(params[d, 0])
                loop = params[d, 1] != 0.0
                for ch in range(3):
                    n = key_count[d, ch]
                    if n == 0:
                        continue
                    first = key_first[d, ch]
                    k0, k1, f = track_segment(key_time, first, n, tau, loop)
                    f = ease(f, interpolation)
                    if ch == CHANNEL_ROTATION:
                        q = q_slerp(load4(key_value, k0), load4(key_value, k1), f)
                        store4(local_rotation, i, q)
                    else:
                        if interpolation == CUBIC:
                            v = cubic_segment(key_time, key_value, first, first + n - 1, k0, k1, f)
                        else:
                            v = v_lerp(load3(key_value, k0), load3(key_value, k1), f)
                        if ch == CHANNEL_POSITION:
                            store3(local_position, i, v)
                        else:
                            store3(local_scale, i, v)
        if orbit is not None:
            if k == ORBIT:
                axis = (params[d, 5], params[d, 6], params[d, 7])
                o = orbit_slot[d]
                radial = (orbit_radial[0, o], orbit_radial[1, o], orbit_radial[2, o])
                radius = params[d, 3]
                store3(local_position, i, (params[d, 0] + radius * radial[0],
                                           params[d, 1] + radius * radial[1],
                                           params[d, 2] + radius * radial[2]))
                if params[d, 12] != 0.0:
                    forward = v_normalize(v_cross(axis, radial))
                    if params[d, 4] < 0.0:  # a negative period runs the circle backwards
                        forward = (-forward[0], -forward[1], -forward[2])
                    store4(local_rotation, i, q_look_rotation(forward, axis))
        if oscillate is not None:
            if k == OSCILLATE:
                w = window_weight(t, start[d], end[d], fade[d])
                if w == 0.0:
                    continue
                value = w * params[d, 3] * portable.sin(two_pi * params[d, 4] * tau + params[d, 5])
                if params[d, 6] != 0.0:
                    axis = (params[d, 0], params[d, 1], params[d, 2])
                    q = q_mul(load4(local_rotation, i), q_axis_angle(axis, value))
                    store4(local_rotation, i, q_normalize(q))
                else:
                    for c in range(3):
                        local_position[i, c] += params[d, c] * value
        if spin is not None:
            if k == SPIN:
                axis = (params[d, 0], params[d, 1], params[d, 2])
                q = q_mul(load4(local_rotation, i), q_axis_angle(axis, params[d, 3] * tau))
                store4(local_rotation, i, q_normalize(q))
        if walk is not None:
            if k == WALK:
                direction = (params[d, 0], params[d, 1], params[d, 2])
                up = (params[d, 9], params[d, 10], params[d, 11])
                for c in range(3):
                    local_position[i, c] += direction[c] * params[d, 3] * tau
                w = window_weight(t, start[d], end[d], fade[d])
                if w == 0.0:
                    continue
                phase = two_pi * params[d, 4] * tau
                bob = w * params[d, 5] * portable.sin(2.0 * phase)
                lateral = w * params[d, 7] * portable.sin(phase)
                side = v_normalize(v_cross(up, direction))
                for c in range(3):
                    local_position[i, c] += up[c] * bob + side[c] * lateral
                roll = q_axis_angle((0.0, 0.0, 1.0), w * params[d, 6] * portable.sin(phase))
                yaw = q_axis_angle((0.0, 1.0, 0.0), w * params[d, 8] * portable.sin(phase))
                q = q_mul(load4(local_rotation, i), q_mul(yaw, roll))
                store4(local_rotation, i, q_normalize(q))
    for m in range(driven.shape[0]):
        i = np.int64(driven[m])   # int64 node ids: one signature of the row helpers (docs/tech-notes.md §7)
        dq = load4(offset_rotation, m)
        moved = q_rotate(dq, load3(local_position, i))
        store3(local_position, i, (offset_position[m, 0] + moved[0],
                                   offset_position[m, 1] + moved[1],
                                   offset_position[m, 2] + moved[2]))
        store4(local_rotation, i, q_normalize(q_mul(dq, load4(local_rotation, i))))


# ----------------------------------------------------------------------------- building
def _unit(v, where: str) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64).reshape(3)
    n = portable.norm(a) if np.isfinite(a).all() else math.nan
    if not np.isfinite(n) or n < 1e-12:
        raise ValueError(f"{where}: expected a non-zero direction, got {list(a)}")
    return a / n


def _rotation(spec: dict, where: str):
    """Quaternion of a mapping's ``rotation`` (xyzw) or ``euler`` (degrees), or None."""
    from magica_py.scene.rigs import rotation_from_spec

    if spec.get("rotation") is None and spec.get("euler") is None:
        return None
    try:
        return np.asarray(rotation_from_spec(spec), dtype=np.float64)
    except ValueError as e:
        raise ValueError(f"{where}: {e}") from None


def _normalise_entry(entry: dict, where: str) -> tuple[str, dict]:
    """(kind, params) of a raw YAML entry or of the config package's normalised form."""
    if "kind" in entry:
        return entry["kind"], dict(entry.get("params") or {})
    kinds = [k for k in (*DRIVER_KINDS, *EVENT_KINDS) if k in entry]
    if len(kinds) != 1:
        raise ValueError(f"{where}: expected exactly one of {', '.join((*DRIVER_KINDS, *EVENT_KINDS))},"
                         f" got {kinds}")
    kind = kinds[0]
    body = entry[kind]
    if kind == "time_scale":
        return kind, {"value": body}
    return kind, dict(body or {})


def _resolve(hierarchy, target, where: str) -> int:
    if isinstance(target, (int, np.integer)) and not isinstance(target, bool):
        if not 0 <= target < hierarchy.count:
            raise ValueError(f"{where}: transform index {target} out of range [0, {hierarchy.count})")
        return int(target)
    try:
        return hierarchy.index(target)
    except KeyError:
        raise ValueError(f"{where}: no transform named {target!r}") from None


@dataclass
class Event:
    at: float
    kind: str
    payload: object
    target: int = -1


class Animation:
    """Drivers (flat arrays read by ``apply_drivers``) and a time-sorted event list.

    Arrays, D drivers, K keys, M driven nodes (all built once; only the teleport offsets
    change, when a teleport fires in UPDATE):

    kind (D,) int8, target (D,) int32, start / end / phase_offset / fade (D,) s,
    params (D, 16) (see the layout comment above), key_first / key_count (D, 3) int32 per
    channel (position, rotation, scale) into key_time (K,) s and key_value (K, 4)
    (vectors in the first three columns), driven (M,) int32 hierarchy nodes,
    offset_position (M, 3) m and offset_rotation (M, 4) teleport offsets (parent space);
    for the O orbit drivers: orbit_slot (D,) int32 (column of driver d, -1 for other kinds),
    orbit_columns (11, O) (start, end, phase offset, period, phase rad, axis x3, u x3: copies
    of the rows above) and orbit_radial (3, O), the unit radial vectors of the current frame
    (written by ``orbit_radials``).
    """

    def __init__(self, hierarchy, drivers: list[dict], events: list[Event]):
        self._build_drivers(hierarchy, drivers)
        self.events = sorted(events, key=lambda e: e.at)  # stable: list order within a time
        extra = [e.target for e in self.events if e.kind == "teleport"]
        self.driven = np.array(sorted(set(self.target.tolist()) | set(extra)), dtype=np.int32)
        self.slot_of = {int(i): m for m, i in enumerate(self.driven)}
        self.offset_position = np.zeros((self.driven.size, 3))
        self.offset_rotation = np.zeros((self.driven.size, 4))
        self.reset()

    # -- construction
    @staticmethod
    def from_specs(entries: list[dict], hierarchy) -> "Animation":
        drivers, events = [], []
        for n, entry in enumerate(entries):
            where = ".".join(map(str, entry["path"])) if "path" in entry else f"animation[{n}]"
            kind, params = _normalise_entry(entry, where)
            if kind in DRIVER_KINDS:
                drivers.append({"kind": kind, "params": params, "where": where,
                                "target": _resolve(hierarchy, entry["target"], f"{where}.target"),
                                "start": float(entry.get("start") or 0.0),
                                "end": math.inf if entry.get("end") is None else float(entry["end"]),
                                "phase_offset": float(entry.get("phase_offset") or 0.0),
                                "fade": float(entry.get("fade") or 0.0)})
            elif kind in EVENT_KINDS:
                events.append(_make_event(hierarchy, kind, params, float(entry["at"]), where))
            else:
                raise ValueError(f"{where}: unknown animation kind {kind!r}")
        return Animation(hierarchy, drivers, events)

    @staticmethod
    def empty(hierarchy=None) -> "Animation":
        return Animation(hierarchy, [], [])

    def _build_drivers(self, hierarchy, drivers: list[dict]) -> None:
        d = len(drivers)
        self.kind = np.zeros(d, np.int8)
        self.target = np.zeros(d, np.int32)
        self.start = np.zeros(d)
        self.end = np.full(d, math.inf)
        self.phase_offset = np.zeros(d)
        self.fade = np.zeros(d)
        self.params = np.zeros((d, PARAM_WIDTH))
        self.key_first = np.zeros((d, 3), np.int32)
        self.key_count = np.zeros((d, 3), np.int32)
        key_time: list[float] = []
        key_value: list[np.ndarray] = []
        for n, drv in enumerate(drivers):
            self.kind[n] = DRIVER_KINDS[drv["kind"]]
            for name in ("target", "start", "end", "phase_offset", "fade"):
                getattr(self, name)[n] = drv[name]
            if self.end[n] <= self.start[n]:
                raise ValueError(f"{drv['where']}.end: expected end > start ({self.start[n]:g}),"
                                 f" got {self.end[n]:g}")
            row = _driver_params(drv["kind"], drv["params"], f"{drv['where']}.{drv['kind']}")
            self.params[n, :row.size] = row
            if drv["kind"] == "keyframes":
                self._add_keys(n, drv["params"], key_time, key_value, f"{drv['where']}.keyframes")
        self.key_time = np.asarray(key_time, dtype=np.float64).reshape(-1)
        self.key_value = np.asarray(key_value, dtype=np.float64).reshape(-1, 4)
        # the orbits' time and circle parameters column by column, in list order
        orbits = np.flatnonzero(self.kind == ORBIT)
        self.orbit_slot = np.full(d, -1, np.int32)
        self.orbit_slot[orbits] = np.arange(orbits.size, dtype=np.int32)
        self.orbit_columns = np.ascontiguousarray(np.vstack([
            self.start[orbits], self.end[orbits], self.phase_offset[orbits],
            self.params[orbits, 4], self.params[orbits, 11], self.params[orbits, 5:8].T,
            self.params[orbits, 8:11].T]).reshape(11, orbits.size))
        self.orbit_radial = np.zeros((3, orbits.size))
        # per driver kind (keyframes, orbit, oscillate, spin, walk): 1 where a driver of that
        # kind exists, else None (``apply_drivers`` compiles only the kinds a scene uses); every
        # kind under ``MAGICA_STAGES=all`` (``jit.stage_policy``: one compile for every scene, a
        # kind with no driver runs none)
        every = stage_policy() == "all"
        self.kinds_used = tuple(1 if every or bool(np.any(self.kind == k)) else None
                                for k in (KEYFRAMES, ORBIT, OSCILLATE, SPIN, WALK))

    def _add_keys(self, n, params, key_time, key_value, where) -> None:
        keys = params.get("keys") or []
        if not keys:
            raise ValueError(f"{where}.keys: expected at least one key")
        times = [float(k["time"]) for k in keys]
        if any(b <= a for a, b in zip(times, times[1:])):
            raise ValueError(f"{where}.keys: key times must increase, got {times}")
        for ch, getter in ((CHANNEL_POSITION, lambda k, w: k.get("position")),
                           (CHANNEL_ROTATION, _rotation),
                           (CHANNEL_SCALE, lambda k, w: k.get("scale"))):
            self.key_first[n, ch] = len(key_time)
            for j, k in enumerate(keys):
                value = getter(k, f"{where}.keys[{j}]")
                if value is None:
                    continue
                row = np.zeros(4)
                row[:len(value)] = value
                key_time.append(float(k["time"]))
                key_value.append(row)
            self.key_count[n, ch] = len(key_time) - self.key_first[n, ch]
        if not self.key_count[n].any():
            raise ValueError(f"{where}.keys: no key has a position, rotation, euler or scale")

    # -- per frame
    def reset(self) -> None:
        """Re-arm every event and clear the teleport offsets (a fresh run)."""
        self.next_event = 0
        self.offset_position[:] = 0.0
        self.offset_rotation[:] = (0.0, 0.0, 0.0, 1.0)

    def evaluate(self, hierarchy, time: float) -> None:
        """Write the driven nodes' local poses for game time ``time`` (no events, no propagate)."""
        if self.driven.size == 0:
            return
        apply_drivers(float(time), self.kind, self.target, self.start, self.end,
                      self.phase_offset, self.fade, self.params, self.key_first,
                      self.key_count, self.key_time, self.key_value, self.driven,
                      self.offset_position, self.offset_rotation,
                      hierarchy.rest_local_position, hierarchy.rest_local_rotation,
                      hierarchy.rest_local_scale, hierarchy.local_position,
                      hierarchy.local_rotation, hierarchy.local_scale,
                      self.orbit_slot, self.orbit_columns, self.orbit_radial, *self.kinds_used)

    def apply(self, hierarchy, ctx) -> None:
        """UPDATE phase: drivers at ``ctx.time.time``, then the events now due, in ``at``
        order (list order at equal times). Writes local poses only: the caller propagates."""
        t = float(ctx.time.time)
        self.evaluate(hierarchy, t)
        if self.next_event >= len(self.events) or self.events[self.next_event].at > t:
            return  # the usual frame: no event due, nothing more to do or allocate
        moved: set[int] = set()  # nodes teleported this frame (their subtrees are stale)
        while self.next_event < len(self.events) and self.events[self.next_event].at <= t:
            event = self.events[self.next_event]
            self.next_event += 1
            if event.kind == "teleport":
                # world poses of the parents must reflect this frame's animation and any
                # teleport of an ancestor earlier in this frame: one propagate per need
                if not moved or self._under(hierarchy, event.target, moved):
                    hierarchy.propagate()
                    moved.clear()
                self._teleport(hierarchy, event)
                moved.add(event.target)
            ctx.events.append((event.kind, event.payload))

    @staticmethod
    def _under(hierarchy, i: int, nodes: set[int]) -> bool:
        """Whether a strict ancestor of node i is in ``nodes``."""
        p = int(hierarchy.parent[i])
        while p >= 0:
            if p in nodes:
                return True
            p = int(hierarchy.parent[p])
        return False

    def _teleport(self, hierarchy, event: Event) -> None:
        """Land the target on the requested world pose now and keep later motion relative
        to it: offset_new = (desired * current^-1) * offset_old (parent space). Needs the
        parent's world pose of this frame (``apply`` propagates first)."""
        i = event.target
        cur_p = hierarchy.local_position[i].copy()
        cur_q = tuple(hierarchy.local_rotation[i])
        payload = event.payload
        hierarchy.set_world_pose(i, payload.get("position"), payload.get("rotation"), propagate=False)
        want_p = hierarchy.local_position[i]
        want_q = tuple(hierarchy.local_rotation[i])
        delta_q = q_normalize(q_mul(want_q, (-cur_q[0], -cur_q[1], -cur_q[2], cur_q[3])))
        delta_p = want_p - np.asarray(q_rotate(delta_q, tuple(cur_p)))
        m = self.slot_of[i]
        old_q = tuple(self.offset_rotation[m])
        self.offset_position[m] = delta_p + np.asarray(q_rotate(delta_q, tuple(self.offset_position[m])))
        self.offset_rotation[m] = q_normalize(q_mul(delta_q, old_q))

    def describe(self) -> list[str]:
        """One line per driver and event (for ``info`` and tests)."""
        names = {v: k for k, v in DRIVER_KINDS.items()}
        lines = [f"{names[int(k)]} -> node {int(t)} [{s:g}, {e:g}] +{o:g}s"
                 for k, t, s, e, o in zip(self.kind, self.target, self.start, self.end,
                                          self.phase_offset)]
        lines += [f"at {e.at:g}: {e.kind} {e.payload}" for e in self.events]
        return lines


def _driver_params(kind: str, p: dict, where: str) -> np.ndarray:
    """The parameter row of one driver (layout in the comment at the top of the module).
    Numbers are checked against the scene format's ranges (``config.schema.DRIVER_FIELDS``),
    for drivers built from Python as for those read from a scene file."""
    from magica_py.config.schema import DRIVER_FIELDS, MIN_ORBIT_PERIOD

    def num(key, default=None):
        value = p.get(key, default)
        if value is None:
            raise ValueError(f"{where}.{key}: required")
        value = float(value)
        if not np.isfinite(value):
            raise ValueError(f"{where}.{key}: expected a finite number, got {value}")
        bounds = DRIVER_FIELDS[kind][key].rng
        if not bounds.contains(value):
            raise ValueError(f"{where}.{key}: expected a number {bounds.describe()}, got {value:g}")
        return value

    rad = math.radians
    if kind == "keyframes":
        interpolation = p.get("interpolation", "linear")
        if interpolation not in INTERPOLATIONS:
            raise ValueError(f"{where}.interpolation: expected one of {sorted(INTERPOLATIONS)},"
                             f" got {interpolation!r}")
        return np.array([INTERPOLATIONS[interpolation], float(bool(p.get("loop", False)))])
    if kind == "orbit":
        axis = _unit(p.get("axis", (0.0, 1.0, 0.0)), f"{where}.axis")
        ref = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.99 else np.array([0.0, 0.0, 1.0])
        u = ref - portable.dot3(ref, axis) * axis
        u /= portable.norm(u)
        period = num("period")
        if not abs(period) >= MIN_ORBIT_PERIOD:
            raise ValueError(f"{where}.period: expected a period of at least {MIN_ORBIT_PERIOD:g} s either way, "
                             f"got {period:g}")
        return np.concatenate([np.asarray(p.get("center", (0.0, 0.0, 0.0)), dtype=np.float64),
                               [num("radius"), period], axis, u,
                               [rad(num("phase", 0.0)), float(bool(p.get("face_path", False)))]])
    if kind == "oscillate":
        prop = p.get("property", "position")
        if prop not in ("position", "rotation"):
            raise ValueError(f"{where}.property: expected position or rotation, got {prop!r}")
        rotation = prop == "rotation"
        amplitude = num("amplitude")
        return np.concatenate([_unit(p.get("axis", (0.0, 1.0, 0.0)), f"{where}.axis"),
                               [rad(amplitude) if rotation else amplitude, num("frequency"),
                                rad(num("phase", 0.0)), float(rotation)]])
    if kind == "spin":
        return np.concatenate([_unit(p.get("axis", (0.0, 1.0, 0.0)), f"{where}.axis"),
                               [rad(num("speed"))]])
    if kind == "walk":
        direction = _unit(p.get("direction", (0.0, 0.0, 1.0)), f"{where}.direction")
        up = _unit(p.get("up", (0.0, 1.0, 0.0)), f"{where}.up")
        if portable.norm(np.cross(up, direction)) < 1e-6:
            raise ValueError(f"{where}: direction must not be parallel to up")
        return np.concatenate([direction, [num("speed", 0.0), num("stride_frequency", 1.8),
                                           num("bob", 0.03), rad(num("sway", 4.0)),
                                           num("lateral", 0.0), rad(num("twist", 0.0))], up])
    raise ValueError(f"{where}: unknown driver kind {kind!r}")


def _make_event(hierarchy, kind: str, params: dict, at: float, where: str) -> Event:
    if not np.isfinite(at):
        raise ValueError(f"{where}.at: expected a finite time, got {at}")
    if kind == "time_scale":
        value = float(params["value"])
        if not np.isfinite(value) or value < 0.0:
            raise ValueError(f"{where}.time_scale: expected a number >= 0, got {value}")
        return Event(at, kind, value)
    if kind == "set_parameter":
        payload = {k: params[k] for k in ("cloth", "key", "value")}
        return Event(at, kind, payload)
    if kind == "wind":  # applied by the cloth system's wind field (magica_py/wind)
        return Event(at, kind, {"zone": params["zone"], "enabled": params.get("enabled"), "main": params.get("main")})
    # teleport
    target = _resolve(hierarchy, params["target"], f"{where}.teleport.target")
    position = params.get("position")
    rotation = _rotation(params, f"{where}.teleport")
    if position is None and rotation is None:
        raise ValueError(f"{where}.teleport: expected a position and/or a rotation (or euler)")
    payload = {"target": target, "name": hierarchy.names[target],
               "position": None if position is None else tuple(float(c) for c in position),
               "rotation": None if rotation is None else tuple(float(c) for c in rotation)}
    return Event(at, kind, payload, target)


def instance_phase_offset(instance: int, step: float = 0.0, jitter: float = 0.0,
                          seed: int = 0) -> float:
    """Per-instance driver time offset for crowds: ``instance * step`` plus a uniform
    [0, jitter) draw that depends only on (seed, instance), so any subset of a crowd
    reproduces the same offsets."""
    offset = instance * float(step)
    if jitter > 0.0:
        offset += float(np.random.default_rng([int(seed), int(instance)]).uniform(0.0, jitter))
    return offset
