"""``magica-py watch SCENE.yaml``: re-run a scene every time it, or an asset it reads, changes.

The tuning loop of a technical artist: keep the viewer open, edit the YAML (a damping, a
collider radius), save, and the new run appears next to the previous ones.

* **What is watched**: the scene file and every asset it reads (``rigs[i].file``, the file of
  ``animation[i].clip``), relative to the scene's folder; the list is refreshed on each save.
  Files are polled (``poll`` s, a handful of ``stat`` calls: portable, no extra dependency).
* **Debounced**: after a change the files must stay unchanged for ``debounce`` s before the
  run starts, so an editor's save-in-several-writes (or a burst of saves) runs once.
* **One recording per run**, named after the scene and a short description of what changed
  (``ponytail · damping 0.05→0.2``, ``ponytail · Fox.glb changed``), each with its own
  recording id, so runs with different parameters sit side by side in the viewer's recording
  list. Output: a viewer (``--connect ADDR``, default the local viewer on port 9876, or
  ``--spawn`` one), and/or one ``.rrd`` per run in ``--rrd-dir``. The scene's own
  ``output.rrd`` is not written by a watch.
* **Bad edits do not stop it**: validation (and build) errors are printed as ``validate``
  prints them, and the watch waits for the next save. A save during a run stops that run
  (its recording keeps the frames it had streamed; a file of it is discarded) and starts the
  new one.
* **Ctrl-C** ends the current run, closes its recording and exits with code 0.
* **The first run on an empty kernel cache** does not wait for the solver's compile: while no
  compiled cloth frame is in the cache, a run short enough to interpret is handed to
  ``magica-py run`` in its interpreted tier (``magica_py/first_run.py``), which streams and
  records it under the same name and file and compiles the solver in the background; the
  runs after that compile are this process's own again. A run too long to interpret compiles
  here, as always.

Each run prints one line: frames, ms/frame, and how long after the save its first frame was
sent (``first frame 0.38 s after the save``): the tuning loop's latency.
"""
from __future__ import annotations

import argparse
import os
import pathlib
import re
import subprocess
import sys
import time
import uuid
from dataclasses import dataclass

DEFAULT_VIEWER = "127.0.0.1:9876"    # the port `rerun` and `rr.spawn()` listen on
DEBOUNCE_SECONDS = 0.2
POLL_SECONDS = 0.1
SUPERSEDE_CHECK_SECONDS = 0.2        # during a run: how often the files are checked again


# ----------------------------------------------------------------------------- files
def scene_assets(data, scene_path) -> list[pathlib.Path]:
    """Asset files a scene document reads (rig files, clip files), resolved as the loader
    resolves them: relative to the scene file's folder."""
    base = pathlib.Path(scene_path).resolve().parent
    found: list[pathlib.Path] = []
    if not isinstance(data, dict):
        return found
    for rig in data.get("rigs") or []:
        if isinstance(rig, dict) and isinstance(rig.get("file"), str):
            found.append(pathlib.Path(os.path.normpath(base / rig["file"])))
    for entry in data.get("animation") or []:
        if isinstance(entry, dict) and isinstance(entry.get("clip"), str):
            found.append(pathlib.Path(os.path.normpath(base / entry["clip"].split("#", 1)[0])))
    return sorted(set(found))


class FileStamps:
    """(mtime_ns, size) of a set of files; a missing file has the stamp None."""

    def __init__(self, paths):
        self.paths = [pathlib.Path(p) for p in paths]
        self.stamps = {p: self._stamp(p) for p in self.paths}

    @staticmethod
    def _stamp(path):
        try:
            st = path.stat()
        except OSError:
            return None
        return (st.st_mtime_ns, st.st_size)

    def with_paths(self, paths) -> "FileStamps":
        """Stamps of ``paths``: the ones taken here kept, new files stamped now."""
        out = FileStamps([])
        out.paths = [pathlib.Path(p) for p in paths]
        out.stamps = {p: self.stamps[p] if p in self.stamps else self._stamp(p) for p in out.paths}
        return out

    def changed(self) -> list[pathlib.Path]:
        """The files whose stamp differs from the one taken (without updating it)."""
        return [p for p in self.paths if self._stamp(p) != self.stamps[p]]

    def newest_mtime(self, paths) -> float:
        """Latest modification time (s since the epoch) among ``paths`` (now if none exist)."""
        times = [s[0] / 1e9 for s in (self._stamp(p) for p in paths) if s is not None]
        return max(times) if times else time.time()


