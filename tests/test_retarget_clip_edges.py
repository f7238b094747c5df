"""Clip edges and scene options of retargeting: a BVH frame count one off, the rest frame
not played, trimming by frames, ``retarget:`` options checked in the scene file, warnings
naming the entry, and ``magica-py retarget-check``."""
import os
import warnings

import numpy as np
import pytest

from retarget_skeletons import DATA, Skeleton
from magica_py.config import ConfigError
from magica_py.config.load import validate_file
from magica_py.io.bvh import load_bvh, parse_bvh
from magica_py.io.retarget import retarget_with_report
from magica_py.io.sections import file_axis_to_project, load_clip

pytestmark = pytest.mark.skipif(not DATA.is_dir(), reason=f"shared test data folder {DATA} is absent")
GODETTE = DATA / "vrm" / "Godette_vrm_v4.vrm"


@pytest.fixture(scope="module")
def walk_bvh(tmp_path_factory):
    return Skeleton("biovision").write_bvh(tmp_path_factory.mktemp("walk"))


@pytest.fixture(scope="module")
def godette_bones():
    from magica_py.io.vrm import load_vrm
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        avatar = load_vrm(GODETTE)
    return avatar.bones, avatar.humanoid


@pytest.mark.parametrize("declared", [120, 122])
def test_a_bvh_frame_count_one_off_is_read_with_a_warning(walk_bvh, tmp_path, declared):
    text = walk_bvh.read_text().replace("Frames: 121", f"Frames: {declared}")
    path = tmp_path / "off.bvh"
    path.write_text(text)
    with pytest.warns(UserWarning, match=rf"off.bvh: line \d+: header declares {declared} frames but the file has "
                                         r"121; all 121 frames are read"):
        bvh = parse_bvh(path)
    assert bvh.frame_count == 121 and bvh.motion.shape[0] == 121


def test_the_rest_frame_is_not_played(walk_bvh, godette_bones):
    bones, humanoid = godette_bones
    anim = load_bvh(walk_bvh)
    full, _ = retarget_with_report(anim.clip, anim.bones, bones, target_map=humanoid, source_rest=0, warn=False)
    clip = load_clip(walk_bvh.name, base_dir=walk_bvh.parent, retarget_to=bones, target_map=humanoid,
                     retarget_options={"source_rest": 0})
    dt = anim.clip.frame_time
    assert clip.duration == pytest.approx(full.duration - dt)
    for tr in clip.tracks:                      # the first key is the source's frame 1
        ref = full.track(tr.node, tr.path)
        assert np.allclose(tr.values[0], ref.values[1], atol=1e-12), tr.node
    # a trim that starts later is left alone; one inside the rest frame starts after it
    later = load_clip(walk_bvh.name, base_dir=walk_bvh.parent, retarget_to=bones, target_map=humanoid,
                      retarget_options={"source_rest": 0}, trim=[0.5, 1.0])
    assert later.duration == pytest.approx(0.5)
    early = load_clip(walk_bvh.name, base_dir=walk_bvh.parent, retarget_to=bones, target_map=humanoid,
                      retarget_options={"source_rest": 0}, trim=[0.0, 1.0])
    assert early.duration == pytest.approx(1.0 - dt)


def test_clips_are_trimmed_by_frames(walk_bvh):
    whole = load_clip(walk_bvh.name, base_dir=walk_bvh.parent)
    part = load_clip(walk_bvh.name, base_dir=walk_bvh.parent, trim_frames=[10, 40])
    dt = whole.frame_time
    assert part.duration == pytest.approx(30 * dt)
    hips = whole.track("Hips", "translation")
    assert np.allclose(part.track("Hips", "translation").values[0], hips.values[10])
    assert np.allclose(part.track("Hips", "translation").values[-1], hips.values[40])
    # glTF: frames are the clip's key times
    fox = load_clip("Fox.glb#Run", base_dir=DATA / "gltf", unit_scale=0.01)
    times = fox.frame_times()
    fox_part = load_clip("Fox.glb#Run", base_dir=DATA / "gltf", unit_scale=0.01, trim_frames=[2, 5])
    assert fox_part.duration == pytest.approx(times[5] - times[2])
    with pytest.raises(ValueError, match=r"frames \[2, 9999\] outside its \d+ frames"):
        load_clip("Fox.glb#Run", base_dir=DATA / "gltf", unit_scale=0.01, trim_frames=[2, 9999])


def test_source_axes_are_read_in_the_file_convention():
    assert np.allclose(file_axis_to_project("+X"), [-1, 0, 0])     # BVH / glTF: X mirrored into Unity axes
    assert np.allclose(file_axis_to_project("z"), [0, 0, 1])
    assert np.allclose(file_axis_to_project([0, 1, 0]), [0, 1, 0])
    assert np.allclose(file_axis_to_project("+Z", "z"), [0, 0, -1])  # VRM 0.x mirrors Z
    with pytest.raises(ValueError, match="expected an axis"):
        file_axis_to_project("sideways")


