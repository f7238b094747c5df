"""Humanoid bone naming: VRM humanoid names as the common vocabulary, default tables for
CMU (cgspeed BVH), Mixamo-like rigs and skeletons already named with VRM names, a generic
word/synonym matcher for hand-named rigs (``thigh.l``, ``UpperArm_R``, ``pelvis``), plus
user overrides (a dict or a YAML file ``{humanoid_name: bone_name}``).

Matching ignores case, a ``prefix:`` namespace (``mixamorig:``, ``mixamorig1:``) and the
separators ``_ - . `` so ``mixamorig:LeftUpLeg``, ``LeftUpLeg`` and ``left_up_leg`` match.
"""
from __future__ import annotations

import re
from pathlib import Path

import yaml

# The VRM humanoid bones the retargeter transfers (at least these; fingers are not mapped).
HUMANOID_BONES = (
    "hips", "spine", "chest", "upperChest", "neck", "head",
    "leftShoulder", "leftUpperArm", "leftLowerArm", "leftHand",
    "rightShoulder", "rightUpperArm", "rightLowerArm", "rightHand",
    "leftUpperLeg", "leftLowerLeg", "leftFoot", "leftToes",
    "rightUpperLeg", "rightLowerLeg", "rightFoot", "rightToes",
)
REQUIRED_BONES = ("hips",)


def _sided(table: dict[str, str]) -> dict[str, str]:
    """Expand '{side}' templates into left/right entries."""
    out = {}
    for human, bone in table.items():
        if "{side}" in human:
            out[human.format(side="left")] = bone.format(Side="Left", S="L")
            out[human.format(side="right")] = bone.format(Side="Right", S="R")
        else:
            out[human] = bone
    return out


CMU = _sided({
    "hips": "Hips", "spine": "LowerBack", "chest": "Spine", "upperChest": "Spine1", "neck": "Neck", "head": "Head",
    "{side}Shoulder": "{Side}Shoulder", "{side}UpperArm": "{Side}Arm", "{side}LowerArm": "{Side}ForeArm",
    "{side}Hand": "{Side}Hand", "{side}UpperLeg": "{Side}UpLeg", "{side}LowerLeg": "{Side}Leg",
    "{side}Foot": "{Side}Foot", "{side}Toes": "{Side}ToeBase",
})
MIXAMO = _sided({
    "hips": "Hips", "spine": "Spine", "chest": "Spine1", "upperChest": "Spine2", "neck": "Neck", "head": "Head",
    "{side}Shoulder": "{Side}Shoulder", "{side}UpperArm": "{Side}Arm", "{side}LowerArm": "{Side}ForeArm",
    "{side}Hand": "{Side}Hand", "{side}UpperLeg": "{Side}UpLeg", "{side}LowerLeg": "{Side}Leg",
    "{side}Foot": "{Side}Foot", "{side}Toes": "{Side}ToeBase",
})
VRM_NAMES = {h: h for h in HUMANOID_BONES}
SCHEMES = {"cmu": CMU, "mixamo": MIXAMO, "vrm": VRM_NAMES}


# Generic matching for rigs named by hand (Blender, Godot, VRoid exports, ...): split a name
# into lower-case words (camelCase, '.', '_', '-', ':' and spaces), read the side from a
# left/right/l/r word, drop filler words and look the rest up in these synonyms.
_GENERIC_CENTRE = {
    "hips": ("hips", "hip", "pelvis"), "spine": ("spine", "tummy", "abdomen", "waist", "lowerback", "spine0"),
    "chest": ("chest", "spine1", "spine2", "thorax", "ribcage"), "upperChest": ("upperchest", "spine3"),
    "neck": ("neck",), "head": ("head",),
}
_GENERIC_SIDED = {
    "Shoulder": ("shoulder", "clavicle", "collar", "collarbone"), "UpperArm": ("upperarm", "arm", "uparm"),
    "LowerArm": ("lowerarm", "forearm", "elbow"), "Hand": ("hand", "wrist"),
    "UpperLeg": ("upperleg", "thigh", "upleg"), "LowerLeg": ("lowerleg", "shin", "calf", "leg", "knee"),
    "Foot": ("foot", "ankle"), "Toes": ("toes", "toe", "toebase"),
}
_FILLER = {"armature", "mixamorig", "bip01", "bip", "def", "jnt", "joint", "bone", "j", "b", "mch", "org"}


def _words(name: str) -> list[str]:
    name = re.sub(r"([a-z0-9])([A-Z])", r"\1 \2", name.rsplit(":", 1)[-1])
    return [w for w in re.split(r"[\s_.\-]+", name.lower()) if w]


