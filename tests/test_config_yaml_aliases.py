"""Anchors, aliases, merge keys and explicit tags: odd YAML is read as YAML means it, and
YAML that cannot be a scene is a ConfigError naming the file, the line and the document path
(never a RecursionError, a hang, or PyYAML's bare ValueError)."""
import time

import pytest

from magica_py import cli
from magica_py.config import ConfigError, load_scene_text
from magica_py.config.document import parse_text

SCENE = """
version: 1
scene: {fps: 60, frames: 3}
rigs:
  - name: r
    bones: [{name: root}, {name: a, parent: root}, {name: b, parent: root}]
    parts: [{chain: {name: tail, parent: a, bones: 3, length: 0.3}}]
animation:
  - {target: a, orbit: &orb {<<: {radius: 0.5, period: 2.0}, period: 3.0}}
  - {target: b, orbit: *orb}
cloths:
  - {name: tail, root_bones: [tail_0]}
"""


def test_a_mapping_with_a_merge_key_reused_through_an_alias_keeps_its_own_keys():
    # PyYAML's flatten_mapping rewrote the anchored node in place, so its second use (*orb) saw
    # the merged 'period' and its own 'period' as two written keys: a false "duplicate key"
    scene = load_scene_text(SCENE)
    assert scene.animation is not None
    doc = parse_text(SCENE, "s.yaml")
    assert doc.data["animation"][0]["orbit"] == {"radius": 0.5, "period": 3.0}
    assert doc.data["animation"][1]["orbit"] == {"radius": 0.5, "period": 3.0}


def test_a_merge_of_several_mappings_the_first_listed_wins_and_own_keys_win_over_all():
    doc = parse_text("a: &a {x: 1, y: 1}\nb: &b {x: 2, z: 2}\nc: {<<: [*a, *b], z: 3}\n", "s.yaml")
    assert doc.data["c"] == {"x": 1, "y": 1, "z": 3}


def test_a_written_key_twice_is_still_a_duplicate_next_to_a_merge():
    with pytest.raises(ConfigError, match=r"s.yaml:1: c.x: duplicate key"):
        parse_text("c: {<<: {y: 1}, x: 1, x: 2}\n", "s.yaml")


@pytest.mark.parametrize("text, path, expected", [
    ("scene: {<<: 5, fps: 60}\n", "scene.<<", "a merge key (<<) takes a mapping or a list of mappings"),
    ("scene: {<<: [1, 2], fps: 60}\n", "scene.<<", "a merge key (<<) takes a mapping or a list of mappings"),
    ("scene: &s {fps: 60, <<: *s}\n", "scene", "merges a mapping into itself"),
    ("scene: &s {fps: 60, self: *s}\n", "scene.self", "refers to a mapping or list that contains it"),
    ("rigs: &l [1, *l]\n", "rigs[1]", "refers to a mapping or list that contains it"),
])
def test_bad_merges_and_recursive_aliases_are_config_errors_with_their_path(text, path, expected):
    with pytest.raises(ConfigError) as err:
        parse_text(text, "s.yaml")
    (issue,) = err.value.issues
    assert issue.path == path and expected in issue.message and issue.line == 1
    assert "s.yaml:1: " + path in str(err.value)


def test_aliases_that_multiply_are_refused_fast_not_expanded():
    text = 'a: &a ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]\n'
    prev = "a"
    for name in "bcdefghij":   # 9**10 values from a 1 kB file
        text += f"{name}: &{name} [" + ", ".join([f"*{prev}"] * 9) + "]\n"
        prev = name
    start = time.perf_counter()
    with pytest.raises(ConfigError, match=r"aliases \(\*name\) expand to more than 1,000,000 values"):
        parse_text(text, "laughs.yaml")
    assert time.perf_counter() - start < 30.0


def test_an_anchor_shared_by_many_entries_stays_within_the_budget():
    entries = "\n".join(f"  - {{<<: *d, name: c{i}}}" for i in range(2000))
    doc = parse_text("defaults: &d {a: 1, b: [1, 2, 3], c: {x: 1}}\nlist:\n" + entries + "\n", "s.yaml")
    assert len(doc.data["list"]) == 2000 and doc.data["list"][-1]["b"] == [1, 2, 3]


@pytest.mark.parametrize("text, path, expected", [
    ("scene: {fps: !!float abc}\n", "scene.fps", "cannot read 'abc' as float"),
    ("scene: {fps: !!int 1.5}\n", "scene.fps", "cannot read '1.5' as int"),
    ("scene: {fps: !!timestamp 2020-99-99}\n", "scene.fps", "cannot read '2020-99-99' as timestamp"),
])
def test_an_explicit_tag_that_does_not_fit_its_text_is_a_config_error(text, path, expected):
    with pytest.raises(ConfigError) as err:
        parse_text(text, "s.yaml")
    assert err.value.issues[0].path == path and expected in err.value.issues[0].message


@pytest.mark.parametrize("text", [
    "scene: &s {fps: 60, self: *s}\n",
    "scene: {<<: 5, fps: 60}\n",
    "scene: {fps: !!float abc}\n",
])
def test_cli_reports_odd_yaml_with_exit_2_and_no_traceback(text, tmp_path, capsys):
    path = tmp_path / "odd.yaml"
    path.write_text(text)
    for command in (["validate", str(path)], ["info", str(path)], ["run", str(path), "--no-rrd", "--frames", "2"]):
        assert cli.main(command) == 2
        err = capsys.readouterr().err
        assert "Traceback" not in err and f"{path}:1: scene" in err


def test_a_set_value_with_a_tag_that_does_not_fit_names_the_override(tmp_path, capsys):
    path = tmp_path / "s.yaml"
    path.write_text(SCENE)
    assert cli.main(["validate", str(path), "--set", "scene.fps=!!float abc"]) == 2
    err = capsys.readouterr().err
    assert "override 'scene.fps=!!float abc': the value cannot be read" in err and "Traceback" not in err
