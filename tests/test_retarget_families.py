"""Retargeting skeletons of every naming family (generated BVH files: centimetres, facing +X,
hips at the floor in the rest pose, with and without clavicles) and the CMU capture onto
Godette and onto the character rig: the bone map found, facing, hips height, limb
directions and the axes knees and elbows bend about (figures: tests/retarget_skeletons.py)."""
import re
import warnings

import numpy as np
import pytest

from retarget_skeletons import (CHARACTER_TRUTH, DATA, FAMILIES, Skeleton, character_bones, cmu_case,
                                family_case, godette, measure)
from magica_py.io.bvh import load_bvh
from magica_py.io.quat import qaxis_angle, qangle
from magica_py.io.retarget import retarget_with_report
from magica_py.io.skeleton_match import match_humanoid
from magica_py.scene.hierarchy import BoneSpec, TransformHierarchy

pytestmark = pytest.mark.skipif(not DATA.is_dir(), reason=f"shared test data folder {DATA} is absent")


@pytest.fixture(scope="module")
def targets():
    bones, humanoid = godette()
    return {"Godette": (bones, humanoid, {"target_map": humanoid}),
            "character": (character_bones(), CHARACTER_TRUTH, {})}


@pytest.fixture(scope="module")
def cases(tmp_path_factory):
    folder = tmp_path_factory.mktemp("families")
    return {family: family_case(family, folder) for family in FAMILIES}


def test_generated_bvh_angles_reproduce_the_walk(tmp_path):
    """The fixture's own oracle: the BVH file read back gives the rotations it was made from."""
    skeleton = Skeleton("biovision")
    hips, local = skeleton.walk()
    anim = load_bvh(skeleton.write_bvh(tmp_path), units="cm", mirror_axis="x")
    from magica_py.io import coords
    for name in ("LeftHip", "LeftKnee", "LeftShoulder", "LeftElbow"):
        got = anim.clip.track(name, "rotation").values
        assert np.all(qangle(got, coords.rotation_to_unity(local[name], "x")) < 1e-6), name
    assert np.allclose(anim.root_positions(), coords.position_to_unity(hips, "x"), atol=1e-7)
    assert abs(hips[0, 1] - 1.0) < 1e-12 and anim.bones[0].position == (0.0, 0.0, 0.0)   # rest hips at the floor


@pytest.mark.parametrize("family", list(FAMILIES))
def test_each_family_is_matched_to_its_true_humanoid_bones(cases, family):
    anim, truth = cases[family]
    h = TransformHierarchy(anim.bones)
    match = match_humanoid(list(h.names), list(h.parent))
    assert match.mapping == truth
    if family.startswith("biovision"):      # LeftShoulder is the upper arm: the structure says so, and the report
        assert any("'LeftShoulder' mapped as leftUpperArm" in n for n in match.notes)


def test_family_names_are_reported():
    from magica_py.io.humanoid import detect_family
    for family in FAMILIES:
        names = [name for name, *_ in Skeleton(family).joints]
        assert detect_family(names) == family.replace("-no-collar", "")


@pytest.mark.parametrize("target", ["Godette", "character"])
@pytest.mark.parametrize("family", list(FAMILIES))
def test_a_family_walk_lands_on_the_target(cases, targets, family, target):
    anim, truth = cases[family]
    bones, target_truth, options = targets[target]
    m = measure(anim.bones, anim.clip, truth, bones, target_truth, source_forward=(-1.0, 0.0, 0.0), options=options)
    assert abs(m["turn_deg"] - 90.0) < 1e-6                         # file +X (project -X) turned onto +Z
    assert m["rest_error"] <= 5.0 and m["tracking_error"] <= 5.0
    assert m["facing_error"] <= 2.0                                  # she walks where she faces
    assert m["hips_error"] <= 0.02                                   # standing hips at her own height
    assert m["knee_axis"] <= 5.0 and m["knee_backwards"] >= 0.99
    if target == "Godette":
        assert -0.02 <= m["feet_floor"] <= 0.02                      # feet neither float nor sink
        assert m["elbow_axis"] <= 5.0 and m["elbow_forwards"] >= 0.99
    report = m["report"]
    assert report.source_frame.describe().startswith("forward -X, up +Y")
    assert report.target_frame.describe().startswith("forward +Z, up +Y")


