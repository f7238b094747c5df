"""A run whose cloths are reset by the solver's guards (a non-finite or runaway particle state)
says so after its summary, instead of ending like a good run with the resets only as events
in the recording."""
from magica_py import cli
from magica_py.runner import RunStats

# the hips swing AMPLITUDE m to and fro 7 times a second with the speed limits off: at 1000 m the
# tail's particles pass the guard's 100 m/s and the cloth is reset (docs/solver.md §E.5)
SCENE = """
scene: {fps: 60, frames: 4}
rigs:
  - name: creature
    bones: [{name: root, position: [0, 1, 0]}, {name: hips, parent: root}]
    parts: [{chain: {name: tail, parent: hips, bones: 4, length: 0.6, direction: [0, 0, -1]}}]
animation:
  - {target: hips, oscillate: {property: position, axis: [1, 0, 0], amplitude: AMPLITUDE, frequency: 7}}
cloths:
  - {name: tail, root_bones: [tail_0], parameters: {inertia.particle_speed_limit: off,
     inertia.movement_speed_limit: off, inertia.rotation_speed_limit: off}}
"""


def test_resets_summary_counts_each_cloth_and_reason_with_its_first_frame():
    stats = RunStats()
    assert stats.resets_summary() == ""
    stats.resets = {("tail", "non-finite particle state"): [5, 0], ("hair", "particle speed above the guard bound"): [1, 7]}
    line = stats.resets_summary()
    assert line.startswith("warning: 6 cloth resets during the run: 'tail' x5 (non-finite particle state, first at frame 0); "
                           "'hair' x1 (particle speed above the guard bound, first at frame 7)")


def test_a_run_whose_cloth_keeps_resetting_warns_after_its_summary(tmp_path, capsys):
    path = tmp_path / "swing.yaml"
    path.write_text(SCENE.replace("AMPLITUDE", "1000"))
    assert cli.main(["run", str(path), "--no-rrd"]) == 0
    err = capsys.readouterr().err
    assert ("magica-py: warning: 2 cloth resets during the run: 'tail' x2 (particle speed above the guard bound, "
            "first at frame 1)") in err


def test_a_good_run_has_no_reset_warning(tmp_path, capsys):
    path = tmp_path / "swing.yaml"
    path.write_text(SCENE.replace("AMPLITUDE", "0.1"))
    assert cli.main(["run", str(path), "--no-rrd"]) == 0
    assert "cloth reset" not in capsys.readouterr().err
