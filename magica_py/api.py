"""The Python API for notebooks and scripts (docs/api.md).

One call::

    result = magica_py.simulate("configs/tail_orbit.yaml", frames=120,
                                overrides=["cloths.tail.parameters.damping=0.2"])
    result.cloths["tail"].positions      # (120, 8, 3) float64, m, world space
    result.metrics["max_edge_stretch"]   # (120,)

and the step-by-step form for finer control (change parameters between frames, read the
state, stop when you like)::

    with magica_py.Session("configs/tail_orbit.yaml") as session:
        for frame in range(60):
            session.step()
        session.system.set_parameter("tail", "damping", 0.5)
        session.step()
        result = session.result()

``Session`` wires what ``magica-py run`` wires (``Player.for_scene``, the cloth solver's
``attach``, optionally the recording sink), plus a RENDER_WRITE system that copies every
frame's cloth particles, bone rotations, metrics and events into arrays.
"""
from __future__ import annotations

import copy
import math
import numbers
import os
import pathlib
from dataclasses import dataclass

import numpy as np

CAPTURE_SYSTEM = "api_capture"


# ----------------------------------------------------------------------------- results
@dataclass
class ClothTrack:
    """One cloth over a run (F frames, N particles; one particle per simulated bone).

    ==================  ============  ====================================================
    positions           (F, N, 3)     display positions, world space, m (what the bones
                                      were written from; docs/solver.md §E.1)
    rotations           (F, N, 4)     world rotation of each particle's bone after the
                                      write-back, quaternion (x, y, z, w), Unity axes
    local_rotations     (F, N, 4)     the same bones' local rotations (what an engine sets)
    bones               N names       the bone (transform) of each particle
    parent              (N,) int32    parent particle or -1 (the chain / mesh baselines)
    edges               (E, 2) int32  proxy edges (particle indices)
    rest_length         (E,) float64  rest length of each edge, m
    ==================  ============  ====================================================
    """

    name: str
    positions: np.ndarray
    rotations: np.ndarray
    local_rotations: np.ndarray
    bones: list[str]
    parent: np.ndarray
    edges: np.ndarray
    rest_length: np.ndarray

    @property
    def particle_count(self) -> int:
        return int(self.positions.shape[1])


@dataclass
class Simulation:
    """The result of ``simulate`` / ``Session.result()``.

    ``time`` and ``delta_time`` are (F,) seconds of game time; ``cloths`` maps each cloth
    name (``skirt#3`` for instance 3 of an instanced cloth) to its ``ClothTrack``;
    ``metrics`` maps a metric name to its (F,) per-frame values: the quality metrics
    ``max_edge_stretch`` (ratio), ``max_penetration`` (m) and ``max_speed`` (m/s), measured
    as the recording sink measures them (docs/recordings.md), plus every number the systems
    reported (``time.*`` wall times in s, ``cloth.steps`` particle-steps, ...; NaN in a frame
    that did not report it). ``events`` lists ``(frame, kind, payload)`` (teleports,
    ``cloth_reset``, ``numpy_warning`` ...). ``wall_time`` (s) leaves out
    ``compile_seconds``, the numba compile of a first run."""

    scene: object
    frames: int
    time: np.ndarray
    delta_time: np.ndarray
    cloths: dict
    metrics: dict
    events: list
    wall_time: float = 0.0
    compile_seconds: float = 0.0
    warnings: str = ""
    recording: str | None = None

    def __repr__(self) -> str:
        cloths = ", ".join(f"{k} ({v.particle_count})" for k, v in list(self.cloths.items())[:6])
        more = f" ... {len(self.cloths) - 6} more" if len(self.cloths) > 6 else ""
        return (f"Simulation({getattr(self.scene, 'name', '?')!r}: {self.frames} frames, cloths: {cloths or 'none'}"
                f"{more}; metrics: {', '.join(sorted(self.metrics)[:8])}{' ...' if len(self.metrics) > 8 else ''})")


