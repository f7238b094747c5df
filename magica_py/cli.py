"""``magica-py``: run, validate and describe scene files.

Commands (``magica-py COMMAND --help`` for each):

* ``run SCENE.yaml|AVATAR.vrm [--frames N] [--rrd PATH] [--no-rrd] [--set K=V ...] [--spawn]
  [--connect ADDR] [--quiet] [--clip CLIP] [--save-scene FILE.yaml]``: build the scene (a VRM
  avatar gets the scene of ``magica_py.avatar``), the player (``default_schedule``), the
  cloth system (``magica_py.solver.attach(player, scene)`` when the solver provides it, else
  ``solver.system.ClothSystem(hierarchy, cloths, colliders, settings).attach(player, scene)``
  as ``magica-py record-all`` does) and
  the sink (``magica_py.sinks.attach(player, scene, options)``), run with the loop of
  ``magica_py.runner`` (progress bar, compile announced and timed apart, warnings as events),
  print a summary. A short first run (no compiled cloth frame cached) goes interpreted in a
  child process while the solver compiles in the background (``magica_py.first_run``);
* ``validate SCENE.yaml [SCENE.yaml ...] [--set ...]``: check everything (and build the cloths when
  ``magica_py.build`` is present), print ``OK`` or every problem;
* ``info SCENE.yaml [--set ...] [--bones]``: settings, rigs, bones, colliders, cloths and,
  when ``magica_py.build`` is present, particles and constraints per cloth;
* commands registered in ``COMMANDS`` by other packages (``inspect``, ``record-all``,
  ``resim`` from ``magica_py.sinks``): ``name -> (module, function, help)``; the function
  takes the remaining argv and returns an exit code. It is imported only when used.

Exit codes: 0 success, 1 unexpected failure (with a traceback: a bug), 2 bad input (scene
file, ``--set``, output path, build error: printed without a traceback), 130 interrupted (^C),
143 terminated (SIGTERM).
No partial output: the recording is written to a temporary name and renamed at the end by the
sink, every other file a command writes likewise (``magica_py/atomic.py``); a failed or
interrupted run deletes the temporary file.

Heavy modules (numpy, numba, rerun) are imported inside the commands, so ``--help`` is fast.
"""
from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import signal
import sys
import traceback
import warnings

from magica_py import atomic

EXIT_OK, EXIT_FAILURE, EXIT_BAD_INPUT, EXIT_INTERRUPTED, EXIT_TERMINATED = 0, 1, 2, 130, 143

# name -> (module, function, one-line help). The function is called with the argv after the
# command name and returns an int exit code. Other packages add their commands here (or call
# register_command); nothing is imported until the command runs.
COMMANDS: dict[str, tuple[str, str, str]] = {
    "inspect": ("magica_py.sinks.inspect", "main_inspect",
                "summarize a recording: frames, entities, particles, metrics, events"),
    "record-all": ("magica_py.sinks.record_all", "main_record_all",
                   "regenerate one recording per showcase config into replays/"),
    "resim": ("magica_py.sinks.resim", "main_resim",
              "re-simulate cloths on the animated pose recorded in an .rrd"),
    "bench": ("magica_py.bench.cli", "main_bench",
              "speed against error: frequency sweep vs a converged reference, Pareto plot (reports/)"),
    "stability": ("magica_py.bench.cli", "main_stability",
                  "hard-case stability suite (configs/hard): finiteness, speed, stretch, penetration, rest"),
    "retarget-check": ("magica_py.io.retarget_check", "main_retarget_check",
                       "each retargeted clip: bone map, facing, hips height, limb rest alignment, lost bones"),
    "watch": ("magica_py.watch", "main_watch",
              "re-run a scene whenever it or an asset it reads changes, each run a recording in the viewer"),
    "new": ("magica_py.starter", "main_new",
            "write a commented starter scene (ponytail, tail, skirt or crowd) that runs as it is"),
    "bake": ("magica_py.bake.cli", "main_bake",
             "simulate a scene and write its bones' motion as animation (.glb / .gltf / .vrm / .bvh)"),
    "batch": ("magica_py.batch.cli", "main_batch",
              "run a job file's cross product of simulations on a Dask cluster; one table of metrics"),
}

def register_command(name: str, module: str, function: str, help: str) -> None:
    """Add a lazily imported subcommand (``function(argv) -> int`` in ``module``)."""
    COMMANDS[name] = (module, function, help)


