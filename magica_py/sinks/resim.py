"""Re-simulate from a recording: `magica-py resim FILE.rrd [--scene OTHER.yaml] [--rrd OUT.rrd]`.

A recording made with ``replay`` logging holds, per frame (float64, exact):

* ``replay/pose``   the local position, rotation and scale of every *driven* transform after
                    UPDATE, i.e. the animated pose the solver read (names in ``replay/nodes``);
* ``replay/time``   every ``UnityTime`` field of the frame (delta time, time scale, fixed
                    updates...), so the frame-time source, hitches and time-scale events are
                    reproduced without re-running the clock;
* ``replay/events`` the events raised before LATE_UPDATE (``set_parameter``, ``time_scale``...),
                    re-raised at the same point.

``resimulate`` builds OTHER.yaml (default: the scene text embedded in the recording), replaces
its ``animation`` system by a playback of those poses, attaches the solver (when present) and a
new sink, and runs the recorded number of frames. With the same scene and parameters the
solver sees bit-identical inputs, so it reproduces the original particles bit for bit.
"""
from __future__ import annotations

import argparse
import json
import pathlib
import sys
from dataclasses import dataclass

import numpy as np

from magica_py.sinks import layout as L
from magica_py.sinks.readback import Recording, RecordingError

PLAYBACK_SYSTEM = "replay_pose"


@dataclass
class ReplayData:
    frames: np.ndarray               # (F,) frame indices
    node_names: list[str]            # (D,)
    local_position: np.ndarray       # (F, D, 3) float64
    local_rotation: np.ndarray       # (F, D, 4)
    local_scale: np.ndarray          # (F, D, 3)
    time_fields: list[str]
    time_values: np.ndarray          # (F, K) float64
    events: dict[int, list]          # frame -> [(kind, payload), ...]
    scene_text: str
    scene_source: str
    scene_name: str
    scene_overrides: tuple[str, ...] = ()   # `--set` overrides of the recorded run

    @property
    def frame_count(self) -> int:
        return int(self.frames.size)


def load_replay(path) -> ReplayData:
    """Read the replay entities of a recording (RecordingError when it has none)."""
    rec = path if isinstance(path, Recording) else Recording(path)
    if f"/{L.REPLAY_POSE}" not in rec.entities or f"/{L.REPLAY_TIME}" not in rec.entities:
        raise RecordingError(f"{rec.path}: no replay data (record with output.log.replay: true to re-simulate)")
    names = [n for n in rec.static_value(f"/{L.REPLAY_NODES}", "names") if n]
    frames, pos = rec.stacked(f"/{L.REPLAY_POSE}", "local_position")
    _, rot = rec.stacked(f"/{L.REPLAY_POSE}", "local_rotation")
    _, scl = rec.stacked(f"/{L.REPLAY_POSE}", "local_scale")
    tframes, tvals = rec.stacked(f"/{L.REPLAY_TIME}", "values")
    if not np.array_equal(frames, tframes) or not np.array_equal(frames, np.arange(frames.size)):
        raise RecordingError(f"{rec.path}: replay frames are not 0..{frames.size - 1} on pose and time")
    d, f = len(names), frames.size
    events: dict[int, list] = {}
    for frame, text in rec.text_rows(f"/{L.REPLAY_EVENTS}", "events"):
        events[frame] = [tuple(e) for e in json.loads(text)]

    def scene_value(key):
        try:
            values = rec.static_value(f"/{L.REPLAY_SCENE}", key)
        except RecordingError:
            return ""
        return values[0] if values else ""

    fields = [x for x in rec.static_value(f"/{L.REPLAY_SCENE}", "time_fields") if x]
    try:
        overrides = tuple(x for x in rec.static_value(f"/{L.REPLAY_SCENE}", "overrides") if x)
    except RecordingError:
        overrides = ()
    return ReplayData(frames=frames, node_names=names, local_position=pos.reshape(f, d, 3),
                      local_rotation=rot.reshape(f, d, 4), local_scale=scl.reshape(f, d, 3),
                      time_fields=fields, time_values=tvals.reshape(f, -1), events=events,
                      scene_text=scene_value("yaml"), scene_source=scene_value("source"),
                      scene_name=scene_value("name"), scene_overrides=overrides)


class RecordedTime:
    """Stands in for runtime.clock.TimeManager: frame i gets the recorded UnityTime exactly.

    Time-scale events are still delivered to ``time_scale`` (the player's handler), but the
    recorded deltas already contain their effect, so the setter only remembers the value."""

    def __init__(self, replay: ReplayData):
        from magica_py.runtime.clock import UnityTime

        self._unity_time = UnityTime
        self.replay = replay
        self.position = 0
        self._time_scale = 1.0
        self._ints = {"frame_count", "fixed_update_count"}

    def advance(self, raw_delta: float):
        i = self.position
        if i >= self.replay.frame_count:
            raise IndexError(f"the recording has {self.replay.frame_count} frames; frame {i} was asked for")
        self.position += 1
        values = {}
        for name, v in zip(self.replay.time_fields, self.replay.time_values[i]):
            values[name] = int(v) if name in self._ints else float(v)
        t = self._unity_time(**values)
        self._time_scale = t.time_scale
        return t

    def next_delta(self) -> float:     # also serves as the frame-time source
        i = min(self.position, self.replay.frame_count - 1)
        k = self.replay.time_fields.index("unscaled_delta_time")
        return float(self.replay.time_values[i, k])

    def reset(self) -> None:
        self.position = 0

    @property
    def time_scale(self) -> float:
        return self._time_scale

    @time_scale.setter
    def time_scale(self, value: float) -> None:
        self._time_scale = float(value)