# ----------------------------------------------------------------------------- loading
def load(scene_or_path, overrides=()):
    """A ``Scene`` from a YAML path, a VRM avatar path, YAML text, or a ``Scene`` (a copy:
    running moves the scene's bones, and a ``Scene`` given by the caller must stay as loaded
    so that it runs again with the same result; ``overrides`` then is an error: they apply
    to a document)."""
    from magica_py.config import load_scene, load_scene_text

    if isinstance(overrides, (str, bytes)):
        raise TypeError(f"overrides: expected a list of 'PATH=VALUE' strings, got the string {overrides!r} "
                        f"(write overrides=[{overrides!r}])")
    if hasattr(scene_or_path, "hierarchy") and hasattr(scene_or_path, "settings"):
        if overrides:
            raise ValueError("overrides apply to a scene document; give the path or the YAML text")
        return copy.deepcopy(scene_or_path)
    if isinstance(scene_or_path, str) and "\n" in scene_or_path:
        return load_scene_text(scene_or_path, list(overrides))
    path = pathlib.Path(os.fspath(scene_or_path))
    if isinstance(scene_or_path, str) and not path.exists() and ("{" in scene_or_path or ": " in scene_or_path):
        raise ValueError(f"scene_or_path: {scene_or_path!r} is not a file; YAML text is recognised by its "
                         "line breaks (a scene document has several lines)")
    from magica_py.avatar import avatar_scene_text, is_vrm_file

    if is_vrm_file(path):
        return load_scene_text(avatar_scene_text(path), list(overrides), source=f"<scene of {path}>")
    return load_scene(path, list(overrides))


# ----------------------------------------------------------------------------- capture
class _Capture:
    """RENDER_WRITE: copies the frame's cloth data, time, metrics and events."""

    def __init__(self, scene, provider):
        from magica_py.sinks.shapes import collider_shapes

        self.scene = scene
        self.provider = provider
        self.topologies = list(provider.cloth_topologies()) if provider is not None else []
        self.transforms = np.concatenate([np.asarray(t.transform_index, np.int64) for t in self.topologies]) \
            if self.topologies else np.zeros(0, np.int64)
        self.collider_shapes = collider_shapes
        self.positions: list[np.ndarray] = []
        self.rotations: list[np.ndarray] = []
        self.local_rotations: list[np.ndarray] = []
        self.shapes: list = []
        self.time: list[float] = []
        self.delta_time: list[float] = []
        self.metrics: list[dict] = []
        self.events: list[tuple] = []

    def run(self, ctx) -> None:
        h = self.scene.hierarchy
        self.time.append(float(ctx.time.time))
        self.delta_time.append(float(ctx.time.delta_time))
        self.metrics.append({k: float(v) for k, v in ctx.metrics.items()
                             if isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)})
        self.events.extend((int(ctx.frame), kind, payload) for kind, payload in ctx.events)
        if not self.topologies:
            return
        self.positions.append(np.array(self._particles(), dtype=np.float64))
        self.rotations.append(np.array(h.world_rotation[self.transforms], dtype=np.float64))
        self.local_rotations.append(np.array(h.local_rotation[self.transforms], dtype=np.float64))
        self.shapes.append(self.collider_shapes(getattr(self.scene, "colliders", None), h))

    def _particles(self) -> np.ndarray:
        if hasattr(self.provider, "particle_positions"):
            return self.provider.particle_positions()
        return np.concatenate([f.positions for f in self.provider.cloth_frames()])

    def result(self, scene) -> tuple[dict, dict]:
        """(cloths, metrics) as arrays."""
        frames = len(self.time)
        names = sorted({k for m in self.metrics for k in m})
        metrics = {k: np.array([m.get(k, np.nan) for m in self.metrics], dtype=np.float64) for k in names}
        cloths = {}
        if self.topologies and frames:
            x = np.stack(self.positions)
            rot, local = np.stack(self.rotations), np.stack(self.local_rotations)
            metrics.update(self._quality(x))
            offset = 0
            bone_names = scene.hierarchy.names
            for t in self.topologies:
                n = t.particle_count
                part = slice(offset, offset + n)
                cloths[t.name] = ClothTrack(
                    name=t.name, positions=x[:, part], rotations=rot[:, part], local_rotations=local[:, part],
                    bones=[bone_names[int(i)] for i in t.transform_index], parent=np.asarray(t.parent, np.int32),
                    edges=np.asarray(t.edges, np.int32).reshape(-1, 2),
                    rest_length=np.asarray(t.rest_length, np.float64))
                offset += n
        return cloths, metrics

    def _quality(self, x: np.ndarray) -> dict:
        from magica_py.sinks.metrics import FrameMetrics
        from magica_py.sinks.shapes import shape_slots

        kind, slot = shape_slots(getattr(self.scene, "colliders", None))
        shapes = {}
        for name in ("sphere_center", "sphere_radius", "capsule_start", "capsule_end", "capsule_start_radius",
                     "capsule_end_radius", "plane_point", "plane_normal"):
            values = [getattr(s, name) for s in self.shapes]
            if values and len(values[0]):
                shapes[name] = np.stack(values)
        return FrameMetrics(self.topologies, kind, slot).compute(x, shapes, np.asarray(self.delta_time))