class InputError(Exception):
    """Bad input detected by the CLI itself (printed without a traceback, exit 2)."""


# ----------------------------------------------------------------------------- parser
def build_parser() -> argparse.ArgumentParser:
    from magica_py import __version__

    parser = argparse.ArgumentParser(
        prog="magica-py",
        description="MagicaCloth2-style BoneCloth secondary motion (hair, tails, skirts) in Python + numba. "
                    "Scenes are YAML files (docs/scene-format.md); recordings open in the Rerun viewer.",
        epilog="Examples:\n  magica-py new my_scene --template ponytail && magica-py watch my_scene.yaml\n"
               "  magica-py run configs/tail_orbit.yaml\n  magica-py run avatar.vrm --save-scene avatar.yaml\n"
               "  magica-py run configs/character_walk.yaml --frames 120 --set cloths.skirt.parameters.damping=0.2\n"
               "  magica-py validate configs/*.yaml\n  magica-py info configs/character_walk.yaml",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"magica-py {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    def scene_args(p, many=False):
        if many:
            p.add_argument("scenes", metavar="SCENE.yaml", nargs="+", help="scene files (format: docs/scene-format.md)")
        else:
            p.add_argument("scene", metavar="SCENE.yaml", help="scene file (format: docs/scene-format.md)")
        p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                       help="override a value before validation, e.g. scene.fps=30, "
                            "cloths[0].parameters.damping=0.2 or cloths.tail.parameters.damping=0.2 "
                            "(VALUE is parsed as YAML; repeatable)")

    run = sub.add_parser("run", help="simulate a scene (or a VRM avatar) and record it",
                         description="Simulate a scene frame by frame and record it for the Rerun viewer. "
                                     "Given a .vrm avatar instead of a scene, its spring bones run as bone cloths "
                                     "on a clip (--clip) or a gentle default motion.")
    scene_args(run)
    run.add_argument("--clip", metavar="CLIP",
                     help="with AVATAR.vrm: a BVH file or FILE.glb#Animation retargeted onto the avatar "
                          "(default: the hips sway and turn, the head turns and nods)")
    run.add_argument("--save-scene", metavar="FILE.yaml",
                     help="with AVATAR.vrm: write the scene used to FILE.yaml (asset paths relative to it) "
                          "so you can edit it and run it again")
    run.add_argument("--frames", type=_positive_int, metavar="N",
                     help="number of frames (default: scene.frames or scene.duration)")
    run.add_argument("--rrd", metavar="PATH", help="write the recording here (default: output.rrd of the scene); "
                                                   "a missing folder is created")
    run.add_argument("--no-rrd", action="store_true", help="do not write a recording file")
    run.add_argument("--spawn", action="store_true",
                     help="start the Rerun viewer and stream to it (no recording file unless --rrd is given)")
    run.add_argument("--connect", metavar="ADDR",
                     help="stream to a running Rerun viewer (host:port or URL; no file unless --rrd)")
    run.add_argument("--no-simulation", action="store_true",
                     help="animate only: do not attach the cloth solver (a quick preview of the motion)")
    run.add_argument("--quiet", "-q", action="store_true", help="no progress bar, no notes, no summary")
    # how `watch` names and streams a run it hands to `run` (its interpreted first run, watch.py)
    run.add_argument("--recording-name", help=argparse.SUPPRESS)
    run.add_argument("--recording-id", help=argparse.SUPPRESS)
    run.add_argument("--batch-frames", type=_positive_int, help=argparse.SUPPRESS)

    validate = sub.add_parser("validate", help="check scene files and report every problem",
                              description="Check scene files completely (and build their cloths when the build "
                                          "module is available); print OK or every problem found. Exit code 2 "
                                          "when any file has a problem.")
    scene_args(validate, many=True)
    validate.add_argument("--quiet", "-q", action="store_true", help="print nothing on success")

    info = sub.add_parser("info", help="describe a scene: bones, colliders, cloths, particles, constraints",
                          description="Describe a scene: settings, rigs, bones, colliders, cloths and, when the "
                                      "build module is available, each cloth's particles and constraints.")
    scene_args(info)
    info.add_argument("--bones", action="store_true", help="list every bone as a tree (long for crowds)")

    for name, (_, _, text) in COMMANDS.items():
        p = sub.add_parser(name, help=text, add_help=False)
        p.add_argument("rest", nargs=argparse.REMAINDER)
    return parser


