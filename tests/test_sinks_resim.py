"""End to end with the real solver: `run` records, `inspect` reads, `resim` reproduces bit for bit."""
from __future__ import annotations

import numpy as np
import pytest
import rerun as rr

from magica_py.config import load_scene
from magica_py.sinks.inspect import summarize
from magica_py.sinks.readback import Recording
from magica_py.sinks.record_all import record_scene
from magica_py.sinks.resim import load_replay, load_scene_for, main_resim, resimulate

FRAMES = 40
SCENE = "configs/tail_orbit.yaml"


@pytest.fixture(autouse=True)
def strict():
    rr.set_strict_mode(True)


@pytest.fixture(scope="module")
def original(tmp_path_factory):
    rr.set_strict_mode(True)
    path = tmp_path_factory.mktemp("resim") / "tail.rrd"
    result = record_scene(load_scene(SCENE), path, frames=FRAMES, batch_frames=16)
    return path, result


def particles(path):
    return Recording(path).stacked("/world/cloths/tail/particles", "Points3D:positions")


def test_the_solver_particles_are_recorded_and_move(original):
    path, result = original
    frames, x = particles(path)
    assert frames.tolist() == list(range(FRAMES)) and x.shape == (FRAMES, 8, 3)
    assert result.particles == 8
    tip_travel = np.linalg.norm(x[-1, -1] - x[0, -1])
    assert tip_travel > 0.05                     # the orbit drags the tail along
    s = summarize(path)
    assert s["metrics"]["solver/steps_per_frame"]["max"] >= 1 and s["metrics"]["motion/max_speed_m_per_s"]["max"] > 0


def test_resim_with_the_same_scene_reproduces_particles_bit_for_bit(original, tmp_path):
    path, _ = original
    replay = load_replay(path)
    scene = load_scene_for(replay)               # the scene text embedded in the recording
    out = tmp_path / "again.rrd"
    resimulate(replay, scene, out)
    fa, xa = particles(path)
    fb, xb = particles(out)
    assert fa.tolist() == fb.tolist()
    np.testing.assert_array_equal(xa, xb)
    _, ja = Recording(path).stacked("/world/rig/joints", "Points3D:positions")
    _, jb = Recording(out).stacked("/world/rig/joints", "Points3D:positions")
    np.testing.assert_array_equal(ja, jb)        # the rig (non-cloth joints) too


def test_resim_with_other_parameters_changes_the_cloth_but_not_the_animated_pose(original, tmp_path):
    path, _ = original
    out = tmp_path / "heavy.rrd"
    assert main_resim([str(path), "--scene", SCENE, "--set", "cloths.tail.parameters.gravity=9.0",
                       "--rrd", str(out)]) == 0
    _, xa = particles(path)
    _, xb = particles(out)
    np.testing.assert_array_equal(xa[:, 0], xb[:, 0])           # fixed root follows the same pose
    assert np.abs(xa[-1, -1] - xb[-1, -1]).max() > 1e-3         # heavier tail hangs elsewhere
    _, pa = Recording(path).stacked("/replay/pose", "local_position")
    _, pb = Recording(out).stacked("/replay/pose", "local_position")
    np.testing.assert_array_equal(pa, pb)


def test_resim_of_a_missing_file_exits_2(tmp_path, capsys):
    assert main_resim([str(tmp_path / "none.rrd")]) == 2
    assert "no such recording file" in capsys.readouterr().err