# ----------------------------------------------------------------------------- session
class Session:
    """A scene ready to run frame by frame: ``scene``, ``player`` (``Player.for_scene``),
    ``system`` (the cloth solver's ``ClothSystem``, None without cloths or with
    ``simulate_cloths=False``) and ``recorder`` (when ``record`` is given).

    ``record``: None (no recording), a path ending in ``.rrd`` (its folder is created), or
    True (the scene's ``output.rrd``). Close the session (or use ``with``) to finish the
    recording; a session closed after an exception discards the file."""

    def __init__(self, scene_or_path, overrides=(), record=None, *, simulate_cloths: bool = True):
        from magica_py.runner import CompileWatch, WarningEvents
        from magica_py.runtime.player import Player
        from magica_py.runtime.phases import Phase, System
        from magica_py.sinks.recorder import find_snapshot_provider

        self.scene = load(scene_or_path, overrides)
        self.player = Player.for_scene(self.scene)
        self.compile_watch = CompileWatch(announce=_print_note)
        self.warning_events = WarningEvents()
        self.recorder = None
        self.system = None
        self.closed = False
        self.recording_kept = False   # set by close(): the recording was renamed into place
        with self.compile_watch:
            if simulate_cloths and self.scene.cloths:
                from magica_py.solver import attach

                self.system = attach(self.player, self.scene)
        self.warning_events.attach(self.player)
        self.capture = _Capture(self.scene, find_snapshot_provider(self.player) if self.system is not None else None)
        self.player.schedule.add(Phase.RENDER_WRITE, System(CAPTURE_SYSTEM, self.capture.run))
        if record is not None and record is not False:
            self.recorder = self._attach_recorder(record)
        self.wall_time = 0.0

    def _attach_recorder(self, record):
        from magica_py.sinks import SinkOptions, attach

        if record is True:
            if self.scene.output.rrd is None:
                raise ValueError(f"record=True: the scene {self.scene.name!r} has no output.rrd; give a path")
            path = pathlib.Path(self.scene.output.rrd)
        else:
            path = pathlib.Path(os.fspath(record))
        if path.suffix != ".rrd":
            raise ValueError(f"record: {str(path)!r} must end in .rrd")
        path.parent.mkdir(parents=True, exist_ok=True)
        return attach(self.player, self.scene, SinkOptions(rrd=path))

    def _check_open(self, what: str) -> None:
        if self.closed:
            raise RuntimeError(f"Session.{what}: the session of {self.scene.name!r} is closed "
                               f"(after {len(self.capture.time)} frames); make a new Session to run more")

    def step(self):
        """Run one frame; returns its ``FrameContext`` (``ctx.metrics``, ``ctx.events``, ...)."""
        import time

        self._check_open("step()")
        start = time.perf_counter()
        compiled = self.compile_watch.seconds
        with self.compile_watch, self.warning_events:
            ctx = self.player.step()
        self.wall_time += time.perf_counter() - start - (self.compile_watch.seconds - compiled)
        return ctx

    def run(self, frames: int | None = None, progress: bool = False) -> "Simulation":
        """Run ``frames`` more frames (default: the scene's length) and return the result so far."""
        from magica_py.runner import FrameProgress, play

        self._check_open("run()")
        if frames is None:
            frames = self.scene.settings.frame_count()
        elif (isinstance(frames, bool) or not isinstance(frames, numbers.Real) or not math.isfinite(frames)
              or not float(frames).is_integer()):
            raise TypeError(f"frames: expected a whole number of frames, got {frames!r}")
        if frames is not None:   # None: a realtime clock with a duration stops on the wall clock
            frames = int(frames)
        if frames is not None and frames < 0:
            raise ValueError(f"frames: expected >= 0, got {frames}")
        bar = FrameProgress(frames, notebook=True, delay=0.5) if progress else None
        if bar is not None:
            self.compile_watch.on_end = bar.pause_ended
        try:
            with self.compile_watch, self.warning_events:
                stats = play(self.player, self.scene, frames, system=self.system, progress=bar,
                             compile_watch=self.compile_watch, warning_events=self.warning_events)
        finally:
            if bar is not None:
                bar.close()
                self.compile_watch.on_end = None
        self.wall_time += stats.wall_time
        return self.result()

    def result(self) -> Simulation:
        """Everything captured so far as arrays."""
        cloths, metrics = self.capture.result(self.scene)
        out = None
        if self.recorder is not None and self.closed and self.recording_kept:
            out = str(self.recorder.output_path) if self.recorder.output_path is not None else None
        return Simulation(scene=self.scene, frames=len(self.capture.time), time=np.asarray(self.capture.time),
                          delta_time=np.asarray(self.capture.delta_time), cloths=cloths, metrics=metrics,
                          events=list(self.capture.events), wall_time=self.wall_time,
                          compile_seconds=self.compile_watch.seconds, warnings=self.warning_events.summary(),
                          recording=out)

    def close(self, success: bool = True) -> None:
        """Finish the recording (renamed into place when ``success``, deleted otherwise)."""
        if not self.closed:
            self.closed = True
            if self.recorder is not None:
                self.recorder.close(success)
                self.recording_kept = bool(success)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        self.close(success=exc_type is None)
        return False


def _print_note(text: str) -> None:
    import sys

    print(f"magica_py: {text}", file=sys.stderr, flush=True)


# ----------------------------------------------------------------------------- one call
def simulate(scene_or_path, frames: int | None = None, overrides=(), record=None, *,
             progress: bool = False) -> Simulation:
    """Load a scene, run it and return per-cloth arrays and metrics (``Simulation``).

    ``scene_or_path``: a scene file, a ``.vrm`` avatar (run as ``magica-py run AVATAR.vrm``
    runs it), YAML text, or a loaded ``Scene``. ``frames``: default the scene's length.
    ``overrides``: ``--set`` strings (``"cloths.tail.parameters.damping=0.2"``), validated
    like the file. ``record``: None, a ``.rrd`` path, or True for the scene's ``output.rrd``.
    ``progress``: a progress bar (a widget in notebooks). Bad input raises
    ``magica_py.ConfigError`` listing every problem."""
    session = Session(scene_or_path, overrides, record)
    ok = False
    try:
        session.run(frames, progress=progress)
        ok = True
    finally:
        session.close(success=ok)
    return session.result()
