"""Humanoid retargeting by world-space rotation deltas (magica_py.io.retarget, io.humanoid)."""
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from magica_py.io.bvh import load_bvh
from magica_py.io.clip import Clip, ClipDriver
from magica_py.io.humanoid import detect_scheme, humanoid_map
from magica_py.io.quat import qconj, qmul, qnormalize, qrotate
from magica_py.io.retarget import RetargetError, pose_world, retarget
from magica_py.scene.hierarchy import TransformHierarchy

DATA = Path(__file__).parents[1].parent / "shared" / "data"
CMU = DATA / "bvh" / "cmu_01_01.bvh"
pytestmark = pytest.mark.skipif(not DATA.is_dir(), reason=f"shared test data folder {DATA} is absent")


@pytest.fixture(scope="module")
def cmu():
    anim = load_bvh(CMU)
    # the first 400 frames keep the tests quick; the clip is still 3.3 s of motion
    short = Clip(anim.clip.name, [replace(t, times=t.times[:400], values=t.values[:400]) for t in anim.clip.tracks],
                 frame_time=anim.clip.frame_time)
    return anim, short


def test_retargeting_onto_its_own_skeleton_reproduces_the_clip(cmu):
    anim, clip = cmu
    out = retarget(clip, anim.bones, anim.bones)
    assert len(out.tracks) == len(clip.tracks)
    for tr in out.tracks:
        ref = clip.track(tr.node, tr.path)
        assert np.allclose(tr.times, ref.times)
        if tr.path == "rotation":
            assert np.all(np.abs(np.sum(tr.values * ref.values, axis=-1)) > 1 - 1e-12), tr.node
        else:
            assert np.allclose(tr.values, ref.values, atol=1e-12)


def _reparameterised(bones, seed=5, scale=1.0):
    """Same rest world positions (times ``scale``), every rest local rotation changed."""
    rng = np.random.default_rng(seed)
    extra = {b.name: qnormalize(rng.normal(size=4)) for b in bones}
    out = []
    for b in bones:
        r_self = extra[b.name]
        r_parent = extra[b.parent] if b.parent else np.array([0.0, 0.0, 0.0, 1.0])
        rot = qmul(qconj(r_parent), qmul(np.asarray(b.rotation), r_self))
        pos = qrotate(qconj(r_parent), np.asarray(b.position) * scale)
        out.append(replace(b, position=tuple(pos), rotation=tuple(rot)))
    return out


@pytest.mark.parametrize("scale", [1.0, 2.0])
def test_retargeting_onto_a_reparameterised_skeleton_reproduces_world_joint_positions(cmu, scale):
    anim, clip = cmu
    target = _reparameterised(anim.bones, scale=scale)
    out = retarget(clip, anim.bones, target)
    src_h, tgt_h = TransformHierarchy(anim.bones), TransformHierarchy(target)
    times = np.arange(0, 400, 37) * clip.frame_time
    _, src_pos = pose_world(clip, src_h, times)
    _, tgt_pos = pose_world(out, tgt_h, times)
    order = [tgt_h.index(n) for n in src_h.names]
    hips = src_h.index("Hips")
    # positions relative to the hips scale with the skeleton; the hips move by the leg-length ratio (= scale)
    rel_src = src_pos - src_pos[:, hips:hips + 1]
    rel_tgt = tgt_pos[:, order] - tgt_pos[:, order][:, hips:hips + 1]
    assert np.allclose(rel_tgt, rel_src * scale, atol=1e-9)
    rest_src = src_h.world_position[hips]
    assert np.allclose(tgt_pos[:, order][:, hips] - rest_src * scale, (src_pos[:, hips] - rest_src) * scale, atol=1e-9)


def test_cmu_walk_drives_a_vrm_avatar_without_nan(cmu):
    from magica_py.io.vrm import load_vrm
    anim, clip = cmu
    with pytest.warns(UserWarning):
        avatar = load_vrm(DATA / "vrm" / "Godette_vrm_v4.vrm")
    out = retarget(clip, anim.bones, avatar.bones, target_map=avatar.humanoid, source_rest=0)
    assert {t.node for t in out.tracks if t.path == "rotation"} == {
        avatar.humanoid[b] for b in avatar.humanoid if b in humanoid_map([b.name for b in anim.bones], "cmu")}
    h = TransformHierarchy(avatar.bones)
    driver = ClipDriver(out, h)
    rest = h.world_position.copy()
    driver.apply(h, 0.0)
    h.propagate()
    # frame 0 is the CMU T-pose, the avatar's rest is a T-pose: the pose barely changes
    hips = h.index("pelvis_Armature")
    assert np.abs(h.world_position - rest).max() < 0.12
    for t in np.linspace(0, clip.duration, 9):
        driver.apply(h, t)
        h.propagate()
        assert np.all(np.isfinite(h.world_position))
    # root translation is the source hips displacement scaled by the leg-length ratio
    track = out.track("pelvis_Armature", "translation")
    src = clip.track("Hips", "translation").values
    moved_src = np.linalg.norm(src[-1] - src[0])
    moved_tgt = np.linalg.norm(track.values[-1] - track.values[0])
    assert 0.3 < moved_tgt / moved_src < 0.7       # Godette's legs are about half as long as subject 01's
    assert h.world_position[hips][1] > 0.3


