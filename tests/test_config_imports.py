"""Scene entries that import asset files: rigs from glTF/VRM, clips, VRM spring bones as cloths."""
import os

import pytest

from magica_py.config import ConfigError, load_scene


def write_scene(tmp_path, body: str):
    path = tmp_path / "scene.yaml"
    path.write_text("version: 1\nscene: {fps: 30, frames: 10}\n" + body)
    return path


def rel(tmp_path, target) -> str:
    """Asset paths are relative to the scene file's folder."""
    return os.path.relpath(target, tmp_path)


def test_rig_and_clip_from_a_glb(tmp_path, shared_data):
    fox = rel(tmp_path, shared_data / "gltf" / "Fox.glb")
    path = write_scene(tmp_path, f"""
rigs:
  - {{name: fox, file: {fox}, unit_scale: 0.01}}
animation:
  - {{clip: "{fox}#Walk", rig: fox, drop: ["b_Tail*"]}}
cloths:
  - {{name: tail, root_bones: ["b_Tail01*"], preset: tail}}
""")
    scene = load_scene(path)
    h = scene.hierarchy
    assert h.count == 26
    tail = scene.cloth("tail")
    assert [h.names[i] for i in tail.root_bones] == ["b_Tail01_012"]
    driven = {h.names[t] for t in scene.animation.target}
    assert driven and not any(n.startswith("b_Tail") for n in driven)  # dropped: the cloth moves them
    assert "b_Hip_01" in driven


def test_vrm_spring_bones_become_cloths_and_colliders(tmp_path, shared_data):
    vrm = rel(tmp_path, shared_data / "vrm" / "Godette_vrm_v4.vrm")
    path = write_scene(tmp_path, f"""
rigs:
  - {{name: avatar, file: {vrm}}}
cloths:
  - {{from_vrm: avatar, group_by: group}}
""")
    with pytest.warns(UserWarning, match="radius 1 m"):
        scene = load_scene(path)
    assert [c.name for c in scene.cloths] == ["vrm_group0", "vrm_group1", "vrm_group2"]
    assert len(scene.colliders) == 4 and all(int(s) == 0 for s in scene.colliders.shape)
    group0 = scene.cloth("vrm_group0")
    assert [scene.colliders.names[i] for i in group0.colliders] == ["vrm_col1_0", "vrm_col1_1"]


@pytest.mark.parametrize("body, path, fragment", [
    ("rigs:\n  - {name: a, file: nowhere.glb}\n", "rigs[0].file", "cannot import"),
    ("rigs:\n  - {name: a, bones: [{name: root}]}\ncloths:\n  - {from_vrm: a}\n", "cloths[0].from_vrm",
     "no rig 'a' loaded from a file"),
    ("rigs:\n  - {name: a, bones: [{name: root}]}\nanimation:\n  - {clip: x.glb, rig: b}\n", "animation[0].rig",
     "unknown rig 'b'"),
    ("rigs:\n  - {name: a, bones: [{name: root}]}\nanimation:\n  - {clip: x.bvh, retarget: {}}\n", "animation[0]",
     "missing 'rig'"),
])
def test_import_errors_name_the_entry(tmp_path, body, path, fragment):
    with pytest.raises(ConfigError) as info:
        load_scene(write_scene(tmp_path, body))
    issues = [i for i in info.value.issues if i.path == path]
    assert issues and fragment in issues[0].message, info.value.report()


def test_unknown_clip_name_is_reported_at_the_clip(tmp_path, shared_data):
    fox = rel(tmp_path, shared_data / "gltf" / "Fox.glb")
    path = write_scene(tmp_path, f"rigs:\n  - {{name: fox, file: {fox}}}\nanimation:\n  - {{clip: '{fox}#Dance', rig: fox}}\n")
    with pytest.raises(ConfigError) as info:
        load_scene(path)
    assert info.value.paths() == ["animation[0].clip"]
    assert "Dance" in info.value.issues[0].message
