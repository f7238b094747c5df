"""Test skeletons for retargeting, one per bone-naming family, and the measures of a retarget.

Every skeleton is the character rig of ``configs/character_walk.yaml`` (hips, spine, chest,
neck, head, thighs hanging 0.45 m from hip joints 0.10 m to each side) completed into a
full humanoid (shins, feet, toes, arms, optionally clavicles and an upper chest), renamed
the way one family names its bones, and written as a BVH file the way awkward sources
write them: **centimetres, facing +X, the hips at the floor in the rest pose** (root
OFFSET 0, the standing height only in the motion), right-handed Y up.

The motion is a generated walk: frame 0 is the rest pose standing (hips 1 m up, toes on
the floor), then 2 s at 60 fps of a 0.9 Hz gait along the file's +X at 1.1 m/s: thighs
swing ±25° about the body's lateral axis, knees bend backwards in the swing phase, feet
stay flat, the hips move so the lowest toe joint stays on the floor, arms hang and swing
in opposition with the elbows bent forwards.

``python tests/retarget_skeletons.py`` prints the figures of docs/import.md (every family
and the CMU capture, onto Godette and onto the character rig).
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

from magica_py.io.quat import qaxis_angle, qconj, qmul, qrotate, qto_matrix

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data"
FPS = 60.0
WALK_SECONDS = 2.0
STRIDE_HZ = 0.9
SPEED = 1.1                 # m/s along the file's +X
TOE_FLOOR = 0.02            # toe joint height above the floor when standing (m)

# body frame -> file axes: forward = +X, up = +Y, the character's left = -Z (right-handed)
FORWARD, UP, LEFT = np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), np.array([0, 0, -1.0])

# role -> rest position in the body frame (forward, up, left) in metres, hips at the origin
BODY = {
    "hips": (0, 0, 0), "spine": (0, 0.12, 0), "chest": (0, 0.28, 0), "upperChest": (0, 0.40, 0),
    "neck": (0, 0.50, 0), "neck2": (0, 0.55, 0), "head": (0, 0.60, 0),
    "Shoulder": (0, 0.46, 0.03), "UpperArm": (0, 0.45, 0.17), "LowerArm": (0, 0.45, 0.45),
    "Hand": (0, 0.45, 0.71), "Finger": (0, 0.45, 0.80),
    "HipJoint": (0, 0, 0), "UpperLeg": (0, -0.04, 0.10), "LowerLeg": (0, -0.49, 0.10),
    "Foot": (0, -0.92, 0.10), "Toes": (0.13, -0.98, 0.10),
}

# name families: role -> name ("{Side}" Left/Right, "{S}" L/R, "{s}" l/r, "{side}" left/right)
# and structure options
FAMILIES = {
    "mixamo": dict(names={
        "hips": "mixamorig:Hips", "spine": "mixamorig:Spine", "chest": "mixamorig:Spine1",
        "upperChest": "mixamorig:Spine2", "neck": "mixamorig:Neck", "head": "mixamorig:Head",
        "Shoulder": "mixamorig:{Side}Shoulder", "UpperArm": "mixamorig:{Side}Arm",
        "LowerArm": "mixamorig:{Side}ForeArm", "Hand": "mixamorig:{Side}Hand", "Finger": "mixamorig:{Side}HandMiddle1",
        "UpperLeg": "mixamorig:{Side}UpLeg", "LowerLeg": "mixamorig:{Side}Leg", "Foot": "mixamorig:{Side}Foot",
        "Toes": "mixamorig:{Side}ToeBase"}, a_pose=False),
    "3dsmax-biped": dict(names={
        "root": "Bip01", "hips": "Bip01_Pelvis", "spine": "Bip01_Spine", "chest": "Bip01_Spine1",
        "upperChest": "Bip01_Spine2", "neck": "Bip01_Neck", "head": "Bip01_Head",
        "Shoulder": "Bip01_{S}_Clavicle", "UpperArm": "Bip01_{S}_UpperArm", "LowerArm": "Bip01_{S}_Forearm",
        "Hand": "Bip01_{S}_Hand", "Finger": "Bip01_{S}_Finger0", "UpperLeg": "Bip01_{S}_Thigh",
        "LowerLeg": "Bip01_{S}_Calf", "Foot": "Bip01_{S}_Foot", "Toes": "Bip01_{S}_Toe0"},
        shoulder_parent="neck", thigh_parent="spine", a_pose=False),       # Biped: clavicles on the neck, thighs on the spine
    "humanik": dict(names={
        "root": "Character1_Reference", "hips": "Character1_Hips", "spine": "Character1_Spine",
        "chest": "Character1_Spine1", "neck": "Character1_Neck", "head": "Character1_Head",
        "UpperArm": "Character1_{Side}Arm", "LowerArm": "Character1_{Side}ForeArm", "Hand": "Character1_{Side}Hand",
        "UpperLeg": "Character1_{Side}UpLeg", "LowerLeg": "Character1_{Side}Leg", "Foot": "Character1_{Side}Foot",
        "Toes": "Character1_{Side}ToeBase"}, a_pose=True),                  # no clavicle, A-pose
    "unreal": dict(names={
        "root": "root", "hips": "pelvis", "spine": "spine_01", "chest": "spine_02", "upperChest": "spine_03",
        "neck": "neck_01", "head": "head", "Shoulder": "clavicle_{s}", "UpperArm": "upperarm_{s}",
        "UpperArmTwistLeaf": "upperarm_twist_01_{s}", "LowerArm": "lowerarm_{s}", "Hand": "hand_{s}",
        "UpperLeg": "thigh_{s}", "LowerLeg": "calf_{s}", "Foot": "foot_{s}", "Toes": "ball_{s}"}, a_pose=True),
    "rigify": dict(names={
        "hips": "DEF-spine", "spine": "DEF-spine.001", "chest": "DEF-spine.002", "upperChest": "DEF-spine.003",
        "neck": "DEF-spine.004", "neck2": "DEF-spine.005", "head": "DEF-spine.006",
        "Shoulder": "DEF-shoulder.{S}", "UpperArm": "DEF-upper_arm.{S}", "UpperArmTwist": "DEF-upper_arm.{S}.001",
        "LowerArm": "DEF-forearm.{S}", "LowerArmTwist": "DEF-forearm.{S}.001", "Hand": "DEF-hand.{S}",
        "UpperLeg": "DEF-thigh.{S}", "UpperLegTwist": "DEF-thigh.{S}.001", "LowerLeg": "DEF-shin.{S}",
        "LowerLegTwist": "DEF-shin.{S}.001", "Foot": "DEF-foot.{S}", "Toes": "DEF-toe.{S}"}, a_pose=False),
    "vrm": dict(names={
        "hips": "hips", "spine": "spine", "chest": "chest", "upperChest": "upperChest", "neck": "neck",
        "head": "head", "UpperArm": "{side}UpperArm", "LowerArm": "{side}LowerArm", "Hand": "{side}Hand",
        "UpperLeg": "{side}UpperLeg", "LowerLeg": "{side}LowerLeg", "Foot": "{side}Foot", "Toes": "{side}Toes"},
        a_pose=False),                                                      # no clavicle
    "cmu-asf": dict(names={
        "hips": "root", "spine": "lowerback", "chest": "upperback", "upperChest": "thorax", "neck": "lowerneck",
        "neck2": "upperneck", "head": "head", "Shoulder": "{s}clavicle", "UpperArm": "{s}humerus",
        "LowerArm": "{s}radius", "Hand": "{s}wrist", "Finger": "{s}hand", "HipJoint": "{s}hipjoint",
        "UpperLeg": "{s}femur", "LowerLeg": "{s}tibia", "Foot": "{s}foot", "Toes": "{s}toes"}, a_pose=False),
    # the CMU boxing / Biovision naming: joints named after the joint they start at, so
    # LeftShoulder is the upper arm and LeftHip the thigh
    "biovision": dict(names={
        "hips": "Hips", "spine": "Ab", "chest": "Chest", "neck": "Neck", "head": "Head",
        "Shoulder": "{Side}Collar", "UpperArm": "{Side}Shoulder", "LowerArm": "{Side}Elbow", "Hand": "{Side}Wrist",
        "UpperLeg": "{Side}Hip", "LowerLeg": "{Side}Knee", "Foot": "{Side}Ankle", "Toes": "{Side}Toe"}, a_pose=False),
    "biovision-no-collar": dict(names={
        "hips": "Hips", "spine": "Ab", "chest": "Chest", "neck": "Neck", "head": "Head",
        "UpperArm": "{Side}Shoulder", "LowerArm": "{Side}Elbow", "Hand": "{Side}Wrist",
        "UpperLeg": "{Side}Hip", "LowerLeg": "{Side}Knee", "Foot": "{Side}Ankle", "Toes": "{Side}Toe"}, a_pose=True),
}
HUMANOID_OF_ROLE = {"hips": "hips", "spine": "spine", "chest": "chest", "upperChest": "upperChest", "neck": "neck",
                    "head": "head", "Shoulder": "Shoulder", "UpperArm": "UpperArm", "LowerArm": "LowerArm",
                    "Hand": "Hand", "UpperLeg": "UpperLeg", "LowerLeg": "LowerLeg", "Foot": "Foot", "Toes": "Toes"}
CHARACTER_TRUTH = {"hips": "hips", "spine": "spine", "chest": "chest", "neck": "neck", "head": "head",
                   "leftUpperLeg": "leg_l", "leftLowerLeg": "knee_l", "rightUpperLeg": "leg_r", "rightLowerLeg": "knee_r"}


def _name(template: str, side: str) -> str:
    return template.format(Side=side.capitalize(), S=side[0].upper(), s=side[0], side=side)


class Skeleton:
    """Joints (file order, parents first) with rest positions in file axes (m) and the true map."""

    def __init__(self, family: str):
        spec = FAMILIES[family]
        self.family = family
        names = spec["names"]
        self.joints: list[tuple[str, str | None, str, str | None]] = []   # (name, parent name, role, side)
        self.truth: dict[str, str] = {}
        role_name: dict[tuple[str, str | None], str] = {}

        def add(role, side, parent_key):
            name = _name(names[role], side or "left")
            parent = role_name.get(parent_key) if parent_key else None
            self.joints.append((name, parent, role, side))
            role_name[(role, side)] = name
            if role in HUMANOID_OF_ROLE:
                self.truth[role if side is None else f"{side}{role}"] = name

        if "root" in names:
            add("root", None, None)
        add("hips", None, ("root", None) if "root" in names else None)
        trunk = [r for r in ("spine", "chest", "upperChest", "neck", "neck2", "head") if r in names]
        for prev, role in zip(["hips"] + trunk, trunk):
            add(role, None, (prev, None))
        top = "upperChest" if "upperChest" in names else "chest"

        def chain(side, parent_key, roles):     # each role the family has, under the previous one
            below = parent_key
            for role in roles:
                if role in names:
                    add(role, side, below)
                    below = (role, side)

        for side in ("left", "right"):
            chain(side, (spec.get("shoulder_parent", top), None),
                  ("Shoulder", "UpperArm", "UpperArmTwist", "LowerArm", "LowerArmTwist", "Hand", "Finger"))
            if "UpperArmTwistLeaf" in names:
                add("UpperArmTwistLeaf", side, ("UpperArm", side))
        for side in ("left", "right"):
            chain(side, (spec.get("thigh_parent", "hips"), None),
                  ("HipJoint", "UpperLeg", "UpperLegTwist", "LowerLeg", "LowerLegTwist", "Foot", "Toes"))
        self.a_pose = spec.get("a_pose", False)
        self.rest = {name: self._rest_position(role, side) for name, _, role, side in self.joints}
        self.index = {name: k for k, (name, *_) in enumerate(self.joints)}

    def _rest_position(self, role: str, side: str | None) -> np.ndarray:
        twist = {"UpperArmTwist": ("UpperArm", "LowerArm"), "LowerArmTwist": ("LowerArm", "Hand"),
                 "UpperLegTwist": ("UpperLeg", "LowerLeg"), "LowerLegTwist": ("LowerLeg", "Foot"),
                 "UpperArmTwistLeaf": ("UpperArm", "LowerArm")}
        if role in twist:
            a, b = twist[role]
            return 0.5 * (self._rest_position(a, side) + self._rest_position(b, side))
        if role == "root":
            role = "hips"
        f, u, l = BODY[role]
        if side == "right":
            l = -l
        p = f * FORWARD + u * UP + l * LEFT
        if self.a_pose and role in ("LowerArm", "Hand", "Finger"):
            pivot = self._rest_position("UpperArm", side)
            p = pivot + qrotate(self.arm_down(side, 45.0), p - pivot)
        return p

    @staticmethod
    def arm_down(side: str, degrees: float) -> np.ndarray:
        """Rotation lowering a side's arm (pointing sideways) by ``degrees`` towards -up."""
        out = LEFT if side == "left" else -LEFT
        return qaxis_angle(_unit(np.cross(out, -UP)), math.radians(degrees))

    # ------------------------------------------------------------------ motion
    def walk(self) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Hips positions (F, 3) m and local rotations {joint: (F, 4)} in file axes; frame 0 is the rest."""
        frames = 1 + int(round(WALK_SECONDS * FPS))
        t = np.arange(frames) / FPS
        phase = 2.0 * math.pi * STRIDE_HZ * t
        active = (np.arange(frames) > 0).astype(float)           # frame 0: the rest pose standing
        lateral = _unit(np.cross(-UP, FORWARD))                  # +angle swings a hanging bone forward
        local = {name: np.tile([0.0, 0.0, 0.0, 1.0], (frames, 1)) for name, *_ in self.joints}
        role_of = {(role, side): name for name, _, role, side in self.joints}
        for side, offset in (("left", 0.0), ("right", math.pi)):
            p = phase + offset
            hip = np.radians(25.0) * np.sin(p) * active
            knee = np.radians(5.0 + 55.0 * np.maximum(0.0, np.cos(p))) * active
            local[role_of[("UpperLeg", side)]] = qaxis_angle(lateral, hip)
            local[role_of[("LowerLeg", side)]] = qaxis_angle(lateral, -knee)      # the shin goes back
            local[role_of[("Foot", side)]] = qaxis_angle(lateral, knee - hip)     # the foot stays flat
            # arms: lowered from the rest pose to hang 10 deg off vertical, swinging against the leg
            hang = 80.0 - (45.0 if self.a_pose else 0.0)
            lower = self.arm_down(side, hang)
            swing = qaxis_angle(lateral, -np.radians(20.0) * np.sin(p) * active)
            upper = qmul(swing, np.tile(lower, (frames, 1)))
            local[role_of[("UpperArm", side)]] = np.where(active[:, None] > 0, upper, local[role_of[("UpperArm", side)]])
            arm_rest = _unit(self.rest[role_of[("LowerArm", side)]] - self.rest[role_of[("UpperArm", side)]])
            elbow_axis = _unit(np.cross(arm_rest, FORWARD))     # the forearm bends towards the front
            elbow = np.radians(15.0 + 25.0 * 0.5 * (1.0 - np.sin(p))) * active
            local[role_of[("LowerArm", side)]] = qaxis_angle(elbow_axis, elbow)
        twist = qaxis_angle(UP, np.radians(4.0) * np.sin(phase) * active)
        local[role_of[("hips", None)]] = twist
        local[role_of[("chest", None)]] = qaxis_angle(UP, -np.radians(9.0) * np.sin(phase) * active)
        hips = np.zeros((frames, 3))
        hips[:, 0] = SPEED * np.maximum(t - 1.0 / FPS, 0.0) * active
        # stand the lowest foot joint on the floor
        world = self.forward_kinematics(np.zeros((frames, 3)), local)
        feet = [self.index[role_of[(r, s)]] for r in ("Foot", "Toes") for s in ("left", "right")]
        lowest = world[:, feet, 1].min(axis=1)
        hips[:, 1] = TOE_FLOOR - lowest
        return hips, local

    def forward_kinematics(self, hips: np.ndarray, local: dict[str, np.ndarray]) -> np.ndarray:
        """World joint positions (F, J, 3) in file axes for the root at ``hips``."""
        frames = hips.shape[0]
        rot = np.zeros((frames, len(self.joints), 4))
        pos = np.zeros((frames, len(self.joints), 3))
        for k, (name, parent, _, _) in enumerate(self.joints):
            if parent is None:
                rot[:, k] = local[name]
                pos[:, k] = hips + self.rest[name]
            else:
                p = self.index[parent]
                rot[:, k] = qmul(rot[:, p], local[name])
                pos[:, k] = pos[:, p] + qrotate(rot[:, p], self.rest[name] - self.rest[parent])
        return pos

    # ------------------------------------------------------------------ BVH text
    def bvh_text(self) -> str:
        hips, local = self.walk()
        children = {name: [] for name, *_ in self.joints}
        for name, parent, *_ in self.joints:
            if parent is not None:
                children[parent].append(name)
        lines = ["HIERARCHY"]

        def write(name, depth):
            pad = "  " * depth
            parent = next(p for n, p, *_ in self.joints if n == name)
            offset = (self.rest[name] - (self.rest[parent] if parent else 0.0)) * 100.0    # centimetres
            lines.append(f"{pad}{'ROOT' if parent is None else 'JOINT'} {name}")
            lines.append(f"{pad}{{")
            lines.append(f"{pad}  OFFSET {offset[0]:.6f} {offset[1]:.6f} {offset[2]:.6f}")
            chans = "6 Xposition Yposition Zposition" if parent is None else "3"
            lines.append(f"{pad}  CHANNELS {chans} Zrotation Xrotation Yrotation")
            for child in children[name]:
                write(child, depth + 1)
            if not children[name]:
                lines.append(f"{pad}  End Site")
                lines.append(f"{pad}  {{")
                lines.append(f"{pad}    OFFSET 0.000000 2.000000 0.000000")
                lines.append(f"{pad}  }}")
            lines.append(f"{pad}}}")

        write(self.joints[0][0], 0)
        frames = hips.shape[0]
        lines += ["MOTION", f"Frames: {frames}", f"Frame Time: {1.0 / FPS:.7f}"]
        angles = {name: zxy_degrees(local[name]) for name, *_ in self.joints}
        for f in range(frames):
            row = []
            for name, parent, *_ in self.joints:
                if parent is None:
                    row += [f"{x * 100.0:.6f}" for x in hips[f]]
                row += [f"{x:.6f}" for x in angles[name][f]]
            lines.append(" ".join(row))
        return "\n".join(lines) + "\n"

    def write_bvh(self, folder: Path) -> Path:
        path = Path(folder) / f"{self.family}.bvh"
        path.write_text(self.bvh_text())
        return path


def zxy_degrees(q: np.ndarray) -> np.ndarray:
    """(F, 4) right-handed quaternions -> (F, 3) BVH angles for ``Zrotation Xrotation Yrotation``
    (R = Rz Rx Ry)."""
    m = qto_matrix(q)
    x = np.arcsin(np.clip(m[:, 2, 1], -1.0, 1.0))
    z = np.arctan2(-m[:, 0, 1], m[:, 1, 1])
    y = np.arctan2(-m[:, 2, 0], m[:, 2, 2])
    return np.degrees(np.stack([z, x, y], axis=1))


def _unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.sqrt(np.sum(v * v, axis=-1, keepdims=True))


# ---------------------------------------------------------------------- targets
def character_bones():
    """The explicit bones of configs/character_walk.yaml's rig (its generated hair and skirt
    bones are not humanoid and are left out)."""
    import yaml

    from magica_py.scene.hierarchy import BoneSpec

    doc = yaml.safe_load((ROOT / "configs" / "character_walk.yaml").read_text())
    rig = doc["rigs"][0]
    return [BoneSpec(b["name"], b.get("parent"), tuple(float(x) for x in b["position"])) for b in rig["bones"]]


def godette():
    import warnings

    from magica_py.io.vrm import load_vrm
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        avatar = load_vrm(DATA / "vrm" / "Godette_vrm_v4.vrm")
    return avatar.bones, dict(avatar.humanoid)


# ---------------------------------------------------------------------- measures
LIMBS = {"leftUpperArm": "leftLowerArm", "leftLowerArm": "leftHand", "rightUpperArm": "rightLowerArm",
         "rightLowerArm": "rightHand", "leftUpperLeg": "leftLowerLeg", "leftLowerLeg": "leftFoot",
         "rightUpperLeg": "rightLowerLeg", "rightLowerLeg": "rightFoot"}


def _angle(a, b) -> np.ndarray:
    a, b = _unit(a), _unit(b)
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1.0, 1.0)))


def _directions(rot, pos, h, truth, human, nxt):
    """Bone direction (F, 3) of humanoid ``human`` towards ``nxt``; when ``nxt`` is not a
    bone of the skeleton (a knee with nothing below), the bone's rest direction continued
    from its parent, turned with the bone."""
    j = h.index(truth[human])
    if nxt in truth:
        return pos[:, h.index(truth[nxt])] - pos[:, j]
    p = h.parent[j]
    rest_dir = h.world_position[j] - h.world_position[p]
    turn = qmul(rot[:, j], qconj(h.world_rotation[j]))
    return qrotate(turn, np.broadcast_to(rest_dir, pos[:, j].shape))


def measure(source_bones, source_clip, source_truth, target_bones, target_truth, *, source_forward,
            target_forward=(0.0, 0.0, 1.0), rest_frame=0, options=None) -> dict:
    """Retarget ``source_clip`` onto the target and measure it against the true maps.

    Returns degrees / metres: ``rest_error`` (max over limbs at the rest frame of the angle
    between the target's limb and the source's turned onto the target's facing),
    ``tracking_error`` (the same, max over every frame), ``facing_error`` (the target hips'
    travel direction against the source's turned onto the target's facing: the target's
    forward for the generated walks), ``hips_error`` (target hips height at the rest
    frame against its rest height), ``feet_floor`` (lowest target foot joint over the
    clip minus its rest height; None without feet), ``knee_axis`` / ``elbow_axis`` (max
    angle between the target's bend axis and the source's turned one, frames bent > 15°),
    ``knee_backwards`` / ``elbow_forwards`` (share of bent frames bending that way)."""
    from magica_py.io.retarget import pose_world, retarget_with_report
    from magica_py.scene.hierarchy import TransformHierarchy

    out, report = retarget_with_report(source_clip, source_bones, target_bones, warn=False, **(options or {}))
    src_h, tgt_h = TransformHierarchy(source_bones), TransformHierarchy(target_bones)
    times = np.arange(int(round(out.duration / out.frame_time)) + 1) * out.frame_time
    s_rot, s_pos = pose_world(source_clip, src_h, times)
    t_rot, t_pos = pose_world(out, tgt_h, times)
    # the true facing turn: source forward onto the target's, both upright (+Y)
    sf, tf = np.asarray(source_forward, float), np.asarray(target_forward, float)
    yaw = math.atan2(sf[0] * tf[2] - sf[2] * tf[0], sf[0] * tf[0] + sf[2] * tf[2])  # angle from sf to tf about +Y
    turn = qaxis_angle([0.0, 1.0, 0.0], -yaw)
    assert np.allclose(qrotate(turn, sf), tf, atol=1e-9)
    result = {"report": report, "turn_deg": report.turn_deg}
    rest_errors, tracking = {}, {}
    for human, nxt in LIMBS.items():
        if human not in target_truth or human not in source_truth or nxt not in source_truth:
            continue
        d_t = _directions(t_rot, t_pos, tgt_h, target_truth, human, nxt)
        d_s = qrotate(turn, s_pos[:, src_h.index(source_truth[nxt])] - s_pos[:, src_h.index(source_truth[human])])
        err = _angle(d_t, d_s)
        rest_errors[human], tracking[human] = float(err[rest_frame]), float(err.max())
    result["rest_errors"] = rest_errors
    result["rest_error"] = max(rest_errors.values())
    result["tracking_error"] = max(tracking.values())
    hips = tgt_h.index(target_truth["hips"])
    first = min(rest_frame + 1, len(times) - 1)
    travel = t_pos[-1, hips] - t_pos[first, hips]
    s_hips = src_h.index(source_truth["hips"])
    expected = qrotate(turn, s_pos[-1, s_hips] - s_pos[first, s_hips])
    travel[1] = expected[1] = 0.0
    result["facing_error"] = float(_angle(travel, expected)) if np.sum(travel * travel) > 1e-4 else float("nan")
    result["hips_error"] = float(abs(t_pos[rest_frame, hips, 1] - tgt_h.world_position[hips, 1]))
    feet = [tgt_h.index(target_truth[h]) for h in ("leftFoot", "rightFoot", "leftToes", "rightToes") if h in target_truth]
    result["feet_floor"] = (float(t_pos[:, feet, 1].min() - tgt_h.world_position[feet, 1].min()) if feet else None)
    for joint, upper, lower, nxt, key, sign in (
            ("knee", "UpperLeg", "LowerLeg", "Foot", "knee_backwards", -1.0),
            ("elbow", "UpperArm", "LowerArm", "Hand", "elbow_forwards", 1.0)):
        worst, good, bent = 0.0, 0, 0
        for side in ("left", "right"):
            u, lo, n = f"{side}{upper}", f"{side}{lower}", f"{side}{nxt}"
            if not all(k in target_truth for k in (u, lo)) or not all(k in source_truth for k in (u, lo, n)):
                continue
            a_t = _directions(t_rot, t_pos, tgt_h, target_truth, u, lo)
            b_t = _directions(t_rot, t_pos, tgt_h, target_truth, lo, n)
            a_s = qrotate(turn, s_pos[:, src_h.index(source_truth[lo])] - s_pos[:, src_h.index(source_truth[u])])
            b_s = qrotate(turn, s_pos[:, src_h.index(source_truth[n])] - s_pos[:, src_h.index(source_truth[lo])])
            mask = _angle(a_s, b_s) > 15.0
            if not mask.any():
                continue
            axis_t, axis_s = np.cross(_unit(a_t), _unit(b_t)), np.cross(_unit(a_s), _unit(b_s))
            worst = max(worst, float(_angle(axis_t[mask], axis_s[mask]).max()))
            # which way the lower bone leaves the upper one, against the target body's forward
            # (forward of the target after the turn: tf turned with the hips' yaw)
            fwd = qrotate(qmul(t_rot[:, hips], qconj(tgt_h.world_rotation[hips])), np.broadcast_to(tf, a_t.shape))
            perp = _unit(b_t) - _unit(a_t) * np.sum(_unit(a_t) * _unit(b_t), axis=-1, keepdims=True)
            good += int(np.sum(sign * np.sum(perp[mask] * fwd[mask], axis=-1) > 0))
            bent += int(mask.sum())
        result[f"{joint}_axis"] = worst if bent else None
        result[key] = good / bent if bent else None
    return result


def family_case(family: str, folder: Path):
    """(BvhAnimation, true humanoid map in the loaded names) of a family's walk."""
    from magica_py.io.bvh import load_bvh

    skeleton = Skeleton(family)
    anim = load_bvh(skeleton.write_bvh(folder))
    return anim, dict(skeleton.truth)


def cmu_case(frames: int = 1200):
    from dataclasses import replace

    from magica_py.io.bvh import load_bvh
    from magica_py.io.clip import Clip
    from magica_py.io.humanoid import CMU
    anim = load_bvh(DATA / "bvh" / "cmu_01_01.bvh")
    clip = Clip(anim.clip.name, [replace(t, times=t.times[:frames], values=t.values[:frames]) for t in anim.clip.tracks],
                frame_time=anim.clip.frame_time)
    names = {b.name for b in anim.bones}
    return anim.bones, clip, {h: b for h, b in CMU.items() if b in names}


def figures(stream=sys.stdout) -> None:
    import tempfile
    rows = []
    god_bones, god_truth = godette()
    targets = [("Godette", god_bones, god_truth, {"target_map": god_truth}),
               ("character", character_bones(), CHARACTER_TRUTH, {})]
    with tempfile.TemporaryDirectory() as tmp:
        cases = []
        for family in FAMILIES:
            anim, truth = family_case(family, Path(tmp))
            cases.append((family, anim.bones, anim.clip, truth, (-1.0, 0.0, 0.0), {}, 0))
        bones, clip, truth = cmu_case()
        cases.append(("CMU 01_01 (frames 0-1199)", bones, clip, truth, (0.0, 0.0, 1.0), {"source_rest": 0}, 0))
        for name, bones, clip, truth, forward, options, rest in cases:
            for target, t_bones, t_truth, t_options in targets:
                m = measure(bones, clip, truth, t_bones, t_truth, source_forward=forward, rest_frame=rest,
                            options={**options, **t_options})
                rows.append((name, target, m))
    fmt = lambda v, spec: "n/a" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, spec)
    print("| source | target | turn | rest error | tracking error | facing error | hips error | feet vs floor "
          "| knee axis | knee back | elbow axis | elbow fwd |", file=stream)
    print("|---|---|---|---|---|---|---|---|---|---|---|---|", file=stream)
    for name, target, m in rows:
        print(f"| {name} | {target} | {m['turn_deg']:.0f}° | {m['rest_error']:.2f}° | {m['tracking_error']:.2f}° | "
              f"{fmt(m['facing_error'], '.2f')}° | {100 * m['hips_error']:.2f} cm | "
              f"{fmt(None if m['feet_floor'] is None else 100 * m['feet_floor'], '+.2f')} cm | "
              f"{fmt(m['knee_axis'], '.2f')}° | {fmt(m['knee_backwards'], '.0%')} | {fmt(m['elbow_axis'], '.2f')}° | "
              f"{fmt(m['elbow_forwards'], '.0%')} |", file=stream)


if __name__ == "__main__":
    figures()
