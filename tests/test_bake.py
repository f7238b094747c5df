"""magica-py bake: the baked file, loaded as a clip on the same rig, reproduces the simulated
local poses (1e-6 m / 1e-6 rad) for glTF, VRM, BVH and generated rigs; the glTF / VRM output
is a copy of the source file (mesh, skin, VRM data kept); bad requests fail cleanly."""
from __future__ import annotations

import json

import numpy as np
import pytest

from magica_py.bake.bake import bake_scene, pose_error
from magica_py.config import load_scene
from magica_py.io.clip import ClipDriver

FRAMES = 6
TOLERANCE_M = 1e-6
TOLERANCE_RAD = 1e-6


def replay(scene_path, overrides, clip, motion, key_times):
    """Apply ``clip`` on a fresh copy of the scene's rig (rest pose) at each key time and read
    the captured bones' local poses back: (F, B, 3), (F, B, 4)."""
    scene = load_scene(scene_path, overrides)
    h = scene.hierarchy
    driver = ClipDriver(clip, h, loop=False)
    bones = np.asarray(motion.bones, dtype=np.int64)
    position = np.zeros(motion.local_position.shape)
    rotation = np.zeros(motion.local_rotation.shape)
    for k, t in enumerate(key_times):
        h.local_position[:] = h.rest_local_position
        h.local_rotation[:] = h.rest_local_rotation
        driver.apply(h, float(t))
        position[k] = h.local_position[bones]
        rotation[k] = h.local_rotation[bones]
    return position, rotation


def normalized(raw: dict) -> dict:
    """glTF JSON with pygltflib's defaults filled in (``mode: 4``, ``emissiveFactor``, ...) so
    that a copy written by pygltflib compares equal to its source."""
    import pygltflib

    return json.loads(pygltflib.GLTF2.gltf_from_json(json.dumps(raw)).to_json())


def assert_round_trip(motion, position, rotation):
    dp, dr = pose_error(motion, position, rotation)
    assert dp < TOLERANCE_M, f"position differs by {dp:.3g} m"
    assert dr < TOLERANCE_RAD, f"rotation differs by {dr:.3g} rad"


def assert_cloth_moved(motion, names):
    """The capture holds the simulated pose, not the animation alone: cloth bones turn."""
    index = [motion.names.index(n) for n in names]
    q = motion.local_rotation[:, index]
    assert np.abs(q[-1] - q[0]).max() > 1e-4


def test_bvh_rig_round_trip_through_our_bvh_writer(tmp_path, shared_data):
    bvh = shared_data / "bvh" / "cmu_01_01.bvh"
    scene_file = tmp_path / "bvh_tail.yaml"
    scene_file.write_text(f"""
version: 1
scene: {{name: bvh_tail, fps: 60, frames: {FRAMES}}}
rigs:
  - name: mocap
    file: {bvh}
    parts:
      - chain: {{name: tail, parent: Hips, bones: 4, length: 0.4, direction: [0, -0.5, -1]}}
animation:
  - {{clip: {bvh}, rig: mocap, trim: [1.0, 1.5], rate: 60, loop: false}}
cloths:
  - {{name: tail, root_bones: [tail_0], connection: line, preset: tail}}
""")
    out = tmp_path / "baked.bvh"
    result = bake_scene(scene_file, out, frames=FRAMES)
    m = result.motion
    assert m.frames == FRAMES and "tail_3" in m.names and "Hips" in m.names
    assert_cloth_moved(m, ["tail_1", "tail_2"])
    from magica_py.io.bvh import load_bvh, parse_bvh

    parsed = parse_bvh(out)
    assert parsed.frame_count == FRAMES and parsed.frame_time == pytest.approx(1 / 60)
    # the rig's own unit (CMU: 1/0.45 inch) is kept: OFFSETs equal the source file's
    source = parse_bvh(bvh)
    assert np.allclose(parsed.offsets[parsed.names.index("LeftUpLeg")], source.offsets[source.names.index("LeftUpLeg")])
    clip = load_bvh(out, units="cmu").clip
    position, rotation = replay(scene_file, (), clip, m, np.arange(FRAMES) * parsed.frame_time)
    assert_round_trip(m, position, rotation)


