"""The job file (YAML) and its expansion into jobs: the cross product of its axes.

```yaml
version: 1
name: presets_by_rate                 # optional: the batch's name (default: the file's stem)
scenes: [../configs/character_walk.yaml]     # paths relative to this file
frames: 120                           # frames per job (default: each scene's own length)
clips:                                # optional axis: animation clips swapped into the scene
  path: animation[0].clip             # where the clip reference goes (default animation[0].clip)
  files: [../../shared/data/bvh/cmu_01_01.bvh]   # relative to this file
overrides:                            # optional axis: named sets of --set strings
  as_is: []
  soft_skirt: [cloths.skirt.preset=soft_skirt]
set:                                  # optional: one axis per path, its values swept
  cloths.hair.preset: [short_hair, long_hair]
fps: [30, 60]                         # optional axis: scene.fps (default: the scene's)
seeds: [0, 1]                         # optional axis: scene.seed (default: the scene's)
outputs: {rrd: false, bake: null}     # per job: a recording, and/or a bake (glb|gltf|vrm|bvh)
plot: {metric: max_stretch, cost: ms_per_sim_second}   # the Pareto plot's axes
```

Jobs = scenes x clips x overrides x (every ``set`` path's values) x fps x seeds. Each job is
plain data (``Job``); its id is a hash of everything that determines its result (the scene
file's bytes, the ``--set`` strings, the frame count, the outputs), so a restarted batch
finds its finished jobs in the output folder, and a changed scene or job is run again.
Problems are reported as ``JobFileError`` naming the file, the path in the document and
what was expected.
"""
from __future__ import annotations

import hashlib
import itertools
import json
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path

import yaml

KEYS = ("version", "name", "scenes", "frames", "clips", "overrides", "set", "fps", "seeds", "outputs", "plot")
BAKE_FORMATS = ("glb", "gltf", "vrm", "bvh")
JOB_FORMAT = 1          # bump when a job's result would change for the same inputs


class JobFileError(ValueError):
    def __init__(self, file, where: str, message: str):
        self.file, self.where, self.message = str(file), where, message
        super().__init__(f"{file}: {where}: {message}" if where else f"{file}: {message}")

    def __reduce__(self):  # unpickles as itself (Dask workers, multiprocessing)
        return (type(self), (self.file, self.where, self.message), self.__dict__)


@dataclass(frozen=True)
class Job:
    """One simulation of the batch (plain data: it travels to a worker).

    ``overrides``: every ``--set`` string applied to the scene, in order (override set,
    ``set`` values, clip, fps, seed); ``labels``: the axis values for the table."""

    job_id: str
    scene: str                           # absolute path
    overrides: tuple[str, ...]
    frames: int | None
    labels: dict = field(default_factory=dict)   # scene, clip, override, fps, seed, set.<path>
    rrd: bool = False
    bake: str | None = None              # output extension without the dot, or None
    scene_sha256: str = ""               # the client's scene file: a worker checks it sees the same

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> "Job":
        return cls(**{**data, "overrides": tuple(data["overrides"])})


@dataclass
class JobFile:
    path: Path
    name: str
    jobs: list[Job]
    metric: str = "max_stretch"
    cost: str = "ms_per_sim_second"


def _fail(path, where, message):
    raise JobFileError(path, where, message)


def _list(path, data, key, kind, default):
    value = data.get(key, default)
    if value is None:
        return default
    if not isinstance(value, list) or not value:
        _fail(path, key, f"expected a non-empty list of {kind}, got {value!r}")
    return value


def _number_list(path, data, key, integer: bool, positive: bool):
    values = _list(path, data, key, "whole numbers" if integer else "numbers", None)
    if values is None:
        return [None]
    for i, v in enumerate(values):
        ok = isinstance(v, int) if integer else isinstance(v, (int, float))
        if not ok or isinstance(v, bool) or (positive and not v > 0):
            _fail(path, f"{key}[{i}]", f"expected a {'positive ' if positive else ''}"
                                       f"{'whole number' if integer else 'number'}, got {v!r}")
    return values


