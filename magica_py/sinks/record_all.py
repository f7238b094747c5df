"""`magica-py record-all`: regenerate replays/<config>.rrd for every showcase config in configs/.

Each scene runs in this process with the cloth solver (when ``magica_py.solver.attach``
exists) and the Rerun sink in batched file mode. The table printed at the end is the cost
figure of docs/recordings.md: simulation wall time (everything but the sink) against the sink's own
time (copying, sending, closing the file).
"""
from __future__ import annotations

import argparse
import os
import pathlib
import sys
import tempfile
from dataclasses import dataclass

DEFAULT_CONFIGS = "configs"
DEFAULT_OUT = "replays"


@dataclass
class RecordResult:
    name: str
    path: pathlib.Path | None
    frames: int
    wall_seconds: float        # whole run including the sink and the file close, less the compiles
    sink_seconds: float        # time inside the sink (copying, sending, closing the file)
    import_seconds: float      # one-time import of rerun (not in sink_seconds)
    particles: int
    bytes: int
    compile_seconds: float = 0.0   # numba compiles during the run (first run only; not in wall_seconds)

    @property
    def sim_seconds(self) -> float:
        return self.wall_seconds - self.sink_seconds - self.import_seconds

    @property
    def sink_ratio(self) -> float:
        """Recording cost as a fraction of the simulation time."""
        return self.sink_seconds / self.sim_seconds if self.sim_seconds > 0 else float("inf")


def scene_frames(scene) -> int:
    """The scene's frame count (``SceneSettings.frame_count()``: frames, or duration at fps)."""
    s = scene.settings
    count = s.frame_count() if hasattr(s, "frame_count") else getattr(s, "frames", None)
    if not count:
        raise ValueError(f"scene {scene.name!r}: no frame count (a realtime clock needs --frames)")
    return int(count)


def attach_solver(player, scene):
    """Add the solver's LATE_UPDATE system: ``magica_py.solver.attach(player, scene)`` when the
    solver package exports it, else its ``ClothSystem`` directly; None when there is no solver."""
    if not getattr(scene, "cloths", None):
        return None
    try:
        from magica_py import solver
    except ImportError:
        return None
    attach = getattr(solver, "attach", None)
    if attach is not None:
        return attach(player, scene)
    try:
        from magica_py.solver.system import ClothSystem
    except ImportError:
        return None
    system = ClothSystem(scene.hierarchy, scene.cloths, getattr(scene, "colliders", None), scene.settings)
    return system.attach(player, scene)


def record_scene(scene, rrd, *, frames=None, batch_frames=None, spawn=False, connect=None, progress=None,
                 recording_id=None, open_at_end=False, compile_watch=None) -> RecordResult:
    """Run ``scene`` with solver and sink; the file appears at ``rrd`` only if the run succeeds.
    With ``compile_watch`` (a ``runner.CompileWatch`` around the call) the frames' compiles are
    left out of the result's times and reported apart."""
    from magica_py.runner import Stopwatch
    from magica_py.runtime.player import Player
    from magica_py.sinks.recorder import SinkOptions, attach

    player = Player.for_scene(scene)
    attach_solver(player, scene)
    recorder = attach(player, scene, SinkOptions(rrd=rrd, no_rrd=rrd is None, spawn=spawn, connect=connect,
                                                 batch_frames=batch_frames, recording_id=recording_id,
                                                 open_at_end=open_at_end))
    n = scene_frames(scene) if frames is None else int(frames)
    ok = False
    with Stopwatch(compile_watch) as run:
        try:
            player.run(n, progress=progress)
            ok = True
        finally:
            recorder.close(success=ok)
    out = recorder.output_path
    particles = sum(t.particle_count for t in recorder.provider.cloth_topologies())
    return RecordResult(name=scene.name, path=out, frames=n, wall_seconds=run.seconds, sink_seconds=recorder.seconds,
                        import_seconds=recorder.import_seconds,
                        particles=particles, bytes=os.path.getsize(out) if out is not None and out.exists() else 0,
                        compile_seconds=run.compiled)


def showcase_configs(folder) -> list[pathlib.Path]:
    folder = pathlib.Path(folder)
    if not folder.is_dir():
        raise ValueError(f"--configs: {str(folder)!r} is not a folder")
    return sorted(p for p in folder.glob("*.yaml") if not p.name.startswith("_"))


def main_record_all(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="magica-py record-all",
                                     description="Regenerate one recording per showcase config: CONFIGS/NAME.yaml -> "
                                                 "OUT/NAME.rrd. Open one with `rerun OUT/NAME.rrd`.")
    parser.add_argument("--configs", default=DEFAULT_CONFIGS, help="folder of scene files (default: configs)")
    parser.add_argument("--out", default=DEFAULT_OUT, help="folder for the recordings (default: replays)")
    parser.add_argument("--only", action="append", default=[], metavar="NAME",
                        help="record only this config (file stem); repeatable")
    parser.add_argument("--frames", type=int, help="override every scene's frame count")
    parser.add_argument("--batch-frames", type=int, help="frames per columnar send (default 64)")
    parser.add_argument("--warmup", type=int, default=0, metavar="N",
                        help="first run N frames without output so JIT compilation is not in the timings")
    args = parser.parse_args(argv)
    from magica_py.config import ConfigError, load_scene

    try:
        configs = showcase_configs(args.configs)
        if args.only:
            unknown = sorted(set(args.only) - {p.stem for p in configs})
            if unknown:
                raise ValueError(f"--only: no config named {unknown} in {args.configs} "
                                 f"(have {[p.stem for p in configs]})")
            configs = [p for p in configs if p.stem in args.only]
        out = pathlib.Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
    except (ValueError, OSError) as exc:
        print(f"magica-py record-all: error: {exc}", file=sys.stderr)
        return 2
    from magica_py.runner import CompileWatch, compile_text

    results, failures = [], 0
    for path in configs:
        # a scene whose stages are not compiled yet says so before its compile starts; the
        # times below leave the compile out and the line reports it apart
        compile_watch = CompileWatch(announce=lambda text, name=path.stem: print(
            f"magica-py record-all: {name}: {text}", file=sys.stderr, flush=True))
        try:
            with compile_watch:
                if args.warmup > 0:   # JIT and rerun's lazy start-up, recorded to a scratch file
                    with tempfile.TemporaryDirectory() as scratch:
                        record_scene(load_scene(path), pathlib.Path(scratch) / "warmup.rrd", frames=args.warmup)
                scene = load_scene(path)
                result = record_scene(scene, out / f"{path.stem}.rrd", frames=args.frames,
                                      batch_frames=args.batch_frames, compile_watch=compile_watch)
        except (ConfigError, ValueError, OSError) as exc:
            failures += 1
            print(f"magica-py record-all: {path}: {exc}", file=sys.stderr)
            continue
        results.append(result)
        print(f"{path.stem:<20} {result.frames:>6} frames {result.particles:>7} particles  "
              f"sim {result.sim_seconds:7.2f} s  sink {result.sink_seconds:6.2f} s "
              f"({100 * result.sink_ratio:5.1f} % of sim, {1000 * result.sink_seconds / max(result.frames, 1):.2f} ms/frame)"
              f"  {result.bytes / 1e6:7.1f} MB -> {result.path}{compile_text(compile_watch.seconds)}",
              flush=True)
    return 1 if failures else 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main_record_all())
