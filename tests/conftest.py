"""Shared test setup.

* Rerun strict mode: a bad logging argument raises instead of warning (docs/tech-notes.md §1).
* ``shared_data``: the third-party test data in ../shared/data (see its NOTICE.md).
"""
import os
import pathlib

import pytest

os.environ.setdefault("RERUN_STRICT", "1")

REPO_ROOT = pathlib.Path(__file__).resolve().parents[1]
SHARED_DATA = REPO_ROOT.parent / "shared" / "data"


@pytest.fixture(scope="session")
def repo_root() -> pathlib.Path:
    return REPO_ROOT


@pytest.fixture(scope="session")
def shared_data() -> pathlib.Path:
    if not SHARED_DATA.is_dir():
        pytest.skip(f"third-party test data not found at {SHARED_DATA} (CI checks it out beside the repo)")
    return SHARED_DATA
