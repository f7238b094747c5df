"""Odd and broken input assets: each is a clear ``AssetError`` naming the file and the place in
it (or, when the file is usable, is read as intended); never a traceback, a silent NaN, or a
crash reported as an internal error."""
import json
import warnings
import struct
from pathlib import Path

import numpy as np
import pytest

from magica_py.io.bvh import load_bvh
from magica_py.io.errors import AssetError
from magica_py.io.gltf import load_gltf
from magica_py.io.retarget import RetargetError
from magica_py.io.sections import load_clip
from magica_py.io.vrm import load_vrm

DATA = Path(__file__).parents[1].parent / "shared" / "data"
CMU = DATA / "bvh" / "cmu_01_01.bvh"
needs_data = pytest.mark.skipif(not DATA.is_dir(), reason=f"shared test data folder {DATA} is absent")


# ----------------------------------------------------------------------------- BVH
def _bvh_text(frames=((0, 0, 0, 10, 20, 30), (1, 0, 0, 15, 25, 35)), offset="1 0 0", frame_time="0.5",
              header_gap="", sep="\n"):
    lines = ["HIERARCHY", "ROOT root", "{", "  OFFSET 0 0 0",
             "  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation",
             "  JOINT child", "  {", f"    OFFSET {offset}", "    CHANNELS 0",
             "    End Site", "    {", "      OFFSET 0 1 0", "    }", "  }", "}",
             "MOTION" + header_gap, f"Frames: {len(frames)}" + header_gap, f"Frame Time: {frame_time}"]
    lines += [" ".join(map(str, f)) for f in frames]
    return sep.join(lines) + sep


def _write(tmp_path, text, name="t.bvh"):
    path = tmp_path / name
    path.write_bytes(text.encode() if isinstance(text, str) else text)
    return path


def _rotations(path):
    return load_bvh(path, units="m").local_rotations()


def test_bvh_byte_order_mark_is_skipped(tmp_path):
    plain = _write(tmp_path, _bvh_text(), "plain.bvh")
    bom = _write(tmp_path, b"\xef\xbb\xbf" + _bvh_text().encode(), "bom.bvh")
    assert np.array_equal(_rotations(bom), _rotations(plain))


def test_bvh_blank_lines_around_the_motion_header_are_skipped(tmp_path):
    plain = _write(tmp_path, _bvh_text(), "plain.bvh")
    gaps = _write(tmp_path, _bvh_text(header_gap="\n\n", sep="\r\n"), "gaps.bvh")
    assert np.array_equal(_rotations(gaps), _rotations(plain))


@pytest.mark.parametrize("value, expected", [
    ("abc", r"bad\.bvh: line 20: frame 1, channel 5: expected a number, got 'abc'"),
    ("nan", r"bad\.bvh: line 20: frame 1, channel 5: expected a finite number, got 'nan'"),
    ("1e400", r"bad\.bvh: line 20: frame 1, channel 5: expected a finite number, got '1e400'"),
])
def test_bvh_bad_frame_value_names_its_line_and_channel(tmp_path, value, expected):
    path = _write(tmp_path, _bvh_text(frames=((0, 0, 0, 10, 20, 30), (1, 0, 0, 15, value, 35))), "bad.bvh")
    with pytest.raises(AssetError, match=expected):
        load_bvh(path)


@pytest.mark.parametrize("offset", ["nan 0 0", "1 inf 0"])
def test_bvh_non_finite_offset_names_its_line(tmp_path, offset):
    path = _write(tmp_path, _bvh_text(offset=offset), "off.bvh")
    with pytest.raises(AssetError, match=r"off\.bvh: line 8: expected a finite number for child OFFSET"):
        load_bvh(path)


@pytest.mark.parametrize("frame_time", ["inf", "0", "-0.1", "nan"])
def test_bvh_frame_time_must_be_positive_and_finite(tmp_path, frame_time):
    path = _write(tmp_path, _bvh_text(frame_time=frame_time), "ft.bvh")
    with pytest.raises(AssetError, match=r"ft\.bvh: line 18: frame time must be a positive finite number"):
        load_bvh(path)


