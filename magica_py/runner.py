"""Playing a prepared scene: the frame loop shared by ``run``, ``watch`` and ``simulate``.

* ``CompileWatch``: listens to numba's documented event API (``numba.core.event``, event
  kind ``"numba:compile"``, which fires only when a function is compiled, not when it is
  loaded from the on-disk cache). The first compile of a run prints "compiling the solver
  for this scene, first run only ..." *before* it starts, and the time spent compiling is
  measured (outermost events only: a kernel compiling its helpers is one compile).
* ``WarningEvents``: numpy's floating-point warnings (``RuntimeWarning: overflow encountered
  in dot`` ...) raised inside a frame become ``("numpy_warning", {...})`` events of that frame
  (so the sink records them on the event log) and are counted for one line of the summary,
  instead of raw Python warnings on the terminal.
* ``FrameProgress``: the progress bar (tqdm: rate, ETA, works on terminals, in logs and
  notebooks); time spent compiling is taken out of its rate and ETA.
* ``play(...)`` -> ``RunStats`` and ``summary_line(...)``: the loop and the line the CLI
  prints, with the compile time reported apart from the ms/frame.
"""
from __future__ import annotations

import sys
import time
import warnings
from collections import Counter
from dataclasses import dataclass, field

# Per-frame metrics: simulation steps this frame (first one present wins) and particle-steps.
STEP_METRICS = ("cloth.simulation_steps", "solver.steps", "simulation.steps")
PARTICLE_STEP_METRIC = "cloth.steps"
WARNING_EVENT = "numpy_warning"        # RuntimeWarning: numpy's floating-point warnings
OTHER_WARNING_EVENT = "warning"        # any other warning raised inside a frame
WARNING_SYSTEM = "warning_events"
COMPILE_MESSAGE = ("compiling the solver for this scene, first run only (compiled kernels are cached for the "
                   "next runs; this can take a minute or more) ...")


# ----------------------------------------------------------------------------- compile
class CompileWatch:
    """Context manager: announces and times numba compiles that happen inside it.

    ``on_first(message)`` is called once, when the first compile starts (default: print to
    stderr); ``on_end()`` after every outermost compile (the progress bar's pause). During
    each outermost compile Python's garbage collector runs less often
    (``jit.fewer_collections``: a first run 3-18 % shorter, docs/architecture.md)."""

    def __init__(self, announce=None, on_end=None):
        self.seconds = 0.0        # wall time of outermost compiles
        self.count = 0            # outermost compiles
        self.announce = announce
        self.on_end = on_end
        self._depth = 0
        self._start = 0.0
        self._context = None
        self._collections = None   # the outermost compile's ``fewer_collections`` block

    # numba.core.event.Listener protocol (duck-typed: notify(event))
    def notify(self, event) -> None:
        if event.is_start:
            if self._depth == 0:
                if self.count == 0 and self.announce is not None:
                    self.announce(COMPILE_MESSAGE)
                self._start = time.perf_counter()
                from magica_py.jit import fewer_collections

                self._collections = fewer_collections()
                self._collections.__enter__()
            self._depth += 1
        elif event.is_end:
            self._depth = max(0, self._depth - 1)
            if self._depth == 0:
                collections, self._collections = self._collections, None
                if collections is not None:
                    collections.__exit__(None, None, None)
                self.seconds += time.perf_counter() - self._start
                self.count += 1
                if self.on_end is not None:
                    self.on_end()

    def __enter__(self):
        from numba.core import event

        listener = _as_listener(self, event)
        self._context = event.install_listener("numba:compile", listener)
        self._context.__enter__()
        return self

    def __exit__(self, *exc):
        collections, self._collections = self._collections, None
        if collections is not None:   # left inside a compile (an error): the thresholds back
            collections.__exit__(None, None, None)
        context, self._context = self._context, None
        return context.__exit__(*exc) if context is not None else False


