"""Write the procedural scenes of the motion-capture stress suite (issue 16 item 7).

    python benchmarks/mocap_scenes.py          # (re)writes configs/hard/mocap_*_{character,godette}.yaml

Every motion drives the rig's root bone with dense keyframes (positions and rotations sampled
every 1/60 s, the jitter every 1/120 s), so that one description serves both rigs:

* ``backflip``: stand, crouch, jump with a full backward turn about the hips in 0.5 s of
  flight (720 deg/s, the hips on a ballistic parabola under 9.81 m/s^2), land, stand;
* ``roll``: crouch to half the hips height, a forward roll (360 deg about the hips in 0.8 s)
  travelling 1.2 hips heights along +Z, stand up;
* ``sprint``: start at 10 m/s^2 to 6 m/s, run 0.4 s, stop at 10 m/s^2, legs swinging +-45 deg
  at 2.5 Hz;
* ``jitter``: the root and the head shaken by uniform noise re-drawn every 1/120 s (a noisy
  120 Hz capture): +-5 mm on each axis for the root, +-3 deg about each axis for the head;
* ``spin``: 3 rev/s about the vertical while running on the spot (the character's is the
  existing ``configs/hard/mocap_spin.yaml``; Godette's is written here with the same drivers).

The rigs: the character of ``configs/character_walk.yaml`` (hair fan with a head sphere,
12 x 4 skirt with thigh capsules and the ground) and Godette from her VRM file with the
cloths and colliders of her spring bones (``from_vrm``, as ``configs/vrm_godette_mocap.yaml``).
Rotations are about the hips: the root (on the floor) is placed so that the hips follow the
path, ``root = hips(t) - R(t) (hips offset)``. A key's rotation is a single-axis angle
(``euler``), so the shortest-arc slerp between keys (at most 12 deg apart) follows it.
"""
from __future__ import annotations

import math
import pathlib

import numpy as np
import yaml

ROOT = pathlib.Path(__file__).resolve().parent.parent
HARD = ROOT / "configs" / "hard"
KEY_PERIOD = 1.0 / 60.0          # s between keys of the smooth motions
JITTER_PERIOD = 1.0 / 120.0      # s between noise samples
GRAVITY = 9.81                   # m/s^2, the jump's parabola

CHARACTER_HEADER = pathlib.Path(ROOT / "configs" / "character_walk.yaml")


# ----------------------------------------------------------------------------- rigs
def character_rig() -> dict:
    """The character rig, colliders and cloths of configs/character_walk.yaml (as committed),
    with its root, hips offset (m, from the root) and the bones the drivers move."""
    doc = yaml.safe_load(CHARACTER_HEADER.read_text())
    return {"rigs": doc["rigs"], "colliders": doc["colliders"], "cloths": doc["cloths"],
            "root": "root", "root_rest": np.zeros(3), "hips_offset": np.array([0.0, 1.0, 0.0]),
            "hips": "hips", "head": "head", "legs": ("leg_l", "leg_r"), "label": "character"}


def godette_rig() -> dict:
    """Godette from her VRM file (the path is relative to configs/hard), her spring-bone cloths
    and colliders; root ``Armature_rootJoint`` rests 0.05 m up, the pelvis 0.595 m above it."""
    return {"rigs": [{"name": "godette", "file": "../../../shared/data/vrm/Godette_vrm_v4.vrm"}],
            "colliders": None,
            "cloths": [{"from_vrm": "godette", "group_by": "group", "oversized_colliders": "keep"}],
            "root": "Armature_rootJoint", "root_rest": np.array([0.0, 0.050284, 0.0]),
            "hips_offset": np.array([0.0, 0.595369, 0.041128]),
            "hips": "pelvis_Armature", "head": "head_Armature", "legs": ("thigh.l_Armature", "thigh.r_Armature"),
            "label": "godette"}


# ----------------------------------------------------------------------------- motions
def rotation_x(angle_deg: float) -> np.ndarray:
    a = math.radians(angle_deg)
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def smoothstep(u: float) -> float:
    u = min(max(u, 0.0), 1.0)
    return u * u * (3.0 - 2.0 * u)


def backflip(t: float, height: float) -> tuple[np.ndarray, float]:
    """Hips displacement (m, from rest) and turn about X (deg) at time t (s): crouch 0.3-0.5 s,
    flight 0.5-1.0 s (the full turn), landing crouch 1.0-1.2 s, stand by 1.5 s."""
    flight = 0.5
    crouch = -0.2 * height
    if t < 0.3:
        return np.zeros(3), 0.0
    if t < 0.5:
        return np.array([0.0, crouch * smoothstep((t - 0.3) / 0.2), 0.0]), 0.0
    if t < 0.5 + flight:
        tau = t - 0.5
        v0 = GRAVITY * flight / 2.0 - crouch / flight      # back to the crouch height on landing
        y = crouch + v0 * tau - 0.5 * GRAVITY * tau * tau
        return np.array([0.0, y, -0.4 * tau / flight]), -360.0 * tau / flight
    if t < 1.2:
        return np.array([0.0, crouch, -0.4]), -360.0
    return np.array([0.0, crouch * (1.0 - smoothstep((t - 1.2) / 0.3)), -0.4]), -360.0


