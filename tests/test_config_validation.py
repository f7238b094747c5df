"""Every bad-input category of scene format v1 gives the expected document path and message.

Each case starts from ``BASE`` (a small valid scene), breaks one thing, and checks that the
ConfigError names the file, the exact document path and says what was expected.
"""
import copy

import pytest
import yaml

from magica_py.config import ConfigError
from magica_py.config.load import validate_file

BASE = {
    "version": 1,
    "scene": {"name": "base", "fps": 60, "frames": 10},
    "rigs": [{
        "name": "creature",
        "bones": [
            {"name": "root", "position": [0, 1, 0]},
            {"name": "hips", "parent": "root", "position": [0, 0, 0]},
            {"name": "head", "parent": "hips", "position": [0, 0.5, 0]},
        ],
        "parts": [{"chain": {"name": "tail", "parent": "hips", "bones": 4, "length": 0.6,
                             "direction": [0, 0, -1]}}],
    }],
    "animation": [
        {"target": "root", "spin": {"axis": [0, 1, 0], "speed": 90}},
        {"at": 0.5, "set_parameter": {"cloth": "tail", "key": "damping", "value": 0.2}},
    ],
    "colliders": [
        {"name": "head_col", "transform": "head", "sphere": {"radius": 0.1}},
        {"name": "body", "transform": "hips", "capsule": {"radius": 0.05, "length": 0.3}},
    ],
    "cloths": [{"name": "tail", "root_bones": ["tail_0"], "preset": "tail",
                "parameters": {"damping": 0.1}, "colliders": ["head_col"]}],
    "output": {"rrd": None},
}


def write(tmp_path, doc, name="scene.yaml"):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def errors_of(tmp_path, doc, overrides=()):
    path = write(tmp_path, doc)
    with pytest.raises(ConfigError) as info:
        validate_file(path, overrides)
    assert info.value.source == str(path)
    return info.value


def test_base_scene_is_valid(tmp_path):
    resolved = validate_file(write(tmp_path, BASE))
    assert [b.name for b in resolved.bones] == ["root", "hips", "head", "tail_0", "tail_1", "tail_2", "tail_3"]
    assert resolved.cloths[0]["root_bones"] == ["tail_0"]


def _set(path, value):
    def mutate(doc):
        node = doc
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value
    return mutate


def _delete(path):
    def mutate(doc):
        node = doc
        for key in path[:-1]:
            node = node[key]
        del node[path[-1]]
    return mutate


def _append(path, value):
    def mutate(doc):
        node = doc
        for key in path:
            node = node[key]
        node.append(value)
    return mutate