class Stopwatch:
    """Context manager: the wall time of a block less the compiles ``watch`` (a ``CompileWatch``,
    or None) saw inside it, so that a command's load, simulate or write time is the same on a
    first run as on the next ones. After the block: ``seconds`` (without the compiles) and
    ``compiled`` (the compiles' wall time)."""

    def __init__(self, watch: CompileWatch | None = None):
        self.watch = watch
        self.seconds = 0.0
        self.compiled = 0.0
        self._start = 0.0
        self._compiled_before = 0.0

    def __enter__(self):
        self._compiled_before = self.watch.seconds if self.watch is not None else 0.0
        self._start = time.perf_counter()
        return self

    def _compiled_so_far(self) -> float:
        return (self.watch.seconds - self._compiled_before) if self.watch is not None else 0.0

    def elapsed(self) -> float:
        """Inside the block: the wall time so far, less the compiles so far."""
        return max(0.0, time.perf_counter() - self._start - self._compiled_so_far())

    def __exit__(self, *exc):
        elapsed = time.perf_counter() - self._start
        self.compiled = self._compiled_so_far()
        self.seconds = max(0.0, elapsed - self.compiled)
        return False


def compile_text(seconds: float) -> str:
    """The summaries' report of a run's compile: ``"; compile 42.1 s, first run only"``, or
    nothing when nothing compiled."""
    return f"; compile {seconds:.1f} s, first run only" if seconds >= 0.05 else ""


def _as_listener(watch: CompileWatch, event):
    class _Listener(event.Listener):
        def on_start(self, ev):
            watch.notify(ev)

        def on_end(self, ev):
            watch.notify(ev)

    return _Listener()


# ----------------------------------------------------------------------------- warnings
class WarningEvents:
    """Turns the warnings raised inside frames into events and counts them.

    ``attach(player)`` adds a RENDER_WRITE system that runs before the sink (add it before
    the sink is attached) and moves the warnings caught so far into ``ctx.events``; use the
    object as a context manager around the frame loop to catch them."""

    def __init__(self):
        self.caught: list[warnings.WarningMessage] = []
        self.counts: Counter = Counter()   # message -> occurrences over the run
        self.first_frame: dict[str, int] = {}
        self._context = None

    def attach(self, player) -> None:
        from magica_py.runtime.phases import Phase, System

        player.schedule.add(Phase.RENDER_WRITE, System(WARNING_SYSTEM, self.drain))
        # a warning raised in a system after the sink (none today) lands in the next frame

    def drain(self, ctx) -> None:
        """Move this frame's warnings into ``ctx.events`` (one event per distinct message)."""
        if not self.caught:
            return
        seen = Counter(f"{w.category.__name__}: {w.message}" for w in self.caught)
        first = {}
        for w in self.caught:
            first.setdefault(f"{w.category.__name__}: {w.message}", w)
        self.caught.clear()
        for message, count in seen.items():
            w = first[message]
            self.counts[message] += count
            self.first_frame.setdefault(message, int(ctx.frame))
            kind = WARNING_EVENT if issubclass(w.category, RuntimeWarning) else OTHER_WARNING_EVENT
            ctx.events.append((kind, {"message": message, "count": count, "source": f"{w.filename}:{w.lineno}"}))

    def __enter__(self):
        self._context = warnings.catch_warnings(record=True)
        self.caught = self._context.__enter__()
        warnings.simplefilter("always", RuntimeWarning)  # every occurrence, not once per line
        return self

    def __exit__(self, *exc):
        leftover = list(self.caught)
        context, self._context = self._context, None
        result = context.__exit__(*exc) if context is not None else False
        self.caught = []
        for w in leftover:  # raised outside a frame's sink phase: count them, do not lose them
            message = f"{w.category.__name__}: {w.message}"
            self.counts[message] += 1
        return result

    def summary(self) -> str:
        """One line: ``3 numpy warnings (overflow encountered in dot x3, first at frame 12) ...``."""
        total = sum(self.counts.values())
        if not total:
            return ""
        parts = []
        for message, count in self.counts.most_common(3):
            where = f", first at frame {self.first_frame[message]}" if message in self.first_frame else ""
            parts.append(f"{message} x{count}{where}")
        more = f" and {len(self.counts) - 3} other kinds" if len(self.counts) > 3 else ""
        return (f"{total} warning{'s' if total != 1 else ''} during the run ({'; '.join(parts)}{more}); "
                f"each is an event of its frame ({WARNING_EVENT} / {OTHER_WARNING_EVENT}) in the recording")