def roll(t: float, height: float) -> tuple[np.ndarray, float]:
    """Crouch to half the hips height 0.3-0.6 s, roll forward 0.6-1.4 s (360 deg, 1.2 hips
    heights along +Z), stand up 1.4-1.8 s."""
    low = -0.5 * height
    travel = 1.2 * height
    if t < 0.3:
        return np.zeros(3), 0.0
    if t < 0.6:
        return np.array([0.0, low * smoothstep((t - 0.3) / 0.3), 0.0]), 0.0
    if t < 1.4:
        u = (t - 0.6) / 0.8
        return np.array([0.0, low, travel * u]), 360.0 * u
    return np.array([0.0, low * (1.0 - smoothstep((t - 1.4) / 0.4)), travel]), 360.0


def sprint(t: float, height: float) -> tuple[np.ndarray, float]:
    """Start at 10 m/s^2 from 0.3 s to 6 m/s, run 0.4 s, stop at 10 m/s^2 (standing from 1.9 s)."""
    a, top = 10.0, 6.0
    t1 = top / a                         # 0.6 s of acceleration
    s = t - 0.3
    if s <= 0.0:
        z = 0.0
    elif s < t1:
        z = 0.5 * a * s * s
    elif s < t1 + 0.4:
        z = 0.5 * a * t1 * t1 + top * (s - t1)
    elif s < 2 * t1 + 0.4:
        u = s - t1 - 0.4
        z = 0.5 * a * t1 * t1 + top * 0.4 + top * u - 0.5 * a * u * u
    else:
        z = a * t1 * t1 + top * 0.4
    return np.array([0.0, 0.0, z]), 0.0


CMU_TRIM = (2.0, 4.0)            # s of the capture: a forward jump and its landing
MOTIONS = {"backflip": (backflip, 1.5), "roll": (roll, 1.8), "sprint": (sprint, 1.9)}   # motion, end (s)
MOTION_TEXT = {
    "backflip": "stand; crouch 0.3-0.5 s; jump with a full backward turn about the hips in the 0.5 s of flight\n"
                "(720 deg/s, hips on a ballistic parabola); landing crouch to 1.2 s; standing from 1.5 s",
    "roll": "crouch to half the hips height 0.3-0.6 s; forward roll 0.6-1.4 s (360 deg about the hips,\n"
            "1.2 hips heights along +Z); stand up by 1.8 s",
    "sprint": "sprint start at 10 m/s^2 from 0.3 s to 6 m/s, 0.4 s at 6 m/s, stop at 10 m/s^2 (standing\n"
              "from 1.9 s); legs swing +-45 deg at 2.5 Hz",
}


class FlowKey(dict):
    """A keyframe written on one line."""


yaml.SafeDumper.add_representer(FlowKey, lambda d, data: d.represent_mapping("tag:yaml.org,2002:map", data,
                                                                               flow_style=True))


def root_keys(motion, rig: dict, end: float) -> list[dict]:
    """Keys of the rig's root: the hips on the motion's path, the body turned about the hips."""
    offset = rig["hips_offset"]
    height = float(offset[1])
    keys = []
    count = int(round(end / KEY_PERIOD))
    for i in range(count + 1):
        t = i * KEY_PERIOD
        shift, angle = motion(t, height)
        root = rig["root_rest"] + offset + shift - rotation_x(angle) @ offset
        keys.append(FlowKey({"time": round(t, 6), "position": [round(float(x), 6) for x in root],
                     "euler": [round(angle, 4), 0.0, 0.0]}))
    return keys


def jitter_keys(rig: dict, start: float, end: float, seed: int) -> tuple[list[dict], list[dict]]:
    """Root position keys (+-5 mm noise) and head rotation keys (+-3 deg noise), every 1/120 s."""
    rng = np.random.default_rng(seed)
    count = int(round((end - start) / JITTER_PERIOD))
    root = [FlowKey({"time": 0.0, "position": [float(x) for x in rig["root_rest"]]})]
    head = [FlowKey({"time": 0.0, "euler": [0.0, 0.0, 0.0]})]
    for i in range(count + 1):
        t = round(start + i * JITTER_PERIOD, 6)
        last = i == count
        noise = np.zeros(3) if last else rng.uniform(-0.005, 0.005, 3)
        turn = np.zeros(3) if last else rng.uniform(-3.0, 3.0, 3)
        root.append(FlowKey({"time": t, "position": [round(float(x), 6) for x in rig["root_rest"] + noise]}))
        head.append(FlowKey({"time": t, "euler": [round(float(x), 4) for x in turn]}))
    return root, head


