"""The sink protocol and the data a sink receives.

A sink sees the scene once (``SceneStatics``: names, topology, colours: everything that does
not change) and then one ``FrameData`` per rendered frame, in the RENDER_WRITE phase:

    sink = SomeSink(statics, ...)
    for each frame:  sink.begin_frame(frame, sim_time); sink.log(data); sink.end_frame()
    sink.close(success)           # success=False discards a file being written

Arrays in ``FrameData`` are views of live simulation state: a sink that keeps them past
``end_frame`` must copy them (the Rerun sink copies into its column buffers).

Cloth data comes from a *snapshot provider* (``SnapshotProvider``): the solver (or a test's
fake) exposes ``cloth_topologies()`` once and ``cloth_frames()`` every frame, so the sink
does not depend on the solver's internal layout.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np


# ----------------------------------------------------------------------------- cloths
@dataclass(frozen=True)
class ClothTopology:
    """What a cloth looks like, fixed at build. Team-local vertex indices (0..N-1).

    ===============  ===========  =================================================
    name             str          cloth name (scene ``cloths[i].name``)
    attribute        (N,) uint8   0x01 fixed, 0x02 move, 0x08 invalid (docs/solver.md §B.5)
    radius           (N,) float   particle radius, m (radius curve at the depth)
    parent           (N,) int32   parent vertex or -1: drawn as the baselines
    edges            (E, 2) int32 proxy edges
    triangles        (T, 3) int32 proxy triangles (empty in line mode)
    rest_length      (E,) float   rest length of each edge, m (for the stretch metric)
    transform_index  (N,) int32   hierarchy node of each particle
    colliders        (C,) int32   indices into the scene's ColliderSet used by this cloth
    ===============  ===========  =================================================
    """

    name: str
    attribute: np.ndarray
    radius: np.ndarray
    parent: np.ndarray
    edges: np.ndarray
    triangles: np.ndarray
    rest_length: np.ndarray
    transform_index: np.ndarray
    colliders: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))

    @property
    def particle_count(self) -> int:
        return int(self.attribute.shape[0])


@dataclass
class ClothFrame:
    """One cloth at the end of LATE_UPDATE (world space, m).

    positions       (N, 3) display positions (§E.1): what the bones were written from
    base_positions  (N, 3) animated base pose the solver read this frame (§C.1), or None
    steps           simulation steps this team ran this frame (§A.4 update_count)
    """

    positions: np.ndarray
    base_positions: np.ndarray | None = None
    steps: int = 0


@runtime_checkable
class SnapshotProvider(Protocol):
    """Anything that can describe the cloths (the solver's ClothSystem adapter, test fakes).

    ``cloth_frames()`` returns one ``ClothFrame`` per topology. A provider whose particles
    already sit in one array may instead (or also) define ``particle_positions()`` ->
    (P, 3), ``particle_base_positions()`` -> (P, 3) | None and ``steps()`` -> int: the
    sink then copies one array per frame whatever the number of cloths (crowds).
    """

    def cloth_topologies(self) -> list[ClothTopology]: ...

    def cloth_frames(self) -> list[ClothFrame]: ...


# ----------------------------------------------------------------------------- colliders
@dataclass
class ColliderShapes:
    """World-space collider shapes of one frame (§G.2/§G.3 evaluated at the frame pose).

    sphere_center (S,3), sphere_radius (S,); capsule_start/end (C,3) centres of the end
    caps, capsule_start_radius/end_radius (C,); plane_point/normal (P,3).
    """

    sphere_center: np.ndarray
    sphere_radius: np.ndarray
    capsule_start: np.ndarray
    capsule_end: np.ndarray
    capsule_start_radius: np.ndarray
    capsule_end_radius: np.ndarray
    plane_point: np.ndarray
    plane_normal: np.ndarray

    @staticmethod
    def empty() -> "ColliderShapes":
        z3, z1 = np.zeros((0, 3)), np.zeros(0)
        return ColliderShapes(z3, z1, z3, z3, z1, z1, z3, z3)


# ----------------------------------------------------------------------------- scene / frame
@dataclass
class LogToggles:
    """What to log (scene ``output.log``); unknown keys in a mapping are rejected."""

    skeleton: bool = True
    particles: bool = True
    edges: bool = True
    triangles: bool = True
    baselines: bool = False
    base_pose: bool = False
    colliders: bool = True
    metrics: bool = True
    events: bool = True
    replay: bool = True   # driven local poses + time: what `resim` needs

    @staticmethod
    def from_any(value: Any) -> "LogToggles":
        if value is None:
            return LogToggles()
        if isinstance(value, LogToggles):
            return value
        if not isinstance(value, dict):  # an object with attributes (the config's spec)
            value = {k: getattr(value, k) for k in LogToggles.__dataclass_fields__ if hasattr(value, k)}
        unknown = set(value) - set(LogToggles.__dataclass_fields__)
        if unknown:
            raise ValueError(f"output.log: unknown toggles {sorted(unknown)}; "
                             f"expected some of {sorted(LogToggles.__dataclass_fields__)}")
        return LogToggles(**{k: bool(v) for k, v in value.items()})


@dataclass
class SceneStatics:
    """The unchanging part of a recording, given to a sink once."""

    name: str
    joint_names: list[str]
    joint_parent: np.ndarray              # (n,) int32
    cloths: list[ClothTopology]
    toggles: LogToggles = field(default_factory=LogToggles)
    replay_node_names: list[str] = field(default_factory=list)
    replay_scene_text: str = ""           # YAML text of the scene, so `resim` can rebuild it
    replay_scene_source: str = ""
    replay_scene_overrides: list[str] = field(default_factory=list)   # `--set` overrides of the run
    time_fields: tuple[str, ...] = ()     # UnityTime field names recorded per frame
    # drawing only (the viewer's entity tree and camera), never read back:
    node_group: list[str] = field(default_factory=list)    # per joint: instance label ("character_17") or ""
    collider_names: list[str] = field(default_factory=list)  # per collider of the ColliderSet
    collider_groups: list[str] = field(default_factory=list)  # per collider: its node's instance label or ""
    view_box: tuple | None = None         # (min (3,), max (3,)) of joints and particles at the first frame
    wind_zones: list | None = None        # the scene's WindZoneSpecs ([] for moving wind alone); None: no wind


@dataclass
class ReplayFrame:
    """What `resim` needs of one frame (float64, exact): see docs/recordings.md."""

    local_position: np.ndarray            # (D, 3) driven transforms, after UPDATE
    local_rotation: np.ndarray            # (D, 4)
    local_scale: np.ndarray               # (D, 3)
    time_values: np.ndarray               # (len(time_fields),) float64
    events_json: str = ""                 # JSON list of events raised before LATE_UPDATE


@dataclass
class FrameData:
    """One rendered frame. ``positions`` holds every cloth's particles concatenated in the
    order of ``SceneStatics.cloths`` (P = sum of particle counts), world space, m."""

    frame: int
    sim_time: float
    delta_time: float
    joint_positions: np.ndarray           # (n, 3) world
    positions: np.ndarray                 # (P, 3) display positions of all cloths
    colliders: ColliderShapes
    metrics: dict[str, float]
    events: list[tuple[str, Any]]
    base_positions: np.ndarray | None = None   # (P, 3) animated base pose, or None
    steps: int = 0                        # simulation steps this frame (max over teams)
    replay: ReplayFrame | None = None
    # instead of ``colliders``: world position, rotation, lossy scale of each collider's
    # transform ((C,3), (C,4), (C,3)), evaluated per batch by a sink given the ColliderSet
    collider_pose: tuple | None = None
    wind: Any = None                      # sinks.wind_view.WindFrame, or None


class Sink(Protocol):
    def begin_frame(self, frame: int, sim_time: float) -> None: ...

    def log(self, data: FrameData) -> None: ...

    def end_frame(self) -> None: ...

    def close(self, success: bool = True) -> None: ...


class NullSink:
    """Accepts everything, keeps nothing (the default when no output is requested)."""

    frames = 0

    def begin_frame(self, frame: int, sim_time: float) -> None:
        pass

    def log(self, data: FrameData) -> None:
        self.frames += 1

    def end_frame(self) -> None:
        pass

    def close(self, success: bool = True) -> None:
        pass
