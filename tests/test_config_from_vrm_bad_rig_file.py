"""A ``from_vrm`` cloth whose rig has a ``file`` or ``prefix`` of the wrong type: the rig's own
error is reported (file, line, path), not a TypeError from joining a list to a path."""
import pytest

from magica_py import cli

SCENE = """
version: 1
scene: {fps: 60, frames: 2}
rigs:
  - {name: godette, file: FILE, prefix: PREFIX}
cloths:
  - {from_vrm: godette}
"""


@pytest.mark.parametrize("file, prefix, path, expected", [
    ("[1, 2]", '""', "rigs[0].file", "expected a .gltf, .glb, .vrm or .bvh file path, got a list [1, 2]"),
    ("{x: 1}", '""', "rigs[0].file", "expected a .gltf, .glb, .vrm or .bvh file path, got a mapping"),
    ("true", '""', "rigs[0].file", "expected a .gltf, .glb, .vrm or .bvh file path, got a bool True"),
    ("VRM", "[x]", "rigs[0].prefix", "expected a name prefix, got a list ['x']"),
])
def test_a_from_vrm_rig_with_a_file_or_prefix_of_the_wrong_type_is_reported_not_a_crash(
        file, prefix, path, expected, tmp_path, capsys, shared_data):
    vrm = shared_data / "vrm" / "Godette_vrm_v4.vrm"
    scene = tmp_path / "s.yaml"
    scene.write_text(SCENE.replace("FILE", file.replace("VRM", str(vrm))).replace("PREFIX", prefix))
    assert cli.main(["validate", str(scene)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "internal error" not in err
    assert f"{scene}:5: {path}: {expected}" in err


RETARGET = """
version: 1
scene: {fps: 60, frames: 2}
rigs:
  - name: character
    bones: [{name: Hips, position: [0, 1, 0]}, {name: Spine, parent: Hips, position: [0, 0.2, 0]}, BAD]
animation:
  - {clip: CLIP, rig: character, retarget: {source_rest: 0}}
"""


@pytest.mark.parametrize("bad, path, expected", [
    ("{name: null, parent: Spine}", "rigs[0].bones[2].name", "missing 'name': expected a bone name"),
    ("{name: true, parent: Spine}", "rigs[0].bones[2].name", "expected a bone name, got a bool True"),
    ("{parent: Spine}", "rigs[0].bones[2]", "missing 'name': expected a bone name"),
])
def test_a_retarget_onto_a_rig_with_a_nameless_bone_reports_the_bone_not_a_crash(bad, path, expected, tmp_path,
                                                                                 capsys, shared_data):
    scene = tmp_path / "s.yaml"
    scene.write_text(RETARGET.replace("BAD", bad).replace("CLIP", str(shared_data / "bvh" / "cmu_01_01.bvh")))
    assert cli.main(["validate", str(scene)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "internal error" not in err
    assert f"{scene}:6: {path}: {expected}" in err
