"""Wire a sink into a player: the RENDER_WRITE system, the replay capture, the options.

``attach(player, scene, options)`` (re-exported by ``magica_py.sinks``) registers

* UPDATE ``capture_replay`` (right after ``animation``): copies the local pose of every
  *driven* transform (see ``driven_nodes``), the frame's ``UnityTime`` and the events raised so
  far. This is exactly what LATE_UPDATE (the solver) starts from, so ``resim`` can rebuild it.
* RENDER_WRITE ``rerun_sink``: gathers a ``FrameData`` (joint world positions, cloth snapshots,
  collider shapes, metrics, events) and hands it to the sink.

It returns the ``Recorder``; the caller must ``close(success)`` it when the run ends (the CLI
does it in a ``finally``): a successful close renames the temporary file to the requested
name, a failed one deletes it.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

import numpy as np

from magica_py.sinks.base import (ClothFrame, ColliderShapes, FrameData, LogToggles, NullSink, ReplayFrame, SceneStatics,
                                  SnapshotProvider)
from magica_py.sinks.shapes import collider_shapes, shape_slots

CAPTURE_SYSTEM = "capture_replay"
SINK_SYSTEM = "rerun_sink"


@dataclass
class SinkOptions:
    """How to record. ``rrd``: a path, or None to use ``scene.output.rrd``; ``no_rrd`` turns
    file output off. ``spawn`` / ``connect`` stream to a viewer (never in tests)."""

    rrd: Any = None
    no_rrd: bool = False
    spawn: bool = False
    connect: str | None = None
    batch_frames: int | None = None
    recording_id: str | None = None
    snapshots: SnapshotProvider | None = None
    toggles: Any = None            # overrides scene.output.log
    replay_nodes: Any = None       # hierarchy indices to record for resim (default: driven_nodes)
    open_at_end: bool = False      # the viewer opens the file at its last frame (screenshots)
    recording_name: str | None = None  # the name the viewer lists (default: the scene's name)


def driven_nodes(scene, player) -> np.ndarray:
    """Transforms whose local pose can change before LATE_UPDATE, recorded for ``resim``.

    When the scene's animation lists what it writes (``Animation.driven``: driver targets and
    teleport targets, scene/animation.py) that list is exact: every other node keeps its rest
    local pose, or is a cloth bone that RESTORE resets and the solver rewrites. Otherwise
    (another animation source) every node the cloth systems do not restore is recorded."""
    animation = getattr(scene, "animation", None)
    for name in ("driven", "targets"):
        listed = getattr(animation, name, None)
        if listed is not None:
            return np.unique(np.asarray(listed, dtype=np.int64).reshape(-1))
    n = scene.hierarchy.count
    restored = np.asarray(getattr(player, "restored_bones", np.zeros(0)), dtype=np.int64)
    mask = np.ones(n, bool)
    mask[restored] = False
    return np.flatnonzero(mask).astype(np.int64)


def find_snapshot_provider(player) -> SnapshotProvider | None:
    """The cloth snapshot provider: the solver's ClothSystem when it is scheduled."""
    from magica_py.runtime.phases import Phase

    for system in player.schedule.systems(Phase.LATE_UPDATE):
        owner = getattr(system.run, "__self__", None)
        for candidate in (owner, getattr(owner, "snapshots", None)):
            if isinstance(candidate, SnapshotProvider):
                return candidate
        if owner is not None:
            adapter = _solver_adapter(owner)
            if adapter is not None:
                return adapter
    return None


def _solver_adapter(owner):
    try:
        from magica_py.sinks.solver_adapter import adapt
    except ImportError:
        return None
    return adapt(owner)


class _EmptyProvider:
    def cloth_topologies(self):
        return []

    def cloth_frames(self):
        return []