def plural(count: int, noun: str) -> str:
    """``1 collider``, ``2 colliders``, ``1,000 bones``."""
    return f"{count:,} {noun}{'' if count == 1 else 's'}"


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number of frames, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected at least 1 frame, got {value}")
    return value


# ----------------------------------------------------------------------------- main
def main(argv=None) -> int:
    """Entry point of the ``magica-py`` console script; returns the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] in COMMANDS:  # registered commands parse their own arguments
        return _run_registered(argv[0], argv[1:])
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: --help (0) or a usage error (2)
        return int(exc.code or 0)
    handler = {"run": cmd_run, "validate": cmd_validate, "info": cmd_info}[args.command]
    args.argv = argv[1:]   # the command's own arguments (``run``'s interpreted tier passes them on)
    previous = _terminate_like_interrupt()
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _show_warning
            return handler(args)
    except KeyboardInterrupt:
        print("magica-py: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Terminated:
        print("magica-py: terminated", file=sys.stderr)
        return EXIT_TERMINATED
    except BrokenPipeError:  # `magica-py info ... | head`: the reader went away
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_OK
    except Exception as exc:  # noqa: BLE001 - classify, then report
        if _is_input_error(exc):
            print(_format_input_error(exc), file=sys.stderr)
            return EXIT_BAD_INPUT
        from magica_py import first_run

        # the interpreted first run's own failure: one line (the run then compiles, and the
        # compiled run reports its own errors), the traceback kept for a bug report
        kept = first_run.record_failure(traceback.format_exc()) if first_run.in_interpreted_tier() else None
        if kept is None:
            traceback.print_exc()
        print(f"magica-py: internal error: {exc}" if kept is None else
              f"magica-py: internal error in the interpreted first run: {type(exc).__name__}: {exc} "
              f"(traceback in {kept})", file=sys.stderr)
        return EXIT_FAILURE
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


class Terminated(BaseException):
    """SIGTERM during a command: raised like ``KeyboardInterrupt`` so that the command's
    ``finally`` blocks run (the recording's temporary file is removed) before it exits 143."""


def _raise_terminated(signum, frame):
    raise Terminated()


def _terminate_like_interrupt():
    """Install ``_raise_terminated`` for SIGTERM (main thread only); the previous handler, or None."""
    import threading

    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "SIGTERM"):
        return None
    return signal.signal(signal.SIGTERM, _raise_terminated)


def _run_registered(name: str, argv: list[str]) -> int:
    module_name, function, _ = COMMANDS[name]
    try:
        module = importlib.import_module(module_name)
        fn = getattr(module, function)
    except (ImportError, AttributeError) as exc:
        print(f"magica-py {name}: not available in this installation ({module_name}.{function}: {exc})",
              file=sys.stderr)
        return EXIT_FAILURE
    return int(fn(argv) or 0)


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Warnings about the user's input (an importer's authoring-quirk note, ...) as one line,
    without the Python source line; other warnings keep Python's format."""
    stream = file if file is not None else sys.stderr
    if issubclass(category, UserWarning) and not issubclass(category, DeprecationWarning):
        stream.write(f"magica-py: warning: {message}\n")
    else:
        stream.write(warnings.formatwarning(message, category, filename, lineno, line))


def _is_input_error(exc: BaseException) -> bool:
    from magica_py.config.errors import ConfigError

    if isinstance(exc, (ConfigError, InputError)):
        return True
    # errors that name a bad input of the user: output path, build of a cloth, an asset file
    # (``magica-py run AVATAR.vrm`` imports the file before any scene exists)
    return type(exc).__name__ in ("OutputError", "BuildError", "ParameterError", "RecordingError", "AssetError")


def _format_input_error(exc: BaseException) -> str:
    from magica_py.config.errors import ConfigError

    if isinstance(exc, ConfigError):
        return exc.report()
    return f"magica-py: error: {exc}"


