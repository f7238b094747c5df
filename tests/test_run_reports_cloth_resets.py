"""A run whose cloths are reset by the solver's guards (a non-finite or runaway particle state)
says so after its summary, instead of ending like a good run with the resets only as events
in the recording."""
from magica_py import cli
from magica_py.runner import RunStats

# spin speed 1e300 deg/s: the driver's angle is far beyond the range of the portable sin/cos
# (kernels/trig.py: accurate for |x| <= 1e4), the hips rotation becomes NaN, and the tail is
# reset every frame (see the report of session 36 on bad scenes)
SCENE = """
scene: {fps: 60, frames: 4}
rigs:
  - name: creature
    bones: [{name: root, position: [0, 1, 0]}, {name: hips, parent: root}]
    parts: [{chain: {name: tail, parent: hips, bones: 4, length: 0.6, direction: [0, 0, -1]}}]
animation:
  - {target: hips, spin: {speed: SPEED, axis: [0, 1, 0]}}
cloths:
  - {name: tail, root_bones: [tail_0]}
"""


def test_resets_summary_counts_each_cloth_and_reason_with_its_first_frame():
    stats = RunStats()
    assert stats.resets_summary() == ""
    stats.resets = {("tail", "non-finite particle state"): [5, 0], ("hair", "particle speed above the guard bound"): [1, 7]}
    line = stats.resets_summary()
    assert line.startswith("warning: 6 cloth resets during the run: 'tail' x5 (non-finite particle state, first at frame 0); "
                           "'hair' x1 (particle speed above the guard bound, first at frame 7)")


def test_a_run_whose_cloth_keeps_resetting_warns_after_its_summary(tmp_path, capsys):
    path = tmp_path / "spin.yaml"
    path.write_text(SCENE.replace("SPEED", "1e300"))
    assert cli.main(["run", str(path), "--no-rrd"]) == 0
    err = capsys.readouterr().err
    assert "magica-py: warning: 4 cloth resets during the run: 'tail' x4 (non-finite particle state, first at frame 0)" in err


def test_a_good_run_has_no_reset_warning(tmp_path, capsys):
    path = tmp_path / "spin.yaml"
    path.write_text(SCENE.replace("SPEED", "90"))
    assert cli.main(["run", str(path), "--no-rrd"]) == 0
    assert "cloth reset" not in capsys.readouterr().err
