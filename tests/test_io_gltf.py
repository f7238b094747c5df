"""glTF / GLB import: hierarchy, skins, animation clips, malformed files (magica_py.io.gltf)."""
import json
from pathlib import Path

import numpy as np
import pytest

from magica_py.io.clip import ClipDriver
from magica_py.io.coords import position_to_unity, rotation_to_unity
from magica_py.io.errors import AssetError
from magica_py.io.gltf import load_gltf
from magica_py.scene.hierarchy import TransformHierarchy

DATA = Path(__file__).parents[1].parent / "shared" / "data"
needs_data = pytest.mark.skipif(not DATA.is_dir(), reason=f"shared test data folder {DATA} is absent")


@needs_data
def test_fox_has_24_joints_a_three_bone_tail_and_three_clips():
    rig = load_gltf(DATA / "gltf" / "Fox.glb", unit_scale=0.01)
    assert len(rig.bones) == 26 and len(rig.joints) == 24
    tail = [b.name for b in rig.bones if b.name.startswith("b_Tail")]
    assert tail == ["b_Tail01_012", "b_Tail02_013", "b_Tail03_014"]
    assert set(rig.joints) >= set(tail)
    assert {k: round(c.duration, 2) for k, c in rig.clips.items()} == {"Survey": 3.42, "Walk": 0.71, "Run": 1.16}
    for clip in rig.clips.values():
        assert len(clip.tracks) == 21
        assert {t.node for t in clip.tracks} >= set(tail)   # the tail is keyframed in every clip
    # centimetre asset scaled to metres: hip height 26.75 cm above its parent
    hip = next(b for b in rig.bones if b.name == "b_Hip_01")
    assert hip.position == pytest.approx((0.0, 0.267484, 0.429382), abs=1e-6)


@needs_data
def test_dropping_the_tail_channels_keeps_every_other_track():
    clip = load_gltf(DATA / "gltf" / "Fox.glb").clip("Run")
    kept = clip.without(["b_Tail*"])
    assert len(kept.tracks) == len(clip.tracks) - 3
    assert not any(t.node.startswith("b_Tail") for t in kept.tracks)
    assert kept.duration == clip.duration


@needs_data
def test_wuson_has_37_joints_a_six_bone_tail_ears_and_its_clips():
    rig = load_gltf(DATA / "gltf" / "wuson.glb")
    assert len(rig.bones) == 40 and len(rig.joints) == 37
    assert {f"Tail0{i}" for i in range(1, 7)} | {"Ear_L", "Ear_R"} <= rig.joints
    assert round(rig.clips["Wuson_Run"].duration, 2) == 0.97
    assert round(rig.clips["Wuson_Walk"].duration, 2) == 3.6
    run = rig.clips["Wuson_Run"]
    assert {"Tail06", "Ear_L", "Ear_R"} <= set(run.nodes())


@needs_data
def test_vrm_rest_pose_matches_the_file_node_transforms():
    path = DATA / "vrm" / "Godette_vrm_v4.vrm"
    rig = load_gltf(path, mirror_axis="z")
    raw = rig.document
    h = TransformHierarchy(rig.bones)
    assert h.count == 71
    for i, node in enumerate(raw.nodes):
        j = h.index(rig.names[i])
        t = position_to_unity(node.translation or [0, 0, 0], "z")
        r = rotation_to_unity(node.rotation or [0, 0, 0, 1], "z")
        assert np.allclose(h.local_position[j], t, atol=1e-6)
        assert np.allclose(h.local_rotation[j], r, atol=1e-6)
        assert np.allclose(h.local_scale[j], node.scale or [1, 1, 1], atol=1e-6)
    # world positions: right-handed forward kinematics (translations only here) then mirrored
    world = {}
    for i, node in enumerate(raw.nodes):
        for c in node.children or []:
            world[c] = i
    def fk(i):
        p = np.array(raw.nodes[i].translation or [0, 0, 0], dtype=float)
        return p + (fk(world[i]) if i in world else 0.0)
    for i in (5, 17, 63):
        assert np.allclose(h.world_position[h.index(rig.names[i])], position_to_unity(fk(i), "z"), atol=1e-6)