# ----------------------------------------------------------------------------- progress
class FrameProgress:
    """A frame progress bar (tqdm) on ``stream`` (stderr): shown after ``delay`` s, with rate
    and ETA; ``update(done)`` takes the number of frames done so far.

    On a terminal it redraws in place at most 10 times a second; into a log file (not a TTY)
    it writes a plain line every ``log_interval`` s; ``notebook=True`` draws a notebook
    widget (tqdm.auto). ``pause_ended()`` takes the time since the last redraw out of the
    rate and ETA (called after a compile)."""

    def __init__(self, total: int | None, stream=None, delay: float = 1.0, notebook: bool = False,
                 log_interval: float = 10.0, desc: str | None = None, unit: str = "frame", initial: int = 0):
        stream = stream if stream is not None else sys.stderr
        terminal = bool(getattr(stream, "isatty", lambda: False)())
        if notebook:
            from tqdm.auto import tqdm
        else:
            from tqdm import tqdm
        self.bar = tqdm(total=total, unit=unit, initial=initial, file=stream if terminal or notebook else _LogLines(stream),
                        delay=delay, desc=desc, leave=True,
                        mininterval=0.1 if terminal or notebook else log_interval,
                        ascii=None if terminal or notebook else True, dynamic_ncols=terminal,
                        ncols=None if terminal or notebook else 100, smoothing=0.1)
        self.done = initial

    def update(self, done: int) -> None:
        if done > self.done:
            self.bar.update(done - self.done)
            self.done = done

    def pause_ended(self) -> None:
        self.bar.unpause()

    def write(self, text: str) -> None:
        """A message above the bar (the bar is redrawn below it)."""
        self.bar.write(text, file=self.bar.fp)

    def close(self) -> None:
        self.bar.close()


class _LogLines:
    """A log file's view of the bar: each redraw as its own line (no carriage returns)."""

    def __init__(self, stream):
        self.stream = stream

    def write(self, text: str) -> None:
        text = text.replace("\r", "").strip()
        if text:
            self.stream.write(text + "\n")

    def flush(self) -> None:
        self.stream.flush()


# ----------------------------------------------------------------------------- the loop
@dataclass
class RunStats:
    """Totals of a run for the summary line."""

    frames: int = 0
    steps: float = 0.0             # simulation steps (the most any cloth ran in a frame, summed)
    steps_known: bool = False
    particle_steps: float = 0.0    # particles x steps, summed over cloths and frames
    wall_time: float = 0.0         # s, the frames without the compile
    compile_seconds: float = 0.0   # s, numba compiles during the run (first run only)
    first_frame_seconds: float = 0.0  # s, the first frame without its compile (loads the cached kernels)
    warnings: str = ""             # the warnings' summary line, "" when none
    resets: dict = field(default_factory=dict)   # (cloth, reason) -> [count, first frame]: cloth_reset events

    def resets_summary(self) -> str:
        """One line on the cloth resets of the run (a guard found a non-finite or runaway particle
        state and reset the cloth), ``""`` when none: a run that keeps resetting is not a good run."""
        if not self.resets:
            return ""
        total = sum(count for count, _ in self.resets.values())
        ordered = sorted(self.resets.items(), key=lambda kv: -kv[1][0])
        parts = [f"{cloth!r} x{count} ({reason}, first at frame {first})"
                 for (cloth, reason), (count, first) in ordered[:3]]
        more = f" and {len(ordered) - 3} more" if len(ordered) > 3 else ""
        return (f"warning: {total} cloth reset{'s' if total != 1 else ''} during the run: {'; '.join(parts)}{more}; "
                f"each is a cloth_reset event of its frame in the recording (check the scene's animation and "
                f"parameters)")