def _scene(tmp_path, animation: str, rig: str | None = None) -> os.PathLike:
    godette = os.path.relpath(GODETTE, tmp_path)
    rig = rig or f"  - {{name: avatar, file: {godette}}}\n"
    path = tmp_path / "scene.yaml"
    path.write_text("version: 1\nscene: {fps: 30, frames: 10}\nrigs:\n" + rig + "animation:\n" + animation)
    return path


def test_scene_retarget_options_turn_the_clip(tmp_path, walk_bvh):
    bvh = os.path.relpath(walk_bvh, tmp_path)
    path = _scene(tmp_path, f"""  - {{clip: {bvh}, rig: avatar, trim_frames: [1, 60], rate: 30,
     retarget: {{source_forward: +X, source_up: +Y}}}}\n""")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)     # Godette's oversized collider note
        resolved = validate_file(path)
    assert resolved is not None


@pytest.mark.parametrize("options, where, fragment", [
    ("retarget: {source_forward: sideways}", "animation[0].retarget.source_forward", "expected an axis of the source file"),
    ("retarget: {source_forward: +X, source_up: -X}", "animation[0].retarget.source_up", "parallel to source_forward"),
    ("retarget: {source_rest: first}", "animation[0].retarget.source_rest", "expected 'bind' or a frame number"),
    ("retarget: {turn: 90}", "animation[0].retarget.turn", "unknown key"),
    ("retarget: {align_rest: 1}", "animation[0].retarget.align_rest", "expected true or false"),
    ("trim: [0, 1], trim_frames: [1, 5]", "animation[0].trim_frames", "not both"),
    ("trim_frames: [5, 2]", "animation[0].trim_frames[1]", "expected last > first"),
    ("trim_frames: [0.5, 2]", "animation[0].trim_frames", "expected [first, last] frame numbers"),
])
def test_bad_retarget_options_are_reported_at_their_path(tmp_path, walk_bvh, options, where, fragment):
    bvh = os.path.relpath(walk_bvh, tmp_path)
    path = _scene(tmp_path, f"  - {{clip: {bvh}, rig: avatar, {options}}}\n")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        with pytest.raises(ConfigError) as info:
            validate_file(path)
    assert where in info.value.paths(), str(info.value)
    assert fragment in str(info.value)


def test_validate_warns_naming_the_entry(tmp_path, walk_bvh):
    """An explicit-bones rig without arms or feet: the lost motion is reported at the entry."""
    bvh = os.path.relpath(walk_bvh, tmp_path)
    rig = ("  - name: body\n    bones:\n      - {name: hips, position: [0, 1, 0]}\n"
           "      - {name: spine, parent: hips, position: [0, 0.3, 0]}\n"
           "      - {name: head, parent: spine, position: [0, 0.4, 0]}\n"
           "      - {name: thigh_l, parent: hips, position: [-0.1, 0, 0]}\n"
           "      - {name: shin_l, parent: thigh_l, position: [0, -0.45, 0]}\n"
           "      - {name: thigh_r, parent: hips, position: [0.1, 0, 0]}\n"
           "      - {name: shin_r, parent: thigh_r, position: [0, -0.45, 0]}\n")
    path = _scene(tmp_path, f"  - {{clip: {bvh}, rig: body}}\n", rig=rig)
    path.write_text(path.read_text().replace("rig: body}", "rig: body, retarget: {}}"))
    with pytest.warns(UserWarning, match=r"scene.yaml: animation\[0\]: retargeting biovision: source bones without "
                                         r"a target \(their motion is lost\): LeftCollar \(0.14 m\), RightCollar \(0.14 m\), LeftAnkle"):
        validate_file(path)


def test_retarget_check_prints_the_map_facing_and_alignment(tmp_path, walk_bvh, capsys):
    from magica_py.cli import main
    bvh = os.path.relpath(walk_bvh, tmp_path)
    path = _scene(tmp_path, f"  - {{clip: {bvh}, rig: avatar, retarget: {{}}}}\n")
    assert main(["retarget-check", str(path)]) == 0
    out = capsys.readouterr().out
    assert "animation[0] -> rig 'avatar'" in out
    assert "leftUpperArm   LeftShoulder" in out and "-> upper_arm.l_Armature" in out
    assert "'LeftShoulder' mapped as leftUpperArm by its place in the chain" in out
    assert "source facing: forward -X, up +Y (detected; feet agree)" in out
    assert "facing turn applied to the source: 90.0 deg" in out
    assert "rest alignment error after retargeting (deg):" in out and "leftLowerLeg     0.00" in out
    bad = _scene(tmp_path, f"  - {{clip: {bvh}, rig: avatar, retarget: {{source_up: 7}}}}\n")
    assert main(["retarget-check", str(bad)]) == 2
    assert "animation[0].retarget.source_up" in capsys.readouterr().err
