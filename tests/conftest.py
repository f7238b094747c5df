"""Shared test setup.

* Rerun strict mode: a bad logging argument raises instead of warning (docs/tech-notes.md §1).
* ``MAGICA_STAGES=all`` (unless set otherwise): every system compiles its frame kernel with
  every optional stage, so the suite compiles the frame kernel once per form (serial,
  parallel) instead of once per combination of stages its scenes use (23 combinations, about
  a quarter of a cold suite's CPU time: docs/BENCHMARKS.md, session 19). An optional stage
  runs only where a block's parameters ask, so the bits are the same
  (tests/test_solver_perf_invariants.py pins it on the showcases and pins the scene's own
  selection, with ``MAGICA_STAGES=used``). Likewise the animation's drivers are compiled once
  with every driver kind (tests/test_animation.py pins the kinds a scene uses and the same
  bits). Subprocesses inherit it.
  ``MAGICA_STAGES=used python -m pytest ...`` runs the suite on each scene's own selection.
* ``OMP_WAIT_POLICY=PASSIVE`` (unless set otherwise): the test-only reference solver's parallel
  frame (tests/reference_solver) uses numba's ``prange``, whose OpenMP threads would otherwise
  spin between its regions and take the cores the rest of the suite needs. The package itself
  uses no ``prange`` (magica_py/threads.py).
* ``MAGICA_COMPILE_HELPER=0`` (unless set otherwise): no first-run compile helper is forked
  (solver/compile_helper.py). Its test (tests/test_compile_helper.py) turns it on where it
  needs it. Elsewhere, under pytest-xdist every CPU already runs a test process, so a helper
  would only take CPU from them; and at the start of a run the 1-minute load average still
  reads the idle machine, so each worker forked one for its first system.
* ``MAGICA_FIRST_RUN=compile`` (unless set otherwise): ``magica-py run`` never takes the
  interpreted first-run tier (magica_py/first_run.py), which would start a background compile
  beside the test processes whenever a test's cache has no compiled cloth frame yet.
  tests/test_first_run.py turns it on where it tests it.
* ``shared_data``: the third-party test data in ../shared/data (see its NOTICE.md).
"""
import os
import pathlib

import pytest

os.environ.setdefault("RERUN_STRICT", "1")
os.environ.setdefault("MAGICA_STAGES", "all")
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
os.environ.setdefault("MAGICA_COMPILE_HELPER", "0")
os.environ.setdefault("MAGICA_FIRST_RUN", "compile")

REPO_ROOT = pathlib.Path(__file__).resolve().parents[1]
SHARED_DATA = REPO_ROOT.parent / "shared" / "data"


@pytest.fixture(scope="session")
def repo_root() -> pathlib.Path:
    return REPO_ROOT


@pytest.fixture
def used_stages(monkeypatch):
    """A test's systems compile the optional stages their scene uses and its animations the
    driver kinds they have (``MAGICA_STAGES=used``, what ``magica-py`` runs), not every one as
    in the rest of the suite: for the tests that pin the selection itself."""
    monkeypatch.setenv("MAGICA_STAGES", "used")


@pytest.fixture(scope="session")
def shared_data() -> pathlib.Path:
    if not SHARED_DATA.is_dir():
        pytest.skip(f"third-party test data not found at {SHARED_DATA} (CI checks it out beside the repo)")
    return SHARED_DATA
