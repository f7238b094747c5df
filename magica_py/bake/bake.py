"""Bake a scene: which file each rig came from, which writer, and the whole run.

``bake_scene(scene_path, out, ...)`` loads the scene, runs it with a ``PoseCapture``
attached and writes ``out``; ``bake_capture(scene, motion, out, ...)`` writes an existing
capture (a batch job captures during its own instrumented run).
"""
from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from magica_py.bake.capture import CapturedMotion, select_bones, simulate_and_capture

GLTF_OUTPUTS = (".glb", ".gltf", ".vrm")
OUTPUTS = GLTF_OUTPUTS + (".bvh",)
BVH_UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "inch": 0.0254, "cmu": 0.0254 / 0.45}


class BakeError(ValueError):
    """A bake that cannot be written as asked (printed without a traceback, exit 2)."""


@dataclass
class FileRig:
    """A rig of the scene loaded from a file (``rigs: - file: ...``), as imported."""

    name: str
    path: Path
    kind: str                          # "gltf" | "vrm" | "bvh"
    prefix: str
    unit_scale: float                  # metres per file unit, as the importer used it
    mirror_axis: str
    node_of: dict[str, int]            # bone name -> glTF node index (glTF / VRM)
    names: frozenset = frozenset()     # the bone names the file brought (glTF nodes, BVH joints)
    instances: int = 1


@dataclass
class BakeResult:
    out: Path
    motion: CapturedMotion
    bytes: int
    load_seconds: float                # s, scene load and build of the rigs' file info
    simulate_seconds: float            # s, the frame loop (solver and capture)
    write_seconds: float
    notes: list[str] = field(default_factory=list)
    compile_seconds: float = 0.0       # s, numba compiles (first run only), left out of the three above


def file_rigs(scene) -> dict[str, FileRig]:
    """The scene's rigs loaded from files, from the scene text as run (``--set`` applied):
    rig name -> ``FileRig`` (importer conventions: mirror axis, unit scale, node names)."""
    import yaml

    from magica_py.io.bvh import BvhAnimation
    from magica_py.io.sections import load_rig

    if not scene.source_text:
        return {}
    data = yaml.safe_load(scene.source_text) or {}
    base = Path(scene.source).resolve().parent if scene.source else Path.cwd()
    instances = {r.name: r.instances for r in scene.rigs}
    out = {}
    for entry in data.get("rigs") or []:
        if not isinstance(entry, dict) or not entry.get("file"):
            continue
        path = Path(os.path.normpath(base / entry["file"]))
        prefix = entry.get("prefix") or ""
        unit_scale = float(entry.get("unit_scale", 1.0))
        with warnings.catch_warnings():   # collider quirks concern the cloths: the scene load reported them
            warnings.simplefilter("ignore", UserWarning)
            imported = load_rig(path, prefix=prefix, unit_scale=unit_scale)
        name = entry.get("name") or path.stem
        if isinstance(imported, BvhAnimation):
            out[name] = FileRig(name, path, "bvh", prefix, imported.unit_scale, "x", {},
                                frozenset(b.name for b in imported.bones), instances.get(name, 1))
            continue
        rig = getattr(imported, "rig", imported)
        kind = "vrm" if rig is not imported else "gltf"
        node_of = {n: i for i, n in enumerate(rig.names) if n is not None}
        out[name] = FileRig(name, path, kind, prefix, rig.unit_scale, rig.mirror_axis, node_of,
                            frozenset(b.name for b in imported.bones), instances.get(name, 1))
    return out


def _file_rig_of_bone(scene, rigs: dict[str, FileRig]) -> dict[int, str]:
    """Hierarchy index -> name of the file rig the bone came from, or that its nearest
    ancestor came from (bones a scene hangs under an imported bone); generated bones are
    left out. Instance copies (``name#3``) count as their rig's."""
    h = scene.hierarchy
    by_name = {}
    for rig in rigs.values():
        for n in rig.names:
            by_name.setdefault(n, rig.name)
    owner: dict[int, str] = {}
    for i in range(h.count):                      # parents before children
        rig = by_name.get(h.names[i].split("#", 1)[0])
        if rig is None and h.parent[i] >= 0:
            rig = owner.get(int(h.parent[i]))
        if rig is not None:
            owner[i] = rig
    return owner


