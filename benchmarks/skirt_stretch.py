"""Skirt and hair edge stretch on violent motion, per frame rate (issue 16 item 3, docs/quality-mode.md
*Long chains and skirts*).

    python benchmarks/skirt_stretch.py [--mode quality|faithful] [--fps 30 60 144 240] [--motions spin backflip ...]

The character rig of ``configs/hard/mocap_spin.yaml`` (hair fan with a head sphere, 12 x 4 skirt
with thigh capsules and a floor) on four motions: ``spin`` (the committed 3 rev/s spin while
running) and three variants this script writes to a temporary folder (the full
``configs/hard/mocap_*`` suite is issue 16 item 7):

* ``backflip``: a full root turn (-360 degrees about X, about the hips) in 0.5 s with a 0.6 m
  jump, legs still;
* ``sprint_stop``: running (thighs +-45 degrees at 2.5 Hz) with a start from rest to 8 m/s and a
  stop, both at 10 m/s^2;
* ``floor_roll``: crouching to 0.35 m hip height, a forward roll (360 degrees in 0.8 s, 1.2 m)
  with the thighs tucked 45 degrees, standing up.

For each run it prints the maximum over the run of the displayed / simulated edge stretch
(``display_stretch.measure``) of the hair, the skirt's parent links and its other edges (rings
and triangle diagonals), and the displayed penetration.
"""
from __future__ import annotations

import argparse
import copy
import math
import pathlib
import sys
import tempfile

import numpy as np
import yaml

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

SPIN = ROOT / "configs" / "hard" / "mocap_spin.yaml"


def _rot_x(deg):
    a = math.radians(deg)
    return np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])


def _keys_about_hips(times, hips, angles, offset):
    """Root keys so that the hips (1 m above the root) follow ``hips`` while the body turns by
    ``angles`` (degrees about X)."""
    keys = []
    for t, h, a in zip(times, hips, angles):
        root = np.asarray(h) - _rot_x(a) @ np.array([0.0, 1.0, 0.0])
        keys.append({"time": float(round(t + offset, 5)), "position": [float(v) for v in root],
                     "euler": [float(a), 0.0, 0.0]})
    return keys


def _legs(start, end):
    return [{"target": f"leg_{side}", "oscillate": {"property": "rotation", "axis": [1, 0, 0], "amplitude": 45,
                                                    "frequency": 2.5, "phase": phase},
             "start": start, "end": end, "fade": 0.2} for side, phase in (("l", 0), ("r", 180))]


def _tuck(start, end, angle):
    keys = [{"time": start, "euler": [0, 0, 0]}, {"time": start + 0.3, "euler": [angle, 0, 0]},
            {"time": end - 0.3, "euler": [angle, 0, 0]}, {"time": end, "euler": [0, 0, 0]}]
    return [{"target": f"leg_{side}", "keyframes": {"interpolation": "smooth", "keys": keys}} for side in "lr"]


def motions(folder: pathlib.Path) -> dict[str, str]:
    base = yaml.safe_load(SPIN.read_text())
    base.pop("output", None)

    def write(name, animation, duration):
        doc = copy.deepcopy(base)
        doc["scene"]["name"] = name
        doc["scene"]["duration"] = duration
        doc["animation"] = animation
        path = folder / f"{name}.yaml"
        path.write_text(yaml.safe_dump(doc, sort_keys=False))
        return str(path)

    out = {"spin": str(SPIN)}
    ts = np.arange(0.0, 0.5 + 1e-9, 1 / 60)
    u = ts / 0.5
    keys = _keys_about_hips(ts, [[0.0, 1.0 + 2.4 * x * (1 - x), -0.3 * x] for x in u],
                            [-360.0 * (3 * x * x - 2 * x ** 3) for x in u], 0.5)
    keys[-1]["euler"] = [0.0, 0.0, 0.0]
    keys = [{"time": 0.0, "position": [0, 0, 0], "euler": [0, 0, 0]}] + keys + \
        [{"time": 2.5, "position": keys[-1]["position"], "euler": [0, 0, 0]}]
    out["backflip"] = write("backflip", [{"target": "root", "keyframes": {"interpolation": "cubic", "keys": keys}}],
                            2.5)

    def sprint(t):
        t -= 0.2
        if t <= 0:
            return 0.0
        if t <= 0.8:
            return 5.0 * t * t
        if t <= 1.3:
            return 3.2 + 8.0 * (t - 0.8)
        if t <= 2.1:
            return 7.2 + 8.0 * (t - 1.3) - 5.0 * (t - 1.3) ** 2
        return 10.4
    keys = [{"time": float(round(t, 5)), "position": [0.0, 0.0, float(sprint(t))]}
            for t in np.arange(0.0, 2.5 + 1e-9, 1 / 60)]
    out["sprint_stop"] = write("sprint_stop", [
        {"target": "root", "keyframes": {"interpolation": "cubic", "keys": keys}},
        {"target": "hips", "walk": {"stride_frequency": 2.5, "bob": 0.04, "sway": 6, "twist": 6},
         "start": 0.2, "end": 2.3, "fade": 0.2}] + _legs(0.2, 2.3), 3.0)

    ts = np.arange(0.0, 1.4 + 1e-9, 1 / 60)
    hips, angles = [], []
    for t in ts:
        if t < 0.3:
            x = t / 0.3
            hips.append([0.0, 1.0 - 0.65 * (3 * x * x - 2 * x ** 3), 0.0])
            angles.append(0.0)
        elif t < 1.1:
            x = (t - 0.3) / 0.8
            s = 3 * x * x - 2 * x ** 3
            hips.append([0.0, 0.35, 1.2 * s])
            angles.append(360.0 * s)
        else:
            x = (t - 1.1) / 0.3
            hips.append([0.0, 0.35 + 0.65 * (3 * x * x - 2 * x ** 3), 1.2])
            angles.append(0.0)
    keys = [{"time": 0.0, "position": [0, 0, 0], "euler": [0, 0, 0]}] + _keys_about_hips(ts, hips, angles, 0.3)
    out["floor_roll"] = write("floor_roll", [{"target": "root", "keyframes": {"interpolation": "cubic", "keys": keys}}]
                              + _tuck(0.3, 1.7, -45), 2.5)
    return out


def main(argv=None) -> int:
    from display_stretch import measure

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mode", default="quality", choices=("quality", "faithful"))
    ap.add_argument("--fps", type=float, nargs="+", default=[30.0, 60.0, 144.0, 240.0])
    ap.add_argument("--motions", nargs="+", default=["spin", "backflip", "sprint_stop", "floor_roll"])
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as folder:
        scenes = motions(pathlib.Path(folder))
        print(f"{args.mode}: max over the run, displayed / simulated edge stretch (%), displayed penetration (mm)")
        print(f"{'motion':<12} {'fps':>4}  {'hair':>11}  {'skirt links':>11}  {'skirt rings':>11}  {'pen':>6}")
        for name in args.motions:
            for fps in args.fps:
                r = measure(scenes[name], fps, args.mode, None, {})
                h, s = r["teams"].index("hair"), r["teams"].index("skirt")
                cell = lambda a, b, j: f"{100 * r[a][:, j].max():5.2f}/{100 * r[b][:, j].max():5.2f}"  # noqa: E731
                print(f"{name:<12} {fps:4g}  {cell('shown', 'state', h)}  {cell('shown', 'state', s)}  "
                      f"{cell('shown_other', 'state_other', s)}  {1000 * r['depth'].max():6.1f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
