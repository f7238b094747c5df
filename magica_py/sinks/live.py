"""Live output: start a Rerun viewer (``--spawn``) or stream to a running one (``--connect``).

Live output works or fails loudly, before the first frame:

* ``check_live_output`` (cheap, called before the solver is built): ``--spawn`` needs a
  display the viewer can open a window on (Linux: an X server answering at ``$DISPLAY`` or a
  Wayland socket); ``--connect`` needs something listening at the address.
* ``open_live_targets`` (called when the sink is attached, still before any frame): starts
  the viewer bundled with rerun-sdk (``rerun.spawn`` with the venv's ``rerun`` executable,
  on port 9876 like rerun itself: a viewer already running there is reused) and checks that
  it really listens; returns the gRPC URLs to stream to.
* the sink flushes the stream when it closes and turns a delivery failure (the viewer went
  away) into an ``OutputError``, so a lost stream is never reported as success.
"""
from __future__ import annotations

import os
import pathlib
import shutil
import socket
import sys
from urllib.parse import urlparse

SPAWN_PORT = 9876              # rerun's default viewer port
PROBE_SECONDS = 2.0            # TCP connection attempt to a viewer
FLUSH_SECONDS = 15.0           # wait for the stream to be delivered at the end of a run


class OutputError(ValueError):
    """The recording cannot be written / streamed where it was asked to go."""


def grpc_url(address: str) -> str:
    """`host:port` or a full rerun URL -> the URL GrpcSink expects."""
    if "://" in address:
        return address
    if ":" not in address:
        raise OutputError(f"--connect: {address!r} is not host:port or a rerun+http:// URL")
    return f"rerun+http://{address}/proxy"


def url_host_port(url: str) -> tuple[str, int]:
    parsed = urlparse(url.replace("rerun+http", "http", 1).replace("rerun+https", "https", 1)
                      .replace("rerun://", "https://", 1))
    if not parsed.hostname or parsed.port is None:
        raise OutputError(f"--connect: cannot read host and port from {url!r}")
    return parsed.hostname, parsed.port


def listening(host: str, port: int, timeout: float = PROBE_SECONDS) -> str | None:
    """None when a TCP connection to host:port succeeds, else the reason."""
    try:
        with socket.create_connection((host, port), timeout=timeout):
            return None
    except OSError as exc:
        return exc.strerror or str(exc)


def display_problem() -> str | None:
    """Why a viewer window cannot open here (None: it can, as far as we can tell)."""
    if not sys.platform.startswith("linux"):
        return None        # macOS / Windows always have a window server for a desktop user
    wayland = os.environ.get("WAYLAND_DISPLAY") or os.environ.get("WAYLAND_SOCKET")
    if wayland:
        runtime = os.environ.get("XDG_RUNTIME_DIR", "")
        if os.environ.get("WAYLAND_SOCKET") or (runtime and (pathlib.Path(runtime) / wayland).exists()) \
                or pathlib.Path(wayland).is_absolute():
            return None
    display = os.environ.get("DISPLAY", "")
    if not display:
        return "no display: neither DISPLAY nor WAYLAND_DISPLAY is set"
    host, _, rest = display.rpartition(":")
    number = rest.split(".")[0]
    if not number.isdigit():
        return f"DISPLAY={display!r} is not a display name like ':0'"
    if host in ("", "unix"):
        sock = pathlib.Path(f"/tmp/.X11-unix/X{number}")
        try:
            with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
                s.settimeout(PROBE_SECONDS)
                s.connect(str(sock))
            return None
        except OSError as exc:
            if host == "unix":
                return f"no X server answers at DISPLAY={display!r} ({exc.strerror or exc})"
        host = "127.0.0.1"
    reason = listening(host, 6000 + int(number))
    return None if reason is None else f"no X server answers at DISPLAY={display!r} ({reason})"


def check_live_output(spawn: bool, connect: str | None) -> None:
    """Fail fast (OutputError) when the requested live output cannot work."""
    if spawn:
        problem = display_problem()
        if problem:
            raise OutputError(f"--spawn: cannot start the Rerun viewer: {problem}. Record to a file instead "
                              "(--rrd FILE.rrd, then open it with `rerun FILE.rrd` on a machine with a display), "
                              "or stream to a viewer running elsewhere with --connect HOST:PORT")
    if connect is not None:
        url = grpc_url(connect)
        host, port = url_host_port(url)
        reason = listening(host, port)
        if reason is not None:
            raise OutputError(f"--connect: no Rerun viewer listens at {host}:{port} ({reason}); start one with "
                              f"`rerun --port {port}` (or use --spawn / --rrd)")


def viewer_executable() -> str | None:
    """The `rerun` viewer installed with rerun-sdk next to this Python (a venv's bin/), else PATH's."""
    here = pathlib.Path(sys.executable).parent / ("rerun.exe" if os.name == "nt" else "rerun")
    if here.exists():
        return str(here)
    return shutil.which("rerun")


def open_live_targets(rr, recording, spawn: bool, connect: str | None) -> list[str]:
    """Start / check the viewers; returns the gRPC URLs to stream to (raises OutputError)."""
    check_live_output(spawn, connect)
    urls = []
    if spawn:
        executable = viewer_executable()
        if executable is None:
            raise OutputError("--spawn: the `rerun` viewer executable was not found (it comes with rerun-sdk; "
                              "is the environment's bin/ folder missing?)")
        if recording is None:   # rerun.spawn ignores the call unless the given recording is enabled
            recording = rr.RecordingStream("magica_py")
        try:
            rr.spawn(port=SPAWN_PORT, connect=False, recording=recording, executable_path=executable,
                     hide_welcome_screen=True)
        except Exception as exc:  # noqa: BLE001 - rerun raises RuntimeError
            raise OutputError(f"--spawn: cannot start the Rerun viewer: {exc}") from exc
        reason = listening("127.0.0.1", SPAWN_PORT)
        if reason is not None:
            raise OutputError(f"--spawn: the Rerun viewer did not start (nothing listens on port {SPAWN_PORT}: "
                              f"{reason}); it needs a working display (DISPLAY={os.environ.get('DISPLAY', '')!r})")
        urls.append(f"rerun+http://127.0.0.1:{SPAWN_PORT}/proxy")
    if connect is not None:
        url = grpc_url(connect)
        if url not in urls:
            urls.append(url)
    return urls