# ----------------------------------------------------------------------------- commands
def cmd_validate(args) -> int:
    from magica_py.config import load_scene

    status = EXIT_OK
    for path in args.scenes:
        try:
            scene = load_scene(path, args.overrides)
            models = _build_models(scene)
        except Exception as exc:  # noqa: BLE001 - report bad files, keep checking the others
            if not _is_input_error(exc):
                raise
            print(_format_input_error(exc), file=sys.stderr)
            status = EXIT_BAD_INPUT
            continue
        if not args.quiet:
            counts = scene.summary()
            particles = ""
            if models:
                total = sum(models[spec.name].particle_count * _copies(scene, spec)
                            for spec in _representative_cloths(scene))
                particles = f", {total} particles"
            print(f"OK {path}: scene {scene.name!r}: {plural(counts['bones'], 'bone')}, "
                  f"{plural(counts['colliders'], 'collider')}, {plural(counts['cloths'], 'cloth')}{particles}")
    return status


def cmd_info(args) -> int:
    from magica_py.config import load_scene

    scene = load_scene(args.scene, args.overrides)
    for line in describe_scene(scene, list_bones=args.bones):
        print(line)
    models = _build_models(scene)
    if models is None:
        print("cloth build: magica_py.build is not available (particles and constraints not shown)")
    else:
        for spec in _representative_cloths(scene):
            for line in _describe_model(models[spec.name]):
                print("  " + line)
    return EXIT_OK


def cmd_run(args) -> int:
    from magica_py import first_run

    if args.no_rrd and args.rrd:
        raise InputError("--rrd and --no-rrd contradict each other; give one")
    try:
        interpreted_first = first_run.wanted(args)
    except first_run.FirstRunError as exc:
        raise InputError(str(exc)) from None
    if interpreted_first:   # a first run: a short one goes interpreted (magica_py/first_run.py)
        code = first_run.run_interpreted(args.argv)
        if code == EXIT_FAILURE:   # a failure of the interpreted tier itself: the compiled run may succeed
            if not args.quiet:
                print("magica-py: the interpreted first run failed; compiling the solver instead",
                      file=sys.stderr, flush=True)
        elif code != first_run.DECLINED:
            return code

    from magica_py.runtime.player import Player
    from magica_py.runner import CompileWatch, WarningEvents, play, summary_line

    if not first_run.in_interpreted_tier() and not args.no_simulation:
        first_run.wait_for_background_compile(_Messages(quiet=args.quiet).note)
    scene = load_run_scene(args)
    frames = args.frames if args.frames is not None else scene.settings.frame_count()
    background = None
    if first_run.in_interpreted_tier():
        if not first_run.interpret(scene, frames):
            return first_run.DECLINED   # nothing written: the parent compiles
        first_run.quiet_floating_point()
        background = first_run.start_background_compile(args.argv)
    player = Player.for_scene(scene)  # default_schedule(scene) + the scene's time source
    created_dir = _ensure_output_folder(scene, args)
    recorder = None
    ok = False
    messages = _Messages(quiet=args.quiet)
    compile_watch = CompileWatch(announce=messages.note, on_end=messages.pause_ended)
    warning_events = WarningEvents()
    try:
        _check_output_path(scene, args)  # fail before the (slow to compile) solver is built
        with compile_watch:
            notes: list[str] = []
            with _cloth_errors_in(scene):
                system = None if args.no_simulation else _attach_solver(player, scene, notes)
            solver_attached = system is not None
            warning_events.attach(player)  # before the sink: this frame's warnings reach its events
            recorder = _attach_sink(player, scene, args, notes)
            if recorder is None and not args.no_rrd:
                notes.append(NO_RECORDING_NOTE.format(name=scene.name))
            if background is not None:
                notes.append(first_run.interpreted_note(background))
            for note in notes:
                messages.note(note)
            messages.start_progress(frames)
            with warning_events:
                summary = play(player, scene, frames, system=system, progress=messages.progress,
                               compile_watch=compile_watch, warning_events=warning_events)
        ok = True
    finally:
        messages.close()
        if recorder is not None:
            recorder.close(ok)
        if not ok and created_dir is not None:
            _remove_if_empty(created_dir)
    if not args.quiet:
        out = getattr(recorder, "output_path", None) if recorder is not None else None
        print(summary_line(scene, summary, solver_attached, out, compile_seconds=compile_watch.seconds,
                           threads=getattr(system, "threads", None), interpreted=background is not None))
        if summary.warnings:
            print(f"magica-py: {summary.warnings}", file=sys.stderr)
        if summary.resets_summary():
            print(f"magica-py: {summary.resets_summary()}", file=sys.stderr)
    return EXIT_OK


