"""The imported-asset showcases (issue 7 item 5) run through YAML, the player and the solver:
configs/vrm_godette_mocap.yaml (a VRM avatar's spring chains on a retargeted capture) and
configs/fox_run.yaml (a glTF animal's tail simulated on its own run clip, tail keys dropped).

Bounds (measured per frame by tests/showcase_run.py, after the write-back, on the bones):

* no non-finite value anywhere in the hierarchy, at any frame;
* edge stretch (parent edges, extension) below the solver issue's 1 % where MagicaCloth2's
  faithful algorithm reaches it (Godette: 0.42 % measured), else at the measured figure with
  margin and the reason (Fox: 1.08 % measured while the body speeds up, bound 1.5 %: the
  faithful step does not reach the issue's 1 % on this whipping tail, cf. the walking
  character's measured figures in tests/test_solver_walk.py);
* root-distance extension within the tether's 3 % (the solver issue's bound);
* penetration: no moving particle deeper than 10 % of the collider's radius inside "collider
  surface + particle radius" (the solver issue's point-mode bound; Godette 7.2 % measured,
  the front hair against the head sphere it rests 12.9 mm inside at the build pose, as
  authored in the VRM: see the test below).
"""
from __future__ import annotations

import json
import os
import shutil
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data"
pytestmark = pytest.mark.skipif(not DATA.is_dir(), reason=f"shared test data folder {DATA} is absent")
sys.path.insert(0, str(Path(__file__).resolve().parent))

from showcase_run import run_showcase, summary  # noqa: E402


@pytest.fixture(scope="module")
def godette():
    return run_showcase(ROOT / "configs" / "vrm_godette_mocap.yaml")


@pytest.fixture(scope="module")
def fox():
    return run_showcase(ROOT / "configs" / "fox_run.yaml")


def test_vrm_avatar_on_retargeted_capture_runs_inside_the_solver_bounds(godette):
    run = godette
    assert run.frames == 360 and run.finite.all(), summary(run)
    assert [c.name for c in run.scene.cloths] == ["vrm_FrontHair", "vrm_Ribbon", "vrm_HairBall"]
    assert run.edge_stretch.max() < 0.01, summary(run)
    assert run.root_stretch.max() < 0.03, summary(run)
    assert run.penetration_ratio.max() < 0.10, summary(run)
    # the cloths move relative to their heads / chest (exactly 0 if nothing were simulated);
    # Godette's springs are stiff (VRM stiffness 1-4, no gravity): centimetres, not decimetres
    assert run.tip_travel.max() > 0.005, summary(run)


def test_vrm_front_hair_starts_inside_the_head_sphere_by_its_authored_overlap(godette):
    """Godette's front-hair tips rest 12.9 mm inside "head sphere + hit radius 0.02 m" in the
    file (UniVRM pushes them out on its first frame too); the solver does the same without
    a blow-up: the deepest penetration after that stays under 10 % of the sphere's radius."""
    assert 0.010 < godette.start_inside < 0.015
    assert godette.penetration[30:].max() < 0.1 * 0.15


def test_fox_tail_swings_on_the_run_clip_inside_the_solver_bounds(fox):
    run = fox
    h = run.scene.hierarchy
    driven = {h.names[t] for t in run.scene.animation.target}
    assert {"b_Hip_01", "b_Tail01_012"} <= driven                   # the clip turns the tail's fixed root
    assert not driven & {"b_Tail02_013", "b_Tail03_014"}            # the simulated bones' keys are dropped
    assert run.frames == 360 and run.finite.all(), summary(run)
    assert run.edge_stretch.max() < 0.015, summary(run)
    assert run.root_stretch.max() < 0.03, summary(run)
    assert run.penetration_ratio.max() < 0.10, summary(run)     # the ground plane, by the particle radius
    # the tail tip moves relative to the hips by decimetres (it is 0.37 m long)
    assert 0.05 < run.tip_travel.mean() < 0.37, summary(run)
    # the clip plays at the rig's unit scale: the hips stay about 0.4 m up, never 40 m
    hips = h.world_position[h.index("b_Hip_01")]
    assert 0.25 < hips[1] < 0.6 and hips[2] > 5.0, hips   # and the fox has run 7 m forward


def test_vrm_end_nodes_and_collider_radii_survive_into_the_built_cloths(godette):
    """VRM 0.x: each spring root swings with its authored end node (``FrontHair_L`` →
    ``FrontHair_L_End``), no virtual tail added; the collider spheres keep the file's radii
    on their nodes, the particles the group's hit radius."""
    from magica_py.bench.metrics import particle_radius
    from magica_py.build import build_cloth

    scene, system = godette.scene, godette.system
    h = scene.hierarchy
    assert not any(n.endswith("_vrm_tail") for n in h.names)
    hair = scene.cloth("vrm_FrontHair")
    model = build_cloth(h, hair)
    names = [h.names[i] for i in model.transform_index]
    assert sorted(names) == sorted([f"FrontHair_{s}" for s in ("Center_L", "Center_R", "R", "L")]
                                   + [f"FrontHair_{s}_End" for s in ("Center_L", "Center_R", "R", "L")])
    for i, name in enumerate(names):
        expected = 0x02 if name.endswith("_End") else 0x01          # roots fixed, end nodes move
        assert model.attribute[i] & 0x03 == expected, name
        if name.endswith("_End"):
            assert names[model.parent[i]] == name[:-4]
    cols = scene.colliders
    assert {cols.names[i]: h.names[int(cols.transform[i])] for i in range(len(cols))} == {
        "vrm_col0_0": "chest_Armature", "vrm_col0_1": "chest_Armature",
        "vrm_col1_0": "head_Armature", "vrm_col1_1": "head_Armature"}
    assert list(cols.radius) == pytest.approx([0.1, 0.217, 0.15, 1.0])
    assert list(cols.shape) == [0, 0, 0, 0]                          # spheres
    assert [cols.names[i] for i in hair.colliders] == ["vrm_col1_0", "vrm_col1_1"]
    assert [cols.names[i] for i in scene.cloth("vrm_Ribbon").colliders] == ["vrm_col0_0", "vrm_col0_1"]
    team = system.team_names.index("vrm_FrontHair")
    radius = particle_radius(system.model, system.parameters)[np.asarray(system.model.particle_team) == team]
    assert radius == pytest.approx(0.02)                             # the group's hitRadius