def frame_steps(ctx, system) -> float | None:
    """Simulation steps of this frame: a solver metric, else the solver's team time state."""
    for name in STEP_METRICS:
        if name in ctx.metrics:
            return float(ctx.metrics[name])
    counts = getattr(getattr(system, "time_state", None), "update_count", None)
    if counts is not None and len(counts):
        return float(max(counts))
    return None


def play(player, scene, frames: int | None, *, system=None, progress: FrameProgress | None = None,
         compile_watch: CompileWatch | None = None, warning_events: WarningEvents | None = None,
         on_frame=None) -> RunStats:
    """Step ``player`` ``frames`` times (or, for a realtime clock with a duration, until that
    much unscaled time has passed). ``on_frame(ctx)`` is called after each frame."""
    stats = RunStats()
    duration = scene.settings.duration if frames is None else None
    with Stopwatch(compile_watch) as clock:
        try:
            while True:
                if frames is not None and stats.frames >= frames:
                    break
                ctx = player.step()
                stats.frames += 1
                if stats.frames == 1:
                    stats.first_frame_seconds = clock.elapsed()
                steps = frame_steps(ctx, system)
                if steps is not None:
                    stats.steps += steps
                    stats.steps_known = True
                stats.particle_steps += float(ctx.metrics.get(PARTICLE_STEP_METRIC, 0.0))
                for kind, payload in ctx.events or ():
                    if kind == "cloth_reset" and isinstance(payload, dict):
                        key = (str(payload.get("cloth")), str(payload.get("reason", "guard")))
                        entry = stats.resets.setdefault(key, [0, stats.frames - 1])
                        entry[0] += 1
                if on_frame is not None:
                    on_frame(ctx)
                if progress is not None:
                    progress.update(stats.frames)
                if duration is not None and ctx.time.unscaled_time >= duration:
                    break
        finally:
            if warning_events is not None:
                stats.warnings = warning_events.summary()
    stats.compile_seconds = clock.compiled
    stats.wall_time = clock.seconds
    return stats


def summary_line(scene, stats: RunStats, solver_attached: bool, output, compile_seconds: float | None = None,
                 threads: int | None = None, interpreted: bool = False) -> str:
    """``name: N frames, S simulation steps (P particle-steps), x ms/frame[ on T threads] (wall w
    s[; compile c s, first run only][; interpreted, first run only]) -> output``.
    ``compile_seconds``: the whole run's compile time (attach included), default the frames'.
    ``threads``: the cloth frame's threads (named when more than one). ``interpreted``: the run
    went interpreted (``magica_py/first_run.py``), so its ms/frame is not the compiled speed."""
    import os

    per_frame = 1000.0 * stats.wall_time / max(stats.frames, 1)
    first = ""
    if stats.frames > 1 and stats.first_frame_seconds > 0.0:  # steady state: the first frame loads kernels
        per_frame = 1000.0 * (stats.wall_time - stats.first_frame_seconds) / (stats.frames - 1)
        first = f", first frame {stats.first_frame_seconds:.2f} s"
    if stats.steps_known:
        steps = f"{int(round(stats.steps))} simulation steps"
        if stats.particle_steps:
            steps += f" ({int(round(stats.particle_steps))} particle-steps)"
    elif not scene.cloths:
        steps = "no cloths"
    elif not solver_attached:
        steps = "no simulation steps (cloth solver not attached)"
    else:
        steps = "simulation steps not reported"
    compiled = stats.compile_seconds if compile_seconds is None else compile_seconds
    compiled_text = compile_text(compiled)
    if interpreted:
        compiled_text += "; interpreted, first run only"
    where = ""
    if output:
        text = os.path.relpath(output)
        where = f" -> {text if not text.startswith('..') else os.path.abspath(output)}"
    on = f" on {threads} threads" if threads is not None and threads > 1 else ""
    return (f"{scene.name}: {stats.frames} frames, {steps}, {per_frame:.2f} ms/frame{on} "
            f"(wall {stats.wall_time:.2f} s{first}{compiled_text}){where}")
