"""Wind figures (issue 20): the cost of wind as a share of the cloth step, and the steady
deflection of a long_hair strand against a hand calculation.

    python benchmarks/bench_wind.py cost [--frames 120] [--reps 5] [--scenes character_walk crowd]
    python benchmarks/bench_wind.py deflection [--seconds 6]

**cost**: each scene is loaded twice, without wind and with one global zone (3 m/s, turbulence
1) and one area zone (a sphere of radius 6 m at the first character, 4 m/s, additive off:
the teams inside feel the sphere, the others the global zone); the difference is the wind
alone (its stage is compiled in only with wind: ``StageSwitches.wind``). After a 30-frame warm-up, ``--reps`` alternating runs of
``--frames`` frames record the solver's ``cloth.kernel`` (the frame kernel plus the wind's
per-frame zone selection, which runs inside the same timer); the median per-frame time of
each is reported and the wind's share ``(wind - calm) / wind``, and the per-frame zone
selection (``WindField.update``) and the wind stage (``wind_block`` over every block, x1.5 steps a
frame at 60 fps / 90 Hz, in one compiled loop) timed alone: their sum over the wind run's
kernel is the direct share, less exposed to the machine's load than the difference.

**deflection**: one 6-bone, 0.5 m strand hanging from a fixed root, the ``long_hair`` preset,
in a steady global wind along +X (5 m/s, turbulence 0: no swing, no gusts), for ``--seconds``;
the tip's horizontal deflection is averaged over the last 2 s. The model (MagicaCloth2, §D.1):
the wind enters the force sum as an acceleration ``a = main · influence`` (m/s², no drag law),
next to gravity ``g`` (the preset's 5 m/s²). A chain free to swing hangs along the total
acceleration, at ``θ = atan(a / g)`` from the vertical, so its tip is ``L sin θ`` downwind
(the chain does not stretch: distance and tether). The preset's angle restoration and angle
limit pull it back towards its rest direction; the run with both off isolates the balance.
"""
from __future__ import annotations

import argparse
import math
import os
import pathlib
import statistics
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from magica_py.jit import kernel  # noqa: E402
from magica_py.wind.force import wind_block  # noqa: E402

WIND = ("wind=[{name: breeze, mode: global, main: 3, turbulence: 1, direction: [1, 0, 0]},"
        " {name: area, mode: sphere, radius: 6, position: [0, 1, 0], main: 4, turbulence: 1, direction: [0, 0, -1]}]")


STEPS_PER_FRAME = 1.5      # 60 fps, 90 Hz


@kernel
def _wind_steps(T, wind_zones, reps, dt):
    """``wind_block`` for every live block, ``reps`` times (the wind stage alone); ``T``: the
    system's ``frame.Tables``."""
    for _ in range(reps):
        for i in range(T.blocks.shape[0]):
            wind_block(T.PS, T.PM, T.TS, T.TI, T.P, T.BI, T.topology, T.blocks[i], dt, wind_zones)


def _system(path, overrides, frames):
    from magica_py.config.load import load_scene
    from magica_py.runtime.player import Player
    from magica_py.solver.system import ClothSystem

    scene = load_scene(path, overrides)
    player = Player.for_scene(scene)
    system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings,
                         wind=scene.wind).attach(player, scene)
    return player, system


def _kernel_times(player, frames):
    times = []
    for _ in range(frames):
        ctx = player.step()
        times.append(ctx.metrics["cloth.kernel"])
    return times