def _with_ancestors(scene, bones: list[int], needed) -> list[int]:
    """``bones`` plus every ancestor for which ``needed(index)`` holds, parents first."""
    parent = scene.hierarchy.parent
    chosen = set(bones)
    for i in bones:
        p = int(parent[i])
        while p >= 0 and p not in chosen and needed(p):
            chosen.add(p)
            p = int(parent[p])
    return sorted(chosen)


def resolve_units(units) -> float:
    if units is None:
        return None
    if isinstance(units, str) and units in BVH_UNITS:
        return BVH_UNITS[units]
    try:
        value = float(units)
    except (TypeError, ValueError):
        raise BakeError(f"--units: expected one of {', '.join(BVH_UNITS)} or metres per file unit, got {units!r}") from None
    if not (value > 0 and math.isfinite(value)):
        raise BakeError(f"--units: expected a positive number of metres per file unit, got {units!r}")
    return value


def check_output(out) -> Path:
    out = Path(out)
    if out.suffix.lower() not in OUTPUTS:
        raise BakeError(f"--out {str(out)!r}: expected a file ending in {', '.join(OUTPUTS)}")
    if out.is_dir():
        raise BakeError(f"--out {str(out)!r} is a folder; give a file name")
    if not out.parent.exists():
        raise BakeError(f"--out {str(out)!r}: the folder {str(out.parent)!r} does not exist")
    if not out.parent.is_dir():
        raise BakeError(f"--out {str(out)!r}: {str(out.parent)!r} is not a folder")
    if not os.access(out.parent, os.W_OK):
        raise BakeError(f"--out {str(out)!r}: the folder {str(out.parent)!r} is not writable")
    return out


def plan_bones(scene, out, patterns=None, rig: str | None = None, rigs: dict | None = None):
    """The bones to capture for ``out`` and the file rig whose copy a glTF output is
    (None for BVH or a new glTF file): ``(bones, file_rig)``."""
    out = Path(out)
    rigs = file_rigs(scene) if rigs is None else rigs
    try:
        bones = select_bones(scene, patterns)
    except ValueError as exc:
        raise BakeError(str(exc)) from None
    if not bones:
        raise BakeError("the scene has no rig bones to bake")
    owner = _file_rig_of_bone(scene, rigs)
    if out.suffix.lower() == ".bvh":
        return _with_ancestors(scene, bones, lambda i: True), None
    used = [name for name in dict.fromkeys(owner.get(i) for i in bones)
            if name in rigs and rigs[name].kind in ("gltf", "vrm")]
    if rig is not None:
        if rig not in rigs or rigs[rig].kind not in ("gltf", "vrm"):
            known = [n for n, r in rigs.items() if r.kind in ("gltf", "vrm")]
            raise BakeError(f"--rig {rig!r}: not a rig loaded from a glTF / GLB / VRM file "
                            f"(those of the scene: {', '.join(known) or 'none'})")
        source = rigs[rig]
    elif len(used) > 1:
        raise BakeError(f"the bones to bake come from {len(used)} glTF / VRM files ({', '.join(used)}); "
                        "a glTF output is a copy of one of them: choose it with --rig NAME")
    else:
        source = rigs[used[0]] if used else None
    if source is not None and source.instances > 1:
        raise BakeError(f"rig {source.name!r} has {source.instances} instances and a copy of its file holds one "
                        "skeleton; write a .bvh (every instance as its own root)")
    if out.suffix.lower() == ".vrm" and (source is None or source.kind != "vrm"):
        raise BakeError(f"--out {str(out)!r}: a .vrm output is a copy of a VRM rig and the scene's bones to bake "
                        "come from none; write a .glb or .gltf")
    in_file = set() if source is None else set(source.node_of)
    names = scene.hierarchy.names
    return _with_ancestors(scene, bones, lambda i: names[i] not in in_file), source