# ----------------------------------------------------------------------------- what changed
def _flatten(data, prefix=(), label=None, out=None) -> dict:
    """Leaves of a document as {path tuple: (readable label, value)}; list elements with a
    ``name`` are keyed by it (so reordering cloths is not a change of every parameter)."""
    out = {} if out is None else out
    if isinstance(data, dict):
        for key, value in data.items():
            _flatten(value, prefix + (str(key),), key if label is None else f"{label}.{key}", out)
    elif isinstance(data, list) and data and all(isinstance(x, (int, float, str, bool)) or x is None for x in data):
        out[prefix] = (label or "document", data)          # a vector or a list of names: one value
    elif isinstance(data, list):
        for i, item in enumerate(data):
            name = item.get("name") if isinstance(item, dict) else None
            key = f"{name}" if isinstance(name, str) else f"[{i}]"
            _flatten(item, prefix + (key,), key if isinstance(name, str) else label, out)
    else:
        out[prefix] = (label or "document", data)
    return out


def _short(value) -> str:
    text = str(value) if not isinstance(value, list) else "[" + ", ".join(str(v) for v in value) + "]"
    return text if len(text) <= 24 else text[:21] + "..."


def describe_change(old, new, changed_assets=(), limit: int = 3) -> str:
    """A short text of what differs between two scene documents (and which assets changed):
    ``ponytail.parameters.damping 0.05→0.2``; ``first run`` when there is no old document."""
    if old is None:
        return "first run"
    parts = []
    a, b = _flatten(old), _flatten(new)
    for path in sorted(set(a) | set(b)):
        if path in a and path in b:
            if a[path][1] != b[path][1]:
                parts.append(f"{b[path][0]} {_short(a[path][1])}→{_short(b[path][1])}")
        elif path in b:
            parts.append(f"+{b[path][0]}={_short(b[path][1])}")
        else:
            parts.append(f"-{a[path][0]}")
    parts.extend(f"{p.name} changed" for p in changed_assets)
    if not parts:
        return "saved unchanged"
    more = f" and {len(parts) - limit} more" if len(parts) > limit else ""
    return ", ".join(parts[:limit]) + more


def scene_name(data, scene_path, overrides=()) -> str:
    """The name a scene document gives its scene, as ``config.load_scene`` resolves it without
    loading the scene: ``scene.name`` (a ``--set scene.name=...`` override first), else the
    file's stem."""
    from magica_py.config.overrides import parse_override

    for override in reversed(list(overrides)):
        try:
            path, value = parse_override(str(override))
        except ValueError:   # reported by the run that loads the scene
            continue
        if path == ["scene", "name"] and isinstance(value, str) and value:
            return value
    scene = data.get("scene") if isinstance(data, dict) else None
    name = scene.get("name") if isinstance(scene, dict) else None
    return name if isinstance(name, str) and name else pathlib.Path(scene_path).stem


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.=-]+", "_", text.replace("→", "-to-")).strip("_")[:60] or "run"


# ----------------------------------------------------------------------------- one run
class _Superseded(Exception):
    """A newer save arrived during a run."""


@dataclass
class RunReport:
    """What one watch run did (tests read these)."""

    index: int
    description: str
    ok: bool
    frames: int = 0
    error: str = ""
    recording: str | None = None       # the .rrd written (with --rrd-dir)
    recording_name: str = ""
    latency: float | None = None       # s from the save to the first frame sent
    superseded: bool = False