def test_humanoid_schemes_are_detected_and_overridable(tmp_path):
    cmu_names = ["Hips", "LowerBack", "Spine", "Spine1", "Neck", "Head", "LeftUpLeg", "LeftLeg", "LeftFoot"]
    assert detect_scheme(cmu_names) == "cmu"
    m = humanoid_map(cmu_names)
    assert m["spine"] == "LowerBack" and m["chest"] == "Spine" and m["leftLowerLeg"] == "LeftLeg"
    mixamo = ["mixamorig:Hips", "mixamorig:Spine", "mixamorig:Spine1", "mixamorig:Spine2", "mixamorig:LeftArm"]
    mm = humanoid_map(mixamo)
    assert mm["spine"] == "mixamorig:Spine" and mm["upperChest"] == "mixamorig:Spine2" and mm["leftUpperArm"] == "mixamorig:LeftArm"
    override = tmp_path / "map.yaml"
    override.write_text("chest: Spine1\nupperChest: null\n")
    o = humanoid_map(cmu_names, overrides=override)
    assert o["chest"] == "Spine1" and "upperChest" not in o
    with pytest.raises(ValueError, match="unknown humanoid bone"):
        humanoid_map(cmu_names, overrides={"tail": "Spine"})
    with pytest.raises(ValueError, match="'Nope' is not a bone"):
        humanoid_map(cmu_names, overrides={"head": "Nope"})


def test_a_skeleton_without_hips_cannot_be_retargeted(cmu):
    anim, clip = cmu
    from magica_py.scene.hierarchy import BoneSpec
    with pytest.raises(RetargetError, match="target skeleton: no bone mapped to humanoid 'hips'"):
        retarget(clip, anim.bones, [BoneSpec("pelvis")], target_map="vrm")


def test_rest_alignment_lets_an_a_pose_target_follow_a_t_pose_source(cmu):
    anim, clip = cmu
    down = np.array([0.0, 0.0, -np.sin(np.pi / 8), np.cos(np.pi / 8)])     # 45 deg about -Z: arm down
    target = [replace(b, rotation=tuple(down)) if b.name == "LeftArm" else b for b in anim.bones]
    src_h, tgt_h = TransformHierarchy(anim.bones), TransformHierarchy(target)
    times = np.arange(0, 400, 50) * clip.frame_time
    _, src_pos = pose_world(clip, src_h, times)

    def arm_directions(positions, h):
        a, b, c = (h.index(n) for n in ("LeftArm", "LeftForeArm", "LeftHand"))
        d1, d2 = positions[:, b] - positions[:, a], positions[:, c] - positions[:, b]
        return d1 / np.linalg.norm(d1, axis=1, keepdims=True), d2 / np.linalg.norm(d2, axis=1, keepdims=True)

    want = arm_directions(src_pos, src_h)
    _, aligned = pose_world(retarget(clip, anim.bones, target), tgt_h, times)
    for got, ref in zip(arm_directions(aligned, tgt_h), want):
        assert np.allclose(got, ref, atol=1e-9)
    with pytest.warns(UserWarning, match="45.0 deg off the source's") as caught:   # it says so, per bone
        unaligned = retarget(clip, anim.bones, target, align_rest=False)
    assert {str(w.message).split(": ")[1].split(" ")[0] for w in caught} == {"leftUpperArm", "leftLowerArm"}
    _, naive = pose_world(unaligned, tgt_h, times)
    upper = arm_directions(naive, tgt_h)[0]
    angles = np.degrees(np.arccos(np.clip(np.sum(upper * want[0], axis=1), -1, 1)))
    assert np.allclose(angles, 45.0, atol=1.0)      # without alignment the arm keeps its 45 deg offset


def test_generic_names_of_a_hand_named_rig_find_its_humanoid_bones():
    import warnings
    from magica_py.io.vrm import load_vrm
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        avatar = load_vrm(DATA / "vrm" / "Godette_vrm_v4.vrm")
    names = [b.name for b in avatar.bones]
    assert detect_scheme(names) == "generic"
    found = humanoid_map(names)
    # every bone the generic matcher finds agrees with the file's own VRM humanoid
    assert len(found) == 21 and all(avatar.humanoid[h] == bone for h, bone in found.items())
    assert humanoid_map(["Root", "Pelvis", "Spine_01", "UpperArm_L", "lowerarm.R", "LeftThigh", "calf_r", "Head"]) == {
        "hips": "Pelvis", "spine": "Spine_01", "leftUpperArm": "UpperArm_L", "rightLowerArm": "lowerarm.R", "leftUpperLeg": "LeftThigh",
        "rightLowerLeg": "calf_r", "head": "Head"}