def playback_system(replay: ReplayData, scene):
    """The UPDATE system that writes the recorded driven poses (and re-raises the events)."""
    h = scene.hierarchy
    missing = [n for n in replay.node_names if n not in h.index_of]
    if missing:
        raise RecordingError(f"the scene {getattr(scene, 'name', '')!r} has no transforms named "
                             f"{missing[:5]}{'...' if len(missing) > 5 else ''}: the recording's rig does not match")
    nodes = np.array([h.index_of[n] for n in replay.node_names], np.int64)

    def replay_pose(ctx) -> None:
        f = ctx.frame
        h.local_position[nodes] = replay.local_position[f]
        h.local_rotation[nodes] = replay.local_rotation[f]
        h.local_scale[nodes] = replay.local_scale[f]
        ctx.events.extend(replay.events.get(f, ()))
        h.propagate()

    return replay_pose


def build_player(replay: ReplayData, scene):
    """A Player that replays ``replay`` on ``scene`` (solver attached when available)."""
    from magica_py.runtime.phases import Phase, System
    from magica_py.runtime.player import Player, default_schedule

    schedule = default_schedule(scene)
    schedule.remove("animation")
    schedule.add(Phase.UPDATE, System(PLAYBACK_SYSTEM, playback_system(replay, scene)))
    clock = RecordedTime(replay)
    player = Player(scene, schedule, clock, clock)
    from magica_py.sinks.record_all import attach_solver

    attach_solver(player, scene)
    return player


def load_scene_for(replay: ReplayData, scene_path=None, overrides=()):
    from magica_py.config import load_scene, load_scene_text

    if scene_path is not None:
        return load_scene(scene_path, overrides)
    if not replay.scene_text:
        raise RecordingError("the recording does not embed its scene: pass --scene SCENE.yaml")
    # the embedded scene is re-read with the recorded run's overrides, then the new ones
    return load_scene_text(replay.scene_text, tuple(replay.scene_overrides) + tuple(overrides),
                           source=replay.scene_source or "<recording>")


def resimulate(recording, scene, output=None, *, spawn=False, connect=None, snapshots=None, batch_frames=None,
               progress=None, compile_watch=None):
    """Run ``scene`` on the recorded pose; returns (player, recorder, wall seconds). With
    ``compile_watch`` (a ``runner.CompileWatch`` around the call) the wall seconds leave out
    the frames' compiles."""
    from magica_py.runner import Stopwatch
    from magica_py.sinks.recorder import SinkOptions, attach

    replay = recording if isinstance(recording, ReplayData) else load_replay(recording)
    player = build_player(replay, scene)
    recorder = attach(player, scene, SinkOptions(rrd=output, no_rrd=output is None, spawn=spawn, connect=connect,
                                                 snapshots=snapshots, batch_frames=batch_frames))
    ok = False
    with Stopwatch(compile_watch) as run:
        try:
            player.run(replay.frame_count, progress=progress)
            ok = True
        finally:
            recorder.close(success=ok)
    return player, recorder, run.seconds


def default_output(path) -> pathlib.Path:
    p = pathlib.Path(path)
    return p.with_name(p.stem + ".resim.rrd")


def main_resim(argv=None) -> int:
    parser = argparse.ArgumentParser(
        prog="magica-py resim",
        description="Re-simulate the cloths of a scene on the animated pose recorded in FILE.rrd and write a new "
                    "recording. Same scene and parameters reproduce the original particles bit for bit.")
    parser.add_argument("recording", help="an .rrd written by `magica-py run` (with replay logging, the default)")
    parser.add_argument("--scene", help="scene whose cloths to rebuild (default: the scene embedded in the recording)")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                        help="override a scene value (like `run --set`)")
    parser.add_argument("--rrd", help="output recording (default: FILE.resim.rrd next to the input)")
    parser.add_argument("--spawn", action="store_true", help="also stream to a new Rerun viewer")
    parser.add_argument("--connect", metavar="ADDR", help="also stream to a running viewer (host:port)")
    args = parser.parse_args(argv)
    from magica_py.runner import CompileWatch, compile_text

    # a first run compiles the solver: said before it starts, left out of the times, reported apart
    compile_watch = CompileWatch(announce=lambda text: print(f"magica-py resim: {text}", file=sys.stderr, flush=True))
    try:
        with compile_watch:
            replay = load_replay(args.recording)
            scene = load_scene_for(replay, args.scene, tuple(args.overrides))
            out = args.rrd or default_output(args.recording)
            player, recorder, seconds = resimulate(replay, scene, out, spawn=args.spawn, connect=args.connect,
                                                   compile_watch=compile_watch)
    except (RecordingError, ValueError, OSError) as exc:
        print(f"magica-py resim: error: {exc}", file=sys.stderr)
        return 2
    print(f"resim: {replay.frame_count} frames of {args.recording} on scene {scene.name!r} -> {out} "
          f"({seconds:.2f} s, {1000 * seconds / max(replay.frame_count, 1):.2f} ms/frame"
          f"{compile_text(compile_watch.seconds)})")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main_resim())
