"""The Rerun sink: writes the layout of ``layout.py`` to an .rrd file and/or a live viewer.

Cost (tech-notes §3): the Python overhead per rerun call (~50–90 µs) dominates, the data is
almost free. So every frame only *copies* its arrays into preallocated column buffers
(``batch_frames`` rows, float32 for geometry, float64 for replay data), and every
``batch_frames`` frames one ``send_columns`` call per entity sends them all. Live streams
(``--spawn`` / ``--connect``) use ``batch_frames=1`` so the viewer follows the simulation.

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

from magica_py.sinks import layout as L
from magica_py.sinks.base import FrameData, SceneStatics
from magica_py.sinks.metrics import FrameMetrics
from magica_py.sinks.shapes import capsule_pose, from_y_rotation

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


class _Columns:
    """Preallocated per-entity column buffers, flushed with send_columns."""

    def __init__(self, rows: int):
        self.rows = rows
        self.buffers: dict[tuple[str, str], np.ndarray] = {}

    def put(self, entity: str, component: str, row: int, values: np.ndarray, dtype=np.float32) -> None:
        key = (entity, component)
        buf = self.buffers.get(key)
        if buf is None:
            buf = self.buffers[key] = np.empty((self.rows,) + values.shape, dtype)
        buf[row] = values


class RerunSink:
    """See the module docstring. ``rrd_path``, ``spawn`` and ``connect`` may be combined."""

    def __init__(self, statics: SceneStatics, *, rrd_path=None, spawn: bool = False, connect: str | None = None,
                 batch_frames: int | None = None, recording_id: str | None = None,
                 collider_kind: np.ndarray | None = None, collider_slot: np.ndarray | None = None):
        import rerun as rr

        if rrd_path is None and not spawn and connect is None:
            raise OutputError("RerunSink needs at least one of rrd_path, spawn, connect")
        self.rr = rr
        self.statics = statics
        self.toggles = statics.toggles
        self.seconds = 0.0                      # wall time spent in this sink (cost figure)
        t0 = time.perf_counter()
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
        if spawn:
            rr.spawn(connect=False)
            sinks.append(rr.GrpcSink())
        if connect is not None:
            sinks.append(rr.GrpcSink(grpc_url(connect)))
        try:
            self.rec.set_sinks(*sinks, default_blueprint=default_blueprint())
        except Exception as exc:  # noqa: BLE001 - rerun raises plain RuntimeError
            self._discard()
            raise OutputError(f"cannot open the recording: {exc}") from exc
        self.closed = False
        self.frames = 0
        self._new_buffers()
        self.scalar_rows: dict[str, list[tuple[int, float]]] = {}
        self.replay_event_rows: list[tuple[int, str]] = []
        parent = statics.joint_parent
        self.bone_child = np.flatnonzero(parent >= 0)
        self.bone_parent = parent[self.bone_child].astype(np.int64)
        self.metrics = FrameMetrics(statics.cloths,
                                    collider_kind if collider_kind is not None else np.zeros(0, np.int64),
                                    collider_slot if collider_slot is not None else np.zeros(0, np.int64))
        self.baseline_child = [np.flatnonzero(c.parent >= 0) for c in statics.cloths]
        self.cloth_positions = np.zeros((self.metrics.particle_count, 3))
        self._log_statics()
        self.seconds += time.perf_counter() - t0

    # ------------------------------------------------------------------ statics
    def _log_statics(self) -> None:
        rr, rec, s, tg = self.rr, self.rec, self.statics, self.toggles
        rec.log(L.WORLD, rr.ViewCoordinates.LEFT_HAND_Y_UP, static=True)
        if tg.skeleton:
            rec.log(L.RIG_JOINTS, rr.Points3D.from_fields(radii=JOINT_RADIUS, colors=L.COLOR_JOINT,
                                                          labels=None), static=True)
            rec.log(L.RIG_BONES, rr.LineStrips3D.from_fields(radii=BONE_RADIUS, colors=L.COLOR_BONE), static=True)
        for cloth in s.cloths:
            colors = np.empty((cloth.particle_count, 4), np.uint8)
            colors[:] = L.COLOR_MOVE
            colors[(cloth.attribute & 0x01) != 0] = L.COLOR_FIXED
            colors[(cloth.attribute & 0x08) != 0] = L.COLOR_INVALID
            if tg.particles:
                rec.log(L.cloth_path(cloth.name, "particles"),
                        rr.Points3D.from_fields(radii=np.asarray(cloth.radius, np.float32), colors=colors), static=True)
            if tg.edges and len(cloth.edges):
                rec.log(L.cloth_path(cloth.name, "edges"),
                        rr.LineStrips3D.from_fields(radii=EDGE_RADIUS, colors=L.COLOR_EDGE), static=True)
            if tg.triangles and len(cloth.triangles):
                rec.log(L.cloth_path(cloth.name, "triangles"),
                        rr.Mesh3D.from_fields(triangle_indices=np.asarray(cloth.triangles, np.uint32),
                                              albedo_factor=[110, 170, 230, 140]), static=True)
            if tg.baselines:
                rec.log(L.cloth_path(cloth.name, "baselines"),
                        rr.LineStrips3D.from_fields(radii=EDGE_RADIUS, colors=L.COLOR_BASELINE), static=True)
            if tg.base_pose:
                rec.log(L.cloth_path(cloth.name, "base_pose"),
                        rr.Points3D.from_fields(radii=np.asarray(cloth.radius, np.float32) * 0.5,
                                                colors=L.COLOR_BASE_POSE), static=True)
        if tg.colliders:
            rec.log(L.COLLIDER_SPHERES, rr.Ellipsoids3D.from_fields(colors=L.COLOR_COLLIDER, fill_mode="solid"),
                    static=True)
            rec.log(L.COLLIDER_CAPSULES, rr.Capsules3D.from_fields(colors=L.COLOR_COLLIDER, fill_mode="solid"),
                    static=True)
            rec.log(L.COLLIDER_PLANES, rr.Boxes3D.from_fields(colors=L.COLOR_PLANE), static=True)
        if tg.replay:
            rec.log(L.REPLAY_SCENE, rr.AnyValues(name=s.name, source=s.replay_scene_source,
                                                 yaml=s.replay_scene_text,
                                                 format_version=L.REPLAY_FORMAT_VERSION,
                                                 time_fields=list(s.time_fields) or [""]), static=True)
            rec.log(L.REPLAY_NODES, rr.AnyValues(names=list(s.replay_node_names) or [""]), static=True)

    # ------------------------------------------------------------------ per frame
    def begin_frame(self, frame: int, sim_time: float) -> None:
        self.frame_index[self.row] = frame
        self.frame_time[self.row] = sim_time

    def log(self, data: FrameData) -> None:
        t0 = time.perf_counter()
        cols, row, tg = self.cols, self.row, self.toggles
        self.frame_index[row] = data.frame
        self.frame_time[row] = data.sim_time
        joints = data.joint_positions
        if tg.skeleton:
            cols.put(L.RIG_JOINTS, "positions", row, joints)
            seg = cols.buffers.get((L.RIG_BONES, "strips"))
            if seg is None:
                cols.put(L.RIG_BONES, "strips", row, np.zeros((self.bone_child.size, 2, 3)))
                seg = cols.buffers[(L.RIG_BONES, "strips")]
            seg[row, :, 0] = joints[self.bone_parent]
            seg[row, :, 1] = joints[self.bone_child]
        offset = 0
        for k, (topo, cf) in enumerate(zip(self.statics.cloths, data.cloths)):
            x = cf.positions
            n = topo.particle_count
            self.cloth_positions[offset:offset + n] = x
            offset += n
            if tg.particles:
                cols.put(L.cloth_path(topo.name, "particles"), "positions", row, x)
            if tg.edges and len(topo.edges):
                cols.put(L.cloth_path(topo.name, "edges"), "strips", row, x[topo.edges])
            if tg.triangles and len(topo.triangles):
                cols.put(L.cloth_path(topo.name, "triangles"), "vertex_positions", row, x)
            if tg.baselines and self.baseline_child[k].size:
                child = self.baseline_child[k]
                cols.put(L.cloth_path(topo.name, "baselines"), "strips", row,
                         np.stack([x[topo.parent[child]], x[child]], axis=1))
            if tg.base_pose and cf.base_positions is not None:
                cols.put(L.cloth_path(topo.name, "base_pose"), "positions", row, cf.base_positions)
        if tg.colliders:
            self._put_colliders(data, row)
        if tg.metrics:
            values = dict(data.metrics)
            values.setdefault("steps", float(max((c.steps for c in data.cloths), default=0)))
            values.update(self.metrics.compute(self.cloth_positions, data.colliders, data.delta_time))
            for key, value in values.items():
                scaled = float(value) * 1000.0 if key.startswith("time.") else float(value)
                self.scalar_rows.setdefault(key, []).append((row, scaled))
        if tg.events and data.events:
            self._log_events(data)
        if tg.replay and data.replay is not None:
            r = data.replay
            cols.put(L.REPLAY_POSE, "local_position", row, r.local_position, np.float64)
            cols.put(L.REPLAY_POSE, "local_rotation", row, r.local_rotation, np.float64)
            cols.put(L.REPLAY_POSE, "local_scale", row, r.local_scale, np.float64)
            cols.put(L.REPLAY_TIME, "values", row, r.time_values, np.float64)
            if r.events_json:
                self.replay_event_rows.append((row, r.events_json))
        self.seconds += time.perf_counter() - t0

    def _put_colliders(self, data: FrameData, row: int) -> None:
        sh, cols = data.colliders, self.cols
        if len(sh.sphere_radius):
            cols.put(L.COLLIDER_SPHERES, "centers", row, sh.sphere_center)
            cols.put(L.COLLIDER_SPHERES, "half_sizes", row, np.repeat(sh.sphere_radius[:, None], 3, axis=1))
        if len(sh.capsule_start):
            length, quat = capsule_pose(sh.capsule_start, sh.capsule_end)
            cols.put(L.COLLIDER_CAPSULES, "translations", row, sh.capsule_start)
            cols.put(L.COLLIDER_CAPSULES, "quaternions", row, quat)
            cols.put(L.COLLIDER_CAPSULES, "lengths", row, length)
            # rerun capsules have one radius: the larger cap (tapered capsules are drawn fat)
            cols.put(L.COLLIDER_CAPSULES, "radii", row, np.maximum(sh.capsule_start_radius, sh.capsule_end_radius))
        if len(sh.plane_point):
            half = np.zeros((len(sh.plane_point), 3))
            half[:, 0] = half[:, 2] = PLANE_HALF_SIZE
            cols.put(L.COLLIDER_PLANES, "centers", row, sh.plane_point)
            cols.put(L.COLLIDER_PLANES, "half_sizes", row, half)
            cols.put(L.COLLIDER_PLANES, "quaternions", row, from_y_rotation(sh.plane_normal))

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

    # ------------------------------------------------------------------ sending
    def flush(self) -> None:
        """Send the buffered frames as columns (one send_columns call per entity)."""
        rr, rec, n = self.rr, self.rec, self.row
        if n == 0:
            return
        frames, times = self.frame_index[:n], self.frame_time[:n]

        def index(rows=slice(None)):
            return [rr.TimeColumn(L.TIMELINE_FRAME, sequence=frames[rows]),
                    rr.TimeColumn(L.TIMELINE_SIM_TIME, duration=times[rows])]

        by_entity: dict[str, dict[str, np.ndarray]] = {}
        for (entity, component), buf in self.cols.buffers.items():
            by_entity.setdefault(entity, {})[component] = buf[:n]
        for entity, comps in by_entity.items():
            archetype, per_row = _ARCHETYPES[entity.rsplit("/", 1)[-1]] if entity.startswith(L.CLOTHS) \
                else _ARCHETYPES[entity]
            if archetype == "AnyValues":
                for name, values in comps.items():  # one call each: row sizes differ per component
                    columns = rr.AnyValues.columns(**{name: values.reshape(-1)}).partition([values[0].size] * n)
                    rec.send_columns(entity, indexes=index(), columns=columns)
                continue
            cls = getattr(rr, archetype)
            first = comps[next(iter(comps))]
            count = first.shape[1]
            flat = {k: v.reshape((n * count,) + v.shape[2:]) for k, v in comps.items()}
            columns = cls.columns(**flat)
            if per_row:
                columns = columns.partition([count] * n)
            rec.send_columns(entity, indexes=index(), columns=columns)
        for key, rows in self.scalar_rows.items():
            sel = np.array([r for r, _ in rows], np.int64)
            values = np.array([v for _, v in rows], np.float64)
            rec.send_columns(L.metric_path(key), indexes=index(sel), columns=rr.Scalars.columns(scalars=values))
        for r, text in self.replay_event_rows:
            rec.set_time(L.TIMELINE_FRAME, sequence=int(frames[r]))
            rec.set_time(L.TIMELINE_SIM_TIME, duration=float(times[r]))
            rec.log(L.REPLAY_EVENTS, rr.AnyValues(events=text))
        self.scalar_rows.clear()
        self.replay_event_rows.clear()
        self._new_buffers()

    def _new_buffers(self) -> None:
        # rerun keeps zero-copy references to the numpy arrays it was given and encodes them
        # later on its own thread: never refill a buffer that was sent, start fresh ones
        self.cols = _Columns(self.batch)
        self.frame_index = np.zeros(self.batch, np.int64)
        self.frame_time = np.zeros(self.batch, np.float64)
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


# archetype per entity (cloth entities by their last path part); True: several instances per row
_ARCHETYPES = {
    L.RIG_JOINTS: ("Points3D", True),
    L.RIG_BONES: ("LineStrips3D", True),
    "particles": ("Points3D", True),
    "base_pose": ("Points3D", True),
    "edges": ("LineStrips3D", True),
    "baselines": ("LineStrips3D", True),
    "triangles": ("Mesh3D", True),
    L.COLLIDER_SPHERES: ("Ellipsoids3D", True),
    L.COLLIDER_CAPSULES: ("Capsules3D", True),
    L.COLLIDER_PLANES: ("Boxes3D", True),
    L.REPLAY_POSE: ("AnyValues", False),
    L.REPLAY_TIME: ("AnyValues", False),
}


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