def generic_map(bone_names) -> dict[str, str]:
    """humanoid → bone by words and synonyms (first match in skeleton order wins)."""
    lookup = {syn: human for human, syns in _GENERIC_CENTRE.items() for syn in syns}
    sided = {syn: part for part, syns in _GENERIC_SIDED.items() for syn in syns}
    out: dict[str, str] = {}
    for name in bone_names:
        words = [w for w in _words(name) if w not in _FILLER and not w.isdigit()]
        side = None
        rest = []
        for w in words:
            if w in ("l", "left") and side is None:
                side = "left"
            elif w in ("r", "right") and side is None:
                side = "right"
            else:
                rest.append(w)
        key = "".join(rest)
        if side is None and key in lookup:
            out.setdefault(lookup[key], name)
        elif side is not None and key in sided:
            out.setdefault(f"{side}{sided[key]}", name)
    return out


# ---------------------------------------------------------------- labels for the structural matcher
# A name gives a side and the parts the bone could be; ``io.skeleton_match`` decides by the
# skeleton's structure. Words that are two parts at once (``shoulder``: the clavicle in
# Mixamo / HumanIK, the upper arm in the Biovision family; ``leg``: the shin in Mixamo,
# the thigh on ``leg_l``; ``hip``: the thigh in ``LeftHip``) carry both.
_LABEL_CENTRE = {
    "hips": ("hips", "hip", "pelvis"),
    "spine": ("spine", "tummy", "abdomen", "ab", "waist", "lowerback", "torso", "upperback"),
    "chest": ("chest", "thorax", "ribcage", "upperchest"),
    "neck": ("neck", "lowerneck", "upperneck"),
    "head": ("head",),
}
_LABEL_SIDED = {
    "Shoulder": ("shoulder", "clavicle", "clav", "collar", "collarbone"),
    "UpperArm": ("upperarm", "arm", "uparm", "humerus", "shoulder"),
    "LowerArm": ("lowerarm", "forearm", "elbow", "radius", "ulna", "lowarm"),
    "Hand": ("hand", "wrist"),
    "LowerLeg": ("lowerleg", "shin", "calf", "knee", "tibia", "leg", "lowleg"),   # before UpperLeg: Mixamo's Leg
    "UpperLeg": ("upperleg", "thigh", "upleg", "femur", "hip", "leg"),
    "Foot": ("foot", "ankle"),
    "Toes": ("toes", "toe", "toebase", "ball"),
    "Finger": ("finger", "fingers", "fingerbase", "thumb", "index", "middle", "ring", "pinky", "little"),
}
_LABEL_FILLER = re.compile(r"^(armature|mixamorig\d*|bip\d*|character\d*|def|mch|org|jnt|joint|bone|j|b|c|"
                           r"end|top|nub|site|\d+)$")
_SIDE_WORDS = {"l": "left", "left": "left", "r": "right", "right": "right"}
_SIDED_WORDS = {w for syns in _LABEL_SIDED.values() for w in syns}


def name_label(name: str) -> tuple[str | None, tuple[str, ...], tuple[str, ...]]:
    """(side, parts, words) read from a bone name: side ``"left"``/``"right"``/None; parts
    the humanoid parts the name could be (``"hips"``, ``"spine"``, ``"chest"``, ``"neck"``,
    ``"head"`` unsided; ``"Shoulder"``, ``"UpperArm"``, ..., ``"Toes"``, ``"Finger"``
    sided); words the lower-case words of the name (for twist / end-site detection).

    ``mixamorig:LeftForeArm`` → (left, (LowerArm,)); ``Bip01_L_Calf`` → (left, (LowerLeg,));
    ``lfemur`` (CMU ASF) → (left, (UpperLeg,)); ``LeftShoulder`` → (left, (Shoulder, UpperArm)).
    """
    words = _words(name)
    side = None
    rest = []
    for w in words:
        if side is None and w in _SIDE_WORDS:
            side = _SIDE_WORDS[w]
            continue
        if _LABEL_FILLER.match(w):
            continue
        rest.append(w)
    if side is None and rest and rest[0][:1] in ("l", "r") and re.sub(r"\d+$", "", rest[0][1:]) in _SIDED_WORDS:
        side = _SIDE_WORDS[rest[0][0]]          # CMU ASF: lfemur, rhand, LHipJoint
        rest[0] = rest[0][1:]
    key = re.sub(r"\d+$", "", "".join(rest))
    if side is None:
        parts = tuple(h for h, syns in _LABEL_CENTRE.items() if key in syns)
    else:
        parts = tuple(p for p, syns in _LABEL_SIDED.items() if key in syns)
        if not parts and any(re.sub(r"\d+$", "", w) in _LABEL_SIDED["Finger"] for w in rest[1:]):
            parts = ("Finger",)
    return side, parts, tuple(words)


