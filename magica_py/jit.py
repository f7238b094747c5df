"""The one place where JIT options are chosen (tests/test_jit_options.py checks every kernel).

* ``cache=True``: compiled kernels are reused across processes (docs/tech-notes.md §7).
* no fastmath: results are reproducible bit for bit and NaN checks keep working (docs/tech-notes.md §9, §11).
* ``error_model="numpy"``: a division by zero yields inf instead of raising inside a
  kernel; the solver's guards catch non-finite values before they reach a transform.
* ``nogil=True``: a kernel releases the GIL (the batch runner's threads, live viewers).
* ``MAGICA_NO_CACHE=1`` disables the cache (read-only installs without NUMBA_CACHE_DIR).

Only numba's documented options are used: nothing here changes LLVM's settings for the
process, so ``NUMBA_DISABLE_JIT=1`` and ``NUMBA_BOUNDSCHECK=1`` apply to every kernel.
"""
from __future__ import annotations

import os

import numba

CACHE = os.environ.get("MAGICA_NO_CACHE", "0") != "1"
JIT_OPTIONS = {"cache": CACHE, "fastmath": False, "error_model": "numpy", "nogil": True, "forceinline": True, "boundscheck": False}


def kernel(fn=None, **overrides):
    """Decorate a numba kernel or helper with the project's JIT options."""
    options = dict(JIT_OPTIONS)
    options.update(overrides)
    if fn is None:
        return lambda f: numba.njit(**options)(f)
    return numba.njit(**options)(fn)
