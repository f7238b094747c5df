"""The numba clip sampler against its numpy twins on random tracks (magica_py.io.clip)."""
import numpy as np
import pytest

from magica_py.io.clip import Clip, ClipDriver, Track, sample_track_many
from magica_py.io.quat import qnormalize
from magica_py.scene.hierarchy import BoneSpec, TransformHierarchy


def _random_clip(seed):
    rng = np.random.default_rng(seed)
    tracks = []
    for i in range(6):
        for path in ("translation", "rotation", "scale"):
            k = int(rng.integers(1, 7))
            times = np.sort(rng.uniform(0.0, 3.0, k)) + np.arange(k) * 0.05
            width = 4 if path == "rotation" else 3
            values = rng.normal(size=(k, width))
            if path == "rotation":
                values = qnormalize(values)
            interp = ("linear", "step", "cubicspline")[int(rng.integers(0, 3))]
            tangents = (rng.normal(size=(k, width)), rng.normal(size=(k, width))) if interp == "cubicspline" else (None, None)
            tracks.append(Track(f"b{i}", path, times, values, interp, *tangents))
    return Clip("random", tracks)


@pytest.mark.parametrize("seed", range(6))
def test_numba_sampler_matches_both_numpy_twins(seed):
    clip = _random_clip(seed)
    h = TransformHierarchy([BoneSpec("root")] + [BoneSpec(f"b{i}", "root") for i in range(6)])
    driver = ClipDriver(clip, h, loop=False)
    times = np.linspace(-0.5, 3.8, 37)
    many = {(tr.node, tr.path): sample_track_many(tr, times) for tr in clip.tracks}
    for n, t in enumerate(times):
        driver.apply(h, t)
        for tr in clip.tracks:
            got = {"translation": h.local_position, "rotation": h.local_rotation, "scale": h.local_scale}[tr.path][h.index(tr.node)]
            ref = tr.sample(t)
            if tr.path == "rotation":
                assert abs(abs(np.dot(got, ref)) - 1.0) < 1e-9
                assert abs(abs(np.dot(many[(tr.node, tr.path)][n], ref)) - 1.0) < 1e-9
            else:
                assert np.allclose(got, ref, atol=1e-9)
                assert np.allclose(many[(tr.node, tr.path)][n], ref, atol=1e-9)


def test_looping_wraps_time_into_the_clip_duration():
    tr = Track("b", "translation", np.array([0.0, 2.0]), np.array([[0.0, 0, 0], [4.0, 0, 0]]))
    h = TransformHierarchy([BoneSpec("b")])
    driver = ClipDriver(Clip("c", [tr]), h, loop=True, speed=2.0, start=0.5)
    driver.apply(h, 1.0)                       # clip time 0.5 + 2.0 = 2.5 → 0.5
    assert h.local_position[0, 0] == pytest.approx(1.0)
    driver.apply(h, -0.5)                      # 0.5 - 1.0 = -0.5 → 1.5
    assert h.local_position[0, 0] == pytest.approx(3.0)


def test_a_track_for_a_missing_bone_raises_or_is_skipped():
    clip = Clip("c", [Track("ghost", "translation", np.array([0.0]), np.zeros((1, 3)))])
    h = TransformHierarchy([BoneSpec("b")])
    with pytest.raises(KeyError, match="track target 'ghost' is not in the hierarchy"):
        ClipDriver(clip, h)
    assert len(ClipDriver(clip, h, missing="skip").track_node) == 0


def test_keyframe_entries_pad_short_tracks_to_the_clip_span():
    a = Track("a", "translation", np.array([0.5, 1.0]), np.array([[1.0, 0, 0], [2.0, 0, 0]]))
    b = Track("b", "scale", np.array([0.0, 3.0]), np.ones((2, 3)))
    entries = Clip("c", [a, b]).to_animation_entries()
    keys = entries[0]["keyframes"]["keys"]
    assert [k["time"] for k in keys] == [0.0, 0.5, 1.0, 3.0]
    assert keys[0]["position"] == [1.0, 0.0, 0.0] and keys[-1]["position"] == [2.0, 0.0, 0.0]
    assert entries[1]["keyframes"]["keys"][0] == {"time": 0.0, "scale": [1.0, 1.0, 1.0]}


def test_trimming_keeps_the_motion_inside_the_window():
    tr = Track("b", "translation", np.array([0.0, 1.0, 2.0, 3.0]), np.array([[0.0, 0, 0], [1, 0, 0], [4, 0, 0], [9, 0, 0]]))
    q = Track("b", "rotation", np.array([0.0, 3.0]), qnormalize(np.array([[0, 0, 0, 1.0], [0, 1, 0, 1.0]])))
    clip = Clip("c", [tr, q])
    cut = clip.trimmed(0.5, 2.5)
    assert cut.duration == pytest.approx(2.0)
    for t in (0.0, 0.4, 1.0, 1.7, 2.0):
        assert np.allclose(cut.track("b", "translation").sample(t), tr.sample(t + 0.5))
        assert abs(np.dot(cut.track("b", "rotation").sample(t), q.sample(t + 0.5))) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="expected 0 <= start < end"):
        clip.trimmed(2.0, 1.0)


def test_resampling_is_exact_for_piecewise_linear_motion_at_the_new_keys():
    tr = Track("b", "translation", np.array([0.0, 1.0, 2.0]), np.array([[0.0, 0, 0], [1, 0, 0], [1, 2, 0]]))
    fine = Clip("c", [tr]).resampled(4.0)
    assert len(fine.tracks[0].times) == 9 and fine.frame_time == 0.25
    assert np.allclose(fine.tracks[0].values[[0, 2, 4, 6, 8]], [[0, 0, 0], [0.5, 0, 0], [1, 0, 0], [1, 1, 0], [1, 2, 0]])