def test_bvh_with_zero_frames_is_a_skeleton_but_not_a_clip(tmp_path):
    path = _write(tmp_path, _bvh_text(frames=()), "empty_motion.bvh")
    anim = load_bvh(path)                      # a skeleton: usable as a rig
    assert anim.frame_count == 0 and [b.name for b in anim.bones] == ["root", "child"]
    with pytest.raises(AssetError, match=r"empty_motion\.bvh: MOTION: Frames: 0: .*at least one frame"):
        load_clip(path)


@needs_data
def test_two_frame_bvh_with_source_rest_0_plays_its_second_frame(tmp_path):
    lines = CMU.read_text().splitlines()
    m = lines.index("MOTION")
    path = _write(tmp_path, "\n".join(lines[:m] + ["MOTION", "Frames: 2", "Frame Time: .0083333"]
                                      + lines[m + 3:m + 5]) + "\n", "two.bvh")
    bones = load_bvh(path).bones
    clip = load_clip(path, retarget_to=bones, retarget_options={"source_rest": 0})
    assert clip.tracks and clip.duration == 0.0
    assert all(len(tr.times) == 1 and np.isfinite(tr.values).all() for tr in clip.tracks)


@pytest.mark.parametrize("offset", ["0 169 0", "0 0 169", "169 0 0"])
def test_automatic_units_read_a_skeleton_the_same_standing_or_lying(tmp_path, offset):
    """The automatic unit measures the rest skeleton's largest extent on any axis: a 1.7 m
    skeleton in centimetres is read as centimetres whichever axis it lies along."""
    bvh = load_bvh(_write(tmp_path, _bvh_text(offset=offset)))
    assert bvh.unit_scale == 0.01


def test_automatic_units_warn_when_no_unit_gives_a_human_size(tmp_path):
    with pytest.warns(UserWarning, match=r"far\.bvh: units auto: rest size 1\.7e\+05 file units along Y → mm "
                                         r"\(170 m\), far from a human's 1\.7 m"):
        assert load_bvh(_write(tmp_path, _bvh_text(offset="0 169999 0"), "far.bvh")).unit_scale == 0.001


