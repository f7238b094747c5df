"""Scene-loader entry points: rig / cloth / clip sections from files (magica_py.io.sections)."""
from pathlib import Path

import numpy as np
import pytest

from magica_py.io.clip import ClipDriver
from magica_py.io.errors import AssetError
from magica_py.io.gltf import load_gltf
from magica_py.io.sections import load_clip, rig_section, split_clip_reference
from magica_py.scene.hierarchy import BoneSpec, TransformHierarchy

DATA = Path(__file__).parents[1].parent / "shared" / "data"
pytestmark = pytest.mark.skipif(not DATA.is_dir(), reason=f"shared test data folder {DATA} is absent")


def _bones(section):
    return [BoneSpec(b["name"], b["parent"], tuple(b["position"]), tuple(b["rotation"]), tuple(b["scale"]))
            for b in section["bones"]]


def test_clip_reference_splits_file_and_clip_name():
    assert split_clip_reference("Fox.glb#Run") == ("Fox.glb", "Run")
    assert split_clip_reference("walk.bvh") == ("walk.bvh", None)


def test_fox_run_with_the_tail_dropped_and_a_prefix():
    clip = load_clip("Fox.glb#Run", base_dir=DATA / "gltf", drop=["fox_b_Tail*"], prefix="fox_", unit_scale=0.01)
    assert len(clip.tracks) == 18 and all(n.startswith("fox_b_") for n in clip.nodes())
    assert not any("Tail" in n for n in clip.nodes())
    hip = clip.track("fox_b_Hip_01", "translation")
    assert np.abs(hip.values).max() < 1.0      # centimetres scaled to metres


def test_a_file_with_several_clips_needs_a_clip_name():
    with pytest.raises(AssetError, match=r"name the clip with Fox\.glb#<name>; the file has \['Run', 'Survey', 'Walk'\]"):
        load_clip("Fox.glb", base_dir=DATA / "gltf")


def test_keyframe_entries_play_like_the_clip_driver():
    from magica_py.scene.animation import Animation
    rig = load_gltf(DATA / "gltf" / "Fox.glb", unit_scale=0.01)
    clip = rig.clip("Walk")
    entries = clip.to_animation_entries(loop=True)
    assert len(entries) == 21 and entries[0]["keyframes"]["keys"][0]["time"] == 0.0
    h_yaml, h_clip = TransformHierarchy(rig.bones), TransformHierarchy(rig.bones)
    animation = Animation.from_specs(entries, h_yaml)
    driver = ClipDriver(clip, h_clip, loop=True)
    for t in (0.05, 0.33, 0.7, 1.1, 2.45):
        animation.evaluate(h_yaml, t)
        driver.apply(h_clip, t)
        assert np.allclose(h_yaml.local_position, h_clip.local_position, atol=1e-9)
        dots = np.abs(np.sum(h_yaml.local_rotation * h_clip.local_rotation, axis=1))
        assert np.all(dots > 1 - 1e-9), t


def test_bvh_clip_retargeted_onto_a_vrm_rig_section():
    rig = rig_section(DATA / "vrm" / "Godette_vrm_v4.vrm", name="godette")
    clip = load_clip("cmu_01_01.bvh", base_dir=DATA / "bvh", retarget_to=_bones(rig), target_map=rig["humanoid"],
                     retarget_options={"source_rest": 0})
    # the rest frame (the T-pose, frame 0) is not played: 2751 of the 2752 frames
    assert clip.frame_time == 0.0083333 and len(clip.tracks[0].times) == 2751
    assert "pelvis_Armature" in clip.nodes() and "head_Armature" in clip.nodes()
    assert all(np.all(np.isfinite(t.values)) for t in clip.tracks)


def test_a_long_capture_can_be_trimmed_and_resampled():
    clip = load_clip("cmu_01_01.bvh", base_dir=DATA / "bvh", trim=[2.0, 4.0], rate=30.0, prefix="cmu_")
    assert clip.duration == pytest.approx(2.0) and len(clip.tracks[0].times) == 61
    assert all(n.startswith("cmu_") for n in clip.nodes())
    full = load_clip("cmu_01_01.bvh", base_dir=DATA / "bvh")
    ref = full.track("Hips", "translation").sample(3.0)
    assert np.allclose(clip.track("cmu_Hips", "translation").sample(1.0), ref, atol=1e-9)


def test_rig_sections_of_a_glb_and_a_bvh():
    fox = rig_section(DATA / "gltf" / "Fox.glb", unit_scale=0.01, prefix="fox_")
    assert fox["name"] == "Fox" and len(fox["bones"]) == 26 and len(fox["joints"]) == 24
    assert fox["joints"][0].startswith("fox_") and fox["humanoid"] == {}
    cmu = rig_section(DATA / "bvh" / "cmu_01_01.bvh")
    assert len(cmu["bones"]) == 31 and cmu["bones"][0]["parent"] is None and cmu["joints"] == []
    with pytest.raises(AssetError, match=r"unknown rig file type '\.fbx'"):
        rig_section(DATA / "gltf" / "Fox.fbx")