def _file_digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def job_id(scene: Path, digest: str, overrides, frames, rrd, bake) -> str:
    text = json.dumps({"format": JOB_FORMAT, "scene": scene.name, "scene_sha256": digest,
                       "overrides": list(overrides), "frames": frames, "rrd": rrd, "bake": bake}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _format(value) -> str:
    """A YAML scalar for a ``--set`` value (flow style, one line)."""
    return yaml.safe_dump(value, default_flow_style=True, width=1 << 20).strip().removesuffix("...").strip()


def load_job_file(path) -> JobFile:
    """Read and expand a job file (see the module docstring)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise JobFileError(path, "", f"cannot read the job file ({exc.strerror or exc})") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}" if mark is not None else ""
        raise JobFileError(path, where, f"invalid YAML ({getattr(exc, 'problem', None) or exc})") from None
    if not isinstance(data, dict):
        _fail(path, "", f"expected a mapping with 'scenes', got {type(data).__name__}")
    unknown = [k for k in data if k not in KEYS]
    if unknown:
        _fail(path, str(unknown[0]), f"unknown key; expected one of {', '.join(KEYS)}")
    if data.get("version", 1) != 1:
        _fail(path, "version", f"expected 1, got {data['version']!r}")
    base = path.resolve().parent
    scenes = []
    for i, s in enumerate(_list(path, data, "scenes", "scene file paths", None) or _fail(path, "scenes", "missing: "
                                                                                          "expected a list of scene files")):
        if not isinstance(s, str):
            _fail(path, f"scenes[{i}]", f"expected a scene file path, got {s!r}")
        full = Path(os.path.normpath(base / s))
        if not full.is_file():
            _fail(path, f"scenes[{i}]", f"scene file {str(full)!r} does not exist")
        scenes.append(full)
    frames = data.get("frames")
    if frames is not None and (not isinstance(frames, int) or isinstance(frames, bool) or frames < 1):
        _fail(path, "frames", f"expected a whole number of frames >= 1, got {frames!r}")

    clip_axis = [(None, None)]
    if data.get("clips") is not None:
        clips = data["clips"]
        if not isinstance(clips, dict):
            _fail(path, "clips", f"expected a mapping {{path, files}}, got {clips!r}")
        for k in clips:
            if k not in ("path", "files"):
                _fail(path, f"clips.{k}", "unknown key; expected path or files")
        target = clips.get("path", "animation[0].clip")
        if not isinstance(target, str) or not target:
            _fail(path, "clips.path", f"expected a document path such as animation[0].clip, got {target!r}")
        clip_axis = []
        for i, ref in enumerate(_list(path, clips, "files", "clip references", None) or
                                _fail(path, "clips.files", "missing: expected a list of clip files")):
            if not isinstance(ref, str):
                _fail(path, f"clips.files[{i}]", f"expected a clip reference (file.bvh or file.glb#Name), got {ref!r}")
            file, _, name = ref.partition("#")
            full = Path(os.path.normpath(base / file))
            if not full.is_file():
                _fail(path, f"clips.files[{i}]", f"clip file {str(full)!r} does not exist")
            clip_axis.append((ref, f"{target}={_format(str(full) + ('#' + name if name else ''))}"))

    override_axis = [(None, ())]
    if data.get("overrides") is not None:
        sets = data["overrides"]
        if isinstance(sets, list):
            sets = {f"set{i}": v for i, v in enumerate(sets)}
        if not isinstance(sets, dict) or not sets:
            _fail(path, "overrides", f"expected a mapping of names to lists of KEY=VALUE strings, got {sets!r}")
        override_axis = []
        for name, items in sets.items():
            items = [] if items is None else items
            if not isinstance(items, list) or not all(isinstance(x, str) and "=" in x for x in items):
                _fail(path, f"overrides.{name}", f"expected a list of KEY=VALUE strings (as for --set), got {items!r}")
            override_axis.append((str(name), tuple(items)))

    sweeps = data.get("set") or {}
    if not isinstance(sweeps, dict):
        _fail(path, "set", f"expected a mapping of document paths to lists of values, got {sweeps!r}")
    sweep_axes = []
    for key, values in sweeps.items():
        if not isinstance(values, list) or not values:
            _fail(path, f"set.{key}", f"expected a non-empty list of values, got {values!r}")
        sweep_axes.append([(str(key), v) for v in values])

    fps_axis = _number_list(path, data, "fps", integer=False, positive=True)
    seed_axis = _number_list(path, data, "seeds", integer=True, positive=False)

    outputs = data.get("outputs") or {}
    if not isinstance(outputs, dict) or any(k not in ("rrd", "bake") for k in outputs):
        _fail(path, "outputs", f"expected a mapping with rrd (true/false) and bake ({'|'.join(BAKE_FORMATS)} or null), "
                               f"got {outputs!r}")
    rrd = outputs.get("rrd", False)
    if not isinstance(rrd, bool):
        _fail(path, "outputs.rrd", f"expected true or false, got {rrd!r}")
    bake = outputs.get("bake")
    if bake is not None and bake not in BAKE_FORMATS:
        _fail(path, "outputs.bake", f"expected one of {', '.join(BAKE_FORMATS)} or null, got {bake!r}")

    plot = data.get("plot") or {}
    if not isinstance(plot, dict) or any(k not in ("metric", "cost") for k in plot):
        _fail(path, "plot", f"expected a mapping with metric and cost column names, got {plot!r}")
    from magica_py.batch.table import METRIC_COLUMNS

    for key, default in (("metric", "max_stretch"), ("cost", "ms_per_sim_second")):
        if plot.get(key, default) not in METRIC_COLUMNS:
            _fail(path, f"plot.{key}", f"expected one of {', '.join(METRIC_COLUMNS)}, got {plot[key]!r}")

    digests = {s: _file_digest(s) for s in scenes}
    jobs, seen = [], set()
    for scene, (clip, clip_set), (oname, oset), sweep, fps, seed in itertools.product(
            scenes, clip_axis, override_axis, itertools.product(*sweep_axes), fps_axis, seed_axis):
        overrides = list(oset) + [f"{k}={_format(v)}" for k, v in sweep]
        if clip_set is not None:
            overrides.append(clip_set)
        if fps is not None:
            overrides.append(f"scene.fps={_format(fps)}")
        if seed is not None:
            overrides.append(f"scene.seed={seed}")
        jid = job_id(scene, digests[scene], overrides, frames, rrd, bake)
        if jid in seen:
            continue
        seen.add(jid)
        labels = {"scene": scene.stem, "clip": clip, "override": oname, "fps": fps, "seed": seed}
        labels.update({f"set.{k}": _format(v) for k, v in sweep})
        jobs.append(Job(jid, str(scene), tuple(overrides), frames, labels, rrd, bake, digests[scene]))
    return JobFile(path, str(data.get("name") or path.stem), jobs, plot.get("metric", "max_stretch"),
                   plot.get("cost", "ms_per_sim_second"))