def test_a_drop_glob_that_matches_no_animated_bone_is_warned_about(tmp_path):
    path = _write(tmp_path, _bvh_text(), "d.bvh")
    with pytest.warns(UserWarning, match=r"d\.bvh: drop 'tail\*' matches no bone the clip animates \(1 bones: "
                                         r"\['root'\]\)") as caught:
        clip = load_clip(path, drop=["tail*"])
    assert len(caught) == 1 and clip.nodes() == ["root"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert load_clip(path, drop=["ro*"]).nodes() == []   # a glob that matches: no warning


@needs_data
def test_a_source_skeleton_without_hips_names_the_file_and_the_way_out(tmp_path):
    path = _write(tmp_path, _bvh_text(), "generic.bvh")
    with pytest.raises(RetargetError, match=r"generic\.bvh: source skeleton: no bone mapped to humanoid 'hips' "
                                            r".*; name it with source_overrides: \{hips: BONE\} or give source_map"):
        load_clip(path, retarget_to=load_bvh(CMU).bones)


# ----------------------------------------------------------------------------- glTF
def _gltf(tmp_path, node=None, name="n.gltf", **top):
    doc = {"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}],
           "nodes": [dict({"name": "a"}, **(node or {}))]}
    doc.update(top)
    path = tmp_path / name
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.parametrize("node, where", [
    ({"matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, float("nan"), 0, 0, 1]}, r"nodes\[0\]\.matrix: expected 16 finite numbers"),
    ({"matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, float("inf"), 0, 0, 1]}, r"nodes\[0\]\.matrix: expected 16 finite numbers"),
    ({"rotation": "abc"}, r"nodes\[0\]\.rotation: expected 4 numbers, got 'abc'"),
    ({"translation": [1, "x", 0]}, r"nodes\[0\]\.translation: expected 3 numbers"),
])
def test_gltf_node_transform_that_is_not_finite_numbers_is_rejected_with_its_path(tmp_path, node, where):
    with pytest.raises(AssetError, match=r"n\.gltf: " + where):
        load_gltf(_gltf(tmp_path, node))


def test_gltf_node_that_is_not_an_object_is_rejected(tmp_path):
    path = tmp_path / "int.gltf"
    path.write_text(json.dumps({"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}], "nodes": [{"name": "a"}, 5]}))
    with pytest.raises(AssetError, match=r"int\.gltf: nodes\[1\]: expected an object, got 5"):
        load_gltf(path)


def _animated(tmp_path, times, values, target="translation", interpolation="LINEAR", **buffer):
    times = np.asarray(times, dtype=np.float32)
    values = np.asarray(values, dtype=np.float32)
    blob = times.tobytes() + values.tobytes()
    (tmp_path / "anim.bin").write_bytes(blob)
    doc = {
        "asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}], "nodes": [{"name": "bone"}],
        "buffers": [dict({"uri": "anim.bin", "byteLength": len(blob)}, **buffer)],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": times.nbytes},
                        {"buffer": 0, "byteOffset": times.nbytes, "byteLength": values.nbytes}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": len(times), "type": "SCALAR"},
                      {"bufferView": 1, "componentType": 5126, "count": len(values),
                       "type": "VEC4" if target == "rotation" else "VEC3"}],
        "animations": [{"name": "clip", "samplers": [{"input": 0, "output": 1, "interpolation": interpolation}],
                        "channels": [{"sampler": 0, "target": {"node": 0, "path": target}}]}],
    }
    for key in [k for k, v in buffer.items() if v is None]:
        del doc["buffers"][0][key]
    path = tmp_path / "anim.gltf"
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.parametrize("times, values, where", [
    ([0, 1, 2], [[0, 0, 0], [1, float("nan"), 0], [2, 0, 0]], r"samplers\[0\]\.output: element 1 is not finite"),
    ([0, 1, 2], [[0, 0, 0], [1, float("inf"), 0], [2, 0, 0]], r"samplers\[0\]\.output: element 1 is not finite"),
    ([0, float("nan"), 2], [[0, 0, 0], [1, 0, 0], [2, 0, 0]], r"samplers\[0\]\.input: element 1 is not finite"),
])
def test_gltf_non_finite_animation_key_is_rejected(tmp_path, times, values, where):
    with pytest.raises(AssetError, match=r"anim\.gltf: animations\[0\]\." + where):
        load_gltf(_animated(tmp_path, times, values))


def test_gltf_zero_quaternion_rotation_key_is_rejected(tmp_path):
    path = _animated(tmp_path, [0, 1, 2], [[0, 0, 0, 1], [0, 0, 0, 0], [0, 0, 0, 1]], target="rotation")
    with pytest.raises(AssetError, match=r"anim\.gltf: animations\[0\]\.samplers\[0\]\.output: element 1 is a zero "
                                         r"quaternion"):
        load_gltf(path)


def test_gltf_cubic_rotation_with_zero_tangents_loads(tmp_path):
    key = [[0, 0, 0, 0], [0, 0, 0.6, 0.8], [0, 0, 0, 0]]   # in-tangent, value, out-tangent
    path = _animated(tmp_path, [0, 1], key + key, target="rotation", interpolation="CUBICSPLINE")
    clip = next(iter(load_gltf(path).clips.values()))
    assert np.allclose(np.linalg.norm(clip.tracks[0].values, axis=1), 1.0)
    with pytest.raises(AssetError, match=r"output: element 4 is a zero quaternion"):
        load_gltf(_animated(tmp_path, [0, 1], key + [[0, 0, 0, 0]] * 3, target="rotation",
                            interpolation="CUBICSPLINE"))


def test_a_trim_past_the_clip_ends_at_its_last_key(tmp_path):
    """trim: [0, 1e30] is the whole clip (a cubic clip is resampled over the trimmed span:
    1e30 s of it failed in numpy's allocation)."""
    key = [[0, 0, 0, 0], [0, 0, 0.6, 0.8], [0, 0, 0, 0]]
    clip = next(iter(load_gltf(_animated(tmp_path, [0, 1], key + key, target="rotation",
                                         interpolation="CUBICSPLINE")).clips.values()))
    whole, past = clip.trimmed(0.0), clip.trimmed(0.0, 1e30)
    assert past.duration == whole.duration == 1.0
    assert all(np.array_equal(a.times, b.times) and np.array_equal(a.values, b.values)
               for a, b in zip(whole.tracks, past.tracks))


def test_gltf_buffer_without_byte_length_is_rejected(tmp_path):
    path = _animated(tmp_path, [0, 1], [[0, 0, 0], [1, 0, 0]], byteLength=None)
    with pytest.raises(AssetError, match=r"anim\.gltf: buffers\[0\]\.byteLength: expected the buffer's size in bytes"):
        load_gltf(path)


def test_gltf_invalid_base64_data_uri_is_rejected(tmp_path):
    path = _animated(tmp_path, [0, 1], [[0, 0, 0], [1, 0, 0]], uri="data:application/octet-stream;base64,@@@x")
    with pytest.raises(AssetError, match=r"anim\.gltf: buffers\[0\]\.uri: invalid base64 data: URI"):
        load_gltf(path)


def test_gltf_negative_accessor_offset_is_rejected(tmp_path):
    path = _animated(tmp_path, [0, 1], [[0, 0, 0], [1, 0, 0]])
    doc = json.loads(path.read_text())
    doc["accessors"][1]["byteOffset"] = -4
    path.write_text(json.dumps(doc))
    with pytest.raises(AssetError, match=r"anim\.gltf: accessors\[1\]: negative byteOffset"):
        load_gltf(path)


# ----------------------------------------------------------------------------- VRM
def _vrm1(tmp_path, mutate=None):
    doc = {"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}],
           "nodes": [{"name": "hips", "children": [1]}, {"name": "hair", "translation": [0, -0.1, 0], "children": [2]},
                     {"name": "hair_end", "translation": [0, -0.1, 0]}],
           "extensions": {"VRMC_vrm": {"specVersion": "1.0", "humanoid": {"humanBones": {"hips": {"node": 0}}}},
                          "VRMC_springBone": {"specVersion": "1.0", "colliders": [
                              {"node": 0, "shape": {"sphere": {"offset": [0, 0, 0], "radius": 0.1}}}],
                              "colliderGroups": [{"colliders": [0]}],
                              "springs": [{"name": "hair", "joints": [{"node": 1}, {"node": 2}], "colliderGroups": [0]}]}}}
    if mutate:
        mutate(doc["extensions"])
    path = tmp_path / "avatar.gltf"
    path.write_text(json.dumps(doc))
    return path


def _vrm0(tmp_path, mutate=None):
    doc = {"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}],
           "nodes": [{"name": "hips", "children": [1]}, {"name": "hair", "translation": [0, -0.1, 0], "children": [2]},
                     {"name": "hair_end", "translation": [0, -0.1, 0]}],
           "extensions": {"VRM": {"humanoid": {"humanBones": [{"bone": "hips", "node": 0}]},
                                  "secondaryAnimation": {"colliderGroups": [],
                                                         "boneGroups": [{"comment": "hair", "bones": [1]}]}}}}
    if mutate:
        mutate(doc["extensions"]["VRM"])
    path = tmp_path / "avatar0.gltf"
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.parametrize("mutate, where", [
    (None, None),
    (lambda e: e["VRMC_springBone"].__setitem__("springs", {"a": 1}), r"extensions\.VRMC_springBone\.springs: expected an array"),
    (lambda e: e["VRMC_springBone"]["springs"][0].__setitem__("joints", "abc"), r"springs\[0\]\.joints: expected an array, got 'abc'"),
    (lambda e: e["VRMC_springBone"]["springs"][0]["joints"].__setitem__(0, 3), r"springs\[0\]\.joints\[0\]: expected an object, got 3"),
    (lambda e: e["VRMC_vrm"]["humanoid"].__setitem__("humanBones", [1, 2]), r"VRMC_vrm\.humanoid\.humanBones: expected an object"),
    (lambda e: e["VRMC_springBone"]["colliders"][0].__setitem__("shape", "sphere"), r"colliders\[0\]\.shape: expected an object"),
    (lambda e: e["VRMC_springBone"]["colliderGroups"][0].__setitem__("colliders", 0), r"colliderGroups\[0\]\.colliders: expected an array"),
])
def test_vrm1_extension_values_of_the_wrong_type_are_asset_errors(tmp_path, mutate, where):
    path = _vrm1(tmp_path, mutate)
    if where is None:
        avatar = load_vrm(path)
        assert [c.joints for c in avatar.chains] == [["hair", "hair_end"]] and avatar.humanoid == {"hips": "hips"}
        return
    with pytest.raises(AssetError, match=r"avatar\.gltf: .*" + where):
        load_vrm(path)


@pytest.mark.parametrize("mutate, where", [
    (None, None),
    (lambda v: v["humanoid"].__setitem__("humanBones", {"hips": {"node": 0}}), r"extensions\.VRM\.humanoid\.humanBones: expected an array"),
    (lambda v: v["humanoid"]["humanBones"].__setitem__(0, "hips"), r"humanBones\[0\]: expected an object, got 'hips'"),
    (lambda v: v["humanoid"]["humanBones"][0].pop("bone"), r"humanBones\[0\]\.bone: expected a humanoid bone name"),
    (lambda v: v["secondaryAnimation"]["boneGroups"][0].__setitem__("bones", 5), r"boneGroups\[0\]\.bones: expected an array, got 5"),
    (lambda v: v["secondaryAnimation"].__setitem__("boneGroups", "x"), r"secondaryAnimation\.boneGroups: expected an array"),
])
def test_vrm0_extension_values_of_the_wrong_type_are_asset_errors(tmp_path, mutate, where):
    path = _vrm0(tmp_path, mutate)
    if where is None:
        avatar = load_vrm(path)
        assert [c.root for c in avatar.chains] == ["hair"] and avatar.humanoid == {"hips": "hips"}
        return
    with pytest.raises(AssetError, match=r"avatar0\.gltf: .*" + where):
        load_vrm(path)


# ----------------------------------------------------------------------------- CLI, bake, build
def test_run_of_a_truncated_vrm_avatar_is_a_clear_error_not_a_crash(tmp_path, capsys):
    from magica_py.cli import EXIT_BAD_INPUT, main

    path = tmp_path / "cut.vrm"
    path.write_bytes(b"glTF" + struct.pack("<II", 2, 5000) + b"\0" * 100)
    assert main(["run", str(path), "--frames", "1", "--rrd", str(tmp_path / "out.rrd")]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert "cut.vrm: GLB header: truncated" in err and "Traceback" not in err and "internal error" not in err
    assert not (tmp_path / "out.rrd").exists()


def test_bake_output_under_a_file_is_refused_before_simulating(tmp_path):
    from magica_py.bake.bake import BakeError, check_output

    (tmp_path / "afile").write_text("")
    with pytest.raises(BakeError, match=r"'.*afile' is not a folder"):
        check_output(tmp_path / "afile" / "x.glb")


def test_atomic_write_into_a_file_as_folder_keeps_the_original_error(tmp_path):
    from magica_py import atomic

    (tmp_path / "afile").write_text("")
    with pytest.raises(NotADirectoryError) as caught:
        atomic.write_bytes(tmp_path / "afile" / "x.bin", b"data")
    assert caught.value.__context__ is None    # the write's own error, not the cleanup's over it