def _animated_gltf(tmp_path: Path, interpolation: str, times, values) -> Path:
    times = np.asarray(times, dtype=np.float32)
    values = np.asarray(values, dtype=np.float32)
    blob = times.tobytes() + values.tobytes()
    (tmp_path / "anim.bin").write_bytes(blob)
    width = values.shape[1]
    doc = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "root", "children": [1]}, {"name": "bone"}],
        "buffers": [{"uri": "anim.bin", "byteLength": len(blob)}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": times.nbytes},
                        {"buffer": 0, "byteOffset": times.nbytes, "byteLength": values.nbytes}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": len(times), "type": "SCALAR",
                       "min": [float(times.min())], "max": [float(times.max())]},
                      {"bufferView": 1, "componentType": 5126, "count": len(values), "type": f"VEC{width}"}],
        "animations": [{"name": "clip", "samplers": [{"input": 0, "output": 1, "interpolation": interpolation}],
                        "channels": [{"sampler": 0, "target": {"node": 1, "path": "translation" if width == 3 else "rotation"}}]}],
    }
    path = tmp_path / "anim.gltf"
    path.write_text(json.dumps(doc))
    return path


def _play(path, t):
    rig = load_gltf(path)
    h = TransformHierarchy(rig.bones)
    ClipDriver(rig.clips["clip"], h, loop=False).apply(h, t)
    return rig, h.local_position[h.index("bone")].copy(), h.local_rotation[h.index("bone")].copy()


def test_linear_translation_is_interpolated_and_mirrored(tmp_path):
    f = _animated_gltf(tmp_path, "LINEAR", [0.0, 1.0], [[0, 0, 0], [2, 4, 6]])
    rig, pos, _ = _play(f, 0.25)
    assert np.allclose(pos, [-0.5, 1.0, 1.5], atol=1e-6)
    assert np.allclose(rig.clips["clip"].track("bone", "translation").sample(0.25), pos, atol=1e-9)


def test_step_holds_the_previous_key_until_the_next(tmp_path):
    f = _animated_gltf(tmp_path, "STEP", [0.0, 1.0, 2.0], [[0, 0, 0], [1, 0, 0], [5, 0, 0]])
    assert np.allclose(_play(f, 0.999)[1], [0, 0, 0])
    assert np.allclose(_play(f, 1.5)[1], [-1, 0, 0])
    assert np.allclose(_play(f, 9.0)[1], [-5, 0, 0])


def test_linear_rotation_is_a_slerp(tmp_path):
    s = np.sin(np.pi / 4)
    f = _animated_gltf(tmp_path, "LINEAR", [0.0, 1.0], [[0, 0, 0, 1], [0, s, 0, s]])  # 0 → 90 deg about +Y
    _, _, q = _play(f, 0.5)
    half = np.sin(np.pi / 8), np.cos(np.pi / 8)
    assert np.allclose(q, [0.0, -half[0], 0.0, half[1]], atol=1e-6)   # 45 deg, mirrored to Unity


def test_cubic_spline_uses_tangents_scaled_by_the_key_gap(tmp_path):
    # keys (in, value, out) at t = 0 and 2: value 0 → 1 on x, out-tangent 3 at key 0, in-tangent 0 at key 1
    values = [[0, 0, 0], [0, 0, 0], [3, 0, 0], [0, 0, 0], [1, 0, 0], [0, 0, 0]]
    f = _animated_gltf(tmp_path, "CUBICSPLINE", [0.0, 2.0], values)
    s = 0.25  # t = 0.5
    expected = (-2 * s**3 + 3 * s**2) * 1.0 + (s**3 - 2 * s**2 + s) * 2.0 * 3.0
    rig, pos, _ = _play(f, 0.5)
    assert pos[0] == pytest.approx(-expected, abs=1e-6)
    assert rig.clips["clip"].track("bone", "translation").sample(0.5)[0] == pytest.approx(-expected, abs=1e-9)


