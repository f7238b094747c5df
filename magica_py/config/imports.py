"""Scene entries that reference asset files, expanded through ``magica_py.io.sections``.

Three entry forms (paths are relative to the scene file's folder):

* ``rigs: - {name: fox, file: Fox.glb, prefix: "", unit_scale: 1.0}``: the file's node
  hierarchy becomes the rig's explicit bones (``io.sections.rig_section``; glTF, GLB, VRM,
  BVH); ``bones`` and ``parts`` may add more bones (e.g. a chain under an imported bone);
* ``animation: - {clip: "Fox.glb#Run", rig: fox, loop: true, drop: ["b_Tail*"],
  retarget: {...}, start, end, phase_offset}``: the clip as keyframe drivers
  (``io.sections.load_clip`` + ``Clip.to_animation_entries``); ``rig`` names the rig whose
  bones the clip drives (its prefix is applied; with ``retarget`` the clip is retargeted
  onto that rig's skeleton by humanoid names); ``drop`` removes the channels of bones the
  cloth simulates;
* ``cloths: - {from_vrm: avatar, group_by: group, chains: [...], prefix: vrm_,
  oversized_colliders: keep}``: the VRM spring bones of rig ``avatar`` (loaded from a .vrm
  file) as cloths and their colliders (``io.sections.vrm_sections``).

Generated entries go through the same checks as written ones; problems are reported at the
path of the entry that generated them. An importer error (``io.errors.AssetError``) is an
issue at that entry's ``file`` / ``clip`` / ``from_vrm`` key.
"""
from __future__ import annotations

import pathlib

from magica_py.config.checker import POSITIVE, Checker

RIG_FILE_KEYS = ("file", "prefix", "unit_scale")
CLIP_KEYS = ("clip", "rig", "loop", "drop", "retarget", "start", "end", "phase_offset", "fade")
VRM_KEYS = ("from_vrm", "group_by", "chains", "prefix", "oversized_colliders")


def base_dir(c: Checker) -> pathlib.Path:
    """Folder that asset paths are relative to: the scene file's, else the current one."""
    source = c.doc.source
    if source and not source.startswith("<"):
        return pathlib.Path(source).resolve().parent
    return pathlib.Path.cwd()


def _asset_error(c: Checker, path: tuple, exc: Exception) -> None:
    c.error(path, f"cannot import: {exc}")


def import_rig_bones(c: Checker, m: dict, path: tuple) -> list[dict] | None:
    """Normalized explicit bones of ``rigs[i].file`` (None after reporting a problem)."""
    file = c.text(m, "file", path, what="a .gltf, .glb, .vrm or .bvh file path")
    prefix = "" if m.get("prefix") in ("", None) else c.text(m, "prefix", path, "", what="a name prefix")
    unit_scale = c.number(m, "unit_scale", path, 1.0, POSITIVE)
    if file is None:
        return None
    full = base_dir(c) / file
    try:
        from magica_py.io.sections import rig_section

        section = rig_section(full, name=m.get("name"), prefix=prefix, unit_scale=unit_scale)
    except (ImportError, ValueError, OSError, KeyError) as exc:
        _asset_error(c, path + ("file",), exc)
        return None
    where = path + ("file",)
    return [{"name": b["name"], "parent": b["parent"], "path": where, "position": tuple(b["position"]),
             "rotation": tuple(b["rotation"]), "scale": tuple(b["scale"])} for b in section["bones"]]


def import_clip_entries(c: Checker, m: dict, path: tuple, rigs: list[dict]) -> list[dict]:
    """Raw (YAML-shaped) keyframe driver entries of an ``animation[i].clip`` entry."""
    m = c.mapping(m, path, CLIP_KEYS)
    if m is None:
        return []
    ref = c.text(m, "clip", path, what="a clip reference: file.glb#Name or file.bvh")
    loop = c.boolean(m, "loop", path, True)
    drop = c.names(m, "drop", path)
    retarget = m.get("retarget")
    if retarget is not None and not isinstance(retarget, dict):
        c.error(path + ("retarget",), f"expected a mapping of retarget options, got {retarget!r}")
        retarget = None
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
    common = {k: m[k] for k in ("start", "end", "phase_offset", "fade") if m.get(k) is not None}
    try:
        from magica_py.io.sections import load_clip
        from magica_py.scene.hierarchy import BoneSpec

        target_bones = None
        if rig is not None and retarget is not None:
            target_bones = [BoneSpec(b["name"], b["parent"], b["position"], b["rotation"], b["scale"])
                            for b in rig["bones"]]
        clip = load_clip(ref, base_dir=base_dir(c), target_bones=target_bones, retarget_options=retarget,
                         drop=tuple(drop), prefix=(rig or {}).get("prefix") or "")
        entries = clip.to_animation_entries(loop=loop)
    except (ImportError, ValueError, OSError, KeyError) as exc:
        _asset_error(c, path + ("clip",), exc)
        return []
    return [dict(e, **common) for e in entries]


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
    try:
        from magica_py.io.sections import vrm_sections

        sections = vrm_sections(base_dir(c) / rig["file"], group_by=group_by, prefix=rig.get("prefix") or "",
                                cloth_prefix=prefix, oversized_colliders=oversized, chains=chains)
    except (ImportError, ValueError, OSError, KeyError) as exc:
        _asset_error(c, path + ("from_vrm",), exc)
        return [], []
    cloths = [{k: v for k, v in entry.items() if k != "notes"} for entry in sections["cloths"]]
    return list(sections["colliders"]), cloths

