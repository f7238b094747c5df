"""The frame runs each block's end of frame (write-back included) right after its steps
(``solver/frame.py``). That is MagicaCloth2's "every cloth reads this frame's transforms before
any writes" only because the frame reads the hierarchy's world pose and the write-back writes
its local pose. (Two cloths never share bones: the config rejects a cloth rooted under
another's bones.) The oracle: a cloth colliding with a sphere carried by a bone another cloth
simulates gives the same bits whichever cloth is declared (and so simulated and written back)
first.
"""
import pathlib

import numpy as np
import yaml

from magica_py.config import load_scene
from magica_py.runtime.player import Player
from magica_py.solver import attach


def two_cloth_scene(folder: pathlib.Path, outer_first: bool, knob: bool = True) -> pathlib.Path:
    outer = {"name": "outer", "root_bones": ["outer_0"], "connection": "line"}
    inner = {"name": "inner", "root_bones": ["inner_0"], "connection": "line"}
    if knob:
        inner.update(colliders=["knob"], collision_mode="point")
    doc = {
        "version": 1,
        "scene": {"name": "nested", "fps": 60, "duration": 1.0, "simulation_frequency": 90, "threads": 1},
        "rigs": [{"name": "r", "bones": [{"name": "root", "position": [0, 1.5, 0]}],
                  "parts": [{"chain": {"name": "outer", "parent": "root", "bones": 6, "length": 0.6,
                                       "direction": [0, -1, 0]}},
                            # beside it, swinging through the knob the outer cloth carries
                            {"chain": {"name": "inner", "parent": "root", "bones": 6, "length": 0.6,
                                       "direction": [0.15, -1, 0]}}]}],
        "animation": [{"target": "root", "orbit": {"center": [0, 1.5, 0], "radius": 0.3, "period": 0.7,
                                                  "axis": [0, 1, 0]}}],
        # a collider carried by a bone the outer cloth simulates
        "colliders": [{"name": "knob", "transform": "outer_4", "sphere": {"radius": 0.1}}],
        "cloths": [outer, inner] if outer_first else [inner, outer],
    }
    path = folder / f"two_cloths_{'outer' if outer_first else 'inner'}_first{'' if knob else '_no_knob'}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def run(path, frames=60):
    scene = load_scene(path)
    player = Player.for_scene(scene)
    system = attach(player, scene, parallel=False)
    out = []
    for _ in range(frames):
        player.step()
        out.append(np.concatenate([system.positions("outer").ravel(), system.positions("inner").ravel()]))
    return np.array(out)


def test_a_cloth_against_a_collider_another_cloth_moves_gives_the_same_bits_in_either_order(tmp_path):
    a = run(two_cloth_scene(tmp_path, outer_first=True))
    b = run(two_cloth_scene(tmp_path, outer_first=False))
    assert np.isfinite(a).all()
    assert np.array_equal(a, b)
    # the case is what it says: the knob the outer cloth carries pushes the inner cloth
    assert np.abs(a - run(two_cloth_scene(tmp_path, outer_first=True, knob=False))).max() > 0.01