@needs_data
def test_numba_clip_driver_matches_the_numpy_reference_on_fox_walk():
    rig = load_gltf(DATA / "gltf" / "Fox.glb", unit_scale=0.01)
    clip = rig.clip("Walk")
    h = TransformHierarchy(rig.bones)
    driver = ClipDriver(clip, h, loop=True)
    for t in (0.0, 0.123, 0.5, 0.70833, 1.3):
        driver.apply(h, t)
        u = driver.clip_time(t)
        for (node, path), value in clip.sample(u).items():
            got = {"translation": h.local_position, "rotation": h.local_rotation}[path][h.index(node)]
            if path == "rotation":
                assert abs(abs(np.dot(got, value)) - 1.0) < 1e-9
            else:
                assert np.allclose(got, value, atol=1e-9)


def test_matrix_nodes_are_decomposed_into_trs(tmp_path):
    m = np.eye(4)
    m[:3, :3] = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]]) * 2.0   # 90 deg about Z, scale 2
    m[:3, 3] = [1, 2, 3]
    f = tmp_path / "m.gltf"
    f.write_text(json.dumps({"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}],
                             "nodes": [{"name": "m", "matrix": list(m.T.ravel())}]}))
    b = load_gltf(f).bones[0]
    assert np.allclose(b.position, [-1, 2, 3]) and np.allclose(b.scale, [2, 2, 2])
    s = np.sqrt(0.5)
    assert np.allclose(b.rotation, [0, 0, -s, s])   # mirrored: -90 deg about Z


@needs_data
def test_truncated_glb_names_the_file_and_says_truncated(tmp_path):
    f = tmp_path / "fox_cut.glb"
    f.write_bytes((DATA / "gltf" / "Fox.glb").read_bytes()[:60000])
    with pytest.raises(AssetError, match=r"fox_cut\.glb: GLB header: truncated: the header declares 162852 bytes but the file has 60000"):
        load_gltf(f)


def test_gltf_json_without_a_scene_is_rejected(tmp_path):
    f = tmp_path / "noscene.gltf"
    f.write_text(json.dumps({"asset": {"version": "2.0"}, "nodes": [{"name": "a"}]}))
    with pytest.raises(AssetError, match=r"noscene\.gltf: scenes: no scene"):
        load_gltf(f)


def test_invalid_json_reports_line_and_column(tmp_path):
    f = tmp_path / "bad.gltf"
    f.write_text('{"asset": {"version": "2.0"},\n "scenes": [}')
    with pytest.raises(AssetError, match=r"bad\.gltf: line 2 column \d+: invalid glTF JSON"):
        load_gltf(f)


def test_child_index_out_of_range_names_the_json_path(tmp_path):
    f = tmp_path / "child.gltf"
    f.write_text(json.dumps({"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}], "nodes": [{"name": "a", "children": [7]}]}))
    with pytest.raises(AssetError, match=r"nodes\[0\]\.children\[0\]: node index 7 does not exist"):
        load_gltf(f)


def test_missing_buffer_file_is_reported(tmp_path):
    f = _animated_gltf(tmp_path, "LINEAR", [0.0, 1.0], [[0, 0, 0], [1, 1, 1]])
    (tmp_path / "anim.bin").unlink()
    with pytest.raises(AssetError, match=r"buffers\[0\]\.uri: cannot read"):
        load_gltf(f)


def test_unknown_clip_name_lists_the_clips(tmp_path):
    f = _animated_gltf(tmp_path, "LINEAR", [0.0, 1.0], [[0, 0, 0], [1, 1, 1]])
    with pytest.raises(AssetError, match=r"no animation named 'Walk'; the file has \['clip'\]"):
        load_gltf(f).clip("Walk")


@needs_data
@pytest.mark.parametrize("file, scale, head, tail, left_foot", [
    ("Fox.glb", 0.01, "b_Head_05", "b_Tail03_014", "b_LeftFoot02_018"),
    ("wuson.glb", 1.0, "Neck", "Tail06", "HindLeg_L_04"),
])
def test_animals_face_plus_z_with_their_left_at_minus_x(file, scale, head, tail, left_foot):
    rig = load_gltf(DATA / "gltf" / file, unit_scale=scale)
    h = TransformHierarchy(rig.bones)
    p = {n: h.world_position[h.index(n)] for n in (head, tail, left_foot)}
    assert p[head][2] - p[tail][2] > 0.9          # head in front (+Z) of the tail tip
    assert p[left_foot][0] < -0.05                # glTF left (+X) mirrored to Unity's -X
    assert p[left_foot][1] < p[head][1]