@pytest.mark.parametrize("target", ["Godette", "character"])
def test_the_cmu_capture_lands_on_the_target(targets, target):
    bones, clip, truth = cmu_case(frames=600)
    t_bones, t_truth, options = targets[target]
    m = measure(bones, clip, truth, t_bones, t_truth, source_forward=(0.0, 0.0, 1.0),
                options={"source_rest": 0, **options})
    assert m["turn_deg"] < 1e-6
    assert m["rest_error"] <= 5.0 and m["facing_error"] <= 2.0 and m["hips_error"] <= 0.02
    # the character's knee bone has no shin below it: its direction is the knee's rotation of
    # a shin continuing the thigh at rest, 3 deg off the capture's T-pose shin
    assert m["knee_axis"] <= (5.0 if target == "Godette" else 15.0) and m["knee_backwards"] >= 0.95
    if target == "Godette":
        assert m["tracking_error"] <= 5.0 and m["elbow_axis"] <= 5.0 and -0.02 <= m["feet_floor"] <= 0.02


def test_a_given_source_facing_replaces_the_detected_one(cases, targets):
    anim, truth = cases["mixamo"]
    bones, humanoid, options = targets["Godette"]
    # the right facing given explicitly: the same clip as detected
    detected, _ = retarget_with_report(anim.clip, anim.bones, bones, warn=False, **options)
    given, report = retarget_with_report(anim.clip, anim.bones, bones, warn=False, source_forward=(-1.0, 0.0, 0.0),
                                         source_up=(0.0, 1.0, 0.0), **options)
    assert report.source_frame.how == "given"
    for a, b in zip(detected.tracks, given.tracks):
        assert np.allclose(a.values, b.values, atol=1e-12)
    # a wrong one is obeyed: the clip is turned by 180 deg instead of 90
    _, wrong = retarget_with_report(anim.clip, anim.bones, bones, warn=False, source_forward=(0.0, 0.0, -1.0), **options)
    assert abs(wrong.turn_deg - 180.0) < 1e-6


def test_an_undetermined_facing_warns_and_does_not_turn(targets):
    bones = [BoneSpec("Hips", None, (0, 1, 0)), BoneSpec("Spine", "Hips", (0, 0.2, 0)), BoneSpec("Head", "Spine", (0, 0.4, 0))]
    from magica_py.io.clip import Clip, Track
    clip = Clip("bare", [Track("Spine", "rotation", np.array([0.0, 0.1]), np.tile(qaxis_angle([1, 0, 0], 0.2), (2, 1)))],
                frame_time=0.1)
    t_bones, humanoid, options = targets["Godette"]
    with pytest.warns(UserWarning, match="facing could not be determined .*no left/right pair"):
        _, report = retarget_with_report(clip, bones, t_bones, **options)
    assert report.turn_deg == 0.0 and not report.source_frame.determined


