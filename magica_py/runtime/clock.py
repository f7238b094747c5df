"""Frame-time sources and a Unity-semantics time manager (docs/solver.md §A.2; Unity ``Time``).

A *frame-time source* says how much real time passed since the previous rendered frame:

* ``FixedFrameRate(fps)``: every frame lasts ``1/fps`` (Unity's ``Time.captureFramerate``).
* ``FrameTimeList(times, cycle=True, then=None)``: frame ``i`` lasts ``times[i]``; the list
  repeats (``cycle``), or after its end every frame lasts ``then`` (an error when ``then`` is
  None). Reproduces hitches (``[1/60]*30 + [1.0]``) and variable frame rates.
* ``RealClock(first_delta, target_fps=None)``: wall-clock time between two calls, optionally
  sleeping so that frames are not shorter than ``1/target_fps`` (a vsync-like cap).

``TimeManager.advance(raw_delta)`` turns a raw frame time into a ``UnityTime`` snapshot.
What is emulated, precisely (all in float64; Unity keeps its clocks in double as well):

* ``unscaled_delta_time = raw`` and ``unscaled_time += raw``. The real interval is not clamped
  (Unity documents maximumDeltaTime as a cap on ``Time.deltaTime`` and ``Time.time`` only).
* ``delta_time = min(raw, maximum_delta_time) * time_scale`` and ``time += delta_time``.
  ``time`` includes the current frame: after frame 0 at 60 fps it is 1/60.
* Fixed updates (FixedUpdate before Update, as Unity runs them): the fixed clock advances in
  ``fixed_delta_time`` increments while ``fixed_time + fixed_delta_time <= time``. The fixed
  clock is kept as ``base + k * fixed_delta_time`` (no running sum, so no drift), and the
  comparison tolerates ``FIXED_TIME_TOLERANCE`` seconds of float noise, so 50 fps with
  fixedDeltaTime 0.02 gives exactly one FixedUpdate per frame. The catch-up is capped by
  ``maximum_delta_time``: when the fixed clock lags scaled time by more than that, the
  excess is dropped (``fixed_time = time - maximum_delta_time``), which bounds the number of
  FixedUpdates per frame to ``maximum_delta_time / fixed_delta_time`` (Unity's documented
  bound; it only matters for time_scale > 1 or a fixed_delta_time changed at run time).
* As in Unity, ``maximum_delta_time`` is kept at least ``fixed_delta_time``; ``time_scale``
  must be finite and >= 0 (0 pauses scaled time and fixed updates, not unscaled time).
* ``frame_count`` counts frames including the current one (1 on the first frame).
* Changes to ``time_scale`` / ``fixed_delta_time`` / ``maximum_delta_time`` take effect on
  the next ``advance`` (the player applies time-scale events at the end of a frame).
"""
from __future__ import annotations

import math
import time as _time
from typing import NamedTuple, Protocol, Sequence

FIXED_TIME_TOLERANCE = 1e-9  # s; absorbs float noise in "fixed_time + fdt <= time"
UNITY_FIXED_DELTA_TIME = 0.02  # Unity's default Time.fixedDeltaTime
UNITY_MAXIMUM_DELTA_TIME = 1.0 / 3.0  # Unity's default Time.maximumDeltaTime (0.3333333)


class FrameTimeSource(Protocol):
    """Where raw frame times come from (seconds of real time per rendered frame)."""

    def next_delta(self) -> float: ...

    def reset(self) -> None: ...