# Naming families, for the report (the matcher itself works from labels and structure).
FAMILIES = ("mixamo", "cmu-cgspeed", "3dsmax-biped", "humanik", "unreal", "rigify", "vrm", "vroid",
            "cmu-asf", "biovision", "generic")


def detect_family(bone_names) -> str:
    """The naming family a skeleton's names come from (one of ``FAMILIES``)."""
    names = list(bone_names)
    keys = {normalize(n) for n in names}
    lower = [n.lower() for n in names]
    if any(n.startswith("mixamorig") for n in lower):
        return "mixamo"
    if any(re.match(r"bip0*1", n) for n in lower):
        return "3dsmax-biped"
    if any(n.startswith("def-") for n in lower) or {"spine001", "spine002"} <= keys:
        return "rigify"
    if any(n.startswith("j_bip_") for n in lower):
        return "vroid"
    if {"lfemur", "ltibia"} <= keys or {"lhumerus", "lradius"} <= keys:
        return "cmu-asf"
    if "lowerback" in keys and "leftupleg" in keys:
        return "cmu-cgspeed"
    if any(re.match(r"character\d*_", n) for n in lower) or "reference" in keys and "leftupleg" in keys:
        return "humanik"
    if "pelvis" in keys and ("thighl" in keys or "calfl" in keys or "clavicle_l" in lower):
        return "unreal"
    if "leftupperleg" in keys and "hips" in keys:
        return "vrm"
    if "leftknee" in keys or "leftcollar" in keys or ("lefthip" in keys and "leftelbow" in keys):
        return "biovision"
    if "leftupleg" in keys:
        return "mixamo"
    return "generic"


def normalize(name: str) -> str:
    return re.sub(r"[\s_.\-]", "", name.rsplit(":", 1)[-1]).lower()


def detect_scheme(bone_names) -> str:
    keys = {normalize(n) for n in bone_names}
    if "lowerback" in keys:
        return "cmu"
    if "spine2" in keys or any(n.lower().startswith("mixamorig") for n in bone_names):
        return "mixamo"
    if "leftupperleg" in keys and "hips" in keys:
        return "vrm"
    if "leftupleg" in keys:
        return "mixamo"
    return "generic"


def load_overrides(source) -> dict[str, str]:
    """Overrides from a dict or a YAML file: ``{humanoid_name: bone_name | null}``."""
    if source is None:
        return {}
    if isinstance(source, (str, Path)):
        path = Path(source)
        try:
            data = yaml.safe_load(path.read_text())
        except (OSError, yaml.YAMLError) as exc:
            raise ValueError(f"{path}: cannot read the humanoid mapping ({exc})") from None
        where = str(path)
    else:
        data, where = source, "mapping"
    if not isinstance(data, dict):
        raise ValueError(f"{where}: expected a mapping humanoid_name: bone_name")
    unknown = [k for k in data if k not in HUMANOID_BONES]
    if unknown:
        raise ValueError(f"{where}: unknown humanoid bone(s) {unknown}; expected some of {', '.join(HUMANOID_BONES)}")
    return {k: v for k, v in data.items()}


def humanoid_map(bone_names, scheme: str | dict = "auto", overrides=None) -> dict[str, str]:
    """humanoid name → bone name for a skeleton, from a scheme table (or a given dict,
    such as a VRM file's humanoid) with overrides applied (``None`` unmaps a bone)."""
    names = list(bone_names)
    by_key = {}
    for n in names:
        by_key.setdefault(normalize(n), n)
    if isinstance(scheme, dict):
        table, direct = scheme, True
    else:
        chosen = detect_scheme(names) if scheme == "auto" else scheme
        if chosen == "generic":
            table, direct = generic_map(names), True
        elif chosen not in SCHEMES:
            raise ValueError(f"unknown naming scheme {chosen!r}; expected auto, generic, {', '.join(sorted(SCHEMES))} "
                             f"or a humanoid mapping")
        else:
            table, direct = SCHEMES[chosen], False
    out = {}
    for human, bone in table.items():
        if human not in HUMANOID_BONES:
            continue
        found = bone if direct and bone in names else by_key.get(normalize(bone))
        if found is not None:
            out[human] = found
    for human, bone in load_overrides(overrides).items():
        if bone is None:
            out.pop(human, None)
        elif bone not in names:
            raise ValueError(f"humanoid override {human}: {bone!r} is not a bone of the skeleton")
        else:
            out[human] = bone
    return out
