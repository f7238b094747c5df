"""The magica-py command line: help, exit codes, error reports without tracebacks, no partial output."""
import subprocess
import sys
import types

import pytest

from magica_py import cli

SCENE = """
version: 1
scene: {name: cli_test, fps: 60, frames: 4}
rigs:
  - name: r
    bones: [{name: root, position: [0, 1, 0]}]
    parts: [{chain: {name: tail, parent: root, bones: 3, length: 0.3}}]
animation:
  - {target: root, spin: {speed: 90}}
colliders:
  - {name: ball, transform: root, sphere: {radius: 0.05}}
cloths:
  - {name: tail, root_bones: [tail_0], preset: tail, colliders: [ball]}
output: {rrd: OUT}
"""

BROKEN = SCENE.replace("radius: 0.05", "radius: -0.05").replace("preset: tail", "preset: tial")


@pytest.fixture
def scene_file(tmp_path):
    path = tmp_path / "scene.yaml"
    path.write_text(SCENE.replace("OUT", str(tmp_path / "out" / "cli_test.rrd")))
    return path


@pytest.fixture
def broken_file(tmp_path):
    path = tmp_path / "broken.yaml"
    path.write_text(BROKEN.replace("OUT", str(tmp_path / "broken.rrd")))
    return path


@pytest.mark.parametrize("argv", [["--help"], ["run", "--help"], ["validate", "--help"], ["info", "--help"]])
def test_help_everywhere(argv, capsys):
    assert cli.main(argv) == 0
    assert "usage: magica-py" in capsys.readouterr().out


