"""The sink commands through the `magica-py` CLI (in-process; no viewer, no network)."""
from __future__ import annotations

import pytest
import rerun as rr

from magica_py.cli import main
from magica_py.sinks.inspect import summarize

SCENE = "configs/tail_orbit.yaml"


@pytest.fixture(autouse=True)
def strict():
    rr.set_strict_mode(True)


def test_run_records_and_inspect_and_resim_read_it(tmp_path, capsys):
    rrd = tmp_path / "tail.rrd"
    assert main(["run", SCENE, "--frames", "12", "--rrd", str(rrd), "--quiet"]) == 0
    s = summarize(rrd)
    assert s["frames"] == 12 and s["cloths"] == {"tail": 8} and s["blueprint"]
    capsys.readouterr()
    assert main(["inspect", str(rrd)]) == 0
    assert "frames      12 (frame 0..11)" in capsys.readouterr().out
    out = tmp_path / "again.rrd"
    assert main(["resim", str(rrd), "--rrd", str(out)]) == 0
    assert summarize(out)["frames"] == 12


def test_run_into_an_impossible_folder_exits_2_and_writes_nothing(tmp_path, capsys):
    # a missing folder is created (as for output.rrd); one under a file cannot be
    (tmp_path / "file").write_text("")
    assert main(["run", SCENE, "--frames", "3", "--rrd", str(tmp_path / "file" / "no" / "x.rrd"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "cannot create the folder" in err and "Traceback" not in err
    assert [p.name for p in tmp_path.iterdir()] == ["file"]


def test_record_all_writes_one_recording_per_config(tmp_path, capsys):
    configs = tmp_path / "configs"
    configs.mkdir()
    (configs / "tail.yaml").write_text(open(SCENE).read())
    out = tmp_path / "replays"
    assert main(["record-all", "--configs", str(configs), "--out", str(out), "--frames", "6"]) == 0
    assert [p.name for p in out.iterdir()] == ["tail.rrd"]
    assert summarize(out / "tail.rrd")["frames"] == 6
    assert "% of sim" in capsys.readouterr().out