def _scene_file(tmp_path, rig_file: str, extra: str = "") -> Path:
    path = tmp_path / "scene.yaml"
    path.write_text(f"""
version: 1
scene: {{fps: 60, frames: 30}}
rigs:
  - {{name: springs, file: {rig_file}}}
cloths:
  - {{from_vrm: springs}}
{extra}""")
    return path


def test_vrm1_tail_joint_and_world_radius_survive_into_the_built_cloth(tmp_path):
    """VRM 1.0 (three-vrm's sphere example): the spring's last joint is its tail, a particle of
    the cloth; the collider's radius is a world length (0.5 m on a 0.25-scaled node)."""
    from magica_py.build import build_cloth
    from magica_py.config import load_scene

    example = DATA / "vrm" / "three-vrm-springbone-examples" / "sphere-collider.gltf"
    scene = load_scene(_scene_file(tmp_path, os.path.relpath(example, tmp_path)))
    h = scene.hierarchy
    (cloth,) = scene.cloths
    model = build_cloth(h, cloth)
    names = [h.names[i] for i in model.transform_index]
    assert names == ["Spring A", "Spring B", "Spring C", "Spring D", "Spring E"]
    assert [int(a) & 0x03 for a in model.attribute] == [0x01, 0x02, 0x02, 0x02, 0x02]
    shapes = scene.colliders.world_shapes(h)
    assert shapes.radius[cloth.colliders[0]] == pytest.approx(0.5)


def test_vrm0_childless_root_gets_its_virtual_tail_particle(tmp_path):
    """A VRM 0.x spring root without children swings a synthetic ``<bone>_vrm_tail`` 7 cm
    (x the joint's world scale) beyond it along parent -> joint, as UniVRM does."""
    from magica_py.build import build_cloth
    from magica_py.config import load_scene

    src = DATA / "vrm" / "three-vrm-springbone-examples"
    for f in ("sphere-collider.gltf", "sphere_mesh.bin"):
        shutil.copy(src / f, tmp_path / f)
    path = tmp_path / "sphere-collider.gltf"
    doc = json.loads(path.read_text())
    del doc["extensions"]["VRMC_springBone"]
    doc["extensions"]["VRM"] = {"secondaryAnimation": {"boneGroups": [{"bones": [4], "stiffiness": 1.0, "dragForce": 0.4,
                                                                         "hitRadius": 0.02, "gravityPower": 0}],
                                                        "colliderGroups": []}}
    path.write_text(json.dumps(doc))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        scene = load_scene(_scene_file(tmp_path, "sphere-collider.gltf"))
    h = scene.hierarchy
    (cloth,) = scene.cloths
    model = build_cloth(h, cloth)
    assert [h.names[i] for i in model.transform_index] == ["Spring E", "Spring E_vrm_tail"]
    step = h.world_position[h.index("Spring E_vrm_tail")] - h.world_position[h.index("Spring E")]
    assert np.allclose(step, [0.0, -0.07 * 0.25, 0.0], atol=1e-12)


def _tail_tip_in_hips(path, overrides=(), simulate=True):
    """Tail tip position in the hips' frame, frames 90-359 (after the start), (270, 3)."""
    from magica_py.config import load_scene
    from magica_py.runtime.player import Player
    from magica_py.solver.system import ClothSystem

    scene = load_scene(path, overrides)
    player = Player.for_scene(scene)
    if simulate:
        ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings).attach(player)
    h = scene.hierarchy
    hips, tip = h.index("b_Hip_01"), h.index("b_Tail03_014")
    rows = []
    for f in range(360):
        player.step()
        if f >= 90:
            rows.append(h.inverse_transform_point(hips, h.world_position[tip]))
    return np.array(rows)


def test_fox_simulated_tail_moves_like_the_animators_keyed_tail():
    """Oracle: the same config with the tail keys kept and no cloth is the animator's tail.
    The simulated tail is not the same motion (it lags and swings with the body), but its
    statistics over the run should match the animation it replaces: the mean tip position
    within 5 cm (measured 3.5 cm) and the swing (standard deviation per axis) within 30 %
    (measured 11.6 / 5.4 cm against 10.9 / 6.9 cm). The first draft of the showcase (every
    tail key dropped, tail preset with gravity 3) hung the tip 22 cm lower and swung it
    17.7 cm vertically."""
    config = ROOT / "configs" / "fox_run.yaml"
    simulated = _tail_tip_in_hips(config)
    keyed = _tail_tip_in_hips(config, ["animation[0].drop=[]", "cloths=[]"], simulate=False)
    assert np.linalg.norm(simulated.mean(axis=0) - keyed.mean(axis=0)) < 0.05
    swing, keyed_swing = simulated.std(axis=0)[:2], keyed.std(axis=0)[:2]
    assert keyed_swing.min() > 0.05                              # the animator wags the tail
    np.testing.assert_allclose(swing, keyed_swing, rtol=0.3)
