"""Scene entries that reference asset files, expanded through ``magica_py.io.sections``.

Three entry forms (paths are relative to the scene file's folder):

* ``rigs: - {name: fox, file: Fox.glb, prefix: "", unit_scale: 1.0}``: the file's node
  hierarchy becomes the rig's explicit bones (``io.sections.rig_section``; glTF, GLB, VRM,
  BVH); ``bones`` and ``parts`` may add more bones (e.g. a chain under an imported bone).
  The rig remembers its file, prefix, unit scale and (VRM) humanoid map for the entries
  below;
* ``animation: - {clip: "Fox.glb#Run", rig: fox, loop: true, drop: ["b_Tail*"],
  retarget: {...}, trim: [start, end], rate: 30, start, end, phase_offset, fade}``: the clip
  as keyframe drivers (``io.sections.load_clip`` + ``Clip.to_animation_entries``). ``rig``
  names the rig whose bones the clip drives. Without ``retarget`` the clip plays on that
  rig's own bones: its prefix and **unit scale** are applied (a centimetre Fox loaded with
  ``unit_scale: 0.01`` needs its clip scaled alike). With ``retarget`` the clip is
  retargeted onto the rig's skeleton by humanoid names, with the rig's own humanoid map
  (VRM) or the automatic one. ``trim`` keeps seconds [start, end] of the source (after
  retargeting, so ``source_rest: 0`` still names the capture's first frame) and ``rate``
  resamples to that many keys per second: a 120 Hz capture of 23 s is 2752 keys per channel,
  slow to load as YAML keyframes. ``drop`` removes the channels of bones the cloth
  simulates. Tracks of the rig's root bones are composed with the rig's placement
  (``position`` / ``rotation``), so a placed rig keeps its place when its root is animated;
* ``cloths: - {from_vrm: avatar, group_by: group, chains: [...], prefix: vrm_,
  oversized_colliders: keep, parameters: {...}}``: the VRM spring bones of rig ``avatar``
  (loaded from a .vrm file) as cloths and their colliders (``io.sections.vrm_sections``);
  ``parameters`` override the mapped VRM values in every generated cloth (a problem is
  reported at ``cloths[i].parameters...``).

Generated entries go through the same checks as written ones; problems are reported at the
path of the entry that generated them. An importer error (``io.errors.AssetError``) is an
issue at that entry's ``file`` / ``clip`` / ``from_vrm`` key.
"""
from __future__ import annotations

import math

import contextvars
import os
import pathlib
import warnings

from magica_py.config.checker import NON_NEGATIVE, POSITIVE, Checker, Range

RIG_FILE_KEYS = ("file", "prefix", "unit_scale")
# m per file unit: millimetres to kilometres and far beyond; 1e300 made the clips' keys overflow
UNIT_SCALE = Range(0.0, 1e6, low_open=True)
CLIP_KEYS = ("clip", "rig", "loop", "drop", "retarget", "trim", "trim_frames", "rate", "start", "end",
             "phase_offset", "fade")
RETARGET_KEYS = ("source_map", "target_map", "source_overrides", "target_overrides", "source_rest",
                 "source_forward", "source_up", "root_translation", "same_names", "align_rest", "rate")
VRM_KEYS = ("from_vrm", "group_by", "chains", "prefix", "oversized_colliders", "parameters")
CLIP_RATE = Range(1.0, 1000.0)  # keys per second after resampling
# ``magica-py retarget-check`` sets a list here: each retargeted clip appends (path, RetargetReport)
RETARGET_REPORTS: contextvars.ContextVar[list | None] = contextvars.ContextVar("retarget_reports", default=None)


def base_dir(c: Checker) -> pathlib.Path:
    """Folder that asset paths are relative to: the scene file's, else the current one."""
    source = c.doc.source
    if source and not source.startswith("<"):
        return pathlib.Path(source).resolve().parent
    return pathlib.Path.cwd()


def asset_path(c: Checker, file: str) -> pathlib.Path:
    """An asset path relative to the scene file's folder, normalised for messages."""
    return pathlib.Path(os.path.normpath(base_dir(c) / file))


def _asset_error(c: Checker, path: tuple, exc: Exception) -> None:
    c.error(path, f"cannot import: {exc}")


