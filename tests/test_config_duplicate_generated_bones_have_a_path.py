"""A duplicate bone name made by a generator part (or by an instanced rig's copy) is reported at
the document path that made it, not as a path-less error on line 1."""
import pytest

from magica_py.config import ConfigError, load_scene_text

SCENE = """
scene: {fps: 60, frames: 2}
rigs:
  - name: r
    bones: [{name: root}, {name: hips, parent: root}]
    parts:
      - chain: {name: tail, parent: hips, bones: 3, length: 0.3}
      - chain: {name: tail, parent: hips, bones: 3, length: 0.3}
"""


def test_a_second_part_with_the_same_name_is_named_by_its_path_and_line():
    with pytest.raises(ConfigError) as err:
        load_scene_text(SCENE, source="s.yaml")
    issues = err.value.issues
    assert [i.path for i in issues] == ["rigs[0].parts[1].chain.name"] * 3
    assert [i.line for i in issues] == [8] * 3
    assert "duplicate transform name 'tail_0'" in issues[0].message


def test_a_part_whose_bones_collide_with_an_explicit_bone_names_a_path():
    text = SCENE.replace("      - chain: {name: tail, parent: hips, bones: 3, length: 0.3}\n", "", 1).replace(
        "{name: hips, parent: root}", "{name: hips, parent: root}, {name: tail_1, parent: root}")
    with pytest.raises(ConfigError) as err:
        load_scene_text(text, source="s.yaml")
    (issue,) = err.value.issues
    assert issue.path in ("rigs[0].bones[2].name", "rigs[0].parts[0].chain.name") and issue.line is not None


def test_a_duplicate_bone_of_an_instanced_rig_is_named_by_its_bone_path():
    text = SCENE.replace("      - chain: {name: tail, parent: hips, bones: 3, length: 0.3}\n", "", 1).replace(
        "{name: hips, parent: root}]", "{name: hips, parent: root}, {name: root}]\n    instances: {count: 2}")
    with pytest.raises(ConfigError) as err:
        load_scene_text(text, source="s.yaml")
    assert {i.path for i in err.value.issues} == {"rigs[0].bones[2].name"}


def test_a_copy_pasted_chain_under_a_cloth_fails_fast_not_in_exponential_time():
    # the two chains' bones have the same names, so every tail_i had two children named
    # tail_{i+1}: the cloth's subtree walk went through 2^40 paths (hours, gigabytes)
    import time

    text = SCENE.replace("bones: 3", "bones: 40") + "cloths:\n  - {name: tail, root_bones: [tail_0]}\n"
    start = time.perf_counter()
    with pytest.raises(ConfigError) as err:
        load_scene_text(text, source="s.yaml")
    assert time.perf_counter() - start < 20.0
    assert {i.path for i in err.value.issues} == {"rigs[0].parts[1].chain.name"}
    assert len(err.value.issues) == 40
