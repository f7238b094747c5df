"""Scene entries that import asset files: rigs from glTF/VRM, clips, VRM spring bones as cloths."""
import os
import warnings

import numpy as np

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
    assert [c.name for c in scene.cloths] == ["vrm_FrontHair", "vrm_Ribbon", "vrm_HairBall"]
    assert len(scene.colliders) == 4 and all(int(s) == 0 for s in scene.colliders.shape)
    group0 = scene.cloth("vrm_FrontHair")
    assert [scene.colliders.names[i] for i in group0.colliders] == ["vrm_col1_0", "vrm_col1_1"]


@pytest.mark.parametrize("body, path, fragment", [
    ("rigs:\n  - {name: a, file: nowhere.glb}\n", "rigs[0].file", "cannot import"),
    ("rigs:\n  - {name: a, bones: [{name: root}]}\ncloths:\n  - {from_vrm: a}\n", "cloths[0].from_vrm",
     "no rig 'a' loaded from a file"),
    ("rigs:\n  - {name: a, bones: [{name: root}]}\nanimation:\n  - {clip: x.glb, rig: b}\n", "animation[0].rig",
     "unknown rig 'b'"),
    ("rigs:\n  - {name: a, bones: [{name: root}]}\nanimation:\n  - {clip: x.bvh, retarget: {}}\n", "animation[0]",
     "missing 'rig'"),
    # a unit scale whose products overflow (the clip's keys became NaN at generated paths)
    ("rigs:\n  - {name: a, file: nowhere.glb, unit_scale: 1e300}\n", "rigs[0].unit_scale",
     "expected a number in (0, 1e+06], got 1e+300"),
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


def _world_at(scene, t, name):
    h = scene.hierarchy
    scene.animation.evaluate(h, t)
    h.propagate()
    return h.world_position[h.index(name)].copy()


def test_a_clip_on_its_own_rig_gets_the_rigs_unit_scale(tmp_path, shared_data):
    """Fox.glb is in centimetres: a rig loaded with unit_scale 0.01 plays its clip at the same
    scale (the clip's b_Hip_01 translation keys are ~40 cm, not ~40 m)."""
    fox = rel(tmp_path, shared_data / "gltf" / "Fox.glb")
    scene = load_scene(write_scene(tmp_path, f"""
rigs:
  - {{name: fox, file: {fox}, unit_scale: 0.01}}
animation:
  - {{clip: "{fox}#Run", rig: fox}}
"""))
    rest_hips = scene.hierarchy.world_position[scene.hierarchy.index("b_Hip_01")].copy()
    assert 0.40 < rest_hips[1] < 0.45
    for t in (0.0, 0.3, 0.7):
        hips = _world_at(scene, t, "b_Hip_01")
        assert 0.25 < hips[1] < 0.6, (t, hips)
        assert np.linalg.norm(hips - rest_hips) < 0.3


def test_a_placed_rig_keeps_its_place_when_the_clip_animates_its_root(tmp_path, shared_data):
    """Keys on a root bone are composed with the rig's placement, like its rest pose."""
    bvh = rel(tmp_path, shared_data / "bvh" / "cmu_01_01.bvh")
    body = f"""
rigs:
  - {{name: mocap, file: {bvh}, position: [5, 0, 0], euler: [0, 90, 0]}}
animation:
  - {{clip: {bvh}, rig: mocap, trim: [0, 1], rate: 30}}
"""
    placed = load_scene(write_scene(tmp_path, body))
    plain = load_scene(write_scene(tmp_path, body.replace("position: [5, 0, 0], euler: [0, 90, 0]", "position: [0, 0, 0]")))
    for t in (0.0, 0.5):
        a, b = _world_at(placed, t, "Hips"), _world_at(plain, t, "Hips")
        expected = np.array([5.0 + b[2], b[1], -b[0]])   # +90 degrees about +Y: (x, y, z) -> (z, y, -x)
        np.testing.assert_allclose(a, expected, atol=1e-9)


def test_trim_and_rate_shrink_a_long_capture(tmp_path, shared_data):
    """trim keeps seconds [start, end] of the source re-timed from 0; rate sets keys per second."""
    bvh = rel(tmp_path, shared_data / "bvh" / "cmu_01_01.bvh")
    scene = load_scene(write_scene(tmp_path, f"""
rigs:
  - {{name: mocap, file: {bvh}}}
animation:
  - {{clip: {bvh}, rig: mocap, trim: [2.0, 4.0], rate: 30}}
"""))
    anim = scene.animation
    hips = scene.hierarchy.index("Hips")
    d = [k for k in range(len(anim.kind)) if anim.target[k] == hips and anim.key_count[k, 1]][0]
    rotation_keys = anim.key_count[d, 1]
    assert rotation_keys == 61                       # 2 s at 30 keys/s, both ends
    times = anim.key_time[anim.key_first[d, 1]:anim.key_first[d, 1] + rotation_keys]
    np.testing.assert_allclose(times[[0, -1]], [0.0, 2.0])
    # the trimmed clip at 0.5 s is the source at 2.5 s
    from magica_py.io import load_bvh
    source = load_bvh(shared_data / "bvh" / "cmu_01_01.bvh")
    expected = source.clip.track("Hips", "translation").sample(2.5)
    np.testing.assert_allclose(_world_at(scene, 0.5, "Hips"), expected, atol=0.02)


@pytest.mark.parametrize("entry, path, fragment", [
    ("trim: [3, 1]", "animation[0].trim[1]", "expected end > start"),
    ("trim: 2", "animation[0].trim", "expected [start, end]"),
    ("rate: 0", "animation[0].rate", "expected a number in [1, 1000] keys/s"),
])
def test_bad_trim_and_rate_are_reported_at_their_key(tmp_path, shared_data, entry, path, fragment):
    bvh = rel(tmp_path, shared_data / "bvh" / "cmu_01_01.bvh")
    with pytest.raises(ConfigError) as info:
        load_scene(write_scene(tmp_path, f"rigs:\n  - {{name: m, file: {bvh}}}\nanimation:\n  - {{clip: {bvh}, rig: m, {entry}}}\n"))
    issues = [i for i in info.value.issues if i.path == path]
    assert issues and fragment in issues[0].message, info.value.report()


def test_retargeting_onto_a_vrm_uses_its_humanoid_map(tmp_path, shared_data, monkeypatch):
    """retarget_to= the rig's bones and target_map= the rig's own VRM humanoid map."""
    from magica_py.io import sections

    seen = {}
    real = sections.load_clip

    def spy(ref, **kwargs):
        seen.update(kwargs)
        return real(ref, **kwargs)

    monkeypatch.setattr(sections, "load_clip", spy)
    vrm = rel(tmp_path, shared_data / "vrm" / "Godette_vrm_v4.vrm")
    bvh = rel(tmp_path, shared_data / "bvh" / "cmu_01_01.bvh")
    with warnings.catch_warnings(record=True) as caught:   # the collider quirk concerns from_vrm cloths only
        warnings.simplefilter("always")
        scene = load_scene(write_scene(tmp_path, f"""
rigs:
  - {{name: avatar, file: {vrm}}}
animation:
  - {{clip: {bvh}, rig: avatar, retarget: {{source_rest: 0}}, trim: [0, 1], rate: 30}}
"""))
    assert not [w for w in caught if "radius 1 m" in str(w.message)]
    assert seen["target_map"]["hips"] == "pelvis_Armature" and seen["target_map"]["leftUpperLeg"] == "thigh.l_Armature"
    assert {b.name for b in seen["retarget_to"]} >= {"pelvis_Armature", "thigh.l_Armature"}
    assert "target_bones" not in seen or seen["target_bones"] is None
    driven = {scene.hierarchy.names[t] for t in scene.animation.target}
    assert {"pelvis_Armature", "thigh.l_Armature", "head_Armature"} <= driven


def test_from_vrm_parameters_override_the_mapped_values_in_every_cloth(tmp_path, shared_data):
    vrm = rel(tmp_path, shared_data / "vrm" / "Godette_vrm_v4.vrm")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        scene = load_scene(write_scene(tmp_path, f"""
rigs:
  - {{name: avatar, file: {vrm}}}
cloths:
  - {{from_vrm: avatar, parameters: {{gravity: 2.5, inertia: {{world_inertia: 0.5}}}}}}
"""))
        plain = load_scene(write_scene(tmp_path, f"rigs:\n  - {{name: avatar, file: {vrm}}}\ncloths:\n  - {{from_vrm: avatar}}\n"))
    for name in ("vrm_FrontHair", "vrm_Ribbon", "vrm_HairBall"):
        params, mapped = scene.cloth(name).parameters, plain.cloth(name).parameters
        assert params["gravity"] == 2.5 and mapped["gravity"] == 0.0
        assert params["inertia.world_inertia"] == 0.5 and mapped["inertia.world_inertia"] == 1.0
        assert params["angle_restoration.stiffness"] == mapped["angle_restoration.stiffness"]   # the rest is kept


def test_from_vrm_bad_parameter_is_reported_at_the_entry(tmp_path, shared_data):
    vrm = rel(tmp_path, shared_data / "vrm" / "Godette_vrm_v4.vrm")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        with pytest.raises(ConfigError) as info:
            load_scene(write_scene(tmp_path, f"rigs:\n  - {{name: avatar, file: {vrm}}}\n"
                                             f"cloths:\n  - {{from_vrm: avatar, parameters: {{gravty: 2}}}}\n"))
    paths = info.value.paths()
    assert paths == ["cloths[0].parameters.gravty"], info.value.report()   # once, not once per cloth
    assert "did you mean 'gravity'" in info.value.issues[0].message


def test_an_explicit_oversized_colliders_choice_silences_the_reminder(tmp_path, shared_data):
    vrm = rel(tmp_path, shared_data / "vrm" / "Godette_vrm_v4.vrm")
    body = f"rigs:\n  - {{name: avatar, file: {vrm}}}\ncloths:\n  - {{from_vrm: avatar{{}}}}\n"
    with pytest.warns(UserWarning, match="radius 1 m exceeds"):
        load_scene(write_scene(tmp_path, body.replace("{}", "")))          # default keep: reminded
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scene = load_scene(write_scene(tmp_path, body.replace("{}", ", oversized_colliders: keep")))
    assert max(scene.colliders.radius) == 1.0                                 # kept, silently


def test_retarget_target_map_auto_finds_the_same_bones_on_godette(tmp_path, shared_data):
    """`retarget: {target_map: auto}` replaces the rig's VRM humanoid map with the generic
    name matcher; on Godette it finds the same bones, so the clip is identical."""
    vrm = rel(tmp_path, shared_data / "vrm" / "Godette_vrm_v4.vrm")
    bvh = rel(tmp_path, shared_data / "bvh" / "cmu_01_01.bvh")
    body = (f"rigs:\n  - {{name: avatar, file: {vrm}}}\nanimation:\n"
            f"  - {{clip: {bvh}, rig: avatar, retarget: {{source_rest: 0}}, trim: [0, 1], rate: 30}}\n")
    own = load_scene(write_scene(tmp_path, body))
    auto = load_scene(write_scene(tmp_path, body.replace("{source_rest: 0}", "{source_rest: 0, target_map: auto}")))
    assert len(own.animation.kind) == len(auto.animation.kind) == 22
    np.testing.assert_array_equal(own.animation.key_value, auto.animation.key_value)