# (case id, mutation, expected path, fragments the message must contain)
CASES = [
    # unknown keys, with a did-you-mean
    ("unknown top-level key", _set(("colider",), []), "colider", ["unknown key 'colider'", "did you mean 'colliders'"]),
    ("unknown scene key", _set(("scene", "fsp"), 30), "scene.fsp", ["unknown key", "did you mean 'fps'"]),
    ("unknown bone key", _set(("rigs", 0, "bones", 0, "postion"), [0, 0, 0]), "rigs[0].bones[0].postion",
     ["did you mean 'position'"]),
    ("unknown chain key", _set(("rigs", 0, "parts", 0, "chain", "lenght"), 1), "rigs[0].parts[0].chain.lenght",
     ["did you mean 'length'"]),
    ("unknown parameter", _set(("cloths", 0, "parameters", "dampin"), 0.1), "cloths[0].parameters.dampin",
     ["unknown parameter", "did you mean 'damping'"]),
    ("unknown nested parameter", _set(("cloths", 0, "parameters", "inertia"), {"world_inertai": 0.5}),
     "cloths[0].parameters.inertia.world_inertai", ["did you mean 'inertia.world_inertia'"]),
    # wrong types
    ("text for a number", _set(("scene", "fps"), "fast"), "scene.fps", ["expected a number", "'fast'"]),
    ("bool for an integer", _set(("scene", "frames"), True), "scene.frames", ["expected an integer"]),
    ("float for an integer", _set(("rigs", 0, "parts", 0, "chain", "bones"), 2.5), "rigs[0].parts[0].chain.bones",
     ["expected an integer"]),
    ("short vector", _set(("rigs", 0, "bones", 0, "position"), [0, 1]), "rigs[0].bones[0].position",
     ["[x, y, z]"]),
    ("mapping for a list", _set(("cloths",), {"name": "tail"}), "cloths", ["expected a list"]),
    ("number for a bool", _set(("colliders", 1, "capsule", "reverse"), 1), "colliders[1].capsule.reverse",
     ["expected true or false"]),
    ("unknown enum value", _set(("cloths", 0, "connection"), "lines"), "cloths[0].connection",
     ["did you mean 'line'", "sequential_loop_mesh"]),
    ("wrong parameter type", _set(("cloths", 0, "parameters", "damping"), "soft"), "cloths[0].parameters.damping",
     ["expected"]),
    ("parameters as an empty list", _set(("cloths", 0, "parameters"), []), "cloths[0].parameters",
     ["expected a mapping of parameter names to values, got []"]),
    # unknown names
    ("bone name with the instance separator", _set(("rigs", 0, "bones", 2, "name"), "head#2"),
     "rigs[0].bones[2].name", ["'head#2': a name cannot contain '#'"]),
    ("part name with the instance separator", _set(("rigs", 0, "parts", 0, "chain", "name"), "tail#1"),
     "rigs[0].parts[0].chain.name", ["a name cannot contain '#'"]),
    ("unknown parent", _set(("rigs", 0, "bones", 2, "parent"), "hip"), "rigs[0].bones[2].parent",
     ["unknown parent 'hip'", "did you mean 'hips'"]),
    ("unknown chain parent", _set(("rigs", 0, "parts", 0, "chain", "parent"), "hipz"), "rigs[0].parts[0].chain.parent",
     ["unknown parent 'hipz'"]),
    ("unknown collider transform", _set(("colliders", 0, "transform"), "haed"), "colliders[0].transform",
     ["unknown transform 'haed'", "did you mean 'head'"]),
    ("unknown animation target", _set(("animation", 0, "target"), "rot"), "animation[0].target",
     ["unknown transform 'rot'", "did you mean 'root'"]),
    ("unknown root bone", _set(("cloths", 0, "root_bones"), ["tial_0"]), "cloths[0].root_bones[0]",
     ["no bone matches 'tial_0'", "did you mean 'tail_0'"]),
    ("glob matching nothing", _set(("cloths", 0, "root_bones"), ["skirt_*_0"]), "cloths[0].root_bones[0]",
     ["no bone matches 'skirt_*_0'"]),
    ("unknown component", _set(("cloths", 0, "component"), "hipss"), "cloths[0].component",
     ["unknown transform 'hipss'"]),
    ("unknown cloth collider", _set(("cloths", 0, "colliders"), ["head_coll"]), "cloths[0].colliders[0]",
     ["unknown collider 'head_coll'", "did you mean 'head_col'"]),
    ("unknown event cloth", _set(("animation", 1, "set_parameter", "cloth"), "tale"), "animation[1].set_parameter.cloth",
     ["unknown cloth 'tale'", "did you mean 'tail'"]),
    ("unknown event parameter", _set(("animation", 1, "set_parameter", "key"), "dumping"), "animation[1].set_parameter.key",
     ["unknown parameter 'dumping'", "did you mean 'damping'"]),
    ("unknown preset", _set(("cloths", 0, "preset"), "tial"), "cloths[0].preset",
     ["unknown preset 'tial'", "did you mean 'tail'"]),
    ("unknown bone attribute bone", _set(("cloths", 0, "bone_attributes"), {"tail_9": "invalid"}),
     "cloths[0].bone_attributes.tail_9", ["no bone of this cloth matches 'tail_9'"]),
    ("unknown bone attribute value", _set(("cloths", 0, "bone_attributes"), {"tail_3": "invalidd"}),
     "cloths[0].bone_attributes.tail_3", ["did you mean 'invalid'"]),
    ("unknown anchor transform", _set(("cloths", 0, "parameters", "inertia"), {"anchor": "nowhere"}),
     "cloths[0].parameters.inertia.anchor", ["unknown transform 'nowhere'"]),
    # structure of names
    ("parent cycle", lambda d: d["rigs"][0]["bones"].extend([{"name": "a", "parent": "b"}, {"name": "b", "parent": "a"}]),
     "rigs[0].bones[3].parent", ["cycle", "a -> b -> a"]),
    ("duplicate bone", _append(("rigs", 0, "bones"), {"name": "head", "parent": "root"}), "rigs[0].bones[3].name",
     ["duplicate transform name 'head'"]),
    ("duplicate generated bone", _append(("rigs", 0, "bones"), {"name": "tail_2", "parent": "root"}),
     "rigs[0].bones[3].name", ["duplicate transform name 'tail_2'"]),
    ("duplicate cloth", _append(("cloths",), {"name": "tail", "root_bones": ["head"]}), "cloths[1].name",
     ["duplicate cloth name 'tail'"]),
    ("duplicate collider", _append(("colliders",), {"name": "body", "transform": "root", "plane": {}}),
     "colliders[2].name", ["duplicate collider name 'body'"]),
    ("bone in two cloths", _append(("cloths",), {"name": "tail2", "root_bones": ["tail_1"]}), "cloths[1].root_bones",
     ["already simulated by cloth 'tail'"]),
    # bad geometry
    ("zero-length quaternion", _set(("rigs", 0, "bones", 1, "rotation"), [0, 0, 0, 0]), "rigs[0].bones[1].rotation",
     ["zero-length quaternion"]),
    ("negative sphere radius", _set(("colliders", 0, "sphere", "radius"), -0.1), "colliders[0].sphere.radius",
     ["expected a number >= 0.001", "-0.1"]),
    ("negative capsule length", _set(("colliders", 1, "capsule", "length"), -0.3), "colliders[1].capsule.length",
     ["expected a number >= 0"]),
    ("negative chain length", _set(("rigs", 0, "parts", 0, "chain", "length"), -1.0), "rigs[0].parts[0].chain.length",
     ["expected a number > 0"]),
    ("zero direction", _set(("rigs", 0, "parts", 0, "chain", "direction"), [0, 0, 0]),
     "rigs[0].parts[0].chain.direction", ["non-zero"]),
    ("zero gravity direction", _set(("scene", "gravity"), [0, 0, 0]), "scene.gravity", ["non-zero"]),
    ("zero scale", _set(("rigs", 0, "bones", 2, "scale"), [1, 0, 1]), "rigs[0].bones[2].scale", ["non-zero scale"]),
    # non-finite numbers
    ("nan position", _set(("rigs", 0, "bones", 0, "position"), [0, float("nan"), 0]), "rigs[0].bones[0].position[1]",
     ["finite"]),
    ("inf fps", _set(("scene", "fps"), float("inf")), "scene.fps", ["finite"]),
    ("nan parameter", _set(("cloths", 0, "parameters", "damping"), float("nan")), "cloths[0].parameters.damping",
     ["finite"]),
    # out of range
    ("frequency out of range", _set(("scene", "simulation_frequency"), 200), "scene.simulation_frequency",
     ["[30, 150]", "200"]),
    ("steps out of range", _set(("scene", "max_steps_per_frame"), 0), "scene.max_steps_per_frame", ["[1, 5]"]),
    ("negative time scale", _set(("scene", "time_scale"), -1), "scene.time_scale", ["[0, 100]"]),
    ("parameter out of range", _set(("cloths", 0, "parameters", "damping"), 1.5), "cloths[0].parameters.damping",
     ["out of range [0, 1]"]),
    ("event value out of range", _set(("animation", 1, "set_parameter", "value"), 3.0),
     "animation[1].set_parameter.value", ["out of range"]),
    ("maximum below fixed delta", _set(("scene", "maximum_delta_time"), 0.01), "scene.maximum_delta_time",
     [">= fixed_delta_time"]),
    ("end before start", _set(("animation", 0, "end"), 0.0), "animation[0].end", ["expected end > start"]),
    ("unsupported version", _set(("version",), 2), "version", ["version 1"]),
    # exactly one of
    ("fps and frame_times", _set(("scene", "frame_times"), [0.016, 0.033]), "scene.frame_times",
     ["only one of fps, frame_times, clock"]),
    ("fps and clock", _set(("scene", "clock"), "realtime"), "scene.clock", ["only one of fps, frame_times, clock"]),
    ("frames and duration", _set(("scene", "duration"), 2.0), "scene.duration", ["only one of frames, duration"]),
    ("rotation and euler", lambda d: d["rigs"][0]["bones"][1].update(rotation=[0, 0, 0, 1], euler=[0, 90, 0]),
     "rigs[0].bones[1].euler", ["only one of rotation, euler"]),
    ("two collider shapes", _set(("colliders", 0, "plane"), {}), "colliders[0].plane",
     ["only one of sphere, capsule, plane"]),
    ("no collider shape", _delete(("colliders", 0, "sphere")), "colliders[0]", ["expected one of sphere, capsule, plane"]),
    ("two motions in one entry", _set(("animation", 0, "orbit"), {"radius": 1, "period": 2}), "animation[0].spin",
     ["only one of keyframes, orbit"]),
    ("two generators in one part", _set(("rigs", 0, "parts", 0, "fan"), {"name": "h"}), "rigs[0].parts[0].fan",
     ["only one of chain, fan, skirt"]),
    # missing values and misplaced keys
    ("missing cloth roots", _delete(("cloths", 0, "root_bones")), "cloths[0].root_bones", ["at least 1"]),
    ("missing sphere radius", _set(("colliders", 0, "sphere"), {}), "colliders[0].sphere", ["missing 'radius'"]),
    ("event without at", _delete(("animation", 1, "at")), "animation[1]", ["missing 'at'"]),
    ("driver with at", _set(("animation", 0, "at"), 1.0), "animation[0].at", ["belongs to events"]),
    ("collider with transform and position", _set(("colliders", 0, "position"), [0, 0, 0]), "colliders[0].position",
     ["center"]),
    ("keys not increasing", _set(("animation", 0), {"target": "root", "keyframes": {"keys": [
        {"time": 1.0, "position": [0, 0, 0]}, {"time": 0.5, "position": [0, 0, 1]}]}}),
     "animation[0].keyframes.keys[1].time", ["must increase"]),
    ("empty key", _set(("animation", 0), {"target": "root", "keyframes": {"keys": [
        {"time": 0.0, "position": [0, 0, 0]}, {"time": 1.0}]}}),
     "animation[0].keyframes.keys[1]", ["at least one of position, rotation"]),
    ("collision mode contradiction", lambda d: d["cloths"][0].update(
        collision_mode="edge", parameters={"collider_collision": {"mode": "point"}}),
     "cloths[0].collision_mode", ["contradicts"]),
    ("output not rrd", _set(("output", "rrd"), "replays/out.mp4"), "output.rrd", [".rrd"]),
    ("unknown log toggle", _set(("output", "log"), {"skeleton": True, "partciles": False}), "output.log.partciles",
     ["did you mean 'particles'"]),
]


