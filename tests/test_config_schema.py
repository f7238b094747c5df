"""docs/scene-format.md stays true: its full example loads, and every key the schema accepts
is documented."""
import pathlib
import re

import numpy as np
import pytest

from magica_py.config import load_scene_text
from magica_py.config import schema

DOC = pathlib.Path(__file__).resolve().parents[1] / "docs" / "scene-format.md"


def doc_text() -> str:
    return DOC.read_text(encoding="utf-8")


def example_yaml() -> str:
    blocks = re.findall(r"```yaml\n(.*?)```", doc_text(), flags=re.S)
    return blocks[0]


def test_documented_full_example_loads_and_uses_every_section():
    scene = load_scene_text(example_yaml(), source="docs/scene-format.md")
    assert scene.name == "example"
    assert {"tail_0", "hair_5_4", "skirt_11_3", "head"} <= set(scene.hierarchy.names)
    assert [c.name for c in scene.cloths] == ["tail", "hair", "skirt", "cape"]
    assert [scene.hierarchy.names[i] for i in scene.cloth("cape").root_bones] == [f"cape_{s}_0" for s in range(5)]
    assert scene.cloth("tail").parameters["angle_limit.use"] is True
    assert len(scene.colliders) == 4
    assert sorted({e.kind for e in scene.animation.events}) == ["set_parameter", "teleport", "time_scale", "wind"]
    assert [(z.name, z.mode) for z in scene.wind] == [("breeze", "global"), ("fan", "sphere")]
    assert set(scene.animation.kind.tolist()) == {0, 1, 2, 3, 4}  # all five driver kinds


def all_schema_keys():
    keys = set(schema.TOP_LEVEL_KEYS) | set(schema.SETTINGS_KEYS) | set(schema.CLOTH_KEYS)
    keys |= set(schema.INSTANCE_FIELDS) | set(schema.DRIVER_COMMON) | set(schema.OUTPUT_LOG_FIELDS)
    for table in (schema.PART_FIELDS, schema.DRIVER_FIELDS, schema.SHAPE_FIELDS, schema.EVENT_FIELDS):
        keys |= set(table)
        for fields in table.values():
            keys |= set(fields)
    keys |= set(schema.EVENT_KINDS)
    keys |= set(schema.WIND_ZONE_KEYS) | set(schema.WIND_MODES) | set(schema.WIND_MODE_ALIASES)
    keys |= set(schema.CONNECTION_MODES) | set(schema.COLLISION_MODES) | set(schema.BONE_ATTRIBUTES)
    keys |= set(schema.UPDATE_MODES) | set(schema.TIMING_MODES)
    from magica_py.config import imports

    keys |= set(imports.RIG_FILE_KEYS) | set(imports.CLIP_KEYS) | set(imports.VRM_KEYS)
    return sorted(keys)


@pytest.mark.parametrize("key", all_schema_keys())
def test_every_schema_key_is_documented(key):
    assert f"`{key}`" in doc_text() or re.search(rf"\b{re.escape(key)}:", doc_text()), \
        f"{key!r} is accepted by the schema but not documented in docs/scene-format.md"


def test_every_preset_is_documented():
    from magica_py.params import PRESETS

    for name in PRESETS:
        assert f"`{name}`" in doc_text()


def test_part_fields_match_the_rig_generators():
    """The YAML keys of every generator are exactly its keyword arguments, with the same defaults."""
    import inspect

    from magica_py.scene import rigs

    assert set(schema.PART_FIELDS) == set(rigs.GENERATORS)
    for kind, fields in schema.PART_FIELDS.items():
        params = inspect.signature(rigs.GENERATORS[kind]).parameters
        assert set(fields) == set(params), kind
        for key, field in fields.items():
            default = params[key].default
            if default is inspect.Parameter.empty:
                assert field.default is schema.REQUIRED or key == "parent", (kind, key)
            elif field.default is not schema.REQUIRED and field.default is not None and default is not None:
                assert tuple(field.default) == tuple(default) if isinstance(default, tuple) \
                    else field.default == default, (kind, key, field.default, default)


def test_output_log_toggles_match_the_sinks():
    import dataclasses

    from magica_py.sinks.base import LogToggles

    fields = {f.name: f.default for f in dataclasses.fields(LogToggles)}
    assert {k: f.default for k, f in schema.OUTPUT_LOG_FIELDS.items()} == fields


# -- the schema accepts exactly what scene.animation implements ---------------------------
def test_keyframe_interpolations_are_the_animation_modules():
    from magica_py.scene.animation import INTERPOLATIONS

    assert schema.DRIVER_FIELDS["keyframes"]["interpolation"].choices == tuple(INTERPOLATIONS)
    for name in INTERPOLATIONS:
        assert f"`{name}`" in doc_text(), f"interpolation {name!r} is not documented"


