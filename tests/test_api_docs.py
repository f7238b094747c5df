"""The example blocks of docs/api.md run as they are (from the repository root)."""
import pathlib
import re

import pytest

DOC = pathlib.Path(__file__).resolve().parents[1] / "docs" / "api.md"
BLOCKS = re.findall(r"```python\n(.*?)```", DOC.read_text(encoding="utf-8"), flags=re.S)


def test_the_page_has_examples():
    assert len(BLOCKS) >= 3


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_api_doc_example_runs(index, repo_root, monkeypatch, capsys):
    monkeypatch.chdir(repo_root)
    exec(compile(BLOCKS[index], f"docs/api.md block {index}", "exec"), {"__name__": "__api_doc__"})
    assert capsys.readouterr().out.strip()  # every example prints what it shows