def import_rig(c: Checker, m: dict, path: tuple) -> dict | None:
    """``rigs[i].file`` → ``{"bones": [...], "humanoid": {...}, "unit_scale": s, "prefix": p}``
    (None after reporting a problem). Bones are normalized explicit-bone entries."""
    file = c.text(m, "file", path, what="a .gltf, .glb, .vrm or .bvh file path")
    prefix = "" if m.get("prefix") in ("", None) else c.text(m, "prefix", path, "", what="a name prefix")
    unit_scale = c.number(m, "unit_scale", path, 1.0, UNIT_SCALE)
    if file is None:
        return None
    full = asset_path(c, file)
    try:
        from magica_py.io.sections import rig_section

        section = rig_section(full, name=m.get("name"), prefix=prefix, unit_scale=unit_scale)
    except (ImportError, ValueError, OSError, KeyError) as exc:
        _asset_error(c, path + ("file",), exc)
        return None
    where = path + ("file",)
    bones = [{"name": b["name"], "parent": b["parent"], "path": where, "position": tuple(b["position"]),
              "rotation": tuple(b["rotation"]), "scale": tuple(b["scale"])} for b in section["bones"]]
    return {"bones": bones, "humanoid": dict(section.get("humanoid") or {}), "unit_scale": unit_scale,
            "prefix": prefix or ""}


def _trim(c: Checker, m: dict, path: tuple):
    """``trim: [start, end]`` in seconds of the source clip (end may be null: to the end)."""
    if m.get("trim") is None:
        return None
    value = m["trim"]
    where = path + ("trim",)
    if not (isinstance(value, list) and len(value) == 2):
        c.error(where, f"expected [start, end] in seconds of the source clip, got {value!r}")
        return None
    start = c.number({0: value[0]}, 0, where, None, NON_NEGATIVE, units="s")
    end = c.number({1: value[1]}, 1, where, None, POSITIVE, units="s") if value[1] is not None else None
    if start is None:
        return None
    if end is not None and end <= start:
        c.error(where + (1,), f"expected end > start ({start:g} s), got {end:g}")
        return None
    return (start, end)


def _trim_frames(c: Checker, m: dict, path: tuple):
    """``trim_frames: [first, last]``: frames of the source clip (last inclusive, may be null)."""
    if m.get("trim_frames") is None:
        return None
    value = m["trim_frames"]
    where = path + ("trim_frames",)
    if m.get("trim") is not None:
        c.error(where, "give trim (seconds) or trim_frames (frames), not both")
        return None
    ok = isinstance(value, list) and len(value) == 2 and all(
        v is None or (isinstance(v, int) and not isinstance(v, bool) and v >= 0) for v in value) and value[0] is not None
    if not ok:
        c.error(where, f"expected [first, last] frame numbers of the source clip (integers >= 0, last may be "
                       f"null: to the end), got {value!r}")
        return None
    if value[1] is not None and value[1] <= value[0]:
        c.error(where + (1,), f"expected last > first ({value[0]}), got {value[1]}")
        return None
    return (value[0], value[1])


def _axis_option(value) -> bool:
    if isinstance(value, str):
        key = value.strip().upper()
        return (key if key[:1] in "+-" else "+" + key) in ("+X", "-X", "+Y", "-Y", "+Z", "-Z")
    return (isinstance(value, list) and len(value) == 3
            and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in value)
            and sum(float(x) * float(x) for x in value) > 1e-12)


def _retarget_options(c: Checker, value, path: tuple) -> dict | None:
    """The ``retarget:`` mapping checked key by key (None after reporting a problem)."""
    where = path + ("retarget",)
    m = c.mapping(value, where, RETARGET_KEYS, what="a mapping of retarget options")
    if m is None:
        return None
    ok = all(k in RETARGET_KEYS for k in m)       # an unknown key was reported by c.mapping
    rest = m.get("source_rest", "bind")
    if not (rest == "bind" or (isinstance(rest, int) and not isinstance(rest, bool) and rest >= 0)):
        c.error(where + ("source_rest",), f"expected 'bind' or a frame number >= 0 (the source's rest pose), got {rest!r}")
        ok = False
    for key in ("source_forward", "source_up"):
        if m.get(key) is not None and not _axis_option(m[key]):
            c.error(where + (key,), f"expected an axis of the source file (+X, -X, +Y, -Y, +Z, -Z) or a non-zero "
                                    f"vector [x, y, z], got {m[key]!r}")
            ok = False
    if m.get("source_forward") is not None and m.get("source_up") is not None and _axis_option(m["source_forward"]) \
            and _axis_option(m["source_up"]):
        from magica_py.io.sections import file_axis_to_project

        f, u = file_axis_to_project(m["source_forward"]), file_axis_to_project(m["source_up"])
        if abs(float(sum(a * b for a, b in zip(f, u)))) > 0.99 * math.sqrt(float(sum(a * a for a in f) * sum(b * b for b in u))):
            c.error(where + ("source_up",), f"source_up {m['source_up']!r} is parallel to source_forward {m['source_forward']!r}")
            ok = False
    for key in ("root_translation", "same_names", "align_rest"):
        if key in m and not isinstance(m[key], bool):
            c.error(where + (key,), f"expected true or false, got {m[key]!r}")
            ok = False
    if m.get("rate") is not None and c.number(m, "rate", where, None, CLIP_RATE, units="Hz") is None:
        ok = False
    for key in ("source_map", "target_map"):
        v = m.get(key)
        if v is not None and not isinstance(v, (str, dict)):
            c.error(where + (key,), f"expected auto, a scheme name (cmu, mixamo, vrm) or a mapping humanoid: bone, got {v!r}")
            ok = False
    options = dict(m)
    for key in ("source_overrides", "target_overrides"):
        v = m.get(key)
        if v is None:
            continue
        if isinstance(v, str):
            options[key] = str(asset_path(c, v))       # a YAML file next to the scene
        elif not isinstance(v, dict):
            c.error(where + (key,), f"expected a mapping humanoid: bone (null unmaps) or a YAML file path, got {v!r}")
            ok = False
    return options if ok else None