NO_RECORDING_NOTE = ("note: this run writes no recording (the scene has no output.rrd); add --rrd replays/{name}.rrd, "
                     "output: {{rrd: replays/{name}.rrd}} to the scene, or --spawn to watch it live")


class _Messages:
    """Notes on stderr, written above the progress bar once it exists (quiet: nothing)."""

    def __init__(self, quiet: bool):
        self.quiet = quiet
        self.progress = None

    def note(self, text: str) -> None:
        if self.quiet:
            return
        line = f"magica-py: {text}"
        if self.progress is not None:
            self.progress.write(line)
        else:
            print(line, file=sys.stderr, flush=True)

    def pause_ended(self) -> None:
        if self.progress is not None:
            self.progress.pause_ended()

    def start_progress(self, frames) -> None:
        if not self.quiet:
            from magica_py.runner import FrameProgress

            self.progress = FrameProgress(frames)

    def close(self) -> None:
        if self.progress is not None:
            self.progress.close()
            self.progress = None


def load_run_scene(args):
    """The scene of ``run``: a scene file, or (``AVATAR.vrm``) the avatar's generated scene,
    written to ``--save-scene`` first when asked."""
    from magica_py.avatar import is_vrm_file
    from magica_py.config import load_scene

    if is_vrm_file(args.scene):
        return _avatar_scene(args)
    for option in ("clip", "save_scene"):
        if getattr(args, option, None):
            flag = "--" + option.replace("_", "-")
            raise InputError(f"{flag} applies to a VRM avatar (magica-py run AVATAR.vrm {flag} ...); "
                             f"{args.scene} is a scene: "
                             + ("add the clip to its animation (docs/scene-format.md)" if option == "clip"
                                else "it is already a scene file"))
    return load_scene(args.scene, args.overrides)


def _avatar_scene(args):
    import pathlib

    from magica_py.avatar import avatar_scene_text
    from magica_py.config import load_scene, load_scene_text

    vrm = pathlib.Path(args.scene)
    if not vrm.is_file():
        raise InputError(f"{args.scene}: file not found")
    if args.clip and not pathlib.Path(args.clip.split("#", 1)[0]).is_file():
        raise InputError(f"--clip: {args.clip.split('#', 1)[0]}: file not found (a .bvh file, or FILE.glb#Animation)")
    if args.save_scene:
        target = pathlib.Path(args.save_scene)
        _check_scene_target(target)
        text = avatar_scene_text(vrm, args.clip, base_dir=target.parent.absolute())
        target.parent.mkdir(parents=True, exist_ok=True)
        atomic.write_text(target, text)
        if not args.quiet:
            print(f"magica-py: wrote the scene to {target} (edit it, then: magica-py run {target})", file=sys.stderr)
        return load_scene(target, args.overrides)
    text = avatar_scene_text(vrm, args.clip, base_dir=pathlib.Path.cwd())
    return load_scene_text(text, args.overrides, source=f"<scene of {args.scene}>")


def _check_scene_target(target) -> None:
    """``--save-scene`` may replace a scene it wrote before, never another file."""
    from magica_py.avatar import SAVED_SCENE_MARK

    if target.suffix.lower() not in (".yaml", ".yml"):
        raise InputError(f"--save-scene: {str(target)!r} must end in .yaml")
    if target.is_dir():
        raise InputError(f"--save-scene: {str(target)!r} is a folder; expected a file name ending in .yaml")
    if target.exists():
        try:
            head = target.read_text(encoding="utf-8", errors="replace")[:200]
        except OSError as exc:
            raise InputError(f"--save-scene: cannot read {str(target)!r}: {exc}") from None
        if SAVED_SCENE_MARK not in head:
            raise InputError(f"--save-scene: {str(target)!r} exists and was not written by --save-scene; "
                             "choose another name (it is not overwritten)")


