"""``magica-py run AVATAR.vrm``: the scene a VRM avatar runs in when no YAML was written.

``avatar_scene_text(vrm, clip=None, base_dir=...)`` returns a commented scene document
(docs/scene-format.md) with

* the avatar as a rig read from its file (``rigs: - {name, file}``);
* its VRM spring bones as bone cloths with their colliders (``cloths: - {from_vrm: ...}``,
  one cloth per spring-bone group, parameters mapped from the file: docs/import.md §3);
* either the clip, retargeted onto the avatar by humanoid bone names
  (``animation: - {clip, rig, retarget}``, a BVH or ``FILE.glb#Name``), or a gentle default
  motion when there is none: the hips sway from side to side and turn, the head turns and
  nods (``oscillate`` drivers on the avatar's humanoid ``hips`` and ``head`` bones), so the
  spring bones have something to follow.

The CLI loads this text like any scene (every check applies) and ``--save-scene FILE.yaml``
writes it, with asset paths relative to the saved file, so a user can continue from it.
"""
from __future__ import annotations

import os
import pathlib

import yaml

DEFAULT_DURATION = 10.0   # s: long enough to see the spring bones settle and swing
CLIP_DURATION_CAP = 30.0  # s: a 20-minute capture is not run whole by default
VRM_SUFFIXES = (".vrm",)
SAVED_SCENE_MARK = "written by `magica-py run ... --save-scene`"  # --save-scene may replace such a file


def is_vrm_file(path) -> bool:
    """A ``.vrm`` file name, or a GLB container whose JSON declares a VRM extension."""
    p = pathlib.Path(path)
    if p.suffix.lower() in VRM_SUFFIXES:
        return True
    if p.suffix.lower() != ".glb" or not p.is_file():
        return False
    with open(p, "rb") as fh:
        head = fh.read(65536)
    return head[:4] == b"glTF" and (b'"VRM"' in head or b'"VRMC_vrm"' in head)


def _relative(path: pathlib.Path, base_dir: pathlib.Path) -> str:
    """``path`` relative to ``base_dir`` when they share a drive, else absolute (POSIX form)."""
    try:
        return pathlib.Path(os.path.relpath(path.resolve(), base_dir.resolve())).as_posix()
    except ValueError:  # another drive (Windows)
        return path.resolve().as_posix()


def _humanoid_bones(vrm: pathlib.Path) -> dict[str, str]:
    """The avatar's humanoid map (``hips`` -> node name ...), as the rig loader names nodes."""
    from magica_py.io.sections import rig_section

    return dict(rig_section(vrm, name="avatar").get("humanoid") or {})


def _clip_seconds(ref: str, base_dir: pathlib.Path) -> float | None:
    """Length of a clip in seconds (read without retargeting), None when it cannot be read:
    the scene's own validation then reports the problem at ``animation[0].clip``."""
    from magica_py.io.sections import load_clip

    try:
        return float(load_clip(ref, base_dir=base_dir).duration)
    except (ValueError, OSError, KeyError, ImportError):
        return None


def default_motion(humanoid: dict[str, str]) -> list[dict]:
    """Oscillate drivers on the hips and head: a 4 cm sway at 0.5 Hz, a 20 degree turn of the
    hips at 0.2 Hz, a 30 degree turn of the head at 0.25 Hz and a 10 degree nod at 0.6 Hz.
    Additive on the rest pose (VRM bones face +Z with local +Y up after import)."""
    entries = []
    hips, head = humanoid.get("hips"), humanoid.get("head") or humanoid.get("neck")
    if hips:
        entries.append({"target": hips, "oscillate": {"property": "position", "axis": [1, 0, 0],
                                                      "amplitude": 0.04, "frequency": 0.5}})
        entries.append({"target": hips, "oscillate": {"property": "rotation", "axis": [0, 1, 0],
                                                      "amplitude": 20, "frequency": 0.2}})
    if head:
        entries.append({"target": head, "oscillate": {"property": "rotation", "axis": [0, 1, 0],
                                                      "amplitude": 30, "frequency": 0.25, "phase": 90}})
        entries.append({"target": head, "oscillate": {"property": "rotation", "axis": [1, 0, 0],
                                                      "amplitude": 10, "frequency": 0.6}})
    return entries


def clip_entry(ref: str, rig: str) -> dict:
    """``animation`` entry of a clip retargeted onto rig ``rig``. A BVH capture is retargeted
    with its first frame as the rest pose (motion captures such as CMU's start in a T-pose;
    their bind pose has the hips on the floor): docs/import.md §5."""
    retarget = {"source_rest": 0} if ref.split("#", 1)[0].lower().endswith(".bvh") else {}
    return {"clip": ref, "rig": rig, "retarget": retarget, "loop": True}


def avatar_scene(vrm, clip: str | None = None, base_dir=None) -> tuple[dict, dict]:
    """(scene document as plain data, facts for the header comment) for ``vrm``.

    Paths in the document are relative to ``base_dir`` (the folder the scene is loaded from or
    saved in; default: the current folder)."""
    vrm = pathlib.Path(vrm)
    base = pathlib.Path(base_dir) if base_dir is not None else pathlib.Path.cwd()
    name = vrm.stem
    rig = "avatar"
    facts = {"vrm": str(vrm), "clip": clip}
    if clip:
        file, _, anim = clip.partition("#")
        ref = _relative(pathlib.Path(file), base) + (f"#{anim}" if anim else "")
        seconds = _clip_seconds(ref, base)
        duration = min(seconds, CLIP_DURATION_CAP) if seconds else DEFAULT_DURATION
        animation = [clip_entry(ref, rig)]
        facts["motion"] = f"the clip {clip}, retargeted by humanoid bone names"
    else:
        humanoid = _humanoid_bones(vrm)
        animation = default_motion(humanoid)
        duration = DEFAULT_DURATION
        facts["motion"] = ("a gentle default motion (hips sway and turn, head turns and nods)" if animation
                           else "no motion: the file has no humanoid hips or head bone")
    doc = {
        "version": 1,
        "scene": {"name": name, "fps": 60, "duration": round(float(duration), 3), "simulation_frequency": 90,
                  "max_steps_per_frame": 3},
        "rigs": [{"name": rig, "file": _relative(vrm, base)}],
        "animation": animation,
        "cloths": [{"from_vrm": rig, "group_by": "group", "oversized_colliders": "keep"}],
        "output": {"rrd": f"replays/{name}.rrd"},
    }
    return doc, facts


def avatar_scene_text(vrm, clip: str | None = None, base_dir=None) -> str:
    """The scene of ``avatar_scene`` as commented YAML (what ``--save-scene`` writes)."""
    doc, facts = avatar_scene(vrm, clip, base_dir)
    header = [
        f"# Scene for the VRM avatar {facts['vrm']}, {SAVED_SCENE_MARK}.",
        "# Its spring bones are simulated as bone cloths (one per spring-bone group, parameters",
        "# mapped from the file: docs/import.md), with the file's colliders; motion: " + facts["motion"] + ".",
        "# Edit and run:  magica-py run THIS.yaml   or keep it running:  magica-py watch THIS.yaml",
        "# Format: docs/scene-format.md; cloth parameters: docs/parameters.md. Add parameter",
        "# overrides to every generated cloth under cloths[0].parameters, e.g. {damping: 0.2}.",
    ]
    body = yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=100)
    return "\n".join(header) + "\n" + body
