"""The one place where JIT options are chosen (tests/test_jit_options.py checks every kernel).

* ``cache=True``: compiled kernels are reused across processes (tech-notes §7).
* no fastmath: results are reproducible bit for bit and NaN checks keep working (§9, §11).
* ``error_model="numpy"``: a division by zero yields inf instead of raising inside a
  kernel; the solver's guards catch non-finite values before they reach a transform.
* ``MAGICA_NO_CACHE=1`` disables the cache (read-only installs without NUMBA_CACHE_DIR).
"""
from __future__ import annotations

import os

import numba

CACHE = os.environ.get("MAGICA_NO_CACHE", "0") != "1"
JIT_OPTIONS = {"cache": CACHE, "fastmath": False, "error_model": "numpy", "nogil": True}


def kernel(fn=None, **overrides):
    """Decorate a numba kernel or helper with the project's JIT options."""
    options = dict(JIT_OPTIONS)
    options.update(overrides)
    if fn is None:
        return lambda f: numba.njit(**options)(f)
    return numba.njit(**options)(fn)
