"""BVH parsing, channel orders, position channels, units and malformed files (magica_py.io.bvh)."""
from pathlib import Path

import numpy as np
import pytest

from magica_py.io.bvh import UNITS, load_bvh, parse_bvh
from magica_py.io.clip import ClipDriver
from magica_py.io.errors import AssetError
from magica_py.scene.hierarchy import TransformHierarchy

DATA = Path(__file__).parents[1].parent / "shared" / "data"
CMU = DATA / "bvh" / "cmu_01_01.bvh"
needs_data = pytest.mark.skipif(not DATA.is_dir(), reason=f"shared test data folder {DATA} is absent")


@needs_data
def test_cmu_header_frame_count_and_frame_time_are_kept():
    anim = load_bvh(CMU)
    header = CMU.read_text().split("MOTION", 1)[1].splitlines()
    assert header[1] == "Frames: 2752" and header[2] == "Frame Time: .0083333"
    assert anim.frame_count == 2752 and anim.frame_time == 0.0083333
    assert len(anim.bones) == 31
    assert anim.clip.duration == pytest.approx(2751 * 0.0083333)
    assert anim.file.channels[0] == ["Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation"]
    assert all(c == ["Zrotation", "Yrotation", "Xrotation"] for c in anim.file.channels[1:])
    assert anim.file.motion.shape == (2752, 96)


@needs_data
def test_cmu_units_are_detected_and_scaled_to_metres():
    anim = load_bvh(CMU)
    assert anim.unit_scale == UNITS["cmu"] and "cmu" in anim.notes[0]
    hips = anim.clip.track("Hips", "translation").values[0]
    # first frame: Hips at (9.3722, 17.8693, -17.3198) file units, X mirrored
    assert np.allclose(hips, np.array([-9.3722, 17.8693, -17.3198]) * 0.0254 / 0.45)
    assert load_bvh(CMU, units="inch").unit_scale == 0.0254


def _bvh(tmp_path, channels_root, channels_child, frames, child_offset=(1, 0, 0), name="t.bvh"):
    lines = ["HIERARCHY", "ROOT root", "{", "  OFFSET 0 0 0", f"  CHANNELS {len(channels_root)} {' '.join(channels_root)}",
             "  JOINT child", "  {", f"    OFFSET {' '.join(map(str, child_offset))}",
             f"    CHANNELS {len(channels_child)} {' '.join(channels_child)}",
             "    End Site", "    {", "      OFFSET 1 0 0", "    }", "  }", "}",
             "MOTION", f"Frames: {len(frames)}", "Frame Time: 0.5"]
    lines += [" ".join(map(str, f)) for f in frames]
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


def _end_position(path, frame=0):
    anim = load_bvh(path, units="m", end_sites=True)
    h = TransformHierarchy(anim.bones)
    ClipDriver(anim.clip, h, loop=False).apply(h, frame * 0.5)
    h.propagate()
    return h.world_position[h.index("child_end")] - h.world_position[h.index("child")]


@pytest.mark.parametrize("order, angles, expected_rh", [
    (["Zrotation", "Xrotation", "Yrotation"], (90, 0, 0), (0, 1, 0)),     # Rz(90) x → y
    (["Xrotation", "Yrotation", "Zrotation"], (0, 90, 0), (0, 0, -1)),    # Ry(90) x → -z
    (["Xrotation", "Yrotation", "Zrotation"], (90, 90, 0), (0, 1, 0)),    # Rx(90) Ry(90) x = Rx(90)(-z) = y
    (["Yrotation", "Xrotation", "Zrotation"], (90, 90, 0), (0, 0, -1)),   # Ry(90) Rx(90) x = Ry(90) x = -z
])
def test_rotation_channels_compose_in_file_order(tmp_path, order, angles, expected_rh):
    path = _bvh(tmp_path, ["Xposition", "Yposition", "Zposition"] + order, [], [[0, 0, 0, *angles]])
    got = _end_position(path)
    # the end site (1, 0, 0) turned by the file's right-handed rotation, then mirrored in X
    expected_unity = np.array(expected_rh, dtype=float) * [-1, 1, 1]
    assert np.allclose(got, expected_unity, atol=1e-9)


def test_position_channels_on_a_child_replace_its_offset(tmp_path):
    path = _bvh(tmp_path, ["Zrotation"], ["Xposition", "Zposition", "Xrotation"], [[0, 5, 7, 0], [0, 6, 8, 0]],
                child_offset=(1, 2, 3))
    anim = load_bvh(path, units="m")
    track = anim.clip.track("child", "translation")
    assert np.allclose(track.values, [[-5, 2, 7], [-6, 2, 8]])     # Y keeps the OFFSET, X mirrored
    assert anim.clip.track("root", "rotation").values.shape == (2, 4)


def test_wrong_channel_count_names_the_line(tmp_path):
    path = _bvh(tmp_path, ["Xposition", "Yposition", "Zposition", "Zrotation"], ["Zrotation"], [[0, 0, 0, 0, 0], [0, 0, 0, 0]])
    with pytest.raises(AssetError, match=r"t\.bvh: line 20: frame 1 has 4 values but the hierarchy declares 5 channels"):
        parse_bvh(path)


def test_frame_count_mismatch_is_reported(tmp_path):
    path = _bvh(tmp_path, ["Zrotation"], ["Zrotation"], [[0, 0], [0, 0]])
    path.write_text(path.read_text().replace("Frames: 2", "Frames: 4"))   # one off is accepted (test_retarget_clip_edges)
    with pytest.raises(AssetError, match=r"header declares 4 frames but the file has 2"):
        parse_bvh(path)


def test_unknown_channel_and_missing_brace_are_reported(tmp_path):
    path = _bvh(tmp_path, ["Wrotation"], ["Zrotation"], [[0, 0]])
    with pytest.raises(AssetError, match=r"line 5: root: unknown channel 'Wrotation'"):
        parse_bvh(path)
    path = _bvh(tmp_path, ["Zrotation"], ["Zrotation"], [[0, 0]], name="b.bvh")
    path.write_text(path.read_text().replace("  }\n}\nMOTION", "  }\nMOTION"))
    with pytest.raises(AssetError, match=r"b\.bvh: line \d+: unexpected end of file before MOTION: joint 'root' is missing its closing"):
        parse_bvh(path)


def test_auto_units_pick_centimetres_for_a_170_unit_skeleton(tmp_path):
    path = _bvh(tmp_path, ["Zrotation"], ["Zrotation"], [[0, 0]], child_offset=(0, 170, 0))
    assert load_bvh(path).unit_scale == 0.01


@needs_data
def test_per_frame_arrays_of_the_cmu_clip():
    anim = load_bvh(CMU)
    rot = anim.local_rotations()
    assert rot.shape == (2752, 31, 4) and np.allclose(np.linalg.norm(rot, axis=2), 1.0)
    assert np.allclose(rot[:, 3], anim.clip.track("LeftLeg", "rotation").values)
    root = anim.root_positions()
    assert root.shape == (2752, 3) and np.allclose(root[0], np.array([-9.3722, 17.8693, -17.3198]) * UNITS["cmu"])
