"""Scene loading: what a valid file turns into (names, instances, globs, defaults, overrides)."""
import math

import numpy as np
import pytest

from magica_py.config import ConfigError, load_scene_text
from magica_py.config.overrides import parse_override

CHARACTER = """
version: 1
scene: {name: test, fps: 50, frames: 20, gravity: [0, -2, 0], update_mode: unscaled, seed: 3}
rigs:
  - name: character
    position: [1, 0, 0]
    euler: [0, 90, 0]
    bones:
      - {name: root}
      - {name: hips, parent: root, position: [0, 1, 0]}
      - {name: head, parent: hips, position: [0, 0.6, 0], euler: [0, 90, 0]}
      - {name: leg_l, parent: hips, position: [-0.1, 0, 0]}
      - {name: leg_r, parent: hips, position: [0.1, 0, 0]}
    parts:
      - skirt: {name: skirt, parent: hips, strands: 12, bones: 3}
      - fan: {name: hair, parent: head, strands: 3, bones: 2, length: 0.2}
    INSTANCES
animation:
  - {target: hips, walk: {bob: 0.02}}
  - {target: root#0, spin: {speed: 10}}
  - {at: 1.0, teleport: {target: root, position: [5, 0, 0]}}
  - {at: 1.5, set_parameter: {cloth: skirt, key: damping, value: 0.3}}
  - {at: 2.0, time_scale: 0.5}
colliders:
  - {name: thigh_l, transform: leg_l, capsule: {radius: 0.06, length: 0.4}}
  - {name: thigh_r, transform: leg_r, capsule: {radius: 0.06, length: 0.4}}
  - {name: ground, position: [0, 0, 0], plane: {}}
cloths:
  - name: skirt
    root_bones: ["skirt_*_0"]
    connection: sequential_loop_mesh
    preset: Skirt
    colliders: ["thigh_*", ground]
    collision_mode: edge
    bone_attributes: {"skirt_0_*": fixed}
  - name: hair
    root_bones: [hair_2_0, hair_0_0]
    parameters: {gravity: 1.5, inertia.world_inertia: 0.25, damping: {value: 0.2}}
output: {rrd: replays/test.rrd, log: {baselines: true}}
"""


def scene_text(instances: str = "") -> str:
    text = CHARACTER.replace("INSTANCES", instances)
    return text if instances else text.replace("root#0", "root")  # only instances have #


@pytest.fixture(scope="module")
def scene():
    return load_scene_text(scene_text(), source="character.yaml")


def test_settings_defaults_and_values(scene):
    s = scene.settings
    assert (s.fps, s.frames, s.update_mode, s.seed) == (50.0, 20, "unscaled", 3)
    assert s.gravity == (0.0, -1.0, 0.0)  # normalized direction
    assert (s.simulation_frequency, s.max_steps_per_frame, s.timing) == (90, 3, "exact")
    assert s.fixed_delta_time == 0.02 and s.maximum_delta_time == pytest.approx(1 / 3)
    assert s.frame_count() == 20


def test_duration_converts_to_frames():
    text = scene_text().replace("frames: 20", "duration: 1.01")
    assert load_scene_text(text).settings.frame_count() == 51  # ceil(1.01 * 50)
    text = scene_text().replace("fps: 50, frames: 20", "frame_times: [0.1, 0.3], duration: 1.0")
    assert load_scene_text(text).settings.frame_count() == 6  # 0.1+0.3+0.1+0.3+0.1 = 0.9 < 1.0, +0.3 = 1.2


