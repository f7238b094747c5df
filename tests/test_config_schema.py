"""docs/scene-format.md stays true: its full example loads, and every key the schema accepts
is documented."""
import pathlib
import re

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
    assert sorted({e.kind for e in scene.animation.events}) == ["set_parameter", "teleport", "time_scale"]
    assert set(scene.animation.kind.tolist()) == {0, 1, 2, 3, 4}  # all five driver kinds


def all_schema_keys():
    keys = set(schema.TOP_LEVEL_KEYS) | set(schema.SETTINGS_KEYS) | set(schema.CLOTH_KEYS)
    keys |= set(schema.INSTANCE_FIELDS) | set(schema.DRIVER_COMMON) | set(schema.OUTPUT_LOG_FIELDS)
    for table in (schema.PART_FIELDS, schema.DRIVER_FIELDS, schema.SHAPE_FIELDS, schema.EVENT_FIELDS):
        keys |= set(table)
        for fields in table.values():
            keys |= set(fields)
    keys |= set(schema.EVENT_KINDS)
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
