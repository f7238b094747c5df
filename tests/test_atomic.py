"""Output files are written whole or not at all (magica_py/atomic.py): an error, ^C or SIGTERM
while writing leaves the old file and no temporary one."""
from __future__ import annotations

import numpy as np
import pytest

from magica_py import atomic


class _Interrupt(BaseException):
    """Stands in for ^C (KeyboardInterrupt) or SIGTERM (cli.Terminated): not an Exception."""


def test_a_finished_write_replaces_the_file_and_leaves_nothing_else(tmp_path):
    path = tmp_path / "report.md"
    path.write_text("old")
    atomic.write_text(path, "new")
    atomic.write_bytes(tmp_path / "row.json", b"{}")
    assert path.read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report.md", "row.json"]


@pytest.mark.parametrize("stop", [_Interrupt, RuntimeError])
def test_a_write_stopped_halfway_keeps_the_old_file_and_removes_the_temporary_one(tmp_path, stop):
    path = tmp_path / "table.csv"
    path.write_text("old")
    with pytest.raises(stop):
        with atomic.replacing(path) as tmp:
            tmp.write_text("half a ta")
            raise stop()
    assert path.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["table.csv"]


def test_a_figure_keeps_the_format_of_its_final_name(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    ax.plot(np.arange(3))
    atomic.save_figure(fig, tmp_path / "plot.png", dpi=50)
    plt.close(fig)
    assert (tmp_path / "plot.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in tmp_path.iterdir()] == ["plot.png"]