class Watch:
    """The watch loop: ``run_forever`` is the command, ``run`` one run of the scene."""

    def __init__(self, scene_path, *, overrides=(), frames: int | None = None, connect: str | None = None,
                 rrd_dir=None, debounce: float = DEBOUNCE_SECONDS, poll: float = POLL_SECONDS,
                 stream=None):
        self.scene_path = pathlib.Path(scene_path)
        self.overrides = list(overrides)
        self.frames = frames
        self.connect = connect
        self.rrd_dir = pathlib.Path(rrd_dir) if rrd_dir is not None else None
        self.debounce = debounce
        self.poll = poll
        self.stream = stream if stream is not None else sys.stderr
        self.reports: list[RunReport] = []
        self.last_data = None                  # the document of the last run that passed validation
        self.stamps = FileStamps([self.scene_path])
        self.run_index = 0

    # -- messages
    def say(self, text: str) -> None:
        print(f"watch: {text}", file=self.stream, flush=True)

    # -- the loop
    def run_forever(self, max_runs: int | None = None, stop=None) -> int:
        """Run now, then after every debounced change; ``max_runs`` / ``stop()`` end it (tests)."""
        outputs = ([f"viewer {self.connect}"] if self.connect else []) + \
                  ([f"{self.rrd_dir}/"] if self.rrd_dir is not None else [])
        self.say(f"watching {self.scene_path} and the assets it reads; each run goes to {' and '.join(outputs)} "
                 "(Ctrl-C to stop)")
        try:
            pending = [self.scene_path]   # the first run
            save_time = time.time()
            while True:
                if pending:
                    self.run(pending, save_time)
                    if max_runs is not None and len(self.reports) >= max_runs:
                        return 0
                    pending = []
                if stop is not None and stop():
                    return 0
                changed = self.stamps.changed()
                if changed:
                    changed = self._settle(changed)
                    save_time = self.stamps.newest_mtime(changed)
                    pending = changed
                else:
                    time.sleep(self.poll)
        except KeyboardInterrupt:
            self.say("stopped")
            return 0

    def _settle(self, changed: list[pathlib.Path]) -> list[pathlib.Path]:
        """Wait until the files stay unchanged for ``debounce`` s; returns every file that changed."""
        seen = set(changed)
        last = FileStamps(self.stamps.paths)
        quiet_since = time.monotonic()
        while time.monotonic() - quiet_since < self.debounce:
            time.sleep(min(self.poll, self.debounce))
            moved = last.changed()
            if moved:
                seen.update(moved)
                last = FileStamps(self.stamps.paths)
                quiet_since = time.monotonic()
        return sorted(seen)

    # -- one run
    def run(self, changed, save_time: float) -> RunReport:
        """Read, validate and run the scene once; errors are reported, never raised (but Ctrl-C)."""
        from magica_py.cli import _format_input_error, _is_input_error
        from magica_py.config.document import read_document
        from magica_py.config.errors import ConfigError

        self.run_index += 1
        before = FileStamps(self.stamps.paths)   # taken before reading: a save from now on is a new change
        data = None
        try:
            data = read_document(self.scene_path).data
        except ConfigError:
            pass  # reported below by load_scene, with every other problem
        assets = scene_assets(data, self.scene_path) if data is not None else \
            [p for p in self.stamps.paths if p != self.scene_path]
        self.stamps = before.with_paths([self.scene_path] + assets)
        changed_assets = [p for p in changed if p != self.scene_path]
        description = describe_change(self.last_data, data, changed_assets) if data is not None else "unreadable"
        report = RunReport(self.run_index, description, ok=False)
        try:
            self._run_scene(report, save_time, data)
        except _Superseded:
            report.superseded = True
            done = f" after {report.frames} frames" if report.frames else ""   # an interpreted child's: not known
            self.say(f"run {report.index} ({description}): stopped{done} by a new save")
        except KeyboardInterrupt:
            raise
        except Exception as exc:  # noqa: BLE001 - a watch reports and keeps going
            if _is_input_error(exc):
                report.error = _format_input_error(exc)
                self.say(f"run {report.index}: the scene has problems; fix them and save again\n{report.error}")
            else:
                import traceback

                report.error = "".join(traceback.format_exception(exc))
                self.say(f"run {report.index}: internal error (a bug; the watch goes on)\n{report.error}")
        self.reports.append(report)
        return report

    def _first_run_interpreted(self) -> bool:
        """Is this run a first run to hand to ``run``'s interpreted tier (no compiled cloth frame
        in the kernel cache yet; ``magica_py/first_run.py``)?"""
        from magica_py import first_run

        try:
            return first_run.wanted(argparse.Namespace(no_simulation=False))
        except first_run.FirstRunError:   # reported when the watch started (main_watch)
            return False

    def _run_interpreted(self, report: RunReport, data) -> bool:
        """A first run, handed to ``magica-py run`` in the interpreted tier: it streams and
        records the run as this process would (same recording name, id and file) after a second
        or two instead of after the solver's compile, and starts that compile in the
        background, so that the runs after it are compiled here. Returns False when the child
        declined (the run is too long to interpret) or failed: the run then compiles here."""
        from magica_py import first_run
        from magica_py.cli import EXIT_BAD_INPUT, EXIT_OK

        name = scene_name(data, self.scene_path, self.overrides)
        report.recording_name = f"{name} · {report.description}"
        argv = [str(self.scene_path)]
        for override in self.overrides:
            argv += ["--set", override]
        if self.frames is not None:
            argv += ["--frames", str(self.frames)]
        rrd = None
        if self.rrd_dir is not None:
            self.rrd_dir.mkdir(parents=True, exist_ok=True)
            rrd = self.rrd_dir / self._rrd_name(name, report)
            argv += ["--rrd", str(rrd)]
        else:
            argv.append("--no-rrd")
        if self.connect:
            argv += ["--connect", self.connect, "--batch-frames", "1"]
        argv += ["--recording-name", report.recording_name, "--recording-id", str(uuid.uuid4())]
        # its notes and progress bar go to the terminal; its summary line is read for the frames
        child = first_run.interpreted_child(argv, stdout=subprocess.PIPE, text=True)
        try:
            while child.poll() is None:
                time.sleep(SUPERSEDE_CHECK_SECONDS)
                if self.stamps.changed():
                    _stop_child(child)
                    raise _Superseded()
        except KeyboardInterrupt:
            try:   # a terminal's ^C reached the child as well: it ends itself (its file removed;
                # a run that completes meanwhile keeps it); its output pipe is drained meanwhile
                child.communicate(timeout=CHILD_GRACE_SECONDS)
            except subprocess.TimeoutExpired:   # only the watch was interrupted
                _stop_child(child)
            raise
        out = child.communicate()[0] or ""
        if out:
            print(out, end="", flush=True)
        code = child.returncode
        if code == EXIT_OK:
            frames = re.search(r": (\d+) frames", out)
            report.frames = int(frames.group(1)) if frames else 0
            report.ok = True
            report.recording = str(rrd) if rrd is not None and rrd.exists() else None
            self.last_data = data
            self.say(f"run {report.index} ({report.description}): {report.frames} frames, interpreted (first run "
                     "only: the solver compiles in the background, and the runs after it are compiled)"
                     + (f" -> {report.recording}" if report.recording else ""))
            return True
        if code == EXIT_BAD_INPUT:
            report.error = "the scene has problems (printed above)"
            self.say(f"run {report.index}: the scene has problems; fix them and save again")
            return True
        if code != first_run.DECLINED:
            self.say(f"run {report.index}: the interpreted first run failed (exit {code}); compiling the solver "
                     "instead")
        return False

    def _rrd_name(self, scene: str, report: RunReport) -> str:
        return f"{_slug(scene)}-{report.index:03d}-{_slug(report.description)}.rrd"

    def _run_scene(self, report: RunReport, save_time: float, data) -> None:
        if data is not None and self._first_run_interpreted() and self._run_interpreted(report, data):
            return
        from magica_py.cli import _attach_solver
        from magica_py.config import load_scene
        from magica_py.runner import CompileWatch, WarningEvents, compile_text, play
        from magica_py.runtime.player import Player
        from magica_py.sinks import SinkOptions, attach

        scene = load_scene(self.scene_path, self.overrides)
        self.last_data = data   # valid: the next run's description is relative to this one
        report.recording_name = f"{scene.name} · {report.description}"
        frames = self.frames if self.frames is not None else scene.settings.frame_count()
        player = Player.for_scene(scene)
        compile_watch = CompileWatch(announce=self.say)
        warning_events = WarningEvents()
        with compile_watch:
            notes: list[str] = []
            system = _attach_solver(player, scene, notes)
            for note in notes:
                self.say(note)
            warning_events.attach(player)
            rrd = None
            if self.rrd_dir is not None:
                self.rrd_dir.mkdir(parents=True, exist_ok=True)
                rrd = self.rrd_dir / self._rrd_name(scene.name, report)
            recorder = attach(player, scene, SinkOptions(rrd=rrd, no_rrd=rrd is None, connect=self.connect,
                                                         batch_frames=1 if self.connect else None,
                                                         recording_id=str(uuid.uuid4()),
                                                         recording_name=report.recording_name))
            ok = False
            try:
                recorder.open()
                next_check = [time.monotonic() + SUPERSEDE_CHECK_SECONDS]

                def on_frame(ctx):
                    report.frames = ctx.frame + 1
                    if ctx.frame == 0:
                        report.latency = time.time() - save_time
                    now = time.monotonic()
                    if now >= next_check[0]:
                        next_check[0] = now + SUPERSEDE_CHECK_SECONDS
                        if self.stamps.changed():
                            raise _Superseded()

                with warning_events:
                    stats = play(player, scene, frames, system=system, compile_watch=compile_watch,
                                 warning_events=warning_events, on_frame=on_frame)
                ok = True
            finally:
                recorder.close(ok)
        report.ok = True
        report.recording = str(recorder.output_path) if recorder.output_path is not None else None
        per_frame = 1000.0 * stats.wall_time / max(stats.frames, 1)
        latency = f"; first frame {report.latency:.2f} s after the save" if report.latency is not None else ""
        compiled = compile_text(compile_watch.seconds)
        self.say(f"run {report.index} ({report.description}): {stats.frames} frames, {per_frame:.2f} ms/frame"
                 f"{compiled}{latency}" + (f" -> {report.recording}" if report.recording else ""))
        if stats.warnings:
            self.say(stats.warnings)