@pytest.mark.parametrize("mutate, path, fragments", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_input_names_path_and_expectation(tmp_path, mutate, path, fragments):
    doc = copy.deepcopy(BASE)
    mutate(doc)
    error = errors_of(tmp_path, doc)
    matching = [i for i in error.issues if i.path == path]
    assert matching, f"no issue at {path!r}; got:\n{error.report()}"
    message = matching[0].message
    for fragment in fragments:
        assert fragment in message, f"{fragment!r} not in {message!r}"
    assert str(tmp_path / "scene.yaml") in error.report()


def test_all_errors_of_a_file_are_reported_together(tmp_path):
    doc = copy.deepcopy(BASE)
    doc["scene"]["fps"] = -1
    doc["colliders"][0]["sphere"]["radius"] = -1
    doc["cloths"][0]["parameters"]["damping"] = 7
    doc["animation"][0]["target"] = "nobody"
    doc["rigs"][0]["bones"][2]["parent"] = "nobody"
    error = errors_of(tmp_path, doc)
    assert set(error.paths()) >= {"scene.fps", "colliders[0].sphere.radius", "cloths[0].parameters.damping",
                                  "animation[0].target", "rigs[0].bones[2].parent"}
    assert error.report().splitlines()[0].endswith(f"{len(error.issues)} errors")


def test_errors_carry_yaml_line_numbers(tmp_path):
    text = "\n".join([
        "version: 1",                                              # 1
        "scene: {fps: 60, frames: 5}",                             # 2
        "rigs:",                                                   # 3
        "  - name: r",                                             # 4
        "    bones:",                                              # 5
        "      - {name: root}",                                    # 6
        "      - name: tip",                                       # 7
        "        parent: roto",                                    # 8
        "colliders:",                                              # 9
        "  - name: c",                                             # 10
        "    transform: root",                                     # 11
        "    sphere:",                                             # 12
        "      radius: -2",                                        # 13
    ])
    path = tmp_path / "lines.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        validate_file(path)
    lines = {i.path: i.line for i in info.value.issues}
    assert lines == {"rigs[0].bones[1].parent": 8, "colliders[0].sphere.radius": 13}
    assert f"{path}:13: colliders[0].sphere.radius: expected a number >= 0.001, got -2" in info.value.report()


def test_duplicate_yaml_key_is_an_error(tmp_path):
    path = tmp_path / "dup.yaml"
    path.write_text("version: 1\nscene: {fps: 60}\nscene: {fps: 30}\nrigs: [{name: r, bones: [{name: a}]}]\n")
    with pytest.raises(ConfigError) as info:
        validate_file(path)
    assert info.value.issues[0].path == "scene"
    assert info.value.issues[0].line == 3
    assert "duplicate key" in info.value.issues[0].message


def test_yaml_syntax_error_reports_the_line(tmp_path):
    path = tmp_path / "syntax.yaml"
    path.write_text("version: 1\nscene:\n  fps: [60\nrigs: []\n")
    with pytest.raises(ConfigError) as info:
        validate_file(path)
    assert "invalid YAML" in info.value.issues[0].message
    assert info.value.issues[0].line is not None


def test_missing_file_is_a_config_error(tmp_path):
    with pytest.raises(ConfigError) as info:
        validate_file(tmp_path / "nope.yaml")
    assert "file not found" in str(info.value)


def test_empty_document_says_the_file_is_empty(tmp_path):
    path = tmp_path / "empty.yaml"
    path.write_text("")
    with pytest.raises(ConfigError) as info:
        validate_file(path)
    assert info.value.paths() == [""] and "the file is empty" in str(info.value)


# ----------------------------------------------------------------------------- robustness
def _paths(node, prefix=()):
    yield prefix
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, prefix + (i,))


ALL_PATHS = [p for p in _paths(BASE) if p]


def test_any_replaced_value_gives_a_config_error_never_a_crash():
    from hypothesis import given, settings, strategies as st

    from magica_py.config.document import Document
    from magica_py.config.load import validate_document

    scalars = st.one_of(st.none(), st.booleans(), st.integers(-5, 5), st.floats(allow_nan=True, allow_infinity=True),
                        st.text(max_size=6), st.sampled_from(["root", "hips", "tail_*", "x#1", "sphere"]))
    values = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                           st.dictionaries(st.text(max_size=5), inner, max_size=3)),
                          max_leaves=6)

    @settings(max_examples=150, deadline=None, derandomize=True)
    @given(st.sampled_from(ALL_PATHS), values)
    def check(path, value):
        doc = copy.deepcopy(BASE)
        node = doc
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value
        try:
            validate_document(Document(doc, "fuzz.yaml"))
        except ConfigError as exc:
            assert exc.issues and all(i.message for i in exc.issues)

    check()
