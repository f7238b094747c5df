"""A cloth that cannot be built is reported like any other scene problem: the file, the cloth's
path in the document, exit 2, no traceback, by validate as well as by run; and values that
validate accepts do not crash later (instances.columns)."""
import pytest

from magica_py import cli
from magica_py.config import ConfigError, load_scene_text

SCENE = """
version: 1
scene: {name: bad_cloth, fps: 60, frames: 3}
rigs:
  - name: r
    bones: [{name: root, position: [0, 1, 0], scale: SCALE}]
    parts: [{chain: {name: tail, parent: root, bones: BONES, length: 0.3}}]
cloths:
  - {name: tail, root_bones: [tail_0]}
output: {rrd: OUT}
"""


def write(tmp_path, scale="[1, 1, 1]", bones=3):
    path = tmp_path / "scene.yaml"
    path.write_text(SCENE.replace("SCALE", scale).replace("BONES", str(bones))
                    .replace("OUT", str(tmp_path / "out" / "bad_cloth.rrd")))
    return path


@pytest.mark.parametrize("scale, bones, expected", [
    ("[-1, 1, 1]", 3, "cloth 'tail': transform 'tail_0' has a negative scale (-1.0, 1.0, 1.0) in the rest pose"),
    ("[1, 1, 1]", 1, "cloth 'tail': root bone 'tail_0' has no child bones"),
])
@pytest.mark.parametrize("command", ["validate", "info", "run"])
def test_a_cloth_that_cannot_be_built_names_the_file_and_document_path(scale, bones, expected, command,
                                                                        tmp_path, capsys):
    path = write(tmp_path, scale, bones)
    argv = [command, str(path)] + (["--frames", "2"] if command == "run" else [])
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "internal error" not in err
    assert f"{path}: cloths[0]: {expected}" in err
    assert not (tmp_path / "out").exists()   # run: nothing written, the folder it made removed


def test_validate_no_longer_passes_a_scene_that_run_refuses_for_its_negative_scale(tmp_path, capsys):
    path = write(tmp_path, "[-1, 1, 1]")
    assert cli.main(["validate", str(path)]) == 2
    assert "OK" not in capsys.readouterr().out


@pytest.mark.parametrize("columns", ["1e30", "9223372036854775808", "500001"])
def test_instance_columns_beyond_the_bone_limit_are_a_range_error_not_an_overflow(columns):
    text = SCENE.replace("SCALE", "[1, 1, 1]").replace("BONES", "3").replace("OUT", "null").replace(
        "    parts:", f"    instances: {{count: 2, columns: {columns}}}\n    parts:")
    with pytest.raises(ConfigError) as err:
        load_scene_text(text, source="s.yaml")
    (issue,) = err.value.issues
    assert issue.path == "rigs[0].instances.columns" and "expected an integer in [0, 500000]" in issue.message


def test_instance_columns_larger_than_the_count_still_work():
    text = SCENE.replace("SCALE", "[1, 1, 1]").replace("BONES", "3").replace("OUT", "null").replace(
        "    parts:", "    instances: {count: 2, columns: 1000}\n    parts:")
    scene = load_scene_text(text)
    assert len(scene.cloths) == 2
