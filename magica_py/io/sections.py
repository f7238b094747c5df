"""What the scene loader calls: imported files as YAML-shaped scene sections.

The config loader owns the YAML; these functions turn the file-referencing entries

    rigs:      - {name: avatar, file: Godette_vrm_v4.vrm}
    animation: - {target: avatar, clip: cmu_01_01.bvh, retarget: {source_rest: 0}}
               - {target: fox, clip: "Fox.glb#Run", drop: ["b_Tail*"]}
    cloths:    - {from_vrm: avatar, group_by: group}

into the plain sections the rest of the loader already understands: a rig dict with
explicit ``bones`` (name, parent, position, rotation xyzw, scale — Unity convention,
metres), ``colliders`` and ``cloths`` entries, and animation either as a ``Clip`` (for
``clip.ClipDriver``, the efficient path) or as YAML keyframe entries.
"""
from __future__ import annotations

import warnings
from pathlib import Path

from magica_py.io.bvh import load_bvh
from magica_py.io.clip import Clip
from magica_py.io.errors import AssetError
from magica_py.io.gltf import load_gltf, read_document
from magica_py.io.retarget import RetargetError, retarget_with_report
from magica_py.io.vrm import load_vrm
from magica_py.scene.hierarchy import BoneSpec

GLTF_SUFFIXES = (".gltf", ".glb", ".vrm")


def bone_entries(bones: list[BoneSpec]) -> list[dict]:
    return [{"name": b.name, "parent": b.parent, "position": [float(x) + 0.0 for x in b.position],
             "rotation": [float(x) + 0.0 for x in b.rotation], "scale": [float(x) + 0.0 for x in b.scale]}
            for b in bones]


def is_vrm(path) -> bool:
    path = Path(path)
    if path.suffix.lower() == ".vrm":
        return True
    if path.suffix.lower() not in GLTF_SUFFIXES:
        return False
    ext = read_document(path)[0].extensions or {}
    return any(k in ext for k in ("VRM", "VRMC_vrm", "VRMC_springBone"))