def import_clip_entries(c: Checker, m: dict, path: tuple, rigs: list[dict]) -> list[dict]:
    """Raw (YAML-shaped) keyframe driver entries of an ``animation[i].clip`` entry."""
    m = c.mapping(m, path, CLIP_KEYS)
    if m is None:
        return []
    ref = c.text(m, "clip", path, what="a clip reference: file.glb#Name or file.bvh")
    loop = c.boolean(m, "loop", path, True)
    drop = c.names(m, "drop", path)
    trim = _trim(c, m, path)
    trim_frames = _trim_frames(c, m, path)
    rate = c.number(m, "rate", path, None, CLIP_RATE, units="keys/s")
    retarget = m.get("retarget")
    if retarget is not None:
        retarget = _retarget_options(c, retarget, path)
        if retarget is None:
            return []
    rig = None
    if m.get("rig") is not None:
        name = c.text(m, "rig", path, what="a rig name")
        rig = next((r for r in rigs if r["name"] == name), None)
        if rig is None:
            from magica_py.config.errors import did_you_mean

            c.error(path + ("rig",), f"unknown rig {name!r}{did_you_mean(name, [r['name'] for r in rigs])}")
            return []
    elif retarget is not None:
        c.error(path, "missing 'rig': retargeting needs the rig the clip drives")
        return []
    if ref is None:
        return []
    if retarget is not None and any(not isinstance(b, dict) or not isinstance(b.get("name"), str)
                                    for b in (rig or {}).get("bones") or ()):
        return []   # a bone of the target rig without a usable name: its own entry reports it
    common = {k: m[k] for k in ("start", "end", "phase_offset", "fade") if m.get(k) is not None}
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", UserWarning)
            clip = _load_clip(c, ref, rig, retarget, trim, trim_frames, rate, drop, path)
            entries = clip.to_animation_entries(loop=loop, resample_rate=rate or 30.0)
    except (ImportError, ValueError, OSError, KeyError) as exc:
        _asset_error(c, path + ("clip",), exc)
        return []
    _rewarn(c, path, caught)
    if rig is not None:
        entries = _placed(entries, rig)
    return [dict(e, **common) for e in entries]


def _rewarn(c: Checker, path: tuple, caught) -> None:
    """Importer warnings again, prefixed with the scene file and the entry that caused them."""
    from magica_py.config.errors import format_path

    where = f"{c.doc.source}: {format_path(path)}"
    for w in caught:
        if issubclass(w.category, UserWarning):
            warnings.warn(f"{where}: {w.message}", UserWarning, stacklevel=2)
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)


def _load_clip(c: Checker, ref: str, rig: dict | None, retarget: dict | None, trim, trim_frames, rate, drop,
               path: tuple = ()):
    from magica_py.io.sections import load_clip
    from magica_py.scene.hierarchy import BoneSpec

    rig = rig or {}
    if retarget is not None:
        options = dict(retarget)
        target_map = options.pop("target_map", None) or rig.get("humanoid") or "auto"
        target = [BoneSpec(b["name"], b["parent"], b["position"], b["rotation"], b["scale"]) for b in rig["bones"]]
        reports = RETARGET_REPORTS.get()
        found: list = []
        clip = load_clip(ref, base_dir=base_dir(c), retarget_to=target, target_map=target_map,
                         retarget_options=options, drop=tuple(drop), trim=trim, trim_frames=trim_frames, rate=rate,
                         report=found)
        if reports is not None:
            reports.extend((path, rig.get("name"), r) for r in found)
        return clip
    unit_scale = rig.get("unit_scale")
    if unit_scale == 1.0 and str(ref).split("#", 1)[0].lower().endswith(".bvh"):
        unit_scale = None  # a BVH rig loaded with unit_scale 1 has automatic units: so has its clip
    return load_clip(ref, base_dir=base_dir(c), drop=tuple(drop), prefix=rig.get("prefix") or "",
                     unit_scale=unit_scale, trim=trim, trim_frames=trim_frames, rate=rate)


