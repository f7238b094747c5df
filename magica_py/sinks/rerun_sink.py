"""The Rerun sink: writes the layout of ``layout.py`` to an .rrd file and/or a live viewer.

Cost (docs/tech-notes.md §3): the Python overhead per rerun call (~50–90 µs) dominates, the data is
almost free. So a frame only *copies* a few whole arrays (joint positions, every cloth's
particles as one (P, 3) array, collider poses, replay pose) into float64 batch buffers;
every ``batch_frames`` frames ``flush`` derives everything else for the whole batch at once
(bone and edge segments, per-cloth slices, the quality metrics with numba kernels, the
characters' box), casts geometry to float32 in the display frame (X negated, see
``layout``) and makes one ``send_columns`` call per entity. Live streams (``--spawn`` /
``--connect``, ``live.py``) use ``batch_frames=1`` so the viewer follows the simulation.

Entities: a cloth and its instances in one rig instance share an entity set; in a crowd
every character (rig instance) has its own (``world/character_17/cloths/skirt``), so that a
hover names the character. Colliders are one entity each (``collider_view``).

Files are written to a hidden temporary name next to the target and renamed on a
successful ``close``; a failed run (``close(success=False)`` or an exception) deletes it, so
there is never a half-written recording under the requested name.
"""
from __future__ import annotations

import json
import os
import pathlib
import time
import uuid

import numpy as np

from magica_py.build.proxy import FIXED, MOVE
from magica_py.jit import kernel
from magica_py.sinks import layout as L
from magica_py.sinks.base import FrameData, SceneStatics
from magica_py.sinks.blueprint import default_blueprint
from magica_py.sinks.collider_view import ColliderView
from magica_py.sinks.live import FLUSH_SECONDS, OutputError, grpc_url, open_live_targets  # noqa: F401 - re-exported
from magica_py.sinks.metrics import FrameMetrics
from magica_py.sinks.shapes import ColliderBatch
from magica_py.sinks.wind_view import WindView

FILE_BATCH_FRAMES = 64
# a crowd has one entity set per character (hundreds of entities, each one call per batch):
# longer batches keep the per-call cost per frame down (256 frames of 7,800 particles: 48 MB)
CROWD_BATCH_FRAMES = 256
CROWD_ENTITY_SETS = 32
JOINT_RADIUS = 0.008        # m
BONE_RADIUS = 0.003
ROOT_LINK_RADIUS = 0.0015
EDGE_RADIUS = 0.0025
PHASES = ("restore", "fixed_update", "update", "late_update")