def load_rig(path, *, prefix: str = "", unit_scale: float = 1.0):
    """The importer result for a rig file: ``VrmAvatar``, ``GltfRig`` or ``BvhAnimation``.

    For a BVH, ``unit_scale`` 1.0 means automatic units (``load_bvh(units="auto")``); any
    other value is metres per file unit."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".bvh":
        return load_bvh(path, prefix=prefix, units="auto" if unit_scale == 1.0 else unit_scale)
    if suffix not in GLTF_SUFFIXES:
        raise AssetError(path, "", f"unknown rig file type {suffix!r}; expected .gltf, .glb, .vrm or .bvh")
    if is_vrm(path):
        return load_vrm(path, prefix=prefix, unit_scale=unit_scale)
    return load_gltf(path, prefix=prefix, unit_scale=unit_scale)


def rig_section(path, *, name: str | None = None, prefix: str = "", unit_scale: float = 1.0) -> dict:
    """``rigs: - file: ...`` → ``{"name", "bones": [...], "joints": [...], "humanoid": {...}}``.

    ``joints`` lists skin joints (glTF); ``humanoid`` maps VRM humanoid names to bones (VRM).
    VRM synthetic nodes (virtual tails, collider frames) are included in ``bones``.
    """
    with warnings.catch_warnings():  # collider quirks concern the cloths: vrm_sections reports them
        warnings.simplefilter("ignore", UserWarning)
        result = load_rig(path, prefix=prefix, unit_scale=unit_scale)
    section = {"name": name or Path(path).stem, "bones": bone_entries(result.bones)}
    rig = getattr(result, "rig", result)
    section["joints"] = sorted(getattr(rig, "joints", set()))
    section["humanoid"] = dict(getattr(result, "humanoid", {}))
    return section


def vrm_sections(path, *, group_by: str = "group", prefix: str = "", cloth_prefix: str = "vrm_",
                 oversized_colliders: str = "keep", chains=None) -> dict:
    """``cloths: - from_vrm: ...`` → ``{"colliders": [...], "cloths": [...], "warnings", "skipped"}``.

    ``chains``: optional list of chain / group names (globs not supported) to keep.
    """
    avatar = load_vrm(path, prefix=prefix, oversized_colliders=oversized_colliders)
    cloths = avatar.cloth_entries(group_by=group_by, prefix=cloth_prefix)
    if not cloths:
        warnings.warn(f"{path}: the VRM has no spring bones (VRM 0.x secondaryAnimation.boneGroups, VRM 1.0 "
                      "VRMC_springBone.springs): it adds no cloth", UserWarning, stacklevel=2)
    if chains is not None:
        wanted = {f"{cloth_prefix}{c}" for c in chains}
        unknown = wanted - {c["name"] for c in cloths}
        if unknown:
            raise AssetError(path, "secondary animation", f"no chain named {sorted(unknown)}; "
                             f"chains: {[c['name'] for c in cloths]}")
        cloths = [c for c in cloths if c["name"] in wanted]
    used = {n for c in cloths for n in c["colliders"]}
    return {"colliders": [c for c in avatar.collider_entries() if c["name"] in used], "cloths": cloths,
            "warnings": list(avatar.warnings), "skipped": list(avatar.skipped)}


def split_clip_reference(ref: str) -> tuple[str, str | None]:
    """``"Fox.glb#Run"`` → (``"Fox.glb"``, ``"Run"``); ``"walk.bvh"`` → (``"walk.bvh"``, None)."""
    file, _, clip = str(ref).partition("#")
    return file, (clip or None)


def load_clip(ref, *, base_dir=".", retarget_to: list[BoneSpec] | None = None, target_map="auto",
              retarget_options: dict | None = None, drop=(), prefix: str = "", unit_scale=None,
              units="auto", target_bones: list[BoneSpec] | None = None, trim=None, trim_frames=None,
              rate: float | None = None, report: list | None = None) -> Clip:
    """``animation: - clip: ...`` → a ``Clip`` targeting the scene's bone names.

    * ``file.glb#Name`` (also .gltf / .vrm): that glTF animation (the only one if ``#Name``
      is omitted and the file has exactly one); ``unit_scale`` as for the rig.
    * ``file.bvh``: the BVH clip (``units`` as in ``load_bvh``).
    * Without ``retarget_to`` the clip drives bones named as in its own file, plus
      ``prefix`` (the rig's prefix: the clip plays on the rig loaded from the same file).
    * With ``retarget_to`` (the target rig's BoneSpecs) it is retargeted by humanoid names:
      ``target_map`` (a scheme or the rig's humanoid dict) and ``retarget_options``
      (source_map, source_overrides, target_overrides, source_rest, source_forward,
      source_up, root_translation, same_names, align_rest, rate); the result targets
      ``retarget_to``'s names. ``source_forward`` / ``source_up`` are axes of the source
      *file* (``"+X"``, ``"-Z"``, ... or a vector, right-handed as written in the BVH /
      glTF), converted like the file's own coordinates. A rest frame named by
      ``source_rest`` (and the frames before it: a T-pose lead-in) is not played.
      ``report``: a list the ``RetargetReport`` is appended to.
    * ``drop``: globs of bones whose channels are removed (bones the cloth simulates),
      matched against the final names.
    * ``trim``: ``[start, end]`` seconds of the source clip to keep, or ``trim_frames``:
      ``[first, last]`` frames of the source (inclusive; BVH frames, glTF key times); both
      re-timed from 0 and applied after retargeting, so ``source_rest`` frames count from
      the source's first frame; ``rate``: resample every track linearly at that rate (Hz),
      e.g. 30 to shrink a 120 Hz capture before turning it into YAML keyframe entries.
    * ``target_bones`` is the former name of ``retarget_to`` (kept for callers).
    """
    if retarget_to is None:
        retarget_to = target_bones
    file, clip_name = split_clip_reference(ref)
    path = Path(base_dir) / file
    options = dict(retarget_options or {})
    mirror = "x"
    if path.suffix.lower() == ".bvh":
        anim = load_bvh(path, units=units if unit_scale is None else unit_scale)
        if anim.frame_count == 0:
            raise AssetError(path, "MOTION", "Frames: 0: the file has a skeleton but no motion; "
                             "a clip needs at least one frame")
        source_bones, clip = anim.bones, anim.clip
    else:
        mirror = "z" if _is_vrm0(path) else "x"
        rig = load_gltf(path, unit_scale=1.0 if unit_scale is None else unit_scale, mirror_axis=mirror)
        if clip_name is None:
            if len(rig.clips) != 1:
                raise AssetError(path, "animations", f"name the clip with {file}#<name>; the file has {sorted(rig.clips) or 'none'}")
            clip = next(iter(rig.clips.values()))
        else:
            clip = rig.clip(clip_name)
        source_bones = rig.bones
    if trim is not None and trim_frames is not None:
        raise ValueError(f"{ref}: give trim (seconds) or trim_frames, not both")
    if trim is not None and not (isinstance(trim, (list, tuple)) and len(trim) == 2):
        raise ValueError(f"{ref}: trim must be [start, end] in seconds, got {trim!r}")
    if trim_frames is not None:
        if not (isinstance(trim_frames, (list, tuple)) and len(trim_frames) == 2):
            raise ValueError(f"{ref}: trim_frames must be [first, last] frames, got {trim_frames!r}")
        trim = clip.frame_span(int(trim_frames[0]), None if trim_frames[1] is None else int(trim_frames[1]))
    # retarget the whole clip first: ``source_rest: <frame>`` names a frame of the source
    # (CMU captures start with a T-pose at frame 0, outside most trims)
    rest_frame = options.get("source_rest")
    if retarget_to is not None:
        for key in ("source_forward", "source_up"):
            if options.get(key) is not None:
                options[key] = file_axis_to_project(options[key], mirror)
        try:
            clip, found = retarget_with_report(clip, source_bones, retarget_to, target_map=target_map, **options)
        except RetargetError as exc:   # the skeletons do not match: say which file's
            raise RetargetError(f"{path}: {exc}") from None
        if report is not None:
            report.append(found)
    elif prefix:
        clip = clip.renamed({n: prefix + n for n in clip.nodes()})
    if isinstance(rest_frame, int) and not isinstance(rest_frame, bool) and retarget_to is not None:
        # the rest frame (a T-pose lead-in) is not played: the clip starts after it
        after = float(clip.frame_times()[min(rest_frame + 1, len(clip.frame_times()) - 1)])
        start, end = (0.0, None) if trim is None else (float(trim[0]), None if trim[1] is None else float(trim[1]))
        if start < after:
            if end is not None and end <= after:
                raise ValueError(f"{ref}: the trim [{start:g}, {end:g}] s ends before the first frame after the "
                                 f"rest frame {rest_frame} ({after:g} s)")
            trim = (after, end)
            if end is None and after >= clip.duration:
                # one frame follows the rest frame (a T-pose and one pose): the clip is that pose
                clip, trim = clip.pose_at(after), None
    if trim is not None:
        clip = clip.trimmed(float(trim[0]), None if trim[1] is None else float(trim[1]))
    if rate is not None:
        clip = clip.resampled(float(rate))
    if drop:
        clip = clip.without(drop)
    return clip


def file_axis_to_project(value, mirror: str = "x"):
    """A direction written in a source file's own axes (``"+X"``, ``"-z"``, ``"Y"`` or three
    numbers; right-handed, as the BVH / glTF stores it) in project (Unity) axes."""
    from magica_py.io import coords
    from magica_py.io.body_frame import AXIS_NAMES

    if isinstance(value, str):
        key = value.strip().upper()
        key = key if key[:1] in "+-" else "+" + key
        if key not in AXIS_NAMES:
            raise ValueError(f"expected an axis +X, -X, +Y, -Y, +Z, -Z or a vector [x, y, z], got {value!r}")
        vector = AXIS_NAMES[key]
    else:
        try:
            vector = [float(x) for x in value]
        except (TypeError, ValueError):
            vector = []
        if len(vector) != 3 or sum(x * x for x in vector) < 1e-12:
            raise ValueError(f"expected an axis +X, -X, +Y, -Y, +Z, -Z or a non-zero vector [x, y, z], got {value!r}")
    return coords.position_to_unity(vector, mirror)


def _is_vrm0(path: Path) -> bool:
    ext = read_document(path)[0].extensions or {}
    return "VRM" in ext and "VRMC_vrm" not in ext
