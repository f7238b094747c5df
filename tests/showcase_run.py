"""Run a showcase config through the player and the solver (no sink) and measure, frame by
frame, what the solver issue bounds: non-finite values, edge stretch, root-distance stretch
and collider penetration. Shared by tests/test_io_showcases.py and
tests/test_showcase_configs.py (and usable by hand: ``python tests/showcase_run.py CONFIG``).

Measures (world space, bone positions after write-back, i.e. what is displayed):

* ``edge_stretch`` (F,): max over parent edges (bone to child: the chains' own lengths) of
  the extension ``length / rest - 1`` (the quantity of the solver issue and of
  tests/test_solver_walk.py); ``mesh_edge_stretch`` (F,): ``|length / rest - 1|`` over every
  proxy edge, horizontal mesh edges included (softer by design in MagicaCloth2);
* ``root_stretch`` (F,): max over moving particles of the extension of their distance to
  their root (the tether's quantity; a bent chain brings its tip closer, which is not
  stretch);
* ``penetration`` (F,) m: deepest moving particle inside "collider surface + particle
  radius" (the surface the solver projects onto, docs/solver.md §D.8), over its cloth's colliders;
* ``penetration_ratio`` (F,): that depth over the collider's radius (plane: the particle
  radius), the unit of the solver issue's "10 % of its radius";
* ``start_inside`` (m): the same depth at the build pose, before any frame: a collider that
  starts inside the cloth pushes it out violently on the first step.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass

import numpy as np

from magica_py.bench import metrics as M


@dataclass
class ShowcaseRun:
    scene: object
    system: object
    frames: int
    finite: np.ndarray
    edge_stretch: np.ndarray
    mesh_edge_stretch: np.ndarray
    root_stretch: np.ndarray
    penetration: np.ndarray
    penetration_ratio: np.ndarray
    start_inside: float
    tip_travel: np.ndarray          # (F,) mean distance of the chain tips from their rest place relative to the component


def _penetration(h, scene, positions, radius, pairs):
    shapes = scene.colliders.world_shapes(h)
    depth = M.penetration_depth(positions, radius, pairs, shapes)
    pi, ci = pairs
    if pi.size == 0:
        return 0.0, 0.0
    scale = np.where(shapes.shape[ci] == 2, radius[pi],
                     np.maximum(np.maximum(shapes.radius[ci], shapes.end_radius[ci]), 1e-9))
    d = np.maximum(depth[pi], 0.0)
    # depth is per particle (max over colliders): attribute it to each pair conservatively
    return float(depth.max()), float((d / scale).max())


def run_showcase(path, frames: int | None = None, overrides=()) -> ShowcaseRun:
    import warnings

    from magica_py.config import load_scene
    from magica_py.runtime.player import Player
    from magica_py.solver.system import ClothSystem

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)   # importer notes (the VRM's r = 1 m sphere)
        scene = load_scene(path, overrides)
    player = Player.for_scene(scene)
    system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings).attach(player)
    h = scene.hierarchy
    h.propagate()
    model = system.model
    nodes = np.asarray(model.transform_index, dtype=np.int64)
    rest = h.world_position[nodes].copy()
    geometry = M.chain_geometry(model, rest)
    radius = M.particle_radius(model, system.parameters)
    team_cols = [list(spec.colliders) if spec.collision_mode != "none" else [] for spec in system.specs]
    pairs = M.particle_collider_pairs(geometry.team, team_cols)
    collides = geometry.moving & ((np.asarray(model.attribute) & 0x10) == 0)
    keep = collides[pairs[0]]
    pairs = (pairs[0][keep], pairs[1][keep])
    start_inside, _ = _penetration(h, scene, rest, radius, pairs)
    tips = np.nonzero(geometry.moving & (np.asarray(model.child_count) == 0))[0]
    component = np.asarray([system.specs[t].component for t in geometry.team[tips]])
    rest_tip_local = np.array([h.inverse_transform_point(int(c), rest[i]) for c, i in zip(component, tips)])

    n = frames if frames is not None else scene.settings.frame_count()
    out = {k: np.zeros(n) for k in ("edge", "mesh", "root", "pen", "ratio", "tip")}
    parent = np.asarray(model.parent, dtype=np.int64)
    child = np.nonzero(parent >= 0)[0]
    parent_rest = np.linalg.norm(rest[child] - rest[parent[child]], axis=1)
    child, parent_rest = child[parent_rest > M.ZERO_LENGTH], parent_rest[parent_rest > M.ZERO_LENGTH]
    finite = np.ones(n, dtype=bool)
    for f in range(n):
        player.step()
        x = h.world_position[nodes]
        finite[f] = bool(np.isfinite(h.world_position).all() and np.isfinite(h.world_rotation).all())
        length = np.linalg.norm(x[child] - x[parent[child]], axis=1)
        out["edge"][f] = float((length / parent_rest - 1.0).max(initial=0.0))
        out["mesh"][f] = float(np.abs(M.edge_stretch(x, geometry)).max(initial=0.0))
        out["root"][f] = float(M.root_distance_stretch(x, geometry).max(initial=0.0))
        out["pen"][f], out["ratio"][f] = _penetration(h, scene, x, radius, pairs)
        if tips.size:
            local = np.array([h.inverse_transform_point(int(c), x[i]) for c, i in zip(component, tips)])
            out["tip"][f] = float(np.linalg.norm(local - rest_tip_local, axis=1).mean())
    return ShowcaseRun(scene, system, n, finite, out["edge"], out["mesh"], out["root"], out["pen"], out["ratio"], start_inside,
                       out["tip"])


def summary(run: ShowcaseRun) -> str:
    worst = int(np.argmax(run.edge_stretch))
    return (f"{run.scene.name}: {run.frames} frames, finite {bool(run.finite.all())}, "
            f"max edge stretch {100 * run.edge_stretch.max():.2f} % (frame {worst}), "
            f"mesh edges {100 * run.mesh_edge_stretch.max():.2f} %, "
            f"max root stretch {100 * run.root_stretch.max():.2f} %, "
            f"max penetration {1000 * run.penetration.max():.2f} mm "
            f"({100 * run.penetration_ratio.max():.1f} % of the collider radius), "
            f"start inside {1000 * run.start_inside:.2f} mm, mean tip travel {run.tip_travel.mean():.3f} m")


if __name__ == "__main__":
    for config in sys.argv[1:]:
        print(summary(run_showcase(config)))