CHILD_GRACE_SECONDS = 5.0   # a child's own ^C clean-up; then it is stopped, then killed


def _stop_child(child) -> None:
    """End an interpreted child run: SIGTERM, which ``run`` handles like ^C (the recording file it
    had begun is removed; SIGINT would not do: a process started with SIGINT ignored, as under
    a job runner, passes that on to its children), then SIGKILL if it has not ended after
    ``CHILD_GRACE_SECONDS``."""
    child.terminate()
    try:
        child.communicate(timeout=CHILD_GRACE_SECONDS)
    except subprocess.TimeoutExpired:
        child.kill()
        child.communicate()


# ----------------------------------------------------------------------------- command
def viewer_listening(address: str, timeout: float = 1.0) -> bool:
    """Whether something accepts connections at ``host:port`` (or a ``rerun+http://host:port/...``
    URL): a run streamed to nobody would be lost, and rerun only says so when it shuts down."""
    import socket
    from urllib.parse import urlsplit

    netloc = urlsplit(address).netloc if "://" in address else address
    host, _, port = netloc.rpartition(":")
    try:
        with socket.create_connection((host or "127.0.0.1", int(port)), timeout=timeout):
            return True
    except (OSError, ValueError):
        return False


def _wait_for_viewer(address: str, seconds: float) -> bool:
    """``viewer_listening``, retried for ``seconds`` (a spawned viewer takes a moment to start)."""
    end = time.monotonic() + seconds
    while True:
        if viewer_listening(address):
            return True
        if time.monotonic() >= end:
            return False
        time.sleep(0.25)