def _placed(entries: list[dict], rig: dict) -> list[dict]:
    """Compose the rig's placement onto keyframes of its root bones (local = placement * key),
    as ``scene.rigs.place_roots`` does for their rest pose."""
    position, rotation = rig.get("position"), rig.get("rotation")
    if position is None or rotation is None:
        return entries
    identity = tuple(position) == (0.0, 0.0, 0.0) and tuple(rotation) == (0.0, 0.0, 0.0, 1.0)
    if identity:
        return entries
    import numpy as np

    from magica_py.io.quat import qmul, qrotate

    roots = {b["name"] for b in rig["bones"] if b["parent"] is None}
    out = []
    for e in entries:
        if e["target"] in roots:
            keys = []
            for k in e["keyframes"]["keys"]:
                k = dict(k)
                if "position" in k:
                    k["position"] = [float(x) for x in np.asarray(position) + qrotate(np.asarray(rotation), np.asarray(k["position"]))]
                if "rotation" in k:
                    k["rotation"] = [float(x) for x in qmul(np.asarray(rotation), np.asarray(k["rotation"]))]
                keys.append(k)
            e = dict(e, keyframes=dict(e["keyframes"], keys=keys))
        out.append(e)
    return out


def import_vrm_sections(c: Checker, m: dict, path: tuple, rigs: list[dict]) -> tuple[list[dict], list[dict]]:
    """Raw (YAML-shaped) collider and cloth entries of a ``cloths[i].from_vrm`` entry."""
    m = c.mapping(m, path, VRM_KEYS)
    if m is None:
        return [], []
    name = c.text(m, "from_vrm", path, what="the name of a rig loaded from a .vrm file")
    group_by = c.choice(m, "group_by", path, ("group", "chain"), "group")
    prefix = c.text(m, "prefix", path, "vrm_", what="a cloth name prefix")
    oversized = c.choice(m, "oversized_colliders", path, ("keep", "clamp", "drop"), "keep")
    chains = c.names(m, "chains", path) if m.get("chains") is not None else None
    if name is None:
        return [], []
    rig = next((r for r in rigs if r["name"] == name), None)
    if rig is None or not rig.get("file"):
        from magica_py.config.errors import did_you_mean

        known = [r["name"] for r in rigs if r.get("file")]
        c.error(path + ("from_vrm",), f"no rig {name!r} loaded from a file{did_you_mean(name, known)}")
        return [], []
    if not isinstance(rig["file"], str) or not isinstance(rig.get("prefix") or "", str):
        return [], []   # a rig file or prefix that is not text: the rig's own entry reports it
    try:
        from magica_py.io.sections import vrm_sections

        with warnings.catch_warnings():
            if "oversized_colliders" in m:  # the scene chose what to do with them: no reminder
                warnings.filterwarnings("ignore", message=".*exceeds MagicaCloth2's 0.5 m", category=UserWarning)
            sections = vrm_sections(asset_path(c, rig["file"]), group_by=group_by, prefix=rig.get("prefix") or "",
                                    cloth_prefix=prefix, oversized_colliders=oversized, chains=chains)
    except (ImportError, ValueError, OSError, KeyError) as exc:
        _asset_error(c, path + ("from_vrm",), exc)
        return [], []
    cloths = [{k: v for k, v in entry.items() if k != "notes"} for entry in sections["cloths"]]
    extra = m.get("parameters")
    if extra is not None and not isinstance(extra, dict):
        c.error(path + ("parameters",), f"expected a mapping of parameter names to values, got {extra!r}")
    elif extra:
        # user overrides on top of the mapped VRM values (nested or dotted keys, as in any cloth)
        for entry in cloths:
            entry["parameters"] = {**_dotted(entry["parameters"]), **_dotted(extra)}
    return list(sections["colliders"]), cloths


def _dotted(parameters: dict, prefix: str = "") -> dict:
    """Nested parameter groups as dotted keys (``{inertia: {anchor: x}}`` → ``inertia.anchor``),
    so a user's key replaces the mapped one of the same name. Curve mappings
    (``{value, curve}``) and leaves stay whole."""
    from magica_py.params import PARAMETERS

    out = {}
    for name, value in parameters.items():
        key = prefix + str(name)
        if key not in PARAMETERS and isinstance(value, dict) and any(k.startswith(key + ".") for k in PARAMETERS):
            out.update(_dotted(value, key + "."))
        else:
            out[key] = value
    return out
