"""The imported showcase inputs run through the real solver (no YAML): Godette's VRM spring
cloths driven by the retargeted CMU clip, and the Fox's tail on its Run clip with the tail
channels dropped. Short runs: no NaN, bone lengths kept, particles outside their colliders."""
import warnings
from pathlib import Path

import numpy as np
import pytest

from magica_py.io import ClipDriver, load_bvh, load_gltf, load_vrm, retarget
from magica_py.params import resolve_parameters
from magica_py.scene.colliders import ColliderSet
from magica_py.scene.hierarchy import TransformHierarchy
from magica_py.scene.scene import ClothSpec

DATA = Path(__file__).parents[1].parent / "shared" / "data"
pytestmark = pytest.mark.skipif(not DATA.is_dir(), reason=f"shared test data folder {DATA} is absent")
FRAMES = 90


def _run(h, driver, system, on_frame):
    restored = system.restored_bones()
    for f in range(FRAMES):
        h.restore_rest_pose(restored)
        driver.apply(h, f / 60.0)
        h.propagate()
        system.step_frame(1.0 / 60.0)
        assert np.all(np.isfinite(h.world_position)), f"NaN at frame {f}"
        on_frame(f)


def test_godette_spring_cloths_follow_the_retargeted_capture():
    from magica_py.solver.system import ClothSystem
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        avatar = load_vrm(DATA / "vrm" / "Godette_vrm_v4.vrm")
    bvh = load_bvh(DATA / "bvh" / "cmu_01_01.bvh")
    clip = retarget(bvh.clip.trimmed(0.0, 2.0), bvh.bones, avatar.bones, target_map=avatar.humanoid, source_rest=0)
    h = TransformHierarchy(avatar.bones)
    colliders = ColliderSet.from_specs(avatar.collider_entries(), h)
    specs = []
    for e in avatar.cloth_entries():
        roots = tuple(h.index(r) for r in e["root_bones"])
        specs.append(ClothSpec(name=e["name"], root_bones=roots, component=int(h.parent[roots[0]]), connection_mode="line",
                               parameters=resolve_parameters(None, e["parameters"], e["name"]),
                               colliders=tuple(colliders.index(c) for c in e["colliders"]),
                               collision_mode=e["collision_mode"]))
    system = ClothSystem(h, specs, colliders)
    pairs = [(h.index(c.joints[1]), h.index(c.joints[0])) for c in avatar.chains]
    rest = np.array([np.linalg.norm(h.world_position[a] - h.world_position[p]) for a, p in pairs])
    stretch = []
    _run(h, ClipDriver(clip, h), system, lambda f: stretch.append(max(
        abs(np.linalg.norm(h.world_position[a] - h.world_position[p]) / r - 1) for (a, p), r in zip(pairs, rest))))
    assert max(stretch) < 0.05
    for chain in avatar.chains:          # the hair and ribbon tips end outside the spheres they collide with
        for name in chain.colliders:
            col = next(c for c in avatar.colliders if c.name == name)
            i = h.index(col.transform)
            centre = h.transform_point(i, col.center)
            gap = np.linalg.norm(h.world_position[h.index(chain.joints[-1])] - centre) - col.radius * h.lossy_scale[i, 0]
            assert gap > chain.vrm["hit_radius"] - 0.005, (chain.name, name, gap)


@pytest.mark.parametrize("file, scale, clip_name, drop, hips, tail", [
    ("Fox.glb", 0.01, "Run", ["b_Tail*"], "b_Hip_01", ["b_Tail01_012", "b_Tail02_013", "b_Tail03_014"]),
    ("wuson.glb", 1.0, "Wuson_Run", ["Tail0*"], "Pelvis", [f"Tail0{i}" for i in range(1, 7)]),
])
def test_animal_tail_swings_on_its_run_clip_with_its_keys_dropped(file, scale, clip_name, drop, hips, tail):
    """The tail follows the body's motion: its tip moves relative to the hips (exactly 0
    without the cloth, since the dropped clip no longer moves it).

    How much depends on how much the body moves, so the bound is relative to the hips' own
    travel: the Fox's Run swings its hips 12 cm, but Wuson_Run only bobs its root 1.6 cm
    vertically (no body rotation: the clip animates the legs, ears and tail), and the 0.8 m
    tail answers with a 3.4 cm swing at the tip. The former absolute 1 cm bound sat within a
    factor 3 of that weak signal, so any solver change that damps the tail a little (the
    working tree is shared with solver work in progress) could fail it; half the hips'
    travel is the physical statement and holds for both animals (measured: Fox 2.2x, Wuson 2.1x)."""
    from magica_py.solver.system import ClothSystem
    rig = load_gltf(DATA / "gltf" / file, unit_scale=scale)
    clip = rig.clip(clip_name).without(drop)
    assert not any(n in clip.nodes() for n in tail)
    h = TransformHierarchy(rig.bones)
    root = h.index(tail[0])
    spec = ClothSpec(name="tail", root_bones=(root,), component=int(h.parent[root]), connection_mode="line",
                     parameters=resolve_parameters("tail", None, "tail"), collision_mode="none")
    system = ClothSystem(h, [spec])
    idx = [h.index(n) for n in tail]
    rest = [np.linalg.norm(h.world_position[idx[k + 1]] - h.world_position[idx[k]]) for k in range(len(idx) - 1)]
    tip_local, hips_world = [], []

    def check(f):
        for k in range(len(idx) - 1):
            length = np.linalg.norm(h.world_position[idx[k + 1]] - h.world_position[idx[k]])
            assert abs(length / rest[k] - 1) < 0.05
        tip_local.append(h.inverse_transform_point(h.index(hips), h.world_position[idx[-1]]))
        hips_world.append(h.world_position[h.index(hips)].copy())

    _run(h, ClipDriver(clip, h), system, check)
    hips_travel = np.ptp(np.array(hips_world), axis=0).max()
    assert hips_travel > 0.01          # the clip (tail channels dropped) still moves the body
    swing = np.ptp(np.array(tip_local), axis=0).max()
    assert swing > 0.5 * hips_travel, (swing, hips_travel)
