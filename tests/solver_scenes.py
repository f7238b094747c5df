"""Small scenes for the solver tests: a hierarchy, cloth specs and a ``ClothSystem``.

Built from the scene engineer's rig generators and the build path, with parameters resolved
by ``magica_py.params`` (overrides as dotted keys), so the tests exercise the real pipeline.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from magica_py.params import resolve_parameters
from magica_py.scene import rigs
from magica_py.scene.colliders import ColliderSet
from magica_py.scene.hierarchy import BoneSpec, TransformHierarchy
from magica_py.solver.system import ClothSystem


@dataclass(frozen=True)
class Spec:
    """A ``scene.ClothSpec`` look-alike (the solver duck-types it)."""

    name: str
    root_bones: tuple
    component: int
    connection_mode: str = "line"
    parameters: object = None
    colliders: tuple = ()
    collision_mode: str = "none"
    bone_attributes: dict = field(default_factory=dict)
    instance: int | None = None


@dataclass
class Settings:
    simulation_frequency: int = 90
    max_steps_per_frame: int = 3
    timing: str = "exact"
    update_mode: str = "normal"


def params(preset=None, **overrides):
    """ClothParameters from a preset and dotted-key overrides (``inertia__world_inertia`` style
    keyword names are converted: ``__`` -> ``.``)."""
    flat = {k.replace("__", "."): v for k, v in overrides.items()}
    return resolve_parameters(preset, flat, "test")


def chain_system(bones=5, length=0.5, direction=(0.0, -1.0, 0.0), root_position=(0.0, 1.0, 0.0),
                 parameters=None, colliders=None, collider_specs=(), collision_mode="none",
                 frequency=90, max_steps=3, timing="exact", connection="line", extra_bones=(),
                 curl=0.0):
    """A root node ``root`` carrying one chain ``tail_0..`` (tail_0 fixed)."""
    bone_list = [BoneSpec("root", None, tuple(root_position))]
    bone_list += rigs.chain("tail", "root", bones, length, direction=direction, curl=curl)
    bone_list += list(extra_bones)
    h = TransformHierarchy(bone_list)
    cs = ColliderSet.from_specs(list(collider_specs), h) if collider_specs else ColliderSet.empty()
    spec = Spec("tail", (h.index("tail_0"),), h.index("root"), connection,
                parameters if parameters is not None else params(),
                tuple(range(cs.count)), collision_mode)
    system = ClothSystem(h, [spec], colliders=cs,
                         settings=Settings(frequency, max_steps, timing))
    return system, h


def chain_nodes(h, bones=5, name="tail"):
    return np.array([h.index(f"{name}_{i}") for i in range(bones)])


def three_tails(parallel=None):
    """Three line-mode tails of 4, 5 and 6 bones under their own roots (the middle one with the
    skirt preset): three teams of different structure, so three blocks. Returns (system,
    hierarchy)."""
    bones = []
    for i in range(3):
        bones += [BoneSpec(f"root{i}", None, (i * 1.0, 1.0, 0.0))]
        bones += rigs.chain(f"tail{i}", f"root{i}", 4 + i, 0.4, direction=(0.0, 0.0, -1.0))
    h = TransformHierarchy(bones)
    specs = [Spec(f"tail{i}", (h.index(f"tail{i}_0"),), h.index(f"root{i}"), "line",
                  params("skirt" if i == 1 else None)) for i in range(3)]
    return ClothSystem(h, specs, settings=Settings(), parallel=parallel), h


def run(system, frames, dt=1.0 / 60.0, before=None):
    """Run frames with a fixed delta; ``before(frame)`` may move the rig (then propagate)."""
    for f in range(frames):
        system.hierarchy.restore_rest_pose(system.restored_bones())
        if before is not None:
            before(f)
        system.hierarchy.propagate()
        system.step_frame(dt)


def pendulum_yaml(theta0: float, *, fps: int, duration: float, solver: str, length: float = 1.0,
                  gravity: float = 9.81, name: str = "pendulum") -> str:
    """Scene YAML of a one-link pendulum (bob at angle ``theta0`` radians from straight down)
    with every restoring term off and no damping; ``solver`` is the ``solver.*`` parameter line
    (``"rate_mode: frequency_consistent"``, ``"mode: quality"``)."""
    x, y = length * np.sin(theta0), -length * np.cos(theta0)
    return f"""
version: 1
scene: {{name: {name}, fps: {fps}, duration: {duration}, simulation_frequency: 90, max_steps_per_frame: 5}}
rigs:
  - name: p
    bones:
      - {{name: anchor, position: [0, 2, 0]}}
      - {{name: b0, parent: anchor, position: [0, 0, 0]}}
      - {{name: b1, parent: b0, position: [{float(x)!r}, {float(y)!r}, 0]}}
cloths:
  - name: pendulum
    root_bones: [b0]
    connection: line
    parameters:
      gravity: {gravity}
      damping: 0
      angle_restoration.use: false
      angle_limit.use: false
      inertia.particle_speed_limit: off
      solver.{solver}
"""