def check_output_path(path: str | os.PathLike, where: str = "--rrd") -> pathlib.Path:
    """Validate a recording path before any simulation runs; returns it absolute."""
    p = pathlib.Path(path).expanduser()
    if str(path).strip() == "":
        raise OutputError(f"{where}: empty recording path; expected a file name ending in .rrd")
    if p.suffix != ".rrd":
        raise OutputError(f"{where}: recording path {str(path)!r} must end in .rrd")
    if p.is_dir():
        raise OutputError(f"{where}: {str(path)!r} is a folder; expected a file name ending in .rrd")
    parent = p.parent if str(p.parent) else pathlib.Path(".")
    if not parent.exists():
        raise OutputError(f"{where}: cannot write {str(path)!r}: folder {str(parent)!r} does not exist")
    if not parent.is_dir():
        raise OutputError(f"{where}: cannot write {str(path)!r}: {str(parent)!r} is not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError(f"{where}: cannot write {str(path)!r}: folder {str(parent)!r} is not writable")
    if p.exists() and not os.access(p, os.W_OK):
        raise OutputError(f"{where}: cannot overwrite {str(path)!r}: the file is read-only")
    return p.absolute()


class _Group:
    """The cloths drawn as one entity set: a cloth and its instances (`skirt#0`, `skirt#1`...)
    within one rig instance (``group``, "" outside instanced rigs)."""

    def __init__(self, name: str, group: str):
        self.name = name
        self.group = group
        self.particles: list[np.ndarray] = []    # global particle indices per member
        self.edges: list[np.ndarray] = []
        self.triangles: list[np.ndarray] = []    # group-local indices
        self.baselines: list[np.ndarray] = []    # (k, 2) global parent/child
        self.radius: list[np.ndarray] = []
        self.attribute: list[np.ndarray] = []
        self.count = 0

    def path(self, part: str) -> str:
        return L.cloth_path(self.name, part, self.group)

    def add(self, topo, offset: int) -> None:
        n = topo.particle_count
        self.particles.append(np.arange(offset, offset + n))
        self.edges.append(np.asarray(topo.edges, np.int64).reshape(-1, 2) + offset)
        self.triangles.append(np.asarray(topo.triangles, np.int64).reshape(-1, 3) + self.count)
        parent = np.asarray(topo.parent, np.int64)
        child = np.flatnonzero(parent >= 0)
        self.baselines.append(np.stack([parent[child], child], axis=1) + offset)
        self.radius.append(np.asarray(topo.radius, np.float64))
        self.attribute.append(np.asarray(topo.attribute, np.uint8))
        self.count += n

    def freeze(self) -> None:
        cat = np.concatenate
        self.particles = cat(self.particles)
        self.edges = cat(self.edges)
        self.triangles = cat(self.triangles)
        self.baselines = cat(self.baselines)
        self.radius = cat(self.radius)
        self.attribute = cat(self.attribute)
        # contiguous members: a slice is cheaper than a gather
        first = int(self.particles[0]) if self.count else 0
        contiguous = self.count and np.array_equal(self.particles, np.arange(first, first + self.count))
        self.slice = slice(first, first + self.count) if contiguous else None

    def take(self, x: np.ndarray) -> np.ndarray:
        return x[:, self.slice] if self.slice is not None else x[:, self.particles]


def instance_group(name: str, node: int | None, node_group) -> str:
    """The instance label of a cloth / collider: its node's (``SceneStatics.node_group``), or,
    without that table, ``instance_<i>`` from a `name#i` suffix."""
    if node_group and node is not None and 0 <= node < len(node_group):
        return node_group[node]
    return f"instance_{name.split('#', 1)[1]}" if "#" in name else ""


def cloth_groups(cloths, node_group=()) -> list[_Group]:
    """Group cloths by instance and name without the instance suffix, in first-seen order."""
    groups: dict[tuple, _Group] = {}
    offset = 0
    for topo in cloths:
        nodes = np.asarray(topo.transform_index)
        group = instance_group(topo.name, int(nodes[0]) if nodes.size else None, node_group)
        key = (group, L.entity_name(L.base_name(topo.name)))
        groups.setdefault(key, _Group(key[1], group)).add(topo, offset)
        offset += topo.particle_count
    for g in groups.values():
        g.freeze()
    return list(groups.values())


def stem_links(parent: np.ndarray, cloth_node: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mask of the links (by child) from a rig root down to its first branching joint: a
    hierarchy root and each node of one child below it form a stem (``root -> hips``, a
    crowd's ``spot -> root -> hips``). Those are placement, not bones: drawn apart, hidden.
    Returns (link mask by child, stem node mask)."""
    n = parent.size
    children = np.bincount(parent[parent >= 0], minlength=n)
    stem = np.zeros(n, bool)
    for i in range(n):          # parents come before their children in the hierarchy
        p = parent[i]
        stem[i] = not cloth_node[i] and (p < 0 or (stem[p] and children[p] == 1))
    link = np.zeros(n, bool)
    has_parent = parent >= 0
    link[has_parent] = stem[parent[has_parent]] & (children[parent[has_parent]] == 1) & ~cloth_node[has_parent]
    return link, stem


class _Buffers:
    """Preallocated float64 per-frame buffers (rows = frames of one batch)."""

    def __init__(self, rows: int):
        self.rows = rows
        self.arrays: dict[str, np.ndarray] = {}

    def put(self, key: str, row: int, values: np.ndarray) -> None:
        buf = self.arrays.get(key)
        if buf is None or buf.shape[1:] != np.shape(values):
            if buf is not None and row:
                raise ValueError(f"sink: {key} changed shape from {buf.shape[1:]} to {np.shape(values)} mid-batch")
            buf = self.arrays[key] = np.empty((self.rows,) + np.shape(values), np.float64)
        buf[row] = values


_COLLIDER_FIELDS = ("sphere_center", "sphere_radius", "capsule_start", "capsule_end", "capsule_start_radius",
                    "capsule_end_radius", "plane_point", "plane_normal")


class RerunSink:
    """See the module docstring. ``rrd_path``, ``spawn`` and ``connect`` may be combined;
    ``live_urls`` (from ``live.open_live_targets``) replaces spawn / connect when the viewers
    were already started and checked; ``open_at_end``: the viewer opens the file at its last
    frame (live streams always follow the newest frame)."""

    def __init__(self, statics: SceneStatics, *, rrd_path=None, spawn: bool = False, connect: str | None = None,
                 batch_frames: int | None = None, recording_id: str | None = None,
                 collider_kind: np.ndarray | None = None, collider_slot: np.ndarray | None = None,
                 collider_set=None, live_urls: list[str] | None = None, open_at_end: bool = False,
                 recording_name: str | None = None):
        t_import = time.perf_counter()
        import rerun as rr
        import rerun.blueprint  # noqa: F401 - one-time import cost, kept out of `seconds`

        if rrd_path is None and not spawn and connect is None and not live_urls:
            raise OutputError("RerunSink needs at least one of rrd_path, spawn, connect")
        self.rr = rr
        self.statics = statics
        self.toggles = statics.toggles
        t0 = time.perf_counter()
        self.import_seconds = t0 - t_import     # importing rerun (once per process)
        self.seconds = 0.0                      # wall time spent in this sink (cost figure)
        self.final_path = check_output_path(rrd_path) if rrd_path is not None else None
        self.temp_path = None
        self.closed = True                      # until the sinks are open
        # the viewer lists a recording by application id and recording name: the scene's
        self.rec = rr.RecordingStream(statics.name or "magica_py", recording_id=recording_id or str(uuid.uuid4()))
        self.rec.set_log_time_enabled(False)
        self.live = bool(live_urls) or spawn or connect is not None
        if live_urls is None and (spawn or connect is not None):
            live_urls = open_live_targets(rr, self.rec, spawn, connect)
        self.live_urls = list(live_urls or [])
        self.batch_frames = batch_frames
        self.batch = max(1, int(batch_frames if batch_frames is not None else (1 if self.live else FILE_BATCH_FRAMES)))
        # from here on an error, ^C or SIGTERM (``cli.Terminated``, a BaseException) closes the
        # stream and removes the temporary file before it leaves: the caller never got the sink,
        # so nobody else could
        try:
            sinks = []
            if self.final_path is not None:
                self.temp_path = self.final_path.with_name(f".{self.final_path.stem}.{os.getpid()}.partial.rrd")
                sinks.append(rr.FileSink(str(self.temp_path)))
            sinks += [rr.GrpcSink(url) for url in self.live_urls]
            self.metrics = FrameMetrics(statics.cloths,
                                        collider_kind if collider_kind is not None else np.zeros(0, np.int64),
                                        collider_slot if collider_slot is not None else np.zeros(0, np.int64))
            blueprint = default_blueprint(statics.name or "scene", box=statics.view_box,
                                          penetration=self.metrics.has_collision, phases=PHASES,
                                          follow=open_at_end or self.live, wind=statics.wind_zones is not None)
            self.rec.set_sinks(*sinks, default_blueprint=blueprint)
            self.rec.send_recording_name(recording_name or statics.name or "magica_py")
        except BaseException as exc:
            self._abandon()
            if isinstance(exc, Exception):   # rerun raises plain RuntimeError
                if self.final_path is not None and self.temp_path is not None and not self.live_urls:
                    raise OutputError(f"cannot write the recording {str(self.final_path)!r} (its temporary file "
                                      f"beside it: {exc})") from exc
                raise OutputError(f"cannot open the recording output: {exc}") from exc
            raise
        self.closed = False
        try:
            self._prepare(statics, collider_kind, collider_slot, collider_set)
            if self.live:   # the statics must reach the viewer: fail before the first frame otherwise
                self._flush_live("before the first frame")
        except BaseException:
            self.close(success=False)
            raise
        self.seconds += time.perf_counter() - t0

    def _prepare(self, statics, collider_kind, collider_slot, collider_set) -> None:
        """Static index arrays, buffers, and the static part of the recording."""
        self.frames = 0
        self.first_frame = None               # its wall times (JIT compilation) are not plotted
        self.scalar_rows: dict[str, list[tuple[int, float]]] = {}
        self.styled: set[str] = set()
        self.replay_event_rows: list[tuple[int, str]] = []
        self._new_buffers()
        parent = np.asarray(statics.joint_parent, np.int64)
        n = parent.size
        node_group = list(statics.node_group) if len(statics.node_group) == n else []
        # links between two cloth particles are drawn as the cloth's edges: not again as bones
        cloth_node = np.zeros(n, bool)
        for c in statics.cloths:
            cloth_node[np.asarray(c.transform_index, np.int64)] = True
        stem_link, stem = stem_links(parent, cloth_node)
        child = np.flatnonzero(parent >= 0)
        child = child[~(cloth_node[child] & cloth_node[parent[child]])]
        groups = np.array(node_group if node_group else [""] * n, dtype=object)
        # cloth bones sit on their particles (docs/solver.md §E.4): the rig's points are the other joints
        self.rig_parts = []                   # (group, joint nodes, bone parents, bone children)
        for group in dict.fromkeys(groups.tolist()):
            joints = np.flatnonzero(~cloth_node & (groups == group))
            bones = child[(groups[child] == group) & ~stem_link[child]]
            if joints.size or bones.size:
                self.rig_parts.append((group, joints, parent[bones], bones))
        roots = child[stem_link[child]]
        self.root_link_parent, self.root_link_child = parent[roots], roots
        # the camera frames every joint but the stems (roots on the floor, grid spots, the lone
        # static nodes of static colliders); a rig that is all stem is framed whole
        self.focus_nodes = np.flatnonzero(~stem) if (~stem).any() else np.arange(n)
        self.groups = cloth_groups(statics.cloths, node_group)
        if self.batch_frames is None and not self.live and len(self.groups) + len(self.rig_parts) > CROWD_ENTITY_SETS:
            self.batch = CROWD_BATCH_FRAMES
            self._new_buffers()
        self.particle_count = sum(c.particle_count for c in statics.cloths)
        self.collider_batch = ColliderBatch(collider_set) if collider_set is not None and len(collider_set.names) \
            else None
        kinds = collider_kind if collider_kind is not None else np.zeros(0, np.int64)
        slots = collider_slot if collider_slot is not None else np.zeros(0, np.int64)
        names = list(statics.collider_names) if len(statics.collider_names) == len(kinds) else \
            [f"{('sphere', 'capsule', 'plane')[int(k)]}_{int(s)}" for k, s in zip(kinds, slots)]
        collider_groups = list(statics.collider_groups) if len(statics.collider_groups) == len(kinds) else \
            [instance_group(name, None, ()) for name in names]
        self.collider_view = ColliderView(names, kinds, slots, collider_groups)
        self.wind_view = WindView(statics.wind_zones, [c.name for c in statics.cloths]) \
            if statics.wind_zones is not None else None
        self._log_statics()

    # ------------------------------------------------------------------ statics
    def _log_statics(self) -> None:
        rr, rec, s, tg = self.rr, self.rec, self.statics, self.toggles
        rec.log(L.WORLD, rr.ViewCoordinates.LUF, static=True)
        rec.log(L.WORLD, rr.AnyValues(display_mirror_x=True, coordinates=(
            "scene: Unity's left-handed frame (X right, Y up, Z forward), metres. Drawn mirrored for Rerun's "
            "right-handed viewer: x_drawn = -x_scene under /world (LUF), so right is right on screen. "
            "/metrics and /replay are in scene units and handedness.")), static=True)
        rec.log(L.FOCUS, rr.Points3D.from_fields(radii=0.0), static=True)
        if self.wind_view is not None:
            self.wind_view.log_statics(rr, rec)
        if tg.skeleton:
            for group, _, _, _ in self.rig_parts:
                rec.log(L.rig_path("joints", group), rr.Points3D.from_fields(radii=JOINT_RADIUS, colors=L.COLOR_JOINT),
                        static=True)
                rec.log(L.rig_path("bones", group), rr.LineStrips3D.from_fields(radii=BONE_RADIUS, colors=L.COLOR_BONE),
                        static=True)
            if self.root_link_child.size:
                rec.log(L.ROOT_LINKS, rr.LineStrips3D.from_fields(radii=ROOT_LINK_RADIUS, colors=L.COLOR_ROOT_LINK),
                        static=True)
        for g in self.groups:
            colors = np.empty((g.count, 4), np.uint8)
            colors[:] = L.COLOR_MOVE
            colors[(g.attribute & FIXED) != 0] = L.COLOR_FIXED
            colors[(g.attribute & (FIXED | MOVE)) == 0] = L.COLOR_INVALID   # Invalid: neither (§B.5)
            if tg.particles:
                rec.log(g.path("particles"), rr.Points3D.from_fields(radii=g.radius.astype(np.float32), colors=colors),
                        static=True)
            if tg.edges and len(g.edges):
                rec.log(g.path("edges"), rr.LineStrips3D.from_fields(radii=EDGE_RADIUS, colors=L.COLOR_EDGE),
                        static=True)
            if tg.triangles and len(g.triangles):
                rec.log(g.path("triangles"), rr.Mesh3D.from_fields(triangle_indices=g.triangles.astype(np.uint32),
                                                                   albedo_factor=[110, 170, 230, 140]), static=True)
            if tg.baselines and len(g.baselines):
                rec.log(g.path("baselines"), rr.LineStrips3D.from_fields(radii=EDGE_RADIUS, colors=L.COLOR_BASELINE),
                        static=True)
            if tg.base_pose:
                rec.log(g.path("base_pose"), rr.Points3D.from_fields(radii=(g.radius * 0.5).astype(np.float32),
                                                                     colors=L.COLOR_BASE_POSE), static=True)
        rec.log(L.REPLAY_SCENE, rr.AnyValues(name=s.name, source=s.replay_scene_source,
                                             yaml=s.replay_scene_text,
                                             format_version=L.REPLAY_FORMAT_VERSION,
                                             time_fields=list(s.time_fields) or [""],
                                             overrides=list(s.replay_scene_overrides) or [""]), static=True)
        if tg.replay:
            rec.log(L.REPLAY_NODES, rr.AnyValues(names=list(s.replay_node_names) or [""]), static=True)

    def _style(self, path: str) -> None:
        """The plot line of a metric, once: its unit in the legend, a colour of its own."""
        if path in self.styled:
            return
        self.styled.add(path)
        phase = path.rsplit("/", 1)[-1][:-3] if path.startswith(L.METRIC_PHASE_TIME + "/") else None
        color = L.COLOR_SERIES.get(path) or L.COLOR_PHASES.get(phase) or \
            L.COLOR_OTHER_SERIES[len(self.styled) % len(L.COLOR_OTHER_SERIES)]
        self.rec.log(path, self.rr.SeriesLines(colors=[color], names=[L.series_label(path)], widths=[1.5]),
                     static=True)

    # ------------------------------------------------------------------ per frame: copies only
    def begin_frame(self, frame: int, sim_time: float) -> None:
        self.frame_index[self.row] = frame
        self.frame_time[self.row] = sim_time

    def log(self, data: FrameData) -> None:
        t0 = time.perf_counter()
        buf, row, tg = self.buf, self.row, self.toggles
        self.frame_index[row] = data.frame
        self.frame_time[row] = data.sim_time
        self.delta_time[row] = data.delta_time
        buf.put("joints", row, data.joint_positions)
        if self.particle_count:
            buf.put("positions", row, data.positions)
            if tg.base_pose and data.base_positions is not None:
                buf.put("base_positions", row, data.base_positions)
        if (tg.colliders or tg.metrics) and data.collider_pose is not None and self.collider_batch is not None:
            position, rotation, scale = data.collider_pose
            buf.put("collider.position", row, position)
            buf.put("collider.rotation", row, rotation)
            buf.put("collider.scale", row, scale)
        elif tg.colliders or tg.metrics:
            for name in _COLLIDER_FIELDS:
                values = getattr(data.colliders, name)
                if len(values):
                    buf.put(name, row, values)
        if tg.metrics:
            if self.first_frame is None:
                self.first_frame = data.frame
            first = data.frame == self.first_frame
            self.scalar_rows.setdefault(L.METRIC_STEPS, []).append((row, float(data.steps)))
            skipped = []
            for key, value in data.metrics.items():
                scale = L.metric_scale(key)
                if first and scale != 1.0:   # wall times of the first frame: JIT compilation, warm-up
                    skipped.append(f"{key} {float(value) * scale:.1f} ms")
                    continue
                self.scalar_rows.setdefault(L.metric_path(key), []).append((row, float(value) * scale))
            if skipped and tg.events:
                self._set_time(data.frame, data.sim_time)
                self.rec.log(L.EVENTS, self.rr.TextLog(
                    "first frame wall times, left out of the plots (JIT compilation and warm-up): "
                    + ", ".join(skipped), level=self.rr.TextLogLevel.DEBUG))
        if self.wind_view is not None and data.wind is not None:
            WindView.put(buf, row, data.wind)
        if tg.events and data.events:
            self._log_events(data)
        if tg.replay and data.replay is not None:
            r = data.replay
            buf.put("replay.local_position", row, r.local_position)
            buf.put("replay.local_rotation", row, r.local_rotation)
            buf.put("replay.local_scale", row, r.local_scale)
            buf.put("replay.time", row, r.time_values)
            if r.events_json:
                self.replay_event_rows.append((row, r.events_json))
        self.seconds += time.perf_counter() - t0

    def _set_time(self, frame, sim_time) -> None:
        self.rec.set_time(L.TIMELINE_FRAME, sequence=int(frame))
        self.rec.set_time(L.TIMELINE_SIM_TIME, duration=float(sim_time))

    def _log_events(self, data: FrameData) -> None:
        rr, rec = self.rr, self.rec
        self._set_time(data.frame, data.sim_time)
        for kind, payload in data.events:
            level = rr.TextLogLevel.WARN if "reset" in str(kind) else rr.TextLogLevel.INFO
            rec.log(L.EVENTS, rr.TextLog(f"{kind}: {_event_text(payload)}", level=level))

    def end_frame(self) -> None:
        self.row += 1
        self.frames += 1
        if self.row == self.batch:
            t0 = time.perf_counter()
            self.flush()
            self.seconds += time.perf_counter() - t0

    # ------------------------------------------------------------------ sending: whole batches
    def _send(self, entity: str, archetype: str, count: int, **components) -> None:
        """One send_columns call: components are (n, count, ...) arrays for n frames, positions
        already in the display frame (``_display``)."""
        rr, n = self.rr, self.row
        flat = {k: v if k == "strips" else np.ascontiguousarray(v, dtype=np.float32).reshape((n * count,) + v.shape[2:])
                for k, v in components.items()}
        columns = getattr(rr, archetype).columns(**flat).partition([count] * n)
        self.rec.send_columns(entity, indexes=self.batch_index, columns=columns)

    def _index(self, rows=slice(None)):
        rr = self.rr
        return [rr.TimeColumn(L.TIMELINE_FRAME, sequence=self.frame_index[:self.row][rows]),
                rr.TimeColumn(L.TIMELINE_SIM_TIME, duration=self.frame_time[:self.row][rows])]

    def flush(self) -> None:
        """Send the buffered frames as columns (one send_columns call per entity and batch)."""
        rr, rec, n, tg = self.rr, self.rec, self.row, self.toggles
        if n == 0:
            return
        a = {k: v[:n] for k, v in self.buf.arrays.items()}
        if "collider.position" in a:
            a.update(self.collider_batch.shapes(a["collider.position"], a["collider.rotation"], a["collider.scale"]))
        self.batch_index = self._index()       # the time columns, shared by every entity of the batch
        joints, x = a.get("joints"), a.get("positions")
        focus = self._send_focus(joints, x)
        shown_joints = _display(joints) if joints is not None else None
        shown_x = _display(x) if x is not None else None
        if tg.skeleton and joints is not None:
            for group, nodes, bone_parent, bone_child in self.rig_parts:
                if nodes.size:
                    self._send(L.rig_path("joints", group), "Points3D", nodes.size, positions=shown_joints[:, nodes])
                if bone_child.size:
                    self._send(L.rig_path("bones", group), "LineStrips3D", bone_child.size,
                               strips=_segments(joints, bone_parent, bone_child))
            if self.root_link_child.size:
                self._send(L.ROOT_LINKS, "LineStrips3D", self.root_link_child.size,
                           strips=_segments(joints, self.root_link_parent, self.root_link_child))
        if x is not None:
            for g in self.groups:
                gx = g.take(shown_x)
                if tg.particles:
                    self._send(g.path("particles"), "Points3D", g.count, positions=gx)
                if tg.edges and len(g.edges):
                    self._send(g.path("edges"), "LineStrips3D", len(g.edges),
                               strips=_segments(x, g.edges[:, 0], g.edges[:, 1]))
                if tg.triangles and len(g.triangles):
                    self._send(g.path("triangles"), "Mesh3D", g.count, vertex_positions=gx)
                if tg.baselines and len(g.baselines):
                    self._send(g.path("baselines"), "LineStrips3D", len(g.baselines),
                               strips=_segments(x, g.baselines[:, 0], g.baselines[:, 1]))
                if tg.base_pose and "base_positions" in a:
                    self._send(g.path("base_pose"), "Points3D", g.count,
                               positions=g.take(_display(a["base_positions"])))
        if tg.colliders:
            self.collider_view.send(rr, rec, self.batch_index, self.frame_index[:n], self.frame_time[:n], a,
                                    focus if focus is not None else np.zeros((n, 2, 3)))
        if tg.metrics:
            if x is not None:
                values = self.metrics.compute(x, a, self.delta_time[:n])
                series = {L.METRIC_MAX_STRETCH: values["max_edge_stretch"] * 100.0,
                          L.METRIC_MAX_SPEED: values["max_speed"]}
                if self.metrics.has_collision:
                    series[L.METRIC_MAX_PENETRATION] = values["max_penetration"] * 1000.0
                for path, column in series.items():
                    self.scalar_rows[path] = list(enumerate(column.tolist()))
            for path, rows in self.scalar_rows.items():
                self._style(path)
                sel = np.array([r for r, _ in rows], np.int64)
                vals = np.array([v for _, v in rows], np.float64)
                rec.send_columns(path, indexes=self._index(sel), columns=rr.Scalars.columns(scalars=vals))
        if self.wind_view is not None:
            self.wind_view.send(rr, rec, self.batch_index, a, metrics=tg.metrics)
        if tg.replay and "replay.time" in a:
            for key, component in (("replay.local_position", "local_position"),
                                   ("replay.local_rotation", "local_rotation"),
                                   ("replay.local_scale", "local_scale"), ("replay.time", "values")):
                entity = L.REPLAY_TIME if key == "replay.time" else L.REPLAY_POSE
                rec.send_columns(entity, indexes=self.batch_index,
                                 columns=rr.AnyValues.columns(**{component: _float64_rows(a[key])}))
            for r, text in self.replay_event_rows:
                self._set_time(self.frame_index[r], self.frame_time[r])
                rec.log(L.REPLAY_EVENTS, rr.AnyValues(events=text))
        self.scalar_rows = {}
        self.replay_event_rows = []
        self._new_buffers()

    def _send_focus(self, joints, x):
        """The characters' box per frame, (n, 2, 3) scene frame, sent as ``world/focus``."""
        box = np.empty((self.row, 2, 3))
        box[:, 0], box[:, 1] = np.inf, -np.inf
        if joints is not None and self.focus_nodes.size:
            grow_box(np.ascontiguousarray(joints, np.float64), self.focus_nodes, box)
        if x is not None and x.shape[1]:
            grow_box(np.ascontiguousarray(x, np.float64), np.arange(x.shape[1]), box)
        if not np.isfinite(box).any():
            return None
        self._send(L.FOCUS, "Points3D", 2, positions=_display(box))
        return box

    def _new_buffers(self) -> None:
        # rerun keeps zero-copy references to the numpy arrays it was given and encodes them
        # later on its own thread: never refill a buffer that was sent, start fresh ones
        self.buf = _Buffers(self.batch)
        self.frame_index = np.zeros(self.batch, np.int64)
        self.frame_time = np.zeros(self.batch, np.float64)
        self.delta_time = np.zeros(self.batch, np.float64)
        self.row = 0

    def _flush_live(self, when: str) -> None:
        """Wait until the live viewers received everything; a failure is an OutputError."""
        try:
            self.rec.flush(timeout_sec=FLUSH_SECONDS)
        except Exception as exc:  # noqa: BLE001 - rerun raises RuntimeError
            where = ", ".join(self.live_urls)
            raise OutputError(f"live output to {where} failed {when}: {exc}; the stream was not delivered") from exc

    def close(self, success: bool = True) -> None:
        if self.closed:
            return
        self.closed = True
        t0 = time.perf_counter()
        live_error = None
        try:
            if success:
                self.flush()
                if self.live:
                    try:
                        self._flush_live(f"after {self.frames} frames")
                    except OutputError as exc:
                        live_error = exc
        finally:
            self.rec.disconnect()  # writes the footer
            self.seconds += time.perf_counter() - t0
            if self.temp_path is not None:
                if success:
                    os.replace(self.temp_path, self.final_path)   # the file itself is complete
                else:
                    self._discard()
        if live_error is not None:
            raise live_error

    def _abandon(self) -> None:
        """Opening failed or was interrupted: the stream's sinks are closed (so that no writer
        creates the file again), then the temporary file is removed."""
        try:
            self.rec.disconnect()
        except Exception:  # noqa: BLE001 - the stream may be half made; the file goes either way
            pass
        self._discard()

    def _discard(self) -> None:
        if self.temp_path is not None:
            try:
                os.unlink(self.temp_path)
            except FileNotFoundError:
                pass

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        self.close(success=exc_type is None)
        return False


def _display(x: np.ndarray) -> np.ndarray:
    """Scene frame -> display frame (X negated), as float32 (negation commutes with the
    rounding: bit for bit the negated float32 of the scene value)."""
    out = np.asarray(x, np.float32).copy()
    out[..., 0] *= -1.0
    return out


@kernel
def grow_box(x, nodes, box):
    """box[b] = (min, max) of box[b] and the points x[b, nodes] (non-finite points skipped)."""
    for b in range(x.shape[0]):
        for k in range(nodes.shape[0]):
            p = nodes[k]
            for c in range(3):
                v = x[b, p, c]
                if v < box[b, 0, c]:
                    box[b, 0, c] = v
                if v > box[b, 1, c]:
                    box[b, 1, c] = v


@kernel
def gather_segments(x, start, end, sign, out):
    """out[(b*S + s)*2 + {0,1}] = float32 sign * x[b, start[s]] and sign * x[b, end[s]]: segments
    of a batch in the display frame (sign = layout.DISPLAY_MIRROR; negation is exact)."""
    count = start.shape[0]
    for b in range(x.shape[0]):
        for k in range(count):
            row = (b * count + k) * 2
            i, j = start[k], end[k]
            for c in range(3):
                out[row, c] = np.float32(sign[c] * x[b, i, c])
                out[row + 1, c] = np.float32(sign[c] * x[b, j, c])


def _segments(x: np.ndarray, start: np.ndarray, end: np.ndarray):
    """(B, P, 3) scene positions and (S,) endpoint indices -> the arrow array of B*S two-point
    strips in the display frame.

    rerun's numpy path for LineStrips3D computes the list offsets in a Python loop (about
    1.5 s for 500k strips); building the arrow array directly takes milliseconds."""
    import pyarrow as pa
    from rerun.components import LineStrip3DBatch

    points = np.empty((x.shape[0] * start.size * 2, 3), np.float32)
    gather_segments(np.ascontiguousarray(x, np.float64), np.ascontiguousarray(start, np.int64),
                    np.ascontiguousarray(end, np.int64), np.array(L.DISPLAY_MIRROR), points)
    list_type = LineStrip3DBatch._ARROW_DATATYPE
    values = pa.FixedSizeListArray.from_arrays(pa.array(points.reshape(-1)), type=list_type.value_type)
    offsets = pa.array(np.arange(0, points.shape[0] + 1, 2, dtype=np.int32))
    return pa.ListArray.from_arrays(offsets, values, type=list_type)


def _float64_rows(values: np.ndarray):
    """(n, ...) float64 -> an arrow list array with one row of float64 per frame (exact bits).

    Given a ready list array, AnyValues.columns takes its outer list as the rows; its own
    path converts value by value in Python (about 1 s per 180 frames × 1,200 values)."""
    import pyarrow as pa

    n = values.shape[0]
    flat = np.ascontiguousarray(values, np.float64).reshape(-1)
    width = flat.size // n if n else 0
    offsets = np.arange(n + 1, dtype=np.int32) * width
    return pa.ListArray.from_arrays(pa.array(offsets), pa.array(flat, type=pa.float64()))


def _event_text(payload) -> str:
    if isinstance(payload, dict):
        return json.dumps(payload, default=_json_default, sort_keys=True)
    return str(payload)


def _json_default(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return str(value)