class Recorder:
    """Holds the sink and the per-frame state shared by the two systems."""

    def __init__(self, player, scene, options: SinkOptions):
        self.player = player
        self.scene = scene
        self.options = options
        toggles = options.toggles if options.toggles is not None else _scene_toggles(scene)
        self.toggles = LogToggles.from_any(toggles)
        self.provider = options.snapshots or find_snapshot_provider(player) or _EmptyProvider()
        self.replay_nodes = None if options.replay_nodes is None else np.asarray(options.replay_nodes, np.int64)
        self.sink = None
        self.pending_replay: ReplayFrame | None = None
        self.colliders = getattr(scene, "colliders", None)
        self.collider_kind, self.collider_slot = shape_slots(self.colliders)
        self.time_fields: tuple[str, ...] = ()
        self.live_urls: list[str] | None = None     # viewers started / checked by attach()

    # ------------------------------------------------------------ lifecycle
    def open(self) -> None:
        """Create the sink (called lazily on the first frame so that every system is attached)."""
        scene, opts = self.scene, self.options
        if self.replay_nodes is None:
            self.replay_nodes = driven_nodes(scene, self.player)
        names = list(scene.hierarchy.names)
        parent = np.asarray(scene.hierarchy.parent, np.int32)
        node_group = instance_labels(getattr(scene, "rigs", None) or (), parent)
        collider_nodes = np.asarray(getattr(self.colliders, "transform", ()), np.int64).reshape(-1)
        cloths = list(self.provider.cloth_topologies())
        statics = SceneStatics(
            name=str(getattr(scene, "name", "scene")),
            joint_names=names, joint_parent=parent,
            cloths=cloths, toggles=self.toggles,
            replay_node_names=[names[i] for i in self.replay_nodes],
            replay_scene_text=_scene_text(scene), replay_scene_source=str(getattr(scene, "source", "") or ""),
            replay_scene_overrides=[str(o) for o in (getattr(scene, "overrides", None) or ())],
            time_fields=self.time_fields, node_group=node_group,
            collider_names=[str(n) for n in getattr(self.colliders, "names", ())],
            collider_groups=[node_group[c] if 0 <= c < len(node_group) else "" for c in collider_nodes],
            view_box=self._view_box(cloths), wind_zones=self._wind_zones())
        rrd = output_rrd(opts, scene)
        if rrd is None and not opts.spawn and opts.connect is None:
            self.sink = NullSink()
            return
        from magica_py.sinks.rerun_sink import RerunSink

        self.sink = RerunSink(statics, rrd_path=rrd, spawn=opts.spawn, connect=opts.connect,
                              batch_frames=opts.batch_frames, recording_id=opts.recording_id,
                              collider_kind=self.collider_kind, collider_slot=self.collider_slot,
                              collider_set=self.colliders, live_urls=self.live_urls,
                              open_at_end=opts.open_at_end, recording_name=opts.recording_name)

    def _view_box(self, cloths):
        """(min, max) of every joint and particle now (the first frame): where the camera starts."""
        points = [np.asarray(self.scene.hierarchy.world_position, np.float64).reshape(-1, 3)]
        if cloths:
            points.append(np.asarray(self._particles()[0], np.float64).reshape(-1, 3))
        points = np.concatenate(points)
        points = points[np.all(np.isfinite(points), axis=1)]
        if not points.size:
            return None
        return points.min(axis=0), points.max(axis=0)

    def close(self, success: bool = True) -> None:
        """End the recording: a successful run of zero frames still leaves a (static-only) file."""
        if self.sink is None and success:
            self.open()
        if self.sink is not None:
            self.sink.close(success)

    @property
    def seconds(self) -> float:
        """Wall time spent inside the sink (copying + sending + closing)."""
        return float(getattr(self.sink, "seconds", 0.0))

    @property
    def import_seconds(self) -> float:
        """One-time cost of importing rerun (not in ``seconds``)."""
        return float(getattr(self.sink, "import_seconds", 0.0))

    @property
    def output_path(self):
        return getattr(self.sink, "final_path", None)

    # ------------------------------------------------------------ systems
    def capture(self, ctx) -> None:
        """UPDATE, after animation: what the solver is about to read."""
        if not self.toggles.replay:
            return
        if not self.time_fields:
            self.time_fields = tuple(ctx.time._fields)
        if self.replay_nodes is None:
            self.replay_nodes = driven_nodes(self.scene, self.player)
        h, d = self.scene.hierarchy, self.replay_nodes
        self.pending_replay = ReplayFrame(
            local_position=h.local_position[d], local_rotation=h.local_rotation[d], local_scale=h.local_scale[d],
            time_values=np.array([float(getattr(ctx.time, f)) for f in self.time_fields]),
            events_json=json.dumps(ctx.events, default=_json_default) if ctx.events else "")

    def render_write(self, ctx) -> None:
        if self.sink is None:
            self.open()
        hierarchy = self.scene.hierarchy
        positions, base, steps = self._particles()
        shapes, pose = ColliderShapes.empty(), None
        if self.colliders is not None and len(self.colliders.names) and (self.toggles.colliders or self.toggles.metrics):
            if getattr(self.sink, "collider_batch", None) is not None:
                pose = self.sink.collider_batch.capture(hierarchy)   # evaluated per batch by the sink
            else:
                shapes = collider_shapes(self.colliders, hierarchy)
        data = FrameData(
            frame=ctx.frame, sim_time=float(ctx.time.time), delta_time=float(ctx.time.delta_time),
            joint_positions=hierarchy.world_position, positions=positions, colliders=shapes,
            metrics={k: float(v) for k, v in ctx.metrics.items() if _is_number(v)},
            events=list(ctx.events), base_positions=base, steps=steps, replay=self.pending_replay,
            collider_pose=pose,
            wind=self.provider.wind_frame() if hasattr(self.provider, "wind_frame") else None)
        self.sink.begin_frame(ctx.frame, data.sim_time)
        self.sink.log(data)
        self.sink.end_frame()
        self.pending_replay = None

    def _wind_zones(self):
        """The scene's wind zones for the drawing ([] with moving wind alone), None without wind."""
        frame = self.provider.wind_frame() if hasattr(self.provider, "wind_frame") else None
        return None if frame is None else list(getattr(self.scene, "wind", ()) or ())

    def _particles(self):
        """(positions (P,3), base positions or None, steps) of every cloth, topology order."""
        prov = self.provider
        if hasattr(prov, "particle_positions"):
            base = prov.particle_base_positions() if self.toggles.base_pose else None
            return prov.particle_positions(), base, int(prov.steps())
        frames = list(prov.cloth_frames())
        if not frames:
            return _NO_PARTICLES, None, 0
        positions = np.concatenate([f.positions for f in frames])
        base = None
        if self.toggles.base_pose and all(f.base_positions is not None for f in frames):
            base = np.concatenate([f.base_positions for f in frames])
        return positions, base, max(int(f.steps) for f in frames)