def test_rig_placement_and_euler_follow_unity(scene):
    h = scene.hierarchy
    root = h.index("root")
    # rig euler (0, 90, 0) = 90 degrees about +Y: local +X maps to world -Z (Unity, left-handed)
    np.testing.assert_allclose(h.local_rotation[root], [0, math.sqrt(0.5), 0, math.sqrt(0.5)], atol=1e-12)
    np.testing.assert_allclose(h.world_position[root], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(h.transform_direction(root, [1, 0, 0]), [0, 0, -1], atol=1e-12)
    head = h.index("head")
    np.testing.assert_allclose(h.local_rotation[head], [0, math.sqrt(0.5), 0, math.sqrt(0.5)], atol=1e-12)


def test_globs_expand_in_hierarchy_order_and_explicit_roots_keep_yaml_order(scene):
    h = scene.hierarchy
    skirt, hair = scene.cloths
    assert [h.names[i] for i in skirt.root_bones] == [f"skirt_{s}_0" for s in range(12)]  # 10, 11 after 9
    assert [h.names[i] for i in hair.root_bones] == ["hair_2_0", "hair_0_0"]


def test_component_defaults_to_first_roots_parent(scene):
    h = scene.hierarchy
    assert h.names[scene.cloths[0].component] == "hips"
    assert h.names[scene.cloths[1].component] == "head"


def test_cloth_colliders_modes_and_attributes(scene):
    skirt = scene.cloth("skirt")
    assert [scene.colliders.names[i] for i in skirt.colliders] == ["thigh_l", "thigh_r", "ground"]
    assert skirt.collision_mode == "edge"
    assert skirt.parameters["collider_collision.mode"] == "edge"
    assert skirt.connection_mode == "sequential_loop_mesh"
    h = scene.hierarchy
    assert {h.names[i]: a for i, a in skirt.bone_attributes.items()} == {
        "skirt_0_0": "fixed", "skirt_0_1": "fixed", "skirt_0_2": "fixed"}
    # static collider: a root node created for it, at its position
    ground = scene.colliders.names.index("ground")
    assert h.parent[scene.colliders.transform[ground]] == -1


def test_parameters_merge_preset_overrides_and_scene_defaults(scene):
    from magica_py.params import resolve_parameters

    skirt = scene.cloth("skirt").parameters
    preset = resolve_parameters("skirt")
    assert skirt["gravity"] == preset["gravity"] == 5.0
    hair = scene.cloth("hair").parameters
    assert hair["gravity"] == 1.5
    assert hair["inertia.world_inertia"] == 0.25
    assert hair["damping"].value == 0.2
    # scene gravity direction and update mode become each cloth's defaults
    assert hair["gravity_direction"] == pytest.approx((0.0, -1.0, 0.0))
    assert hair["update_mode"] == "unscaled"


def test_scene_gravity_direction_reaches_parameters():
    text = scene_text().replace("gravity: [0, -2, 0]", "gravity: [3, 0, -4]")
    s = load_scene_text(text)
    assert s.cloth("hair").parameters["gravity_direction"] == pytest.approx((0.6, 0.0, -0.8))


def test_output_section(scene):
    assert str(scene.output.rrd) == "replays/test.rrd"
    assert scene.output.logs("baselines") and scene.output.logs("skeleton") and not scene.output.logs("base_pose")


def test_events_and_drivers_reach_the_animation(scene):
    kinds = [e.kind for e in scene.animation.events]
    assert kinds == ["teleport", "set_parameter", "time_scale"]
    assert scene.animation.events[1].payload == {"cloth": "skirt", "key": "damping", "value": 0.3}


# ----------------------------------------------------------------------------- instancing
INSTANCED = "instances: {count: 3, spacing: [2, 0, 0], columns: 2, phase_offset: 0.25}"


@pytest.fixture(scope="module")
def crowd():
    return load_scene_text(scene_text(INSTANCED))


def test_instances_name_every_bone_and_place_roots_on_a_grid(crowd):
    h = crowd.hierarchy
    n_per = h.count // 3 if "collider:ground" not in h.index_of else (h.count - 1) // 3
    assert crowd.rigs[0].instances == 3 and crowd.rigs[0].nodes_per_instance == n_per
    for i in range(3):
        assert f"hips#{i}" in h.index_of and f"skirt_11_2#{i}" in h.index_of
    assert "hips" not in h.index_of
    roots = [h.world_position[h.index(f"root#{i}")] for i in range(3)]
    np.testing.assert_allclose(roots[1] - roots[0], [2, 0, 0], atol=1e-12)
    np.testing.assert_allclose(roots[2] - roots[0], [0, 0, 2], atol=1e-12)  # second row


def test_instanced_cloths_and_colliders_are_replicated_per_instance(crowd):
    h = crowd.hierarchy
    names = [c.name for c in crowd.cloths]
    assert names == ["skirt#0", "skirt#1", "skirt#2", "hair#0", "hair#1", "hair#2"]
    assert crowd.colliders.names == ("thigh_l#0", "thigh_l#1", "thigh_l#2", "thigh_r#0", "thigh_r#1",
                                     "thigh_r#2", "ground")
    skirt1 = crowd.cloth("skirt#1")
    assert skirt1.instance == 1
    assert [crowd.colliders.names[i] for i in skirt1.colliders] == ["thigh_l#1", "thigh_r#1", "ground"]
    assert h.names[skirt1.component] == "hips#1"
    assert all(h.names[i].endswith("#1") for i in skirt1.root_bones)
    assert all(h.names[i].endswith("#1") for i in skirt1.bone_attributes)


def test_instanced_animation_is_replicated_with_phase_offsets(crowd):
    anim = crowd.animation
    h = crowd.hierarchy
    walk_targets = [h.names[t] for t, k in zip(anim.target, anim.kind) if k == 4]
    assert walk_targets == ["hips#0", "hips#1", "hips#2"]
    offsets = [float(o) for t, o, k in zip(anim.target, anim.phase_offset, anim.kind) if k == 4]
    assert offsets == [0.0, 0.25, 0.5]
    spin_targets = [h.names[t] for t, k in zip(anim.target, anim.kind) if k == 3]
    assert spin_targets == ["root#0"]  # named with its instance: not replicated
    teleports = [e.payload["name"] for e in anim.events if e.kind == "teleport"]
    assert teleports == ["root#0", "root#1", "root#2"]
    params = [e.payload["cloth"] for e in anim.events if e.kind == "set_parameter"]
    assert params == ["skirt#0", "skirt#1", "skirt#2"]


def test_phase_jitter_is_seeded_and_reproducible():
    text = scene_text("instances: {count: 4, phase_jitter: 0.5}")
    a, b = load_scene_text(text), load_scene_text(text)
    walk_a = a.animation.phase_offset[a.animation.kind == 4]
    np.testing.assert_array_equal(walk_a, b.animation.phase_offset[b.animation.kind == 4])
    assert np.all((walk_a >= 0) & (walk_a < 0.5)) and len(set(walk_a.tolist())) == 4
    other = load_scene_text(text.replace("seed: 3", "seed: 4"))
    assert not np.array_equal(walk_a, other.animation.phase_offset[other.animation.kind == 4])


# ----------------------------------------------------------------------------- overrides
def test_override_syntax():
    assert parse_override("cloths[0].parameters.damping=0.2") == (["cloths", 0, "parameters", "damping"], 0.2)
    assert parse_override("cloths.tail.parameters.inertia.world_inertia=1") == (
        ["cloths", "tail", "parameters", "inertia", "world_inertia"], 1)
    assert parse_override("scene.gravity=[1, 0, 0]") == (["scene", "gravity"], [1, 0, 0])
    assert parse_override("scene.name=fast run") == (["scene", "name"], "fast run")
    with pytest.raises(ValueError, match="PATH=VALUE"):
        parse_override("scene.fps")


@pytest.mark.parametrize("override", ["cloths[1].parameters.gravity=0.5", "cloths.hair.parameters.gravity=0.5",
                                      "cloths.1.parameters.gravity=0.5", "cloths[-1].parameters.gravity=0.5"])
def test_overrides_by_index_or_name_are_equivalent(override):
    s = load_scene_text(scene_text(), [override])
    assert s.cloth("hair").parameters["gravity"] == 0.5


def test_overrides_reach_scene_settings_and_generators():
    s = load_scene_text(scene_text(), ["scene.fps=30", "rigs.character.parts.skirt.strands=8",
                                       "cloths.skirt.root_bones=[skirt_0_0, skirt_4_0]"])
    assert s.settings.fps == 30.0
    assert "skirt_7_0" in s.hierarchy.index_of and "skirt_8_0" not in s.hierarchy.index_of
    assert [s.hierarchy.names[i] for i in s.cloth("skirt").root_bones] == ["skirt_0_0", "skirt_4_0"]


def test_overrides_are_validated_and_tagged():
    with pytest.raises(ConfigError) as info:
        load_scene_text(scene_text(), ["cloths.hair.parameters.damping=3", "scene.max_steps_per_frame=9"])
    issues = {i.path: i for i in info.value.issues}
    assert set(issues) == {"cloths[1].parameters.damping", "scene.max_steps_per_frame"}
    assert "(from --set cloths.hair.parameters.damping=3)" in issues["cloths[1].parameters.damping"].message
    assert issues["scene.max_steps_per_frame"].line is None  # the value no longer comes from the file


def test_override_adding_an_unknown_key_is_reported():
    with pytest.raises(ConfigError) as info:
        load_scene_text(scene_text(), ["scene.frame_rate=30"])
    assert info.value.paths() == ["scene.frame_rate"]


@pytest.mark.parametrize("override, fragment", [
    ("cloths.tial.parameters.damping=0.1", "no element named 'tial'"),
    ("cloths[5].parameters.damping=0.1", "index 5 is out of range"),
    ("scene.fps.value=3", "cannot descend"),
    ("=3", "path before '=' is empty"),
])
def test_bad_override_paths(override, fragment):
    with pytest.raises(ConfigError) as info:
        load_scene_text(scene_text(), [override])
    assert fragment in str(info.value)


def test_source_text_reflects_overrides():
    s = load_scene_text(scene_text(), ["scene.fps=25"])
    assert "fps: 25" in s.source_text
    again = load_scene_text(s.source_text)
    assert again.settings.fps == 25.0 and again.hierarchy.names == s.hierarchy.names


def test_cloth_outside_an_instanced_rig_collides_with_every_copy():
    text = scene_text(INSTANCED).replace("output:", """  - {name: flag, root_bones: [flag_0], colliders: ["thigh_l"]}
output:""")
    text = text.replace("rigs:\n", "rigs:\n  - {name: pole, bones: [{name: pole}], parts: [{chain: {name: flag, parent: pole, bones: 3, length: 0.5}}]}\n", 1)
    s = load_scene_text(text)
    flag = s.cloth("flag")
    assert flag.instance is None
    assert [s.colliders.names[i] for i in flag.colliders] == ["thigh_l#0", "thigh_l#1", "thigh_l#2"]


def test_set_parameter_event_for_one_instance():
    text = scene_text(INSTANCED).replace("{cloth: skirt, key: damping", "{cloth: skirt#2, key: damping")
    s = load_scene_text(text)
    assert [e.payload["cloth"] for e in s.animation.events if e.kind == "set_parameter"] == ["skirt#2"]


def test_scene_settings_drive_the_runtime_clock():
    from magica_py.runtime.player import Player

    text = scene_text().replace("fps: 50, frames: 20", "frame_times: [0.01, 0.05], frames: 4, time_scale: 0.5, "
                                                       "fixed_delta_time: 0.01, maximum_delta_time: 0.04")
    s = load_scene_text(text)
    player = Player.for_scene(s)
    times = [player.step().time for _ in range(3)]
    assert [t.unscaled_delta_time for t in times] == [0.01, 0.05, 0.01]
    assert [t.delta_time for t in times] == pytest.approx([0.005, 0.02, 0.005])  # 0.05 capped at 0.04, x0.5
    assert times[0].fixed_delta_time == 0.01


def test_yaml_merge_keys_reuse_definitions_and_own_keys_win():
    text = """
version: 1
scene: {fps: 60, frames: 3}
rigs:
  - name: r
    bones: [{name: root}, {name: a, parent: root}, {name: b, parent: root}]
colliders:
  - &ball {name: ball_a, transform: a, sphere: {radius: 0.1}}
  - {<<: *ball, name: ball_b, transform: b}
"""
    s = load_scene_text(text)
    assert s.colliders.names == ("ball_a", "ball_b")
    assert [s.hierarchy.names[i] for i in s.colliders.transform] == ["a", "b"]
    assert s.colliders.radius.tolist() == [0.1, 0.1]
    with pytest.raises(ConfigError, match="duplicate key"):
        load_scene_text(text.replace("name: ball_b, transform: b", "name: ball_b, name: ball_c"))


def test_cloth_on_one_named_instance_defaults_its_component_to_that_instance():
    text = scene_text(INSTANCED).replace('root_bones: [hair_2_0, hair_0_0]', 'root_bones: ["hair_*_0#1"]')
    s = load_scene_text(text)
    hair = s.cloth("hair")
    assert hair.instance is None
    assert [s.hierarchy.names[i] for i in hair.root_bones] == ["hair_0_0#1", "hair_1_0#1", "hair_2_0#1"]
    assert s.hierarchy.names[hair.component] == "head#1"


def test_instance_globs_follow_hierarchy_order():
    text = scene_text(INSTANCED).replace('root_bones: ["skirt_*_0"]', 'root_bones: ["skirt_*_0#2"]')
    s = load_scene_text(text)
    skirt = s.cloth("skirt")
    assert [s.hierarchy.names[i] for i in skirt.root_bones] == [f"skirt_{k}_0#2" for k in range(12)]
    # bone_attributes {"skirt_0_*": fixed} reach the whole strand of that instance
    assert sorted(s.hierarchy.names[i] for i in skirt.bone_attributes) == ["skirt_0_0#2", "skirt_0_1#2", "skirt_0_2#2"]