def main_watch(argv=None) -> int:
    parser = argparse.ArgumentParser(
        prog="magica-py watch",
        description="Re-run a scene whenever the YAML or an asset it reads changes. Each run is its own "
                    "recording, named after the scene and what changed, streamed to a Rerun viewer (and/or "
                    "written to --rrd-dir), so runs sit side by side in the viewer's recording list. Bad edits "
                    "print their errors and the watch goes on; Ctrl-C stops it.",
        epilog="Example:\n  rerun &                                    # a viewer (or use --spawn)\n"
               "  magica-py watch configs/tail_orbit.yaml   # then edit and save the YAML",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("scene", metavar="SCENE.yaml", help="scene file (format: docs/scene-format.md)")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                        help="override a value on every run (as in `run`)")
    parser.add_argument("--frames", type=int, metavar="N", help="frames per run (default: the scene's length)")
    viewer = parser.add_mutually_exclusive_group()
    viewer.add_argument("--connect", metavar="ADDR", default=None,
                        help=f"stream to the viewer at ADDR (host:port or URL; default {DEFAULT_VIEWER})")
    viewer.add_argument("--spawn", action="store_true", help="start a Rerun viewer first and stream to it")
    viewer.add_argument("--no-viewer", action="store_true", help="do not stream (use with --rrd-dir)")
    parser.add_argument("--rrd-dir", metavar="DIR", help="also write each run to DIR/<scene>-<n>-<change>.rrd")
    parser.add_argument("--debounce", type=float, default=DEBOUNCE_SECONDS, metavar="S",
                        help=f"wait until the files are quiet this long after a save (default {DEBOUNCE_SECONDS} s)")
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0)
    if args.frames is not None and args.frames < 1:
        print("magica-py watch: error: --frames: expected at least 1 frame", file=sys.stderr)
        return 2
    if not pathlib.Path(args.scene).is_file():
        print(f"magica-py watch: error: {args.scene}: file not found", file=sys.stderr)
        return 2
    from magica_py import first_run

    try:   # a bad MAGICA_FIRST_RUN / MAGICA_INTERPRET_BUDGET, said once, before the first run
        first_run.mode()
        first_run.budget()
    except first_run.FirstRunError as exc:
        print(f"magica-py watch: error: {exc}", file=sys.stderr)
        return 2
    if args.no_viewer and args.rrd_dir is None:
        print("magica-py watch: error: --no-viewer without --rrd-dir would run without any output", file=sys.stderr)
        return 2
    connect = None if args.no_viewer else (args.connect or DEFAULT_VIEWER)
    if args.spawn:
        try:
            import rerun as rr

            rr.spawn(connect=False)   # once; every run then connects to it
        except Exception as exc:  # noqa: BLE001 - rerun raises plain errors without a display
            print(f"magica-py watch: error: cannot start the viewer: {exc}", file=sys.stderr)
            return 2
    if connect is not None and not _wait_for_viewer(connect, 10.0 if args.spawn else 0.0):
        print(f"magica-py watch: error: no Rerun viewer is listening at {connect}: start one (`rerun`), or use "
              "--spawn, or --no-viewer --rrd-dir DIR to keep each run as a file", file=sys.stderr)
        return 2
    watch = Watch(args.scene, overrides=args.overrides, frames=args.frames, connect=connect,
                  rrd_dir=args.rrd_dir, debounce=args.debounce)
    return watch.run_forever()