# ----------------------------------------------------------------------------- run helpers
def _attach_solver(player, scene, notes: list[str]):
    """``magica_py.solver.attach(player, scene)`` when the solver provides it; returns the
    attached system (or True when attach returns nothing), None when there is no solver."""
    if not scene.cloths:
        return None
    try:
        solver = importlib.import_module("magica_py.solver")
    except ImportError as exc:
        notes.append(f"cloth solver unavailable ({exc}); cloths are not simulated")
        return None
    attach = getattr(solver, "attach", None)
    if attach is None:  # the solver package without its hook: use its ClothSystem directly
        try:
            from magica_py.solver.system import ClothSystem
        except ImportError:
            notes.append("this installation's magica_py.solver has no attach() and no ClothSystem; cloths are "
                         "not simulated (bones follow the animation only)")
            return None
        return ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings).attach(player, scene)
    system = attach(player, scene)
    return system if system is not None else True


def _attach_sink(player, scene, args, notes: list[str]):
    """``magica_py.sinks.attach(player, scene, options)``; returns the recorder (or None)."""
    wants_output = (not args.no_rrd and (args.rrd or scene.output.rrd)) or args.spawn or args.connect
    if not wants_output:
        return None  # nothing to write or stream: no sink at all
    try:
        sinks = importlib.import_module("magica_py.sinks")
        attach = getattr(sinks, "attach")
    except (ImportError, AttributeError) as exc:
        if wants_output:
            raise InputError(f"cannot record: the sinks package is unavailable ({exc}); use --no-rrd") from None
        return None
    options = {"rrd": args.rrd, "no_rrd": bool(args.no_rrd), "spawn": bool(args.spawn), "connect": args.connect}
    for name in ("recording_name", "recording_id", "batch_frames"):   # watch.py's runs only
        if getattr(args, name, None) is not None:
            options[name] = getattr(args, name)
    options_type = getattr(sinks, "SinkOptions", None)
    return attach(player, scene, options_type(**options) if options_type else options)


def _live(args) -> bool:
    """--spawn / --connect: a live run writes a recording file only when --rrd asks for one."""
    return bool(args.spawn or args.connect)


def _check_output_path(scene, args) -> None:
    """The sink's own checks, run early: the path (``sinks.rerun_sink.check_output_path``) and
    the live output (``sinks.live.check_live_output``: a display for --spawn, a listening
    viewer for --connect)."""
    if _live(args):
        from magica_py.sinks.live import check_live_output

        check_live_output(bool(args.spawn), args.connect)
    if args.no_rrd or (_live(args) and not args.rrd):
        return
    path = args.rrd or scene.output.rrd
    if path is None:
        return
    try:
        from magica_py.sinks.rerun_sink import check_output_path
    except ImportError:
        return  # the sink checks again when it is attached
    check_output_path(path, "--rrd" if args.rrd else "output.rrd")


def _ensure_output_folder(scene, args):
    """Create the folder of the recording (``--rrd`` or the scene's ``output.rrd``, e.g.
    replays/) when missing, the same way for both; returns the first folder created, so a
    failed run can remove what it made. A live run (``--spawn`` / ``--connect``) writes the
    scene's ``output.rrd`` only when ``--rrd`` asks for a file."""
    import pathlib

    if args.no_rrd or (not args.rrd and (scene.output.rrd is None or _live(args))):
        return None
    folder = pathlib.Path(args.rrd).expanduser().parent if args.rrd else scene.output.rrd.parent
    where = "--rrd" if args.rrd else "output.rrd"
    if str(folder) in ("", ".") or folder.exists():
        return None
    top = folder
    while not top.parent.exists():
        top = top.parent
    try:
        folder.mkdir(parents=True)
    except OSError as exc:
        raise InputError(f"{where}: cannot create the folder {str(folder)!r}: {exc}") from None
    return top


def _remove_if_empty(folder) -> None:
    """Remove ``folder`` and the empty folders under it (what a failed run created)."""
    import shutil

    try:
        if not any(path.is_file() for path in folder.rglob("*")):
            shutil.rmtree(folder)
    except OSError:
        pass


