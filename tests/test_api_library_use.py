"""The Python API used as a library by a pipeline or a tuning tool, in one long-lived
process: a loaded ``Scene`` run many times, sessions side by side, results and errors sent
between processes (Dask workers), and the wrong call order."""
import copy
import pickle

import numpy as np
import pytest

import magica_py
from magica_py.api import Session

TAIL = "configs/tail_orbit.yaml"


@pytest.fixture
def in_repo(repo_root, monkeypatch):
    monkeypatch.chdir(repo_root)
    return repo_root


def _bits(result):
    return {name: (t.positions.tobytes(), t.rotations.tobytes(), t.local_rotations.tobytes())
            for name, t in result.cloths.items()}


def test_a_loaded_scene_runs_again_with_the_same_bits(in_repo):
    scene = magica_py.load_scene(TAIL)
    pose = scene.hierarchy.local_position.copy(), scene.hierarchy.local_rotation.copy()
    first = magica_py.simulate(scene, frames=30)
    second = magica_py.simulate(scene, frames=30)
    from_path = magica_py.simulate(TAIL, frames=30)
    assert _bits(first) == _bits(second) == _bits(from_path)
    # the caller's scene is left as loaded (a run moves the bones of its own copy)
    assert np.array_equal(scene.hierarchy.local_position, pose[0])
    assert np.array_equal(scene.hierarchy.local_rotation, pose[1])


def test_two_sessions_of_one_loaded_scene_step_side_by_side_as_alone(in_repo):
    scene = magica_py.load_scene(TAIL)
    alone = magica_py.simulate(TAIL, frames=20)
    a = Session(scene)
    for _ in range(5):      # a runs ahead: b is built while a's bones are mid-run
        a.step()
    b = Session(scene)
    for _ in range(15):
        a.step()
        b.step()
    for _ in range(5):
        b.step()
    assert _bits(a.result()) == _bits(b.result()) == _bits(alone)


def test_a_scene_and_a_simulation_pickle_for_a_worker(in_repo):
    scene = magica_py.load_scene(TAIL)
    assert _bits(magica_py.simulate(pickle.loads(pickle.dumps(scene)), frames=10)) == \
        _bits(magica_py.simulate(copy.deepcopy(scene), frames=10))
    result = magica_py.simulate(TAIL, frames=10)
    back = pickle.loads(pickle.dumps(result))
    assert _bits(back) == _bits(result) and back.frames == 10
    assert back.scene.output.log == result.scene.output.log


def test_errors_unpickle_as_themselves(in_repo):
    from magica_py.batch.jobs import JobFileError
    from magica_py.build.errors import BuildError
    from magica_py.io.errors import AssetError
    from magica_py.params import ParameterError

    with pytest.raises(magica_py.ConfigError) as info:
        magica_py.simulate(TAIL, overrides=["cloths.tail.parameters.damping=5"])
    errors = [info.value, ParameterError("cloths[0].parameters.damping", "expected a number"),
              BuildError("tail", "no bones"), AssetError("a.glb", "nodes[3]", "bad"),
              JobFileError("jobs.yaml", "jobs[0]", "bad")]
    for error in errors:
        back = pickle.loads(pickle.dumps(error))
        assert type(back) is type(error) and str(back) == str(error)
    assert pickle.loads(pickle.dumps(info.value)).paths() == ["cloths[0].parameters.damping"]


def test_a_discarded_recording_is_not_reported(in_repo, tmp_path):
    target = tmp_path / "run.rrd"
    with pytest.raises(RuntimeError, match="boom"):
        with Session(TAIL, record=target) as session:
            session.run(3)
            raise RuntimeError("boom")
    assert not target.exists()
    assert session.result().recording is None
    with Session(TAIL, record=target) as kept:
        kept.run(3)
    assert kept.result().recording == str(target) and target.is_file()


def test_step_and_run_after_close_raise(in_repo, tmp_path):
    session = Session(TAIL, record=tmp_path / "run.rrd")
    session.step()
    session.close()
    session.close()  # twice: nothing more happens
    with pytest.raises(RuntimeError, match="closed"):
        session.step()
    with pytest.raises(RuntimeError, match="closed"):
        session.run(2)
    assert session.result().frames == 1


@pytest.mark.parametrize("frames", [2.5, "10", True, float("nan"), float("inf")])  # nan, inf: ran forever
def test_frames_must_be_a_whole_number(in_repo, frames):
    with pytest.raises(TypeError, match="frames: expected a whole number"):
        magica_py.simulate(TAIL, frames=frames)


def test_frames_as_a_whole_float_run(in_repo):
    assert magica_py.simulate(TAIL, frames=3.0).frames == 3


def test_overrides_given_as_one_string_raise_a_type_error(in_repo):
    with pytest.raises(TypeError, match=r"overrides=\['cloths.tail.parameters.damping=0.2'\]"):
        magica_py.simulate(TAIL, frames=1, overrides="cloths.tail.parameters.damping=0.2")


@pytest.mark.parametrize("direction, speed, match", [
    ([0, 1, 0], float("nan"), "speed"), ([0, 1, 0], float("inf"), "speed"),
    ([float("inf"), 1, 0], 1.0, "direction"), ([1, 0], 1.0, "direction"), ("up", 1.0, "direction")])
def test_add_force_rejects_non_finite_or_misshapen_input(in_repo, direction, speed, match):
    with Session(TAIL) as session:
        with pytest.raises(ValueError, match=match):
            session.system.add_force("tail", direction, speed)
        session.system.add_force("tail", [0, 1, 0], 2.0)   # the session stays usable
        result = session.run(5)
    assert np.isfinite(result.cloths["tail"].positions).all()


def test_attach_solver_refuses_a_scene_that_is_not_the_players(in_repo):
    """It used to schedule the other scene's bone indices in this player's hierarchy: an
    IndexError from the propagation plan, then a segmentation fault at the next GC."""
    import gc

    tail, walk = magica_py.load_scene(TAIL), magica_py.load_scene("configs/character_walk.yaml")
    player = magica_py.Player.for_scene(tail)
    with pytest.raises(ValueError, match="another hierarchy"):
        magica_py.attach_solver(player, walk)
    gc.collect()
    system = magica_py.attach_solver(player, tail)   # the player stays usable
    for _ in range(3):
        player.step()
    assert np.isfinite(system.positions("tail")).all()


def test_one_line_yaml_text_is_not_taken_for_a_missing_file(in_repo):
    with pytest.raises(ValueError, match=r"'version: 1' is not a file; YAML text is recognised by its line breaks"):
        magica_py.simulate("version: 1")


@pytest.mark.parametrize("value", ["x", None, [1]])
def test_a_time_scale_that_is_not_a_number_names_what_was_expected(in_repo, value):
    with Session(TAIL) as session:
        with pytest.raises(ValueError, match=r"time scale must be a number in \[0, 1\], got "):
            session.system.set_time_scale("tail", value)