def test_help_is_fast_and_imports_nothing_heavy():
    code = ("import sys, magica_py.cli as c; c.build_parser(); "
            "print(sorted(m for m in ('numpy', 'numba', 'rerun', 'yaml') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_usage_error_exits_2(capsys):
    assert cli.main(["run"]) == 2
    assert "SCENE.yaml" in capsys.readouterr().err
    assert cli.main(["run", "x.yaml", "--frames", "0"]) == 2


def test_validate_ok(scene_file, capsys):
    assert cli.main(["validate", str(scene_file)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"OK {scene_file}: scene 'cli_test': 4 bones, 1 collider, 1 cloth")


@pytest.mark.parametrize("command", ["validate", "info", "run"])
def test_bad_input_exits_2_without_traceback(command, broken_file, tmp_path, capsys):
    assert cli.main([command, str(broken_file)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert f"{broken_file}: 2 errors" in err
    assert "colliders[0].sphere.radius: expected a number >= 0.001, got -0.05" in err
    assert "cloths[0].preset: unknown preset 'tial' (did you mean 'tail'?)" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["broken.yaml"]  # nothing written


def test_bad_override_exits_2_and_writes_nothing(scene_file, tmp_path, capsys):
    assert cli.main(["run", str(scene_file), "--set", "cloths.tail.parameters.damping=5"]) == 2
    err = capsys.readouterr().err
    assert "cloths[0].parameters.damping" in err and "(from --set cloths.tail.parameters.damping=5)" in err
    assert "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_rrd_into_a_missing_folder_creates_it_like_output_rrd(scene_file, tmp_path, capsys):
    target = tmp_path / "missing_folder" / "deeper" / "x.rrd"
    assert cli.main(["run", str(scene_file), "--rrd", str(target), "--frames", "2"]) == 0
    assert target.is_file()


def test_unwritable_output_exits_2_and_leaves_nothing(scene_file, tmp_path, capsys):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    target = blocker / "x.rrd"
    assert cli.main(["run", str(scene_file), "--rrd", str(target)]) == 2
    err = capsys.readouterr().err
    assert "--rrd" in err and "Traceback" not in err
    bad_name = tmp_path / "new_folder" / "x.txt"   # not .rrd: refused, and the folder made for it removed
    assert cli.main(["run", str(scene_file), "--rrd", str(bad_name)]) == 2
    assert "must end in .rrd" in capsys.readouterr().err
    assert not bad_name.parent.exists()


def test_contradicting_output_flags(scene_file, tmp_path, capsys):
    assert cli.main(["run", str(scene_file), "--no-rrd", "--rrd", str(tmp_path / "a.rrd")]) == 2
    assert "contradict" in capsys.readouterr().err


def test_run_without_recording_prints_summary(scene_file, tmp_path, capsys):
    assert cli.main(["run", str(scene_file), "--no-rrd", "--frames", "3", "--no-simulation"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("cli_test: 3 frames, ")
    assert "ms/frame" in out
    assert not (tmp_path / "out").exists()


def test_run_writes_the_scene_recording_and_creates_its_folder(scene_file, tmp_path, capsys):
    assert cli.main(["run", str(scene_file), "--quiet", "--no-simulation"]) == 0
    assert capsys.readouterr().out == ""
    files = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert files == ["cli_test.rrd"]  # no temporary file left behind
    assert (tmp_path / "out" / "cli_test.rrd").stat().st_size > 0


def test_failed_run_leaves_no_partial_recording(scene_file, tmp_path, monkeypatch, capsys):
    from magica_py.runtime.player import Player

    real_step = Player.step
    calls = {"n": 0}

    def failing_step(self):
        calls["n"] += 1
        if calls["n"] == 3:
            raise RuntimeError("simulated crash in frame 3")
        return real_step(self)

    monkeypatch.setattr(Player, "step", failing_step)
    target = tmp_path / "partial.rrd"
    assert cli.main(["run", str(scene_file), "--rrd", str(target), "--no-simulation"]) == 1
    err = capsys.readouterr().err
    assert "simulated crash in frame 3" in err  # an internal error keeps its traceback
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.yaml"]


def test_info_lists_bones_colliders_cloths(scene_file, capsys):
    assert cli.main(["info", str(scene_file), "--bones"]) == 0
    out = capsys.readouterr().out
    assert "bones: 4 transforms in 1 rig\n" in out
    assert "ball: sphere on 'root', radius 0.05" in out
    assert "'tail': line, preset tail, component 'root'" in out
    assert "\n    root\n      tail_0\n        tail_1\n          tail_2\n" in out  # --bones: indented tree


def test_info_shows_parameters_beyond_the_preset(scene_file, capsys):
    argv = ["info", str(scene_file), "--set", "cloths.tail.parameters.inertia.world_inertia=0.5",
            "--set", "cloths.tail.parameters.inertia.particle_speed_limit=false"]
    assert cli.main(argv) == 0
    out = capsys.readouterr().out
    assert "parameters beyond the preset: inertia.world_inertia=0.5, inertia.particle_speed_limit=off" in out


def test_registered_commands_are_imported_lazily(monkeypatch, capsys):
    module = types.ModuleType("fake_magica_command")
    seen = []
    module.main_hello = lambda argv: seen.append(list(argv)) or 7
    monkeypatch.setitem(sys.modules, "fake_magica_command", module)
    monkeypatch.setitem(cli.COMMANDS, "hello", ("fake_magica_command", "main_hello", "say hello"))
    assert cli.main(["hello", "a", "--b"]) == 7
    assert seen == [["a", "--b"]]
    assert cli.main(["--help"]) == 0
    assert "say hello" in capsys.readouterr().out


def test_unavailable_registered_command(monkeypatch, capsys):
    monkeypatch.setitem(cli.COMMANDS, "ghost", ("magica_py.no_such_module", "main", "nothing"))
    assert cli.main(["ghost"]) == 1
    assert "not available" in capsys.readouterr().err


def test_summary_counts_simulation_steps():
    from magica_py.runner import RunStats, summary_line

    stats = RunStats()
    stats.frames, stats.steps, stats.steps_known, stats.wall_time = 60, 90.0, True, 0.5
    scene = types.SimpleNamespace(name="s", cloths=[1])
    line = summary_line(scene, stats, True, None)
    assert line == "s: 60 frames, 90 simulation steps, 8.33 ms/frame (wall 0.50 s)"
    stats.particle_steps = 720.0
    assert "90 simulation steps (720 particle-steps)" in summary_line(scene, stats, True, None)
    stats.steps_known = False
    assert "no simulation steps (cloth solver not attached)" in summary_line(scene, stats, False, None)
    assert "no cloths" in summary_line(types.SimpleNamespace(name="s", cloths=[]), stats, False, None)


def test_frame_steps_come_from_a_metric_or_the_solver_time_state():
    from magica_py.runner import frame_steps

    ctx = types.SimpleNamespace(metrics={"cloth.simulation_steps": 2.0})
    assert frame_steps(ctx, None) == 2.0
    system = types.SimpleNamespace(time_state=types.SimpleNamespace(update_count=[1, 3, 0]))
    assert frame_steps(types.SimpleNamespace(metrics={}), system) == 3.0
    assert frame_steps(types.SimpleNamespace(metrics={}), None) is None


def test_validate_checks_every_file_and_fails_if_any_is_bad(scene_file, broken_file, capsys):
    assert cli.main(["validate", str(scene_file), str(broken_file), str(scene_file)]) == 2
    captured = capsys.readouterr()
    assert captured.out.count("OK ") == 2
    assert f"{broken_file}: 2 errors" in captured.err and "Traceback" not in captured.err


def test_set_overrides_are_kept_on_the_scene_and_recorded_for_resim(scene_file, tmp_path, capsys):
    """Scene.overrides holds the --set strings; the recording stores them and resim re-reads the
    embedded scene with them (so a re-simulation is the run that was recorded)."""
    from magica_py.config import load_scene
    from magica_py.sinks.resim import load_replay, load_scene_for

    sets = ["cloths.tail.parameters.damping=0.3", "scene.frames=3"]
    assert load_scene(scene_file, sets).overrides == tuple(sets)
    assert load_scene(scene_file).overrides == ()
    out = tmp_path / "with_sets.rrd"
    argv = ["run", str(scene_file), "--rrd", str(out), "--quiet"]
    for s in sets:
        argv += ["--set", s]
    assert cli.main(argv) == 0
    replay = load_replay(out)
    assert tuple(replay.scene_overrides) == tuple(sets)
    again = load_scene_for(replay)
    assert again.overrides == tuple(sets)
    assert again.cloth("tail").parameters["damping"].value == pytest.approx(0.3)
    assert again.settings.frames == 3 and replay.frames.size == 3


def test_info_summarises_the_animation(scene_file, capsys):
    assert cli.main(["info", str(scene_file)]) == 0
    assert "animation: 1 drivers on 1 bones (1 spin)" in capsys.readouterr().out


def test_info_of_an_imported_clip_counts_its_keyframe_drivers(tmp_path, capsys, shared_data):
    """A glTF clip becomes one keyframe driver per animated bone and channel: info says so."""
    import os

    data = shared_data / "gltf" / "Fox.glb"
    fox = os.path.relpath(data, tmp_path)
    path = tmp_path / "fox.yaml"
    path.write_text(f"scene: {{frames: 2}}\nrigs:\n  - {{name: fox, file: {fox}, unit_scale: 0.01}}\n"
                    f"animation:\n  - {{clip: '{fox}#Walk', rig: fox, drop: ['b_Tail*']}}\n")
    assert cli.main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    # Fox Walk animates 20 nodes; the 3 tail bones are dropped; b_Hip_01 has two channels
    assert "animation: 18 drivers on 17 bones (18 keyframes)" in out, out