# ----------------------------------------------------------------------------- info helpers
def describe_scene(scene, list_bones: bool = False) -> list[str]:
    """Human-readable lines for ``info``."""
    s = scene.settings
    h = scene.hierarchy
    if s.frame_source == "fps":
        source = f"{s.fps:g} fps"
    elif s.frame_source == "frame_times":
        source = f"{len(s.frame_times)} frame times ({'cycled' if s.frame_times_cycle else 'once'})"
    else:
        source = "real-time clock"
    frames = s.frame_count()
    length = f"{frames} frames" if frames is not None else f"{s.duration:g} s"
    out = [f"scene {scene.name!r} ({scene.source or '<text>'})",
           f"  time: {source}, {length}, time scale {s.time_scale:g}, update mode {s.update_mode}, "
           f"timing {s.timing}",
           f"  simulation: {s.simulation_frequency} Hz, at most {s.max_steps_per_frame} steps per frame; fixed "
           f"delta time {s.fixed_delta_time:g} s, maximum delta time {s.maximum_delta_time:.4g} s",
           f"  gravity direction {tuple(round(x, 4) for x in s.gravity)}, seed {s.seed}",
           f"bones: {plural(h.count, 'transform')} in {plural(len(scene.rigs), 'rig')}"]
    for rig in scene.rigs:
        inst = f", {rig.instances} instances" if rig.instances > 1 else ""
        roots = ", ".join(h.names[i] for i in rig.root_nodes[:3]) + (" ..." if len(rig.root_nodes) > 3 else "")
        out.append(f"  rig {rig.name!r}: {rig.nodes_per_instance} bones{inst} (root {roots})")
    if list_bones:
        out.extend(_bone_tree(h))
    out.extend(_describe_animation(scene))
    cols = scene.colliders
    out.append(f"colliders: {len(cols)}")
    shape_names = ("sphere", "capsule", "plane")
    shown = {}
    for i in range(len(cols)):
        base = _base_name(cols.names[i])
        shown.setdefault(base, []).append(i)
    for base, members in shown.items():
        i = members[0]
        kind = shape_names[int(cols.shape[i])]
        if kind == "sphere":
            size = f"radius {cols.radius[i]:g}"
        elif kind == "capsule":
            size = (f"radius {cols.radius[i]:g}..{cols.end_radius[i]:g}, length {cols.length[i]:g}, "
                    f"axis {'xyz'[int(cols.direction[i])]}")
        else:
            size = "normal +Y"
        label = f"{base} x{len(members)} (instance 0 shown)" if len(members) > 1 else cols.names[i]
        out.append(f"  {label}: {kind} on {h.names[int(cols.transform[i])]!r}, {size}")
    zones = getattr(scene, "wind", ()) or ()
    if zones:
        out.append(f"wind zones: {len(zones)}")
        for z in zones:
            where = f"on {h.names[z.transform]!r}" if z.transform >= 0 else "fixed"
            area = {"sphere": f"radius {z.radius:g} m", "radial": f"radius {z.radius:g} m",
                    "box": "size " + " x ".join(f"{v:g}" for v in z.size) + " m"}.get(z.mode, "everywhere")
            extra = (", additive" if z.addition else "") + ("" if z.enabled else ", off at start")
            out.append(f"  {z.name}: {z.mode} {where}, {area}, {z.main:g} m/s, turbulence {z.turbulence:g}{extra}")
    out.append(f"cloths: {len(scene.cloths)}")
    for spec in _representative_cloths(scene):
        copies = _copies(scene, spec)
        label = f"{_base_name(spec.name)!r} x{copies} (instance 0 shown)" if spec.instance is not None \
            else repr(spec.name)
        roots = [h.names[i] for i in spec.root_bones]
        shown = ", ".join(roots[:6]) + (f" ... ({len(roots)} roots)" if len(roots) > 6 else "")
        out.append(f"  {label}: {spec.connection_mode}, preset {spec.preset or 'defaults'}, "
                   f"component {h.names[spec.component]!r}")
        out.append(f"    roots: {shown}")
        cols_text = ", ".join(scene.colliders.names[i] for i in spec.colliders) or "none"
        out.append(f"    colliders ({spec.collision_mode}): {cols_text}")
        changes = _parameter_changes(scene, spec)
        if changes:
            out.append(f"    parameters beyond the preset: {', '.join(changes)}")
        if spec.bone_attributes:
            attrs = ", ".join(f"{h.names[i]}={a}" for i, a in list(spec.bone_attributes.items())[:8])
            out.append(f"    bone attributes: {attrs}")
    return out