def test_limbs_off_at_rest_and_lost_source_bones_warn(cases, targets):
    anim, _ = cases["humanik"]                          # an A-pose source onto T-pose Godette
    bones, humanoid, options = targets["Godette"]
    with pytest.warns(UserWarning) as caught:   # every limb off at rest, each its own warning
        retarget_with_report(anim.clip, anim.bones, bones, align_rest=False, **options)
    messages = [str(w.message) for w in caught]
    # 45 deg A-pose, her arm 4 deg below level
    assert any(re.search(r"leftUpperArm \(upper_arm.l_Armature\) is 41.0 deg off", m) for m in messages), messages
    assert {m.split(": ")[1].split(" ")[0] for m in messages} == {
        "leftUpperArm", "rightUpperArm", "leftLowerArm", "rightLowerArm"}, messages
    with warnings.catch_warnings():
        warnings.simplefilter("error")                   # aligned: no warning at all
        _, report = retarget_with_report(anim.clip, anim.bones, bones, **options)
    assert max(report.limb_errors.values()) < 1e-6
    with pytest.warns(UserWarning, match=r"source bones without a target .*Character1_LeftArm \(0\.28 m\)"):
        _, report = retarget_with_report(anim.clip, anim.bones, character_bones())
    # the rig has no arms and no feet: the topmost bones of each lost part, each at least 10 % of a leg long
    assert {b for b, _, _ in report.lost} == {"Character1_LeftArm", "Character1_RightArm", "Character1_LeftFoot",
                                              "Character1_RightFoot"}
    text = "\n".join(report.lines())
    assert "leftUpperLeg   Character1_LeftUpLeg" in text and "-> leg_l" in text
    assert "facing turn applied to the source: 90.0 deg" in text


def test_the_character_rig_maps_its_thigh_as_the_thigh():
    h = TransformHierarchy(character_bones())
    match = match_humanoid(list(h.names), list(h.parent))
    assert match.mapping == CHARACTER_TRUTH
    assert "'leg_l' mapped as leftUpperLeg by its place in the chain (by its name alone it would be leftLowerLeg)" \
        in match.notes


def test_real_skeletons_are_matched_like_their_own_maps():
    """Godette's hand-made names give her file's VRM humanoid; CMU's give the CMU table."""
    from magica_py.io.humanoid import CMU, HUMANOID_BONES
    bones, humanoid = godette()
    h = TransformHierarchy(bones)
    match = match_humanoid(list(h.names), list(h.parent))
    assert match.mapping == {k: v for k, v in humanoid.items() if k in HUMANOID_BONES}
    cmu = load_bvh(DATA / "bvh" / "cmu_01_01.bvh")
    h = TransformHierarchy(cmu.bones)
    match = match_humanoid(list(h.names), list(h.parent))
    assert match.mapping == CMU and match.family == "cmu-cgspeed" and match.notes == []


@pytest.mark.parametrize("name, label", [
    ("J_Bip_L_UpperArm", ("left", ("UpperArm",))), ("J_Bip_C_Hips", (None, ("hips",))),
    ("Bip01_R_Toe0", ("right", ("Toes",))), ("rhumerus", ("right", ("UpperArm",))),
    ("LeftShoulder", ("left", ("Shoulder", "UpperArm"))), ("leg_l", ("left", ("LowerLeg", "UpperLeg"))),
    ("DEF-upper_arm.L.001", ("left", ("UpperArm",))), ("mixamorig:LeftHandIndex1", ("left", ("Finger",))),
    ("Ab", (None, ("spine",))), ("clavicle_r", ("right", ("Shoulder",))), ("ball_l", ("left", ("Toes",))),
])
def test_names_are_labelled_with_their_side_and_possible_parts(name, label):
    from magica_py.io.humanoid import name_label
    assert name_label(name)[:2] == label


def test_twist_and_split_bones_are_not_taken_for_joints():
    # Rigify: DEF-forearm.L.001 splits the forearm; an arm roll bone sits in the chain
    names = ["Hips", "Chest", "LeftArm", "LeftArmRoll", "LeftForeArm", "LeftForeArm.001", "LeftHand",
             "RightArm", "RightForeArm", "RightHand", "LeftUpLeg", "LeftLeg", "LeftFoot", "RightUpLeg", "RightLeg",
             "RightFoot", "Head"]
    parents = [-1, 0, 1, 2, 3, 4, 5, 1, 7, 8, 0, 10, 11, 0, 13, 14, 1]
    m = match_humanoid(names, parents).mapping
    assert (m["leftUpperArm"], m["leftLowerArm"], m["leftHand"]) == ("LeftArm", "LeftForeArm", "LeftHand")
    assert "leftShoulder" not in m and m["hips"] == "Hips" and m["head"] == "Head"