def bake_capture(scene, motion: CapturedMotion, out, source: FileRig | None = None, rigs: dict | None = None,
                 units=None, animation_name: str | None = None) -> list[str]:
    """Write ``motion`` of ``scene`` to ``out`` (format from the extension); returns notes."""
    from magica_py.bake.bvh_writer import write_bvh
    from magica_py.bake.gltf_writer import write_gltf

    out = Path(out)
    if out.suffix.lower() == ".bvh":
        rigs = file_rigs(scene) if rigs is None else rigs
        scale = resolve_units(units)
        if scale is None:
            owner = _file_rig_of_bone(scene, rigs)
            bvh = [rigs[n] for n in dict.fromkeys(owner.get(int(i)) for i in motion.bones)
                   if n in rigs and rigs[n].kind == "bvh"]
            scale = bvh[0].unit_scale if len(bvh) == 1 else 1.0
        return write_bvh(out, motion, unit_scale=scale, mirror_axis="x")
    if units is not None:
        raise BakeError("--units applies to a .bvh output; a glTF copy keeps its file's unit scale")
    name = animation_name or f"{scene.name}_baked"
    if source is None:
        return write_gltf(out, motion, animation_name=name)
    return write_gltf(out, motion, source=source.path, node_of=source.node_of, unit_scale=source.unit_scale,
                      mirror_axis=source.mirror_axis, animation_name=name)


def bake_scene(scene_path, out, overrides=(), bones=None, frames: int | None = None, rig: str | None = None,
               units=None, animation_name: str | None = None, progress=None, compile_watch=None) -> BakeResult:
    """Load, simulate and bake ``scene_path`` to ``out`` (see the package docstring). With
    ``compile_watch`` (a ``runner.CompileWatch`` around the call) the result's load, simulate
    and write times leave out the compiles, reported apart as ``compile_seconds``."""
    from magica_py.config import load_scene
    from magica_py.runner import Stopwatch

    out = check_output(out)
    if units is not None and out.suffix.lower() != ".bvh":
        raise BakeError("--units applies to a .bvh output; a glTF copy keeps its file's unit scale")
    with Stopwatch(compile_watch) as whole:
        with Stopwatch(compile_watch) as loading:
            scene = load_scene(scene_path, overrides)
            count = frames if frames is not None else scene.settings.frame_count()
            if count is None:
                raise BakeError("the scene runs on the wall clock for a duration: give --frames N to bake it")
            rigs = file_rigs(scene)
            chosen, source = plan_bones(scene, out, bones, rig, rigs)
        motion = simulate_and_capture(scene, chosen, count, progress, compile_watch)
        with Stopwatch(compile_watch) as writing:
            try:
                notes = bake_capture(scene, motion, out, source, rigs, units, animation_name)
            except OSError as exc:   # written whole or not at all (atomic): nothing is left behind
                raise BakeError(f"--out {str(out)!r}: cannot write the file ({exc.strerror or exc})") from None
    size = out.stat().st_size + (out.with_suffix(".bin").stat().st_size if out.suffix.lower() == ".gltf" else 0)
    return BakeResult(out, motion, size, loading.seconds, motion.wall_time, writing.seconds, notes, whole.compiled)


def pose_error(motion: CapturedMotion, position: np.ndarray, rotation: np.ndarray) -> tuple[float, float]:
    """Largest position (m) and rotation (rad) difference between ``motion`` and poses
    (F, B, 3) / (F, B, 4) read back from a baked file (q and -q are the same rotation)."""
    from magica_py.io.quat import qconj, qmul

    dp = float(np.abs(position - motion.local_position).max(initial=0.0))
    rel = qmul(qconj(motion.local_rotation), rotation)
    angle = 2.0 * np.arctan2(np.linalg.norm(rel[..., :3], axis=-1), np.abs(rel[..., 3]))
    return dp, float(angle.max(initial=0.0))
