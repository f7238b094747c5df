"""magica_py.simulate / Session: the arrays they return against the scene's own state."""
import numpy as np
import pytest

import magica_py
from magica_py.api import Session

TAIL = "configs/tail_orbit.yaml"


@pytest.fixture
def in_repo(repo_root, monkeypatch):
    monkeypatch.chdir(repo_root)
    return repo_root


def test_public_names_are_lazy_and_listed():
    assert {"simulate", "Session", "load_scene", "ConfigError", "Player", "attach_solver"} <= set(dir(magica_py))
    assert magica_py.simulate is magica_py.api.simulate
    with pytest.raises(AttributeError):
        magica_py.no_such_name


def test_simulate_returns_positions_that_are_the_written_bones(in_repo):
    with Session(TAIL) as session:
        result = session.run(30)
        h = session.scene.hierarchy
        tail = result.cloths["tail"]
        bones = [h.index(name) for name in tail.bones]
        # the last frame's bones sit on the particles and carry the recorded rotations
        assert np.allclose(h.world_position[bones], tail.positions[-1], atol=1e-9)
        assert np.array_equal(h.world_rotation[bones], tail.rotations[-1])
        assert np.array_equal(h.local_rotation[bones], tail.local_rotations[-1])
    assert tail.positions.shape == (30, 8, 3) and result.time.shape == (30,)
    assert np.allclose(np.diff(result.time), 1 / 60)
    assert tail.parent[0] == -1 and tail.edges.shape[1] == 2
    assert set(result.metrics) >= {"max_edge_stretch", "max_penetration", "max_speed", "cloth.steps"}
    assert all(v.shape == (30,) for v in result.metrics.values())
    assert result.compile_seconds >= 0.0 and result.wall_time > 0.0


def test_simulate_is_deterministic_and_overrides_change_the_motion(in_repo):
    a = magica_py.simulate(TAIL, frames=20)
    b = magica_py.simulate(TAIL, frames=20)
    c = magica_py.simulate(TAIL, frames=20, overrides=["cloths.tail.parameters.gravity=9"])
    assert np.array_equal(a.cloths["tail"].positions, b.cloths["tail"].positions)
    assert not np.allclose(a.cloths["tail"].positions[-1], c.cloths["tail"].positions[-1])
    # the root particle is fixed: it follows the animation whatever the gravity
    assert np.allclose(a.cloths["tail"].positions[:, 0], c.cloths["tail"].positions[:, 0])


def test_stepping_a_session_equals_one_call(in_repo):
    whole = magica_py.simulate(TAIL, frames=12)
    with Session(TAIL) as session:
        for _ in range(5):
            session.step()
        session.run(7)
        stepped = session.result()
    assert np.array_equal(whole.cloths["tail"].positions, stepped.cloths["tail"].positions)


def test_simulate_accepts_yaml_text_and_a_loaded_scene(in_repo):
    text = (in_repo / TAIL).read_text()
    from_text = magica_py.simulate(text, frames=5)
    scene = magica_py.load_scene(TAIL)
    from_scene = magica_py.simulate(scene, frames=5)
    assert np.array_equal(from_text.cloths["tail"].positions, from_scene.cloths["tail"].positions)
    with pytest.raises(ValueError, match="overrides apply"):
        magica_py.simulate(scene, frames=1, overrides=["scene.fps=30"])


def test_record_writes_the_recording_into_a_new_folder(in_repo, tmp_path):
    target = tmp_path / "new" / "run.rrd"
    result = magica_py.simulate(TAIL, frames=4, record=target)
    assert result.recording == str(target) and target.is_file()
    with pytest.raises(ValueError, match="must end in .rrd"):
        magica_py.simulate(TAIL, frames=1, record=tmp_path / "run.txt")


def test_numpy_warnings_in_a_frame_become_events_and_a_summary(in_repo):
    from magica_py.runtime.phases import Phase, System

    with Session(TAIL) as session:
        def overflow(ctx):
            if ctx.frame == 2:
                np.float64(1e308) * np.float64(10.0)   # RuntimeWarning: overflow encountered
        session.player.schedule.add(Phase.LATE_UPDATE, System("overflow", overflow))
        result = session.run(4)
    kinds = [(frame, kind) for frame, kind, _ in result.events]
    assert kinds == [(2, "numpy_warning")]
    payload = result.events[0][2]
    assert "overflow" in payload["message"] and payload["count"] == 1
    assert result.warnings.startswith("1 warning during the run") and "first at frame 2" in result.warnings


def test_bad_input_raises_config_error_with_every_problem(in_repo):
    with pytest.raises(magica_py.ConfigError) as info:
        magica_py.simulate(TAIL, overrides=["cloths.tail.parameters.damping=5", "scene.fps=-1"])
    assert set(info.value.paths()) == {"cloths[0].parameters.damping", "scene.fps"}
