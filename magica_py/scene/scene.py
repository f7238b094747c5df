"""The validated scene: what ``config.load_scene(path, overrides=())`` returns.

Everything here is already checked (``magica_py.config``): names are resolved to hierarchy
indices, instanced rigs are expanded (bone ``hips`` of instance 3 is ``hips#3``), parameters
are complete ``ClothParameters``. The runtime, build, solver and sinks read a ``Scene`` and
never the YAML.
"""
from __future__ import annotations

import math
import pathlib
from dataclasses import dataclass, field
from typing import Any, Iterator, Mapping


class FrozenMapping(Mapping):
    """A read-only mapping that pickles and deep-copies (``types.MappingProxyType`` does
    neither, and a ``Scene`` must: a Dask worker receives one, ``simulate`` copies one and
    returns it inside a pickled ``Simulation``)."""

    __slots__ = ("_data",)

    def __init__(self, data: Mapping | None = None):
        self._data = dict(data or {})

    def __getitem__(self, key):
        return self._data[key]

    def __iter__(self) -> Iterator:
        return iter(self._data)

    def __len__(self) -> int:
        return len(self._data)

    def __repr__(self) -> str:
        return f"FrozenMapping({self._data!r})"

    def __reduce__(self):
        return (FrozenMapping, (self._data,))


@dataclass(frozen=True)
class SceneSettings:
    """``scene:`` section. Exactly one frame-time source is set: ``fps`` (fixed rate),
    ``frame_times`` (seconds per frame, cycled: hitches, variable rates) or ``clock ==
    "realtime"`` (the wall clock). Exactly one run length: ``frames`` or ``duration`` (s)."""

    name: str
    fps: float | None = 60.0
    frame_times: tuple[float, ...] | None = None
    frame_times_cycle: bool = True         # repeat frame_times (else the last one is kept)
    clock: str | None = None
    frames: int | None = 600
    duration: float | None = None
    time_scale: float = 1.0
    update_mode: str = "normal"            # normal | unity_physics | unscaled (docs/solver.md §A.4)
    simulation_frequency: int = 90         # Hz, [30, 150] (§A.3)
    max_steps_per_frame: int = 3           # [1, 5]
    global_time_scale: float = 1.0         # MagicaCloth2's global time scale [0, 1] (cloth only)
    fixed_delta_time: float = 0.02         # s, Unity Time.fixedDeltaTime
    maximum_delta_time: float = 1.0 / 3.0  # s, Unity Time.maximumDeltaTime
    gravity: tuple[float, float, float] = (0.0, -1.0, 0.0)  # unit world direction
    timing: str = "exact"                  # exact | faithful | faithful32 (Appendix 3.1)
    seed: int = 0
    threads: str | int = "auto"            # "auto" | threads the cloth frame uses (docs/scene-format.md)

    @property
    def frame_source(self) -> str:
        """"fps", "frame_times" or "realtime"."""
        if self.clock == "realtime":
            return "realtime"
        return "frame_times" if self.frame_times else "fps"

    def frame_count(self) -> int | None:
        """Frames to run: ``frames``, or enough frames to cover ``duration`` of unscaled time
        (None for a realtime clock with a duration: the run stops on the wall clock)."""
        if self.frames is not None:
            return self.frames
        if self.frame_source == "fps":
            return max(1, math.ceil(self.duration * self.fps - 1e-9))
        if self.frame_source == "frame_times":
            total, n = 0.0, 0
            times = self.frame_times
            while total < self.duration - 1e-12:
                if not self.frame_times_cycle and n >= len(times):
                    break  # a non-cycled list ends the run
                total += times[n % len(times)]
                n += 1
            return max(n, 1)
        return None

    def nominal_frame_time(self) -> float:
        """Seconds per frame for a fixed rate; the mean of ``frame_times``; 1/60 for realtime."""
        if self.frame_source == "fps":
            return 1.0 / self.fps
        if self.frame_source == "frame_times":
            return sum(self.frame_times) / len(self.frame_times)
        return 1.0 / 60.0


@dataclass(frozen=True)
class ClothSpec:
    """One cloth component (``cloths:`` entry, one per instance for an instanced rig).

    ``root_bones``: hierarchy indices in YAML order (globs expanded in hierarchy order);
    ``component``: index of the transform carrying the component (default: the first root's
    parent, or the first root when it has none); ``colliders``: indices into
    ``scene.colliders``; ``bone_attributes``: hierarchy index -> "fixed" | "move" | "invalid"
    (explicit overrides of the default: roots fixed, the rest move).
    """

    name: str
    root_bones: tuple[int, ...]
    component: int
    connection_mode: str
    parameters: Any                        # magica_py.params.ClothParameters
    colliders: tuple[int, ...] = ()
    collision_mode: str = "point"
    bone_attributes: Mapping[int, str] = field(default_factory=FrozenMapping)
    instance: int | None = None            # instance number for a replicated cloth
    preset: str | None = None
    document_path: str = ""                # e.g. "cloths[1]", for messages


@dataclass(frozen=True)
class OutputSpec:
    """``output:`` section: the recording path (None: no recording) and what to log."""

    rrd: pathlib.Path | None = None
    log: Mapping[str, bool] = field(default_factory=FrozenMapping)

    def logs(self, what: str) -> bool:
        return bool(self.log.get(what, False))


@dataclass(frozen=True)
class RigInfo:
    """One rig as placed in the hierarchy: its root node per instance and its node count."""

    name: str
    root_nodes: tuple[int, ...]            # the rig's root node in each instance
    nodes_per_instance: int
    instances: int                          # 1 when not instanced


@dataclass
class Scene:
    """A runnable scene (see docs/architecture.md "Scene")."""

    name: str
    source: pathlib.Path | None
    settings: SceneSettings
    hierarchy: Any                          # scene.hierarchy.TransformHierarchy
    colliders: Any                          # scene.colliders.ColliderSet
    animation: Any                          # scene.animation.Animation
    cloths: list[ClothSpec]
    output: OutputSpec
    rigs: list[RigInfo] = field(default_factory=list)
    collider_names: list[str] = field(default_factory=list)
    source_text: str | None = None          # YAML of the scene as run (overrides applied): for replays
    overrides: tuple[str, ...] = ()         # the `--set PATH=VALUE` strings it was loaded with, in order:
                                            # recorded so `magica-py resim` can re-apply them
    wind: tuple = ()                        # wind.zones.WindZoneSpec per `wind:` entry (none: no wind zones)

    def cloth(self, name: str) -> ClothSpec:
        for spec in self.cloths:
            if spec.name == name:
                return spec
        raise KeyError(f"no cloth named {name!r}; cloths: {', '.join(c.name for c in self.cloths)}")

    def summary(self) -> dict:
        """Counts for ``magica-py info`` and logs."""
        return {"bones": self.hierarchy.count, "rigs": len(self.rigs), "colliders": len(self.collider_names),
                "cloths": len(self.cloths), "wind_zones": len(self.wind)}