def _describe_animation(scene) -> list[str]:
    """Drivers by kind (with the bones they move, keys for keyframes) and events by kind: an
    imported clip shows as keyframe drivers, one per animated bone and channel."""
    anim = scene.animation
    if anim is None:
        return ["animation: none"]
    kinds = getattr(anim, "kind", ())
    names = {0: "keyframes", 1: "orbit", 2: "oscillate", 3: "spin", 4: "walk"}
    counts: dict[str, int] = {}
    for k in kinds:
        label = names.get(int(k), str(int(k)))
        counts[label] = counts.get(label, 0) + 1
    events: dict[str, int] = {}
    for e in getattr(anim, "events", ()):
        events[e.kind] = events.get(e.kind, 0) + 1
    driven = len(set(int(t) for t in getattr(anim, "target", ())))
    parts = [f"{n} {kind}" for kind, n in counts.items()]
    out = [f"animation: {len(kinds)} drivers on {driven} bones" + (f" ({', '.join(parts)})" if parts else "")
           + (f"; events: {', '.join(f'{n} {k}' for k, n in events.items())}" if events else "")]
    key_time = getattr(anim, "key_time", None)
    if counts.get("keyframes") and key_time is not None and len(key_time):
        out.append(f"  keyframes: {len(key_time)} keys over [{float(key_time.min()):g}, {float(key_time.max()):g}] s")
    return out


def _parameter_changes(scene, spec) -> list[str]:
    """``key=value`` for every parameter that differs from the cloth's preset (or defaults),
    scene-level defaults (gravity direction, update mode) included."""
    try:
        from magica_py.params import resolve_parameters

        base = resolve_parameters(spec.preset, {"update_mode": "normal"})
    except (ImportError, ValueError):
        return []
    out = []
    for key, value in spec.parameters.items():
        if key in base and base[key] != value:
            shown = value.value if hasattr(value, "value") and hasattr(value, "use_curve") else value
            if isinstance(shown, tuple):
                shown = "(" + ", ".join(f"{x:.4g}" for x in shown) + ")"
            elif isinstance(shown, float):
                shown = "off" if shown == -1.0 and "limit" in key else f"{shown:g}"
            out.append(f"{key}={shown}")
    return out


def _bone_tree(h) -> list[str]:
    out = []
    depth = [0] * h.count
    for i in range(h.count):
        p = int(h.parent[i])
        depth[i] = depth[p] + 1 if p >= 0 else 0
        out.append("    " + "  " * depth[i] + h.names[i])
    return out


def _base_name(name: str) -> str:
    return name.split("#", 1)[0]


def _copies(scene, spec) -> int:
    """How many cloths the YAML entry of ``spec`` became (instances)."""
    if spec.instance is None:
        return 1
    return sum(1 for c in scene.cloths if c.instance is not None and _base_name(c.name) == _base_name(spec.name))


def _representative_cloths(scene):
    """One cloth per YAML entry (instance 0 of a replicated cloth)."""
    seen, out = set(), []
    for spec in scene.cloths:
        key = _base_name(spec.name) if spec.instance is not None else spec.name
        if key not in seen:
            seen.add(key)
            out.append(spec)
    return out


def _build_models(scene):
    """Build the representative cloths with ``magica_py.build`` (None when unavailable)."""
    try:
        build = importlib.import_module("magica_py.build")
        build_cloth = getattr(build, "build_cloth")
    except (ImportError, AttributeError):
        return None
    with _cloth_errors_in(scene):
        return {spec.name: build_cloth(scene.hierarchy, spec) for spec in _representative_cloths(scene)}


@contextlib.contextmanager
def _cloth_errors_in(scene):
    """A cloth that cannot be built (``BuildError``) reported like a scene problem: the file and
    the cloth's path in the document (``cloths[1]``), exit code 2."""
    try:
        yield
    except Exception as exc:
        if type(exc).__name__ != "BuildError":
            raise
        from magica_py.config.errors import ConfigError, Issue

        cloth = getattr(exc, "cloth", None)
        spec = next((c for c in scene.cloths if c.name == cloth), None)
        path = getattr(spec, "document_path", "") or ""
        where = f"cloth {cloth!r}" if cloth is not None else ""
        message = getattr(exc, "message", None) or str(exc)
        raise ConfigError(str(scene.source) if scene.source is not None else None,
                          [Issue(path, f"{where}: {message}" if where else message)]) from None


def _describe_model(model) -> list[str]:
    try:
        from magica_py.build import describe
    except ImportError:
        return [f"cloth {getattr(model, 'name', '?')!r}: {model.particle_count} particles"]
    return describe(model)


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
