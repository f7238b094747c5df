"""magica-py new: every template is a valid scene that runs as it is."""
import pytest
import yaml

from magica_py import cli
from magica_py.starter import TEMPLATES, main_new, starter_text


@pytest.mark.parametrize("template", sorted(TEMPLATES))
def test_every_template_runs_as_written(template, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main_new([f"my_{template}", "--template", template]) == 0
    assert "magica-py watch my_" in capsys.readouterr().out
    text = (tmp_path / f"my_{template}.yaml").read_text()
    assert text.count("\n#") + text.startswith("#") >= 5          # commented for a newcomer
    assert "{name}" not in text and "{file}" not in text
    assert yaml.safe_load(text)["output"]["rrd"] == f"replays/my_{template}.rrd"
    assert cli.main(["run", f"my_{template}.yaml", "--frames", "3"]) == 0
    out = capsys.readouterr()
    assert f"my_{template}: 3 frames" in out.out and (tmp_path / "replays" / f"my_{template}.rrd").is_file()


def test_new_never_overwrites_without_force(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "mine.yaml").write_text("precious: true\n")
    assert main_new(["mine"]) == 2
    assert "already exists" in capsys.readouterr().err
    assert (tmp_path / "mine.yaml").read_text() == "precious: true\n"
    assert main_new(["mine.yaml", "--force", "-t", "tail"]) == 0
    assert "name: mine" in (tmp_path / "mine.yaml").read_text()


def test_new_rejects_names_that_cannot_name_a_recording(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main_new(["bad name"]) == 2
    assert "a scene name is" in capsys.readouterr().err
    assert main_new(["x", "--template", "cape"]) == 2    # argparse: unknown template


def test_templates_fill_in_the_name_and_file():
    text = starter_text("ponytail", "hero", "scenes/hero.yaml")
    assert "magica-py run scenes/hero.yaml" in text and "name: hero" in text and "replays/hero.rrd" in text