def test_gltf_rig_round_trip_into_a_copy_of_the_fox(tmp_path, repo_root, shared_data):
    scene_path = repo_root / "configs" / "fox_run.yaml"
    out = tmp_path / "fox_baked.glb"
    result = bake_scene(scene_path, out, frames=FRAMES, animation_name="sim")
    m = result.motion
    assert_cloth_moved(m, ["b_Tail02_013", "b_Tail03_014"])
    from magica_py.io.gltf import load_gltf, read_document

    rig = load_gltf(out, unit_scale=0.01)
    assert set(rig.clips) == {"Survey", "Walk", "Run", "sim"}           # the original clips are kept
    _, _, raw = read_document(out)
    _, _, source = read_document(shared_data / "gltf" / "Fox.glb")
    raw, source = normalized(raw), normalized(source)
    for key in ("meshes", "skins", "materials", "images", "textures"):
        assert raw.get(key) == source.get(key), key
    assert len(raw["nodes"]) == len(source["nodes"])                       # no node added: all are the file's
    clip = rig.clip("sim")
    times = clip.tracks[0].times if len(clip.tracks[0].times) == FRAMES else m.times.astype(np.float32)
    position, rotation = replay(scene_path, (), clip, m, times)
    assert_round_trip(m, position, rotation)


def test_vrm_rig_round_trip_keeps_the_avatar(tmp_path, repo_root, shared_data):
    scene_path = repo_root / "configs" / "vrm_godette_mocap.yaml"
    out = tmp_path / "godette_baked.vrm"
    result = bake_scene(scene_path, out, frames=FRAMES)
    m = result.motion
    from magica_py.io.gltf import read_document
    from magica_py.io.sections import load_clip

    _, _, raw = read_document(out)
    _, _, source = read_document(shared_data / "vrm" / "Godette_vrm_v4.vrm")
    assert raw["extensions"]["VRM"] == source["extensions"]["VRM"]         # spring bones, humanoid, meta
    raw, source = normalized(raw), normalized(source)
    assert raw["meshes"] == source["meshes"] and raw["skins"] == source["skins"]
    assert [a["name"] for a in raw["animations"]] == ["vrm_godette_mocap_baked"]
    clip = load_clip(f"{out}#vrm_godette_mocap_baked")                     # VRM 0.x: mirrored along Z
    position, rotation = replay(scene_path, (), clip, m, m.times.astype(np.float32))
    assert_round_trip(m, position, rotation)
    chain_bones = [n for n in m.names if n.startswith("FrontHair") or n.startswith("Ribbon")]
    assert chain_bones
    # the hair is simulated on top of a moving capture: its local rotation changes
    assert np.abs(np.diff(m.local_rotation[:, [m.names.index(n) for n in chain_bones]], axis=0)).max() > 1e-5


@pytest.mark.parametrize("suffix", [".bvh", ".gltf"])
def test_generated_rig_round_trip_as_bvh_and_as_a_new_gltf(tmp_path, repo_root, suffix):
    scene_path = repo_root / "configs" / "character_walk.yaml"
    overrides = ()
    out = tmp_path / f"walk{suffix}"
    result = bake_scene(scene_path, out, overrides, bones=["skirt_*", "hips"], frames=FRAMES)
    m = result.motion
    assert "root" in m.names and "hips" in m.names            # ancestors come along
    assert not any(n.startswith("hair") for n in m.names)
    if suffix == ".bvh":
        from magica_py.io.bvh import load_bvh

        clip = load_bvh(out, units="m").clip
        times = np.arange(FRAMES) * (1 / 60)
    else:
        from magica_py.io.gltf import load_gltf

        assert out.with_suffix(".bin").exists()
        rig = load_gltf(out)
        assert [b.name for b in rig.bones] == m.names             # the nodes, parents first
        clip = rig.clip("character_walk_baked")
        times = m.times.astype(np.float32)
    position, rotation = replay(scene_path, overrides, clip, m, times)
    assert_round_trip(m, position, rotation)


