"""Scale (issue 16 item 4, docs/parameters.md *Scale*): in quality mode every length-like
parameter follows the cloth's scale, so a rig built at scale 0.01 behaves as the same rig at
scale 1 seen at 0.01. The rig: a 10-bone tail under a root that sways, a sphere collider in
the tail's path under the same root; the runs at scale 1 and 0.01 (animation amplitude scaled
with it) are compared in the root's frame, divided by the scale.
"""
import pathlib

import numpy as np
import yaml

from magica_py.bench.variants import Variant, prepare

FRAMES = 60


def scene(folder: pathlib.Path, s: float) -> str:
    doc = {
        "version": 1,
        "scene": {"name": "scaled_tail", "fps": 60, "duration": FRAMES / 60.0, "simulation_frequency": 90,
                  "max_steps_per_frame": 3, "gravity": [0, -1, 0]},
        "rigs": [{"name": "r", "bones": [{"name": "root", "position": [0, 1.0 * s, 0], "scale": [s, s, s]},
                                         {"name": "hips", "parent": "root", "position": [0, 0, 0]},
                                         {"name": "ball", "parent": "root", "position": [0, -0.3, -0.25]}],
                  "parts": [{"chain": {"name": "tail", "parent": "hips", "bones": 10, "length": 0.5,
                                       "direction": [0, -0.5, -1]}}]}],
        "animation": [{"target": "root", "oscillate": {"property": "position", "axis": [1, 0, 0],
                                                       "amplitude": 0.3 * s, "frequency": 1.5}}],
        "colliders": [{"name": "ball_col", "transform": "ball", "sphere": {"radius": 0.1}}],
        "cloths": [{"name": "tail", "root_bones": ["tail_0"], "connection": "line", "colliders": ["ball_col"],
                    "collision_mode": "point"}],
    }
    path = folder / f"scaled_tail_{s:g}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return str(path)


def tail_in_root_frame(path: str, parameters: dict) -> np.ndarray:
    """(F, N, 3) bone positions minus the root's, every frame."""
    p = prepare(Variant("scale", path, parameters=parameters))
    h = p.scene.hierarchy
    nodes = np.asarray(p.system.model.transform_index)
    root = h.index("root")
    out = []
    for _ in range(p.frames):
        p.player.step()
        out.append(h.world_position[nodes] - h.world_position[root])
    return np.array(out)


def test_quality_rig_at_0_01_moves_as_the_rig_at_1_seen_at_0_01(tmp_path):
    quality = {"solver.mode": "quality"}
    big = tail_in_root_frame(scene(tmp_path, 1.0), quality)
    small = tail_in_root_frame(scene(tmp_path, 0.01), quality) / 0.01
    assert np.abs(big).max() > 0.1
    error = np.linalg.norm(small - big, axis=-1).max()
    assert error <= 1e-3 * 0.5          # 0.1 % of the 0.5 m tail


def test_faithful_rig_at_0_01_does_not_scale_its_particle_radius(tmp_path):
    """The reference's lengths are world metres: the faithful small rig's 2 cm particles are
    as big as its tail (the oracle's other side)."""
    big = tail_in_root_frame(scene(tmp_path, 1.0), {})
    small = tail_in_root_frame(scene(tmp_path, 0.01), {}) / 0.01
    assert np.linalg.norm(small - big, axis=-1).max() > 0.05