def _check_delta(value, what: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{what}: expected a number of seconds, got {value!r}") from None
    if not math.isfinite(v) or v <= 0.0:
        raise ValueError(f"{what}: expected a finite frame time > 0 s, got {value!r}")
    return v


class FixedFrameRate:
    """Every frame lasts exactly ``1/fps`` seconds."""

    def __init__(self, fps: float):
        try:
            fps_value = float(fps)
        except (TypeError, ValueError):
            raise ValueError(f"fps: expected a number, got {fps!r}") from None
        if not math.isfinite(fps_value) or fps_value <= 0.0:
            raise ValueError(f"fps: expected a finite frame rate > 0, got {fps!r}")
        self.fps = fps_value
        self.delta = 1.0 / fps_value

    def next_delta(self) -> float:
        return self.delta

    def reset(self) -> None:
        pass

    def __repr__(self) -> str:
        return f"FixedFrameRate({self.fps:g})"


class FrameTimeList:
    """Frame ``i`` lasts ``times[i]``; then the list repeats or every frame lasts ``then``."""

    def __init__(self, times: Sequence[float], cycle: bool = True, then: float | None = None):
        if len(times) == 0:
            raise ValueError("frame_times: expected a non-empty list of frame times in seconds")
        self.times = tuple(_check_delta(t, f"frame_times[{i}]") for i, t in enumerate(times))
        self.cycle = bool(cycle)
        self.then = None if then is None else _check_delta(then, "frame_times (then)")
        self.position = 0

    def next_delta(self) -> float:
        i = self.position
        self.position += 1
        if i < len(self.times):
            return self.times[i]
        if self.cycle:
            return self.times[i % len(self.times)]
        if self.then is not None:
            return self.then
        raise IndexError(f"frame_times: the list of {len(self.times)} frame times is exhausted at "
                         f"frame {i} (cycle=False and no 'then' frame time)")

    def reset(self) -> None:
        self.position = 0

    def __repr__(self) -> str:
        return f"FrameTimeList({len(self.times)} times, cycle={self.cycle})"


class RealClock:
    """Wall-clock frame times (``time.perf_counter``), optionally capped to ``target_fps``.

    The first call returns ``first_delta`` (there is no previous frame to measure from).
    """

    def __init__(self, first_delta: float = 1.0 / 60.0, target_fps: float | None = None,
                 now=_time.perf_counter, sleep=_time.sleep):
        self.first_delta = _check_delta(first_delta, "first_delta")
        if target_fps is None:
            self.min_delta = 0.0
        else:
            self.min_delta = 1.0 / _check_delta(target_fps, "target_fps")
        self._now = now
        self._sleep = sleep
        self._last: float | None = None

    def next_delta(self) -> float:
        t = self._now()
        if self._last is None:
            self._last = t
            return self.first_delta
        delta = t - self._last
        if delta < self.min_delta:
            self._sleep(self.min_delta - delta)
            t = self._now()
            delta = t - self._last
        self._last = t
        return max(delta, 1e-9)  # two calls in the same clock tick still move time forward

    def reset(self) -> None:
        self._last = None


class UnityTime(NamedTuple):
    """One frame's Unity ``Time`` values (seconds). Produced by ``TimeManager.advance``.

    Immutable; a named tuple rather than a frozen dataclass because one is made every frame
    and a frozen dataclass takes about a microsecond longer to construct (a single tail's
    whole frame is ~30 us)."""

    frame_count: int             # frames so far including this one (1 on the first frame)
    delta_time: float            # min(raw, maximum_delta_time) * time_scale
    unscaled_delta_time: float   # raw frame time
    time: float                  # sum of delta_time, this frame included
    unscaled_time: float         # sum of unscaled_delta_time, this frame included
    fixed_delta_time: float      # fixed step (scaled time)
    fixed_time: float            # fixed clock after this frame's FixedUpdates
    fixed_update_count: int      # FixedUpdates run this frame (before Update)
    time_scale: float
    maximum_delta_time: float


class TimeManager:
    """Unity's frame clock and FixedUpdate accumulation (module docstring for the details)."""

    def __init__(self, fixed_delta_time: float = UNITY_FIXED_DELTA_TIME,
                 maximum_delta_time: float = UNITY_MAXIMUM_DELTA_TIME, time_scale: float = 1.0):
        self.fixed_delta_time = fixed_delta_time
        self.maximum_delta_time = maximum_delta_time
        self.time_scale = time_scale
        self.reset()

    # -- settings (validated; effective from the next advance)
    @property
    def time_scale(self) -> float:
        return self._time_scale

    @time_scale.setter
    def time_scale(self, value: float) -> None:
        v = float(value)
        if not math.isfinite(v) or v < 0.0:
            raise ValueError(f"time_scale: expected a finite number >= 0, got {value!r}")
        self._time_scale = v

    @property
    def fixed_delta_time(self) -> float:
        return self._fixed_delta_time

    @fixed_delta_time.setter
    def fixed_delta_time(self, value: float) -> None:
        v = _check_delta(value, "fixed_delta_time")
        if hasattr(self, "_fixed_base"):  # re-anchor the fixed clock where it stands now
            self._fixed_base = self.fixed_time
            self._fixed_steps = 0
        self._fixed_delta_time = v

    @property
    def maximum_delta_time(self) -> float:
        """Never below fixed_delta_time (Unity enforces the same)."""
        return max(self._maximum_delta_time, self._fixed_delta_time)

    @maximum_delta_time.setter
    def maximum_delta_time(self, value: float) -> None:
        self._maximum_delta_time = _check_delta(value, "maximum_delta_time")

    @property
    def fixed_time(self) -> float:
        return self._fixed_base + self._fixed_steps * self._fixed_delta_time

    def reset(self) -> None:
        """Back to the start of play: all clocks 0, no frame yet."""
        self.frame_count = 0
        self.time = 0.0
        self.unscaled_time = 0.0
        self._fixed_base = 0.0
        self._fixed_steps = 0
        self.last: UnityTime | None = None

    def advance(self, raw_delta: float) -> UnityTime:
        """Start a new frame that took ``raw_delta`` seconds of real time."""
        if type(raw_delta) is float and 0.0 < raw_delta < math.inf:
            raw = raw_delta   # the usual frame (NaN fails the test and is refused below)
        else:
            raw = _check_delta(raw_delta, "frame time")
        fdt = self._fixed_delta_time
        max_dt = max(self._maximum_delta_time, fdt)
        scale = self._time_scale
        delta = min(raw, max_dt) * scale
        self.frame_count += 1
        self.unscaled_time += raw
        time = self.time + delta
        self.time = time

        # fixed clock catches up with scaled time; the lag beyond maximum_delta_time is dropped
        base = self._fixed_base
        steps = self._fixed_steps
        if time - (base + steps * fdt) > max_dt:
            base = self._fixed_base = time - max_dt
            steps = 0
        count = 0
        while base + (steps + 1) * fdt <= time + FIXED_TIME_TOLERANCE:
            steps += 1
            count += 1
        self._fixed_steps = steps

        self.last = UnityTime(self.frame_count, delta, raw, time, self.unscaled_time, fdt,
                              base + steps * fdt, count, scale, max_dt)
        return self.last


def time_from_settings(settings) -> tuple[FrameTimeSource, TimeManager]:
    """A frame-time source and a TimeManager from scene settings (read by attribute name).

    Understands ``fps`` | ``frame_times`` (+ optional ``frame_times_cycle``, default True;
    when False the last frame time repeats after the list) |
    ``clock == "realtime"``, and ``fixed_delta_time``, ``maximum_delta_time``, ``time_scale``
    when present (Unity defaults otherwise). Works with any object, not only config's.
    """
    def get(name, default=None):
        if isinstance(settings, dict):
            return settings.get(name, default)
        return getattr(settings, name, default)

    frame_times = get("frame_times")
    clock = get("clock")
    fps = get("fps")
    if frame_times:
        cycle = bool(get("frame_times_cycle", True))
        # not cycled: the last frame time is kept after the list (SceneSettings semantics)
        source: FrameTimeSource = FrameTimeList(frame_times, cycle=cycle,
                                                then=None if cycle else frame_times[-1])
    elif clock in ("realtime", "real", "wall"):
        source = RealClock(first_delta=1.0 / float(fps) if fps else 1.0 / 60.0)
    elif fps:
        source = FixedFrameRate(fps)
    else:
        source = FixedFrameRate(60.0)
    manager = TimeManager(
        fixed_delta_time=get("fixed_delta_time") or UNITY_FIXED_DELTA_TIME,
        maximum_delta_time=get("maximum_delta_time") or UNITY_MAXIMUM_DELTA_TIME,
        time_scale=1.0 if get("time_scale") is None else get("time_scale"),
    )
    return source, manager
