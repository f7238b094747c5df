"""The Rerun sink: writes the layout of ``layout.py`` to an .rrd file and/or a live viewer.

Cost (docs/tech-notes.md §3): the Python overhead per rerun call (~50–90 µs) dominates, the data is
almost free. So a frame only *copies* a few whole arrays (joint positions, every cloth's
particles as one (P, 3) array, collider shapes, replay pose) into float64 batch buffers;
every ``batch_frames`` frames ``flush`` derives everything else for the whole batch at once
(bone and edge segments, per-cloth slices, the quality metrics with numba kernels), casts
geometry to float32 and makes one ``send_columns`` call per entity. Live streams
(``--spawn`` / ``--connect``) use ``batch_frames=1`` so the viewer follows the simulation.

Cloths are grouped by name without the instance suffix: the 100 ``skirt#i`` of a crowd are
one ``world/cloths/skirt`` entity set (fewer calls, and a usable entity tree in the viewer).

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

from magica_py.jit import kernel
from magica_py.sinks import layout as L
from magica_py.sinks.base import FrameData, SceneStatics
from magica_py.sinks.metrics import FrameMetrics
from magica_py.sinks.shapes import ColliderBatch, capsule_pose, from_y_rotation

FILE_BATCH_FRAMES = 64
PLANE_HALF_SIZE = 2.0       # m: planes are infinite; draw a 4 m square patch
JOINT_RADIUS = 0.008        # m
BONE_RADIUS = 0.003
EDGE_RADIUS = 0.0025


class OutputError(ValueError):
    """The recording cannot be written where it was asked to go."""


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


def grpc_url(address: str) -> str:
    """`host:port` or a full rerun URL -> the URL GrpcSink expects."""
    if "://" in address:
        return address
    if ":" not in address:
        raise OutputError(f"--connect: {address!r} is not host:port or a rerun+http:// URL")
    return f"rerun+http://{address}/proxy"


def default_blueprint():
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(origin="/world", name="scene"),
            rrb.Vertical(
                rrb.TimeSeriesView(origin="/metrics", name="cloth quality",
                                   contents=[f"/{L.METRIC_MAX_STRETCH}", f"/{L.METRIC_MAX_PENETRATION}"]),
                rrb.TimeSeriesView(origin="/metrics", name="speed (m/s)", contents=[f"/{L.METRIC_MAX_SPEED}"]),
                rrb.TimeSeriesView(origin="/metrics", name="steps", contents=[f"/{L.METRIC_STEPS}"]),
                rrb.TimeSeriesView(origin=f"/{L.METRIC_PHASE_TIME}", name="phase wall time (ms)"),
                rrb.TextLogView(origin=f"/{L.EVENTS}", name="events"),
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )


class _Group:
    """The cloths drawn as one entity set: a cloth and its instances (`skirt#0`, `skirt#1`...)."""

    def __init__(self, name: str):
        self.name = name
        self.particles: list[np.ndarray] = []    # global particle indices per member
        self.edges: list[np.ndarray] = []
        self.triangles: list[np.ndarray] = []    # group-local indices
        self.baselines: list[np.ndarray] = []    # (k, 2) global parent/child
        self.radius: list[np.ndarray] = []
        self.attribute: list[np.ndarray] = []
        self.count = 0

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


def cloth_groups(cloths) -> list[_Group]:
    """Group cloths by name without the instance suffix (`hair#3` -> `hair`), in first-seen order."""
    groups: dict[str, _Group] = {}
    offset = 0
    for topo in cloths:
        key = L.entity_name(topo.name.split("#")[0])
        groups.setdefault(key, _Group(key)).add(topo, offset)
        offset += topo.particle_count
    for g in groups.values():
        g.freeze()
    return list(groups.values())


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
    """See the module docstring. ``rrd_path``, ``spawn`` and ``connect`` may be combined."""

    def __init__(self, statics: SceneStatics, *, rrd_path=None, spawn: bool = False, connect: str | None = None,
                 batch_frames: int | None = None, recording_id: str | None = None,
                 collider_kind: np.ndarray | None = None, collider_slot: np.ndarray | None = None,
                 collider_set=None):
        t_import = time.perf_counter()
        import rerun as rr
        import rerun.blueprint  # noqa: F401 - one-time import cost, kept out of `seconds`

        if rrd_path is None and not spawn and connect is None:
            raise OutputError("RerunSink needs at least one of rrd_path, spawn, connect")
        self.rr = rr
        self.statics = statics
        self.toggles = statics.toggles
        t0 = time.perf_counter()
        self.import_seconds = t0 - t_import     # importing rerun (once per process)
        self.seconds = 0.0                      # wall time spent in this sink (cost figure)
        self.final_path = check_output_path(rrd_path) if rrd_path is not None else None
        self.temp_path = None
        live = spawn or connect is not None
        self.batch = max(1, int(batch_frames if batch_frames is not None else (1 if live else FILE_BATCH_FRAMES)))
        self.rec = rr.RecordingStream(L.APPLICATION_ID, recording_id=recording_id or str(uuid.uuid4()))
        self.rec.set_log_time_enabled(False)
        sinks = []
        if self.final_path is not None:
            self.temp_path = self.final_path.with_name(f".{self.final_path.stem}.{os.getpid()}.partial.rrd")
            sinks.append(rr.FileSink(str(self.temp_path)))
        try:
            if spawn:   # the viewer bundled with rerun-sdk; needs a display (docs/tech-notes.md §6)
                rr.spawn(connect=False)
                sinks.append(rr.GrpcSink())
            if connect is not None:
                sinks.append(rr.GrpcSink(grpc_url(connect)))
            self.rec.set_sinks(*sinks, default_blueprint=default_blueprint())
        except Exception as exc:  # noqa: BLE001 - rerun raises plain RuntimeError
            self._discard()
            raise OutputError(f"cannot open the recording output: {exc}") from exc
        self.closed = False
        try:
            self._prepare(statics, collider_kind, collider_slot, collider_set)
        except Exception:
            self.close(success=False)   # no temporary file left behind
            raise
        self.seconds += time.perf_counter() - t0

    def _prepare(self, statics, collider_kind, collider_slot, collider_set) -> None:
        """Static index arrays, buffers, and the static part of the recording."""
        self.frames = 0
        self.scalar_rows: dict[str, list[tuple[int, float]]] = {}
        self.replay_event_rows: list[tuple[int, str]] = []
        self._new_buffers()
        parent = np.asarray(statics.joint_parent, np.int64)
        # links between two cloth particles are drawn as the cloth's edges: not again as bones
        cloth_node = np.zeros(parent.size, bool)
        for c in statics.cloths:
            cloth_node[np.asarray(c.transform_index, np.int64)] = True
        # cloth bones sit on their particles (docs/solver.md §E.4): the rig's points are the other joints
        self.joint_nodes = None if not cloth_node.any() else np.flatnonzero(~cloth_node)
        child = np.flatnonzero(parent >= 0)
        child = child[~(cloth_node[child] & cloth_node[parent[child]])]
        self.bone_child = child
        self.bone_parent = parent[child]
        self.groups = cloth_groups(statics.cloths)
        self.particle_count = sum(c.particle_count for c in statics.cloths)
        self.collider_batch = ColliderBatch(collider_set) if collider_set is not None and len(collider_set.names) \
            else None
        self.metrics = FrameMetrics(statics.cloths,
                                    collider_kind if collider_kind is not None else np.zeros(0, np.int64),
                                    collider_slot if collider_slot is not None else np.zeros(0, np.int64))
        self._log_statics()

    # ------------------------------------------------------------------ statics
    def _log_statics(self) -> None:
        rr, rec, s, tg = self.rr, self.rec, self.statics, self.toggles
        rec.log(L.WORLD, rr.ViewCoordinates.LEFT_HAND_Y_UP, static=True)
        if tg.skeleton:
            rec.log(L.RIG_JOINTS, rr.Points3D.from_fields(radii=JOINT_RADIUS, colors=L.COLOR_JOINT), static=True)
            rec.log(L.RIG_BONES, rr.LineStrips3D.from_fields(radii=BONE_RADIUS, colors=L.COLOR_BONE), static=True)
        for g in self.groups:
            colors = np.empty((g.count, 4), np.uint8)
            colors[:] = L.COLOR_MOVE
            colors[(g.attribute & 0x01) != 0] = L.COLOR_FIXED
            colors[(g.attribute & 0x08) != 0] = L.COLOR_INVALID
            if tg.particles:
                rec.log(L.cloth_path(g.name, "particles"),
                        rr.Points3D.from_fields(radii=g.radius.astype(np.float32), colors=colors), static=True)
            if tg.edges and len(g.edges):
                rec.log(L.cloth_path(g.name, "edges"),
                        rr.LineStrips3D.from_fields(radii=EDGE_RADIUS, colors=L.COLOR_EDGE), static=True)
            if tg.triangles and len(g.triangles):
                rec.log(L.cloth_path(g.name, "triangles"),
                        rr.Mesh3D.from_fields(triangle_indices=g.triangles.astype(np.uint32),
                                              albedo_factor=[110, 170, 230, 140]), static=True)
            if tg.baselines and len(g.baselines):
                rec.log(L.cloth_path(g.name, "baselines"),
                        rr.LineStrips3D.from_fields(radii=EDGE_RADIUS, colors=L.COLOR_BASELINE), static=True)
            if tg.base_pose:
                rec.log(L.cloth_path(g.name, "base_pose"),
                        rr.Points3D.from_fields(radii=(g.radius * 0.5).astype(np.float32),
                                                colors=L.COLOR_BASE_POSE), static=True)
        if tg.colliders:
            rec.log(L.COLLIDER_SPHERES, rr.Ellipsoids3D.from_fields(colors=L.COLOR_COLLIDER, fill_mode="solid"),
                    static=True)
            rec.log(L.COLLIDER_CAPSULES, rr.Capsules3D.from_fields(colors=L.COLOR_COLLIDER, fill_mode="solid"),
                    static=True)
            rec.log(L.COLLIDER_PLANES, rr.Boxes3D.from_fields(colors=L.COLOR_PLANE), static=True)
        rec.log(L.REPLAY_SCENE, rr.AnyValues(name=s.name, source=s.replay_scene_source,
                                             yaml=s.replay_scene_text,
                                             format_version=L.REPLAY_FORMAT_VERSION,
                                             time_fields=list(s.time_fields) or [""],
                                             overrides=list(s.replay_scene_overrides) or [""]), static=True)
        if tg.replay:
            rec.log(L.REPLAY_NODES, rr.AnyValues(names=list(s.replay_node_names) or [""]), static=True)

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
        if tg.skeleton:
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
            self.scalar_rows.setdefault("steps", []).append((row, float(data.steps)))
            for key, value in data.metrics.items():
                scaled = float(value) * 1000.0 if key.startswith("time.") else float(value)
                self.scalar_rows.setdefault(key, []).append((row, scaled))
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

    def _log_events(self, data: FrameData) -> None:
        rr, rec = self.rr, self.rec
        rec.set_time(L.TIMELINE_FRAME, sequence=int(data.frame))
        rec.set_time(L.TIMELINE_SIM_TIME, duration=float(data.sim_time))
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
        """One send_columns call: components are (n, count, ...) arrays for n frames."""
        rr, n = self.rr, self.row
        flat = {k: v if k == "strips" else np.ascontiguousarray(v, dtype=np.float32).reshape((n * count,) + v.shape[2:])
                for k, v in components.items()}
        columns = getattr(rr, archetype).columns(**flat).partition([count] * n)
        self.rec.send_columns(entity, indexes=self._index(), columns=columns)

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
        if tg.skeleton and "joints" in a:
            joints = a["joints"]
            shown = joints if self.joint_nodes is None else joints[:, self.joint_nodes]
            self._send(L.RIG_JOINTS, "Points3D", shown.shape[1], positions=shown)
            if self.bone_child.size:
                self._send(L.RIG_BONES, "LineStrips3D", self.bone_child.size,
                           strips=_segments(joints, self.bone_parent, self.bone_child))
        x = a.get("positions")
        if x is not None:
            for g in self.groups:
                gx = g.take(x)
                if tg.particles:
                    self._send(L.cloth_path(g.name, "particles"), "Points3D", g.count, positions=gx)
                if tg.edges and len(g.edges):
                    self._send(L.cloth_path(g.name, "edges"), "LineStrips3D", len(g.edges),
                               strips=_segments(x, g.edges[:, 0], g.edges[:, 1]))
                if tg.triangles and len(g.triangles):
                    self._send(L.cloth_path(g.name, "triangles"), "Mesh3D", g.count, vertex_positions=gx)
                if tg.baselines and len(g.baselines):
                    self._send(L.cloth_path(g.name, "baselines"), "LineStrips3D", len(g.baselines),
                               strips=_segments(x, g.baselines[:, 0], g.baselines[:, 1]))
                if tg.base_pose and "base_positions" in a:
                    self._send(L.cloth_path(g.name, "base_pose"), "Points3D", g.count,
                               positions=g.take(a["base_positions"]))
        if tg.colliders:
            self._send_colliders(a)
        if tg.metrics:
            if x is not None:
                values = self.metrics.compute(x, a, self.delta_time[:n])
                for key, series in values.items():
                    self.scalar_rows[key] = list(enumerate(series.tolist()))
            for key, rows in self.scalar_rows.items():
                sel = np.array([r for r, _ in rows], np.int64)
                vals = np.array([v for _, v in rows], np.float64)
                rec.send_columns(L.metric_path(key), indexes=self._index(sel), columns=rr.Scalars.columns(scalars=vals))
        if tg.replay and "replay.time" in a:
            for key, component in (("replay.local_position", "local_position"),
                                   ("replay.local_rotation", "local_rotation"),
                                   ("replay.local_scale", "local_scale"), ("replay.time", "values")):
                entity = L.REPLAY_TIME if key == "replay.time" else L.REPLAY_POSE
                rec.send_columns(entity, indexes=self._index(),
                                 columns=rr.AnyValues.columns(**{component: _float64_rows(a[key])}))
            for r, text in self.replay_event_rows:
                rec.set_time(L.TIMELINE_FRAME, sequence=int(self.frame_index[r]))
                rec.set_time(L.TIMELINE_SIM_TIME, duration=float(self.frame_time[r]))
                rec.log(L.REPLAY_EVENTS, rr.AnyValues(events=text))
        self.scalar_rows = {}
        self.replay_event_rows = []
        self._new_buffers()

    def _send_colliders(self, a) -> None:
        if "sphere_center" in a:
            r = a["sphere_radius"]
            self._send(L.COLLIDER_SPHERES, "Ellipsoids3D", r.shape[1], centers=a["sphere_center"],
                       half_sizes=np.repeat(r[..., None], 3, axis=2))
        if "capsule_start" in a:
            start, end = a["capsule_start"], a["capsule_end"]
            n, c = start.shape[:2]
            length, quat = capsule_pose(start.reshape(-1, 3), end.reshape(-1, 3))
            # rerun capsules have one radius: the larger cap (tapered capsules are drawn fat)
            radius = np.maximum(a["capsule_start_radius"], a["capsule_end_radius"])
            self._send(L.COLLIDER_CAPSULES, "Capsules3D", c, translations=start, quaternions=quat.reshape(n, c, 4),
                       lengths=length.reshape(n, c), radii=radius)
        if "plane_point" in a:
            point = a["plane_point"]
            n, c = point.shape[:2]
            half = np.zeros((n, c, 3))
            half[..., 0] = half[..., 2] = PLANE_HALF_SIZE
            quat = from_y_rotation(a["plane_normal"].reshape(-1, 3)).reshape(n, c, 4)
            self._send(L.COLLIDER_PLANES, "Boxes3D", c, centers=point, half_sizes=half, quaternions=quat)

    def _new_buffers(self) -> None:
        # rerun keeps zero-copy references to the numpy arrays it was given and encodes them
        # later on its own thread: never refill a buffer that was sent, start fresh ones
        self.buf = _Buffers(self.batch)
        self.frame_index = np.zeros(self.batch, np.int64)
        self.frame_time = np.zeros(self.batch, np.float64)
        self.delta_time = np.zeros(self.batch, np.float64)
        self.row = 0

    def close(self, success: bool = True) -> None:
        if self.closed:
            return
        self.closed = True
        t0 = time.perf_counter()
        try:
            if success:
                self.flush()
        finally:
            self.rec.disconnect()  # writes the footer
            self.seconds += time.perf_counter() - t0
            if self.temp_path is not None:
                if success:
                    os.replace(self.temp_path, self.final_path)
                else:
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


@kernel
def gather_segments(x, start, end, out):
    """out[(b*S + s)*2 + {0,1}] = float32 x[b, start[s]] and x[b, end[s]]: segments of a batch."""
    count = start.shape[0]
    for b in range(x.shape[0]):
        for k in range(count):
            row = (b * count + k) * 2
            i, j = start[k], end[k]
            for c in range(3):
                out[row, c] = np.float32(x[b, i, c])
                out[row + 1, c] = np.float32(x[b, j, c])


def _segments(x: np.ndarray, start: np.ndarray, end: np.ndarray):
    """(B, P, 3) positions and (S,) endpoint indices -> the arrow array of B*S two-point strips.

    rerun's numpy path for LineStrips3D computes the list offsets in a Python loop (about
    1.5 s for 500k strips); building the arrow array directly takes milliseconds."""
    import pyarrow as pa
    from rerun.components import LineStrip3DBatch

    points = np.empty((x.shape[0] * start.size * 2, 3), np.float32)
    gather_segments(np.ascontiguousarray(x, np.float64), np.ascontiguousarray(start, np.int64),
                    np.ascontiguousarray(end, np.int64), points)
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