def _scene(animation: str, bones: str = "[{name: root}, {name: a, parent: root}]"):
    return load_scene_text(f"scene: {{fps: 10, frames: 2}}\nrigs:\n  - {{name: r, bones: {bones}}}\n"
                           f"animation:\n{animation}")


def _world(scene, t, name="a"):
    h = scene.hierarchy
    scene.animation.evaluate(h, t)
    h.propagate()
    return h.world_position[h.index(name)].copy(), h.world_rotation[h.index(name)].copy()


def test_cubic_keyframes_pass_smoothly_through_the_keys():
    scene = _scene("  - {target: a, keyframes: {interpolation: cubic, keys: [{time: 0, position: [0, 0, 0]}, "
                   "{time: 1, position: [1, 0, 0]}, {time: 2, position: [1, 1, 0]}]}}\n")
    assert _world(scene, 1.0)[0] == pytest.approx([1, 0, 0])
    # Catmull-Rom tangent at key 1: (p2 - p0) / 2 s = (0.5, 0.5, 0); one-sided at the last
    # key: (p2 - p1) / 1 s = (0, 1, 0). Halfway, the Hermite weights are h00 = h01 = 1/2,
    # h10 = 1/8, h11 = -1/8: 0.5 p1 + 0.125 m1 + 0.5 p2 - 0.125 m2 = (1.0625, 0.4375, 0)
    p, _ = _world(scene, 1.5)
    assert p == pytest.approx([1.0625, 0.4375, 0.0])


def test_walk_lateral_twist_and_up_reach_the_driver():
    scene = _scene("  - {target: a, walk: {stride_frequency: 1.0, bob: 0, sway: 0, lateral: 0.1, twist: 30,"
                   " direction: [0, 0, 1], up: [0, 1, 0]}}\n")
    p, q = _world(scene, 0.25)                     # a quarter stride: sin = 1
    assert p == pytest.approx([0.1, 0.0, 0.0])     # along up x direction = (0,1,0) x (0,0,1) = +X
    angle = 2 * np.degrees(np.arctan2(np.linalg.norm(q[:3]), q[3]))
    assert angle == pytest.approx(30.0) and q[1] == pytest.approx(np.sin(np.radians(15)))  # yaw about +Y


def test_walk_stride_frequency_counts_gait_cycles():
    """stride_frequency 1: the bob (once per step) repeats twice a second."""
    scene = _scene("  - {target: a, walk: {stride_frequency: 1.0, bob: 0.1, sway: 0}}\n")
    assert _world(scene, 0.125)[0][1] == pytest.approx(0.1)   # sin(2 * 2 pi * 0.125) = 1
    assert _world(scene, 0.625)[0][1] == pytest.approx(0.1)   # one step later: the next peak


def test_orbit_turns_clockwise_seen_from_the_axis_tip():
    """Unity is left-handed: a positive turn about +Y takes +X to -Z (clockwise from above)."""
    scene = _scene("  - {target: a, orbit: {radius: 1, period: 4}}\n")
    assert _world(scene, 1.0)[0] == pytest.approx([0.0, 0.0, -1.0])
    backwards = _scene("  - {target: a, orbit: {radius: 1, period: -4}}\n")
    assert _world(backwards, 1.0)[0] == pytest.approx([0.0, 0.0, 1.0])


def test_orbit_period_zero_is_an_error():
    from magica_py.config import ConfigError

    with pytest.raises(ConfigError) as info:
        _scene("  - {target: a, orbit: {radius: 1, period: 0}}\n")
    assert info.value.paths() == ["animation[0].orbit.period"]


def test_spin_and_rotation_oscillation_turn_about_the_nodes_own_axes():
    """A node turned 90 degrees about Z spinning about its own +Y turns about world -X."""
    bones = "[{name: root}, {name: a, parent: root, euler: [0, 0, 90]}, {name: tip, parent: a, position: [0, 0, 1]}]"
    for driver in ("spin: {axis: [0, 1, 0], speed: 90}",
                   "oscillate: {property: rotation, axis: [0, 1, 0], amplitude: 90, frequency: 0.25}"):
        scene = _scene(f"  - {{target: a, {driver}}}\n", bones)
        tip, _ = _world(scene, 1.0, "tip")            # 90 degrees about the node's +Y = world -X
        assert tip == pytest.approx([0.0, 1.0, 0.0], abs=1e-9), driver