_NO_PARTICLES = np.zeros((0, 3))


def attach(player, scene, options: SinkOptions | dict | None = None) -> Recorder:
    """Register the capture (UPDATE) and sink (RENDER_WRITE) systems; returns the Recorder.

    Validates the output path right away so a bad ``--rrd`` fails before any simulation.
    """
    from magica_py.runtime.phases import Phase, System

    if options is None:
        options = SinkOptions()
    elif isinstance(options, dict):
        options = SinkOptions(**options)
    recorder = Recorder(player, scene, options)
    rrd = output_rrd(options, scene)
    if rrd is not None:
        from magica_py.sinks.rerun_sink import check_output_path

        check_output_path(rrd, "--rrd" if options.rrd is not None else "output.rrd")
    if options.spawn or options.connect is not None:   # start / check the viewer before any frame
        import rerun as rr

        from magica_py.sinks.live import open_live_targets

        recorder.live_urls = open_live_targets(rr, None, options.spawn, options.connect)
    schedule = player.schedule
    anchor = "animation" if any(s.name == "animation" for s in schedule.systems(Phase.UPDATE)) else None
    schedule.add(Phase.UPDATE, System(CAPTURE_SYSTEM, recorder.capture), after=anchor)
    schedule.add(Phase.RENDER_WRITE, System(SINK_SYSTEM, recorder.render_write))
    return recorder


# ------------------------------------------------------------------ helpers
def output_rrd(options: SinkOptions, scene):
    """The recording file of a run: ``--rrd`` when given; none with ``no_rrd``; none in live mode
    (``spawn`` / ``connect``: a live run writes a file only when asked with ``--rrd``); else the
    scene's ``output.rrd``."""
    if options.no_rrd:
        return None
    if options.rrd is not None:
        return options.rrd
    if options.spawn or options.connect is not None:
        return None
    return _scene_rrd(scene)


def instance_labels(rigs, parent: np.ndarray) -> list[str]:
    """Per hierarchy node: ``<rig>_<i>`` for the nodes of instance i of an instanced rig, else
    "" (the viewer groups a crowd's entities per character with it)."""
    n = parent.size
    label = [""] * n
    for rig in rigs:
        if int(getattr(rig, "instances", 1) or 1) <= 1:
            continue
        for i, root in enumerate(getattr(rig, "root_nodes", ())):
            if 0 <= root < n:
                label[root] = f"{rig.name}_{i}"
    for i in range(n):             # parents come before their children in the hierarchy
        p = parent[i]
        if not label[i] and p >= 0 and label[p]:
            label[i] = label[p]
    return label


def _scene_rrd(scene):
    output = getattr(scene, "output", None)
    return getattr(output, "rrd", None) if output is not None else None


def _scene_toggles(scene):
    output = getattr(scene, "output", None)
    log = dict(getattr(output, "log", {}) or {}) if output is not None else {}
    known = set(LogToggles.__dataclass_fields__)
    return {k: v for k, v in log.items() if k in known}


def _scene_text(scene) -> str:
    text = getattr(scene, "source_text", None)
    if text:
        return str(text)
    source = getattr(scene, "source", None)
    if source:
        try:
            with open(source, encoding="utf-8") as fh:
                return fh.read()
        except OSError:
            return ""
    return ""


def _is_number(v) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)


def _json_default(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (set, frozenset, tuple)):
        return list(value)
    return str(value)


# keep ClothFrame importable from here for adapters
__all__ = ["attach", "Recorder", "SinkOptions", "driven_nodes", "find_snapshot_provider", "ClothFrame"]
