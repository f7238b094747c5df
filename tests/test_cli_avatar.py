"""magica-py run AVATAR.vrm: the avatar's spring bones run without a scene file."""
import numpy as np
import yaml

from magica_py import cli
from magica_py.avatar import avatar_scene, default_motion


def test_default_motion_moves_the_hips_and_head():
    entries = default_motion({"hips": "pelvis", "head": "skull"})
    assert {e["target"] for e in entries} == {"pelvis", "skull"}
    assert all("oscillate" in e for e in entries)
    assert default_motion({}) == []


def test_run_a_vrm_and_save_its_scene(shared_data, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    vrm = shared_data / "vrm" / "Godette_vrm_v4.vrm"
    saved = tmp_path / "scenes" / "godette.yaml"
    assert cli.main(["run", str(vrm), "--frames", "6", "--no-rrd", "--save-scene", str(saved)]) == 0
    out = capsys.readouterr()
    assert "Godette_vrm_v4: 6 frames" in out.out and "wrote the scene" in out.err
    doc = yaml.safe_load(saved.read_text())
    assert [c["from_vrm"] for c in doc["cloths"]] == ["avatar"]
    assert not doc["rigs"][0]["file"].startswith("/")                 # relative to the saved file
    assert {e["target"] for e in doc["animation"]} == {"pelvis_Armature", "head_Armature"}
    # the saved scene runs as it is, and a second --save-scene may replace it
    assert cli.main(["run", str(saved), "--frames", "3", "--no-rrd", "-q"]) == 0
    assert cli.main(["run", str(vrm), "--frames", "1", "--no-rrd", "-q", "--save-scene", str(saved)]) == 0


def test_save_scene_never_replaces_another_file(shared_data, tmp_path, capsys):
    other = tmp_path / "mine.yaml"
    other.write_text("version: 1\n")
    vrm = shared_data / "vrm" / "Godette_vrm_v4.vrm"
    assert cli.main(["run", str(vrm), "--frames", "1", "--no-rrd", "--save-scene", str(other)]) == 2
    assert "not written by --save-scene" in capsys.readouterr().err
    assert other.read_text() == "version: 1\n"


def test_a_clip_is_retargeted_onto_the_avatar(shared_data, tmp_path):
    vrm = shared_data / "vrm" / "Godette_vrm_v4.vrm"
    clip = shared_data / "bvh" / "cmu_01_01.bvh"
    doc, facts = avatar_scene(vrm, str(clip), base_dir=tmp_path)
    entry = doc["animation"][0]
    assert entry["rig"] == "avatar" and entry["retarget"] == {"source_rest": 0}
    assert 20.0 < doc["scene"]["duration"] <= 30.0           # the capture's length (23 s), capped
    import magica_py

    result = magica_py.simulate(vrm, frames=4)               # the API takes the avatar too
    assert set(result.cloths) and all(np.isfinite(c.positions).all() for c in result.cloths.values())


def test_a_missing_clip_is_named(shared_data, capsys):
    vrm = shared_data / "vrm" / "Godette_vrm_v4.vrm"
    assert cli.main(["run", str(vrm), "--clip", "nowhere/walk.bvh#x", "--no-rrd"]) == 2
    assert "--clip: nowhere/walk.bvh: file not found" in capsys.readouterr().err


def test_clip_and_save_scene_need_an_avatar(repo_root, capsys):
    scene = str(repo_root / "configs" / "tail_orbit.yaml")
    assert cli.main(["run", scene, "--clip", "x.bvh"]) == 2
    assert "--clip applies to a VRM avatar" in capsys.readouterr().err
    assert cli.main(["run", scene, "--save-scene", "x.yaml"]) == 2
    assert "--save-scene applies to a VRM avatar" in capsys.readouterr().err
