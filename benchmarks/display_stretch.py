"""Displayed against simulated stretch and penetration, per frame (docs/quality-mode.md, issue 16).

    python benchmarks/display_stretch.py configs/vrm_godette_mocap.yaml --fps 144 --mode quality
    python benchmarks/display_stretch.py configs/character_walk.yaml --fps 144 --mode quality --set ...

For every frame the script records, over every proxy edge of the scene's cloths:

* the displayed edge stretch (parent links and the other proxy edges, e.g. a skirt's rings,
  apart): the bones' world positions after the write-back (what a user
  sees), ``|p1 - p0| / rest - 1``;
* the simulated edge stretch: the same of the solver states the display interpolates, the
  last step's (``ClothSystem.particles.old_pos``) and the one before it;
* the displayed penetration: depth of a moving bone inside a collider of its cloth plus its
  particle radius, at this frame's collider pose (m).

It prints the maxima per cloth and over the run, and the frame of the largest displayed
stretch. Rest lengths are the bones' world rest pose at build (scale 1 rigs).
"""
from __future__ import annotations

import argparse
import pathlib
import sys

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from magica_py.bench import metrics as M  # noqa: E402
from magica_py.bench.variants import Variant, prepare, rest_geometry  # noqa: E402


def measure(scene: str, fps: float, mode: str, duration: float | None, parameters: dict, overrides=()) -> dict:
    params = dict(parameters)
    params["solver.mode"] = mode
    variant = Variant(label=f"{pathlib.Path(scene).stem}@{fps:g}", scene=scene, overrides=tuple(overrides),
                      parameters=params, fps=fps, duration=duration)
    p = prepare(variant)
    scene_obj, player, system = p.scene, p.player, p.system
    model = system.model
    h = scene_obj.hierarchy
    nodes, geometry, pairs = rest_geometry(p)
    n = nodes.shape[0]
    radius = M.particle_radius(model, system.parameters)
    edge_team = geometry.team[geometry.edges[:, 0]] if geometry.edges.size else np.zeros(0, dtype=np.int64)
    parent = np.asarray(model.parent, dtype=np.int64)
    e = geometry.edges
    vertical = (parent[e[:, 0]] == e[:, 1]) | (parent[e[:, 1]] == e[:, 0]) if e.size else np.zeros(0, bool)
    teams = sorted(set(int(t) for t in edge_team))
    names = {t: getattr(system.specs[t], "name", str(t)) if t < len(system.specs) else str(t) for t in teams}
    shown = np.zeros((p.frames, len(teams)))
    state = np.zeros((p.frames, len(teams)))
    shown_other = np.zeros((p.frames, len(teams)))   # edges that are not parent links (skirt rings)
    state_other = np.zeros((p.frames, len(teams)))
    depth = np.zeros(p.frames)
    ps = system.particles
    dt = 1.0 / p.frequency
    for i in range(p.frames):
        player.step()
        now = h.world_position[nodes]
        es_shown = M.edge_stretch(now, geometry)
        # the two step states the display interpolates: the last (old_pos) and the one before
        # (old_pos - real_velocity dt, D.10's definition), which at render rates below the
        # frequency ends inside the frame
        old_pos = ps.old_pos   # the view gathers a copy of the packed state: once per frame
        es_state = np.maximum(M.edge_stretch(old_pos[:n], geometry),
                              M.edge_stretch(old_pos[:n] - ps.real_velocity[:n] * dt, geometry))
        for j, t in enumerate(teams):
            sel = (edge_team == t) & vertical
            shown[i, j] = es_shown[sel].max(initial=0.0)
            state[i, j] = es_state[sel].max(initial=0.0)
            sel = (edge_team == t) & ~vertical
            shown_other[i, j] = es_shown[sel].max(initial=0.0)
            state_other[i, j] = es_state[sel].max(initial=0.0)
        if pairs[0].shape[0]:
            depth[i] = M.penetration_depth(now, radius, pairs, scene_obj.colliders.world_shapes(h)).max()
    return {"teams": [names[t] for t in teams], "shown": shown, "state": state, "depth": depth,
            "shown_other": shown_other, "state_other": state_other,
            "frames": p.frames}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene")
    ap.add_argument("--fps", type=float, default=144.0)
    ap.add_argument("--mode", default="quality", choices=("quality", "faithful"))
    ap.add_argument("--duration", type=float, default=None, help="seconds (default: the scene's)")
    ap.add_argument("--param", action="append", default=[], help="key=value parameter of every cloth")
    ap.add_argument("--set", action="append", default=[], help="scene override (as magica-py run --set)")
    args = ap.parse_args(argv)
    params = {}
    for kv in args.param:
        key, value = kv.split("=", 1)
        try:
            params[key] = float(value)
        except ValueError:
            params[key] = value
    r = measure(args.scene, args.fps, args.mode, args.duration, params, args.set)
    print(f"{args.scene} {args.mode} {args.fps:g} fps, {r['frames']} frames {' '.join(args.param)}")
    print(f"{'cloth / edges':<30} {'shown max %':>12} {'state max %':>12} {'shown-state max %':>18}")
    for j, name in enumerate(r["teams"]):
        for kind, a, b in (("parent links", "shown", "state"), ("other edges", "shown_other", "state_other")):
            shown, state = r[a][:, j], r[b][:, j]
            if not shown.any() and not state.any() and kind == "other edges":
                continue
            print(f"{name + ' ' + kind:<30} {100 * shown.max():12.2f} {100 * state.max():12.2f} "
                  f"{100 * (shown - state).max():18.2f}")
    worst = int(np.unravel_index(np.argmax(np.maximum(r["shown"], r["shown_other"])), r["shown"].shape)[0])
    print(f"largest displayed stretch at frame {worst}; displayed penetration max "
          f"{1000 * r['depth'].max():.1f} mm")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
