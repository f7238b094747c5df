"""Live output (`--spawn`, `--connect`) works or fails loudly, before the first frame.

The successful stream goes to a real Rerun gRPC server (``rerun --port P --save FILE``, the
viewer executable of rerun-sdk without a window), which saves what it received."""
from __future__ import annotations

import os
import pathlib
import signal
import socket
import subprocess
import time

import pytest

from magica_py.cli import main
from magica_py.sinks.live import display_problem, viewer_executable
from magica_py.sinks.readback import Recording

SCENE = str(pathlib.Path("configs/tail_orbit.yaml").absolute())


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def no_display(monkeypatch):
    for name in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setattr("sys.platform", "linux")


def test_spawn_without_a_display_exits_2_before_anything_runs(tmp_path, monkeypatch, capsys, no_display):
    monkeypatch.chdir(tmp_path)
    start = time.perf_counter()
    assert main(["run", SCENE, "--frames", "3", "--spawn"]) == 2
    err = capsys.readouterr().err
    assert "--spawn: cannot start the Rerun viewer: no display" in err and "Traceback" not in err
    assert time.perf_counter() - start < 10          # no solver was built, no frame ran
    assert list(tmp_path.iterdir()) == []            # and no recording (nor replays/) was written


def test_a_display_name_without_an_x_server_is_reported(monkeypatch):
    monkeypatch.setenv("DISPLAY", ":987")
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_SOCKET", raising=False)
    monkeypatch.setattr("sys.platform", "linux")
    assert "no X server answers at DISPLAY=':987'" in display_problem()


def test_connect_to_a_closed_port_exits_2_before_anything_runs(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    port = free_port()
    assert main(["run", SCENE, "--frames", "3", "--connect", f"127.0.0.1:{port}"]) == 2
    err = capsys.readouterr().err
    assert f"--connect: no Rerun viewer listens at 127.0.0.1:{port}" in err and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []


class GrpcServer:
    """``rerun --port P --save FILE`` or ``--serve-grpc``: a Rerun server without a window, stopped by its pid."""

    def __init__(self, saved=None):
        self.saved = saved
        self.port = free_port()
        env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
        args = [viewer_executable(), "--port", str(self.port)] + (["--save", str(saved)] if saved else ["--serve-grpc"])
        # its own process group: the venv's `rerun` is a wrapper that starts the real binary as a child
        self.process = subprocess.Popen(args, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                        start_new_session=True)

    def __enter__(self):
        deadline = time.time() + 30
        while time.time() < deadline:
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=1).close()
                return self
            except OSError:
                time.sleep(0.2)
        self.__exit__()
        raise RuntimeError("the rerun server did not start")

    def __exit__(self, *exc):
        # the client has flushed when the run returns, but the server writes what it received on
        # its own time: wait until the saved file stops growing (at most 10 s) before stopping it
        if self.saved is not None:
            deadline, last, stable_since = time.time() + 10, -1, time.time()
            while time.time() < deadline:
                size = self.saved.stat().st_size if self.saved.exists() else -1
                if size != last:
                    last, stable_since = size, time.time()
                elif time.time() - stable_since > 0.5:
                    break
                time.sleep(0.05)
        # Ctrl-C to the wrapper and the server it started: `--save` finishes writing what it got
        os.killpg(self.process.pid, signal.SIGINT)
        try:
            self.process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(self.process.pid, signal.SIGKILL)
            self.process.wait()


@pytest.mark.skipif(viewer_executable() is None, reason="the rerun executable of rerun-sdk is not installed")
def test_connect_streams_every_frame_and_writes_no_file_unless_asked(tmp_path, monkeypatch):
    import warnings

    saved = tmp_path / "received.rrd"
    run_dir = tmp_path / "cwd"
    run_dir.mkdir()
    monkeypatch.chdir(run_dir)
    with GrpcServer(saved) as server:
        assert main(["run", SCENE, "--frames", "5", "--connect", f"127.0.0.1:{server.port}", "--quiet"]) == 0
    assert list(run_dir.iterdir()) == []        # live mode: the scene's output.rrd is not written
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")            # the server's file has no footer (it was stopped)
        received = Recording(saved)
    frames, tail = received.stacked("/world/cloths/tail/particles", "Points3D:positions")
    assert frames.tolist() == [0, 1, 2, 3, 4] and tail.shape[1:] == (8, 3)
    with GrpcServer() as server:
        assert main(["run", SCENE, "--frames", "2", "--connect", f"127.0.0.1:{server.port}", "--rrd", "asked.rrd",
                     "--quiet"]) == 0
    assert [p.name for p in run_dir.iterdir()] == ["asked.rrd"]