def cost(args) -> None:
    for name in args.scenes:
        path = ROOT / "configs" / f"{name}.yaml"
        runs = {}
        for label, overrides in (("calm", ()), ("wind", (WIND,))):
            player, system = _system(path, overrides, args.frames)
            _kernel_times(player, 30)
            runs[label] = (player, system, [])
        for _ in range(args.reps):
            for label, (player, _system_, medians) in runs.items():
                medians.append(statistics.median(_kernel_times(player, args.frames)))
        system = runs["wind"][1]
        tables = system.tables
        zones = system._wind_zones()
        t0 = time.perf_counter()
        for _ in range(args.frames):
            system.select_wind()
        update = (time.perf_counter() - t0) / args.frames
        _wind_steps(tables, zones, 1, 1.0 / 90.0)     # compile
        t0 = time.perf_counter()
        _wind_steps(tables, zones, args.frames * 3, 1.0 / 90.0)
        stage = (time.perf_counter() - t0) / (args.frames * 3) * STEPS_PER_FRAME
        calm = statistics.median(runs["calm"][2])
        wind = statistics.median(runs["wind"][2])
        felt = runs["wind"][1].teams.wind_zone_count
        print(f"{name:16s} teams {len(felt):4d} (feeling a zone: {int((felt > 0).sum())}; the sphere replaces the global zone inside it) "
              f"kernel calm {calm * 1e3:7.3f} ms  wind {wind * 1e3:7.3f} ms  share {(wind - calm) / wind * 100:5.1f} %"
              f" (zone selection {update * 1e3:.3f} ms, wind stage alone {stage * 1e3:.3f} ms: "
              f"{(update + stage) / wind * 100:.1f} %)  load {os.getloadavg()[0]:.1f}")


STRAND = """
scene: {{fps: 60, duration: {seconds}, simulation_frequency: 90}}
rigs:
  - name: r
    bones: [{{name: root, position: [0, 2, 0]}}]
    parts:
      - chain: {{name: hair, parent: root, bones: 6, length: 0.5, direction: [0, -1, 0]}}
cloths:
  - {{name: hair, root_bones: [hair_0], preset: long_hair, parameters: {parameters}}}
wind:
  - {{name: steady, mode: global, main: 5, turbulence: 0, direction: [1, 0, 0]}}
"""


def deflection(args) -> None:
    import numpy as np

    from magica_py import solver
    from magica_py.config.load import load_scene_text
    from magica_py.params import resolve_parameters
    from magica_py.runtime.player import Player

    preset = resolve_parameters("long_hair")
    g = float(preset["gravity"])
    length = 0.5
    cases = [("long_hair (influence 0.2)", "{}", 0.2),
             ("restoration and angle limit off", "{angle_restoration.use: false, angle_limit.use: false}", 0.2),
             ("influence 1", "{wind.influence: 1.0}", 1.0),
             ("influence 1, restoration and limit off",
              "{wind.influence: 1.0, angle_restoration.use: false, angle_limit.use: false}", 1.0)]
    fps = 60
    for label, parameters, influence in cases:
        scene = load_scene_text(STRAND.format(seconds=args.seconds, parameters=parameters))
        player = Player.for_scene(scene)
        system = solver.attach(player, scene)
        frames = int(round(args.seconds * fps))
        tips = []
        for f in range(frames):
            player.step()
            if f >= frames - 2 * fps:
                tips.append(system.positions("hair")[-1].copy())
        tips = np.array(tips)
        measured = float(np.mean(tips[:, 0]))
        a = 5.0 * influence
        theta = math.atan2(a, g)
        print(f"{label:40s} a = {a:.1f} m/s^2, g = {g:.1f}: hand L sin(atan(a/g)) = {length * math.sin(theta):.4f} m "
              f"({math.degrees(theta):.1f} deg); measured mean tip x {measured:.4f} m "
              f"(std {float(np.std(tips[:, 0])):.1e}), drop {2.0 - float(np.mean(tips[:, 1])):.4f} m")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="what", required=True)
    c = sub.add_parser("cost")
    c.add_argument("--frames", type=int, default=120)
    c.add_argument("--reps", type=int, default=5)
    c.add_argument("--scenes", nargs="+", default=["character_walk", "crowd"])
    d = sub.add_parser("deflection")
    d.add_argument("--seconds", type=float, default=6.0)
    args = parser.parse_args()
    cost(args) if args.what == "cost" else deflection(args)


if __name__ == "__main__":
    main()
