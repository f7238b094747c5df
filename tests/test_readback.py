"""Read-back helper and `magica-py inspect`, checked on files written directly with rerun."""
from __future__ import annotations

import json

import numpy as np
import pytest
import rerun as rr

from magica_py.sinks.fakes import frame_data, statics, trajectory
from magica_py.sinks.inspect import main_inspect, summarize
from magica_py.sinks.readback import Recording, RecordingError
from magica_py.sinks.rerun_sink import RerunSink


@pytest.fixture(autouse=True)
def strict():
    rr.set_strict_mode(True)


@pytest.fixture
def plain(tmp_path):
    """A recording written with plain per-frame rr.log calls (not our sink)."""
    path = tmp_path / "plain.rrd"
    traj = np.random.default_rng(1).random((7, 5, 3))
    with rr.RecordingStream("reader_test", recording_id="r") as rec:
        rec.save(path)
        rec.set_log_time_enabled(False)
        for f, pos in enumerate(traj):
            rec.set_time("frame", sequence=f)
            rec.set_time("sim_time", duration=0.25 * f)
            rec.log("a/points", rr.Points3D(pos))
            rec.log("m/x", rr.Scalars(float(f) ** 2))
        rec.log("a/points", rr.Points3D.from_fields(radii=0.5), static=True)
    return path, traj


def test_rows_return_each_logged_row_as_float32(plain):
    path, traj = plain
    rec = Recording(path)
    frames, rows = rec.rows("/a/points", "Points3D:positions")
    assert frames.tolist() == list(range(7))
    for f in range(7):
        assert rows[f].dtype == np.float32 and rows[f].shape == (5, 3)
        np.testing.assert_array_equal(rows[f], traj[f].astype(np.float32))


def test_durations_come_back_in_nanoseconds(plain):
    path, _ = plain
    times, _ = Recording(path).rows("/a/points", "Points3D:positions", timeline="sim_time")
    assert times.tolist() == [250_000_000 * f for f in range(7)]


def test_scalars_and_statics(plain):
    path, _ = plain
    rec = Recording(path)
    frames, values = rec.scalars("/m/x")
    assert values.tolist() == [float(f) ** 2 for f in range(7)]
    np.testing.assert_array_equal(rec.static_value("/a/points", "Points3D:radii"), np.array([0.5], np.float32))
    assert rec.blueprint_count == 0


def test_missing_component_is_a_named_error(plain):
    path, _ = plain
    with pytest.raises(RecordingError, match=r"no 'Points3D:colors' logged on '/a/points'"):
        Recording(path).rows("/a/points", "Points3D:colors")


@pytest.fixture
def sink_file(tmp_path):
    path = tmp_path / "fake.rrd"
    sink = RerunSink(statics(), rrd_path=path, batch_frames=3, collider_kind=np.array([0, 1, 2]),
                     collider_slot=np.array([0, 0, 0]))
    for f, (j, t, s) in enumerate(trajectory(8)):
        sink.begin_frame(f, f / 60)
        sink.log(frame_data(f, j, t, s))
        sink.end_frame()
    sink.close()
    return path


def test_inspect_summary_counts_frames_particles_metrics_and_events(sink_file):
    s = summarize(sink_file)
    assert s["frames"] == 8 and (s["first_frame"], s["last_frame"]) == (0, 7)
    assert s["duration"] == pytest.approx(7 / 60, abs=1e-9)
    assert s["cloths"] == {"tail": 3, "skirt": 4} and s["particles"] == 7
    assert s["metrics"]["steps"] == {"min": 2.0, "mean": 2.0, "max": 2.0, "count": 8, "unit": "steps"}
    assert s["metrics"]["time/late_update"]["max"] == pytest.approx(2.0)
    assert s["metrics"]["max_speed"]["min"] == 0.0
    assert s["events"] == [{"frame": 3, "text": 'teleport: {"frame": 3, "target": "root"}'}]
    assert s["entities"]["/world/cloths/tail/particles"] == {"rows": 8, "static": True}
    assert s["replay"] == {"available": True, "driven_transforms": 1}
    assert s["blueprint"] is True and s["scene"] == "fake"


def test_inspect_command_prints_the_summary(sink_file, capsys):
    assert main_inspect([str(sink_file)]) == 0
    out = capsys.readouterr().out
    assert "frames      8 (frame 0..7)" in out
    assert "particles   7 in 2 cloth(s)" in out
    assert "frame      3  teleport:" in out
    assert main_inspect([str(sink_file), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["particles"] == 7


def test_inspect_of_a_bad_file_exits_2_without_traceback(tmp_path, capsys):
    bad = tmp_path / "x.rrd"
    bad.write_text("nope")
    assert main_inspect([str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("magica-py inspect: error:") and "Traceback" not in err