# ----------------------------------------------------------------------------- scenes
def leg_swing(rig: dict, start: float, end: float) -> list[dict]:
    left, right = rig["legs"]
    return [{"target": left, "oscillate": {"property": "rotation", "axis": [1, 0, 0], "amplitude": 45,
                                           "frequency": 2.5, "phase": 0}, "start": start, "end": end, "fade": 0.2},
            {"target": right, "oscillate": {"property": "rotation", "axis": [1, 0, 0], "amplitude": 45,
                                            "frequency": 2.5, "phase": 180}, "start": start, "end": end, "fade": 0.2}]


def scene(name: str, rig: dict, animation: list, duration: float, description: str) -> str:
    doc = {"version": 1,
           "scene": {"name": name, "fps": 60, "duration": duration, "simulation_frequency": 90,
                     "max_steps_per_frame": 3, "gravity": [0, -1, 0], "seed": 1},
           "rigs": rig["rigs"], "animation": animation}
    if rig["colliders"] is not None:
        doc["colliders"] = rig["colliders"]
    doc["cloths"] = rig["cloths"]
    doc["output"] = {"rrd": f"replays/{name}.rrd",
                     "log": {"skeleton": True, "particles": True, "edges": True, "colliders": True, "metrics": True}}
    head = "".join(f"# {line}\n" if line else "#\n" for line in description.splitlines())
    body = yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=120)
    return head + body


def write_all() -> list[pathlib.Path]:
    written = []
    common = ("Hard case of the motion-capture stress suite (issue 16 item 7; docs/STABILITY.md,\n"
              "`magica-py stability --suite mocap`). Written by benchmarks/mocap_scenes.py: edit that, not this.\n")
    for rig in (character_rig(), godette_rig()):
        label = rig["label"]
        for motion_name, (motion, end) in MOTIONS.items():
            animation = [{"target": rig["root"], "keyframes": {"interpolation": "linear",
                                                               "keys": root_keys(motion, rig, end)}}]
            if motion_name == "sprint":
                animation += leg_swing(rig, 0.3, end)
            doc = scene(f"mocap_{motion_name}_{label}", rig, animation, end + 2.0,
                        common + f"Motion ({label} rig): {MOTION_TEXT[motion_name]}.")
            written.append(_write(f"mocap_{motion_name}_{label}.yaml", doc))
        root, head = jitter_keys(rig, 0.3, 1.8, seed=16)
        animation = [{"target": rig["root"], "keyframes": {"interpolation": "linear", "keys": root}},
                     {"target": rig["head"], "keyframes": {"interpolation": "linear", "keys": head}}]
        doc = scene(f"mocap_jitter_{label}", rig, animation, 3.8,
                    common + "Motion: the root shaken +-5 mm and the head +-3 deg, noise re-drawn every 1/120 s "
                             f"from 0.3 to 1.8 s ({label} rig).")
        written.append(_write(f"mocap_jitter_{label}.yaml", doc))
        if label == "godette":
            animation = [{"target": rig["root"], "spin": {"axis": [0, 1, 0], "speed": 1080}, "start": 0.2,
                          "end": 1.7, "fade": 0.3}] + leg_swing(rig, 0.2, 1.7)
            doc = scene("mocap_spin_godette", rig, animation, 4.0,
                        common + "Motion: 3 rev/s about the vertical 0.2-1.7 s (faded in and out over 0.3 s) "
                                 "while the legs swing +-45 deg at 2.5 Hz (Godette rig; the character's is "
                                 "mocap_spin.yaml).")
            written.append(_write("mocap_spin_godette.yaml", doc))
        clip = {"clip": "../../../shared/data/bvh/cmu_01_01.bvh", "rig": rig["rigs"][0]["name"],
                "retarget": {"source_rest": 0}, "trim": list(CMU_TRIM), "rate": 60, "loop": False}
        doc = scene(f"mocap_cmu_{label}", rig, [clip], CMU_TRIM[1] - CMU_TRIM[0] + 2.0,
                    common + f"Motion: CMU capture 01_01 (mocap.cs.cmu.edu, NSF EIA-0196217; cgspeed BVH), seconds "
                             f"{CMU_TRIM[0]:g}-{CMU_TRIM[1]:g} (a forward jump and its landing), retargeted by humanoid "
                             f"bone names, then held for 2 s ({label} rig).")
        written.append(_write(f"mocap_cmu_{label}.yaml", doc))
    return written


def _write(name: str, text: str) -> pathlib.Path:
    path = HARD / name
    path.write_text(text)
    return path


if __name__ == "__main__":
    for p in write_all():
        print(p.relative_to(ROOT))