def test_bake_refuses_bad_requests_without_writing(tmp_path, repo_root, capsys):
    from magica_py.cli import main

    scene = str(repo_root / "configs" / "character_walk.yaml")
    cases = [(["--out", str(tmp_path / "x.fbx")], "expected a file ending in"),
             (["--out", str(tmp_path / "x.vrm"), "--frames", "2"], "a .vrm output is a copy of a VRM rig"),
             (["--out", str(tmp_path / "x.bvh"), "--bones", "nope_*", "--frames", "2"], "matches no bone"),
             (["--out", str(tmp_path / "no" / "x.bvh")], "does not exist"),
             (["--out", str(tmp_path / "x.glb"), "--units", "cm", "--frames", "2"], "--units applies to a .bvh")]
    for argv, message in cases:
        assert main(["bake", scene, *argv]) == 2
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []


def test_bake_cli_writes_and_summarises(tmp_path, repo_root, capsys):
    from magica_py.cli import main

    out = tmp_path / "tail.bvh"
    assert main(["bake", str(repo_root / "configs" / "tail_orbit.yaml"), "--out", str(out), "--frames", "3"]) == 0
    captured = capsys.readouterr()
    assert "bones x 3 frames" in captured.out
    assert out.read_text().startswith("HIERARCHY") and not list(tmp_path.glob("*.partial"))


def test_vrm1_rig_with_two_roots_round_trip(tmp_path, shared_data):
    """A VRM 1.0 spring example (plain glTF axes, mirrored along X): both root nodes of the
    file (the spring chain and the collider's node) are baked, the chain swings."""
    source = shared_data / "vrm" / "three-vrm-springbone-examples" / "sphere-collider.gltf"
    scene_file = tmp_path / "vrm1.yaml"
    scene_file.write_text(f"""
version: 1
scene: {{name: vrm1, fps: 60, frames: {FRAMES}}}
rigs:
  - {{name: springs, file: {source}}}
animation:
  - {{target: Spring A, oscillate: {{property: rotation, axis: [0, 0, 1], amplitude: 40, frequency: 2}}}}
cloths:
  - {{from_vrm: springs}}
""")
    out = tmp_path / "springs.vrm"
    m = bake_scene(scene_file, out, frames=FRAMES).motion
    assert set(m.names) == {"Spring A", "Spring B", "Spring C", "Spring D", "Spring E", "Collider"}
    assert_cloth_moved(m, ["Spring C", "Spring D"])
    from magica_py.io.gltf import load_gltf

    clip = load_gltf(out).clip("vrm1_baked")                       # VRM 1.0: mirrored along X
    position, rotation = replay(scene_file, (), clip, m, m.times.astype(np.float32))
    assert_round_trip(m, position, rotation)


def test_a_node_given_by_a_matrix_is_written_as_trs_and_round_trips(tmp_path):
    """glTF forbids ``matrix`` on an animated node: the copy carries the node's TRS instead."""
    c, s = np.cos(np.pi / 6), np.sin(np.pi / 6)
    matrix = [c, 0, -s, 0, 0, 1, 0, 0, s, 0, c, 0, 0.1, 1.0, 0.2, 1]     # column-major: turn about Y, then move
    (tmp_path / "m.gltf").write_text(json.dumps({
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "base", "matrix": matrix, "children": [1]},
                  {"name": "b1", "translation": [0, -0.2, 0], "children": [2]},
                  {"name": "b2", "translation": [0, -0.2, 0]}]}))
    scene_file = tmp_path / "m.yaml"
    scene_file.write_text(f"""
version: 1
scene: {{name: matrix_rig, fps: 60, frames: {FRAMES}}}
rigs: [{{name: r, file: m.gltf}}]
animation:
  - {{target: base, oscillate: {{property: rotation, axis: [1, 0, 0], amplitude: 30, frequency: 3}}}}
cloths:
  - {{name: c, root_bones: [b1], connection: line}}
""")
    out = tmp_path / "out.gltf"
    m = bake_scene(scene_file, out, frames=FRAMES).motion
    written = json.loads(out.read_text())
    assert "matrix" not in written["nodes"][0]
    from magica_py.io.gltf import load_gltf

    rig = load_gltf(out)
    assert np.allclose(rig.bones[0].position, load_gltf(tmp_path / "m.gltf").bones[0].position)
    position, rotation = replay(scene_file, (), rig.clip("matrix_rig_baked"), m, m.times.astype(np.float32))
    assert_round_trip(m, position, rotation)
