"""The one place where JIT options are chosen (tests/test_jit_options.py checks every kernel).

* ``cache=True``: compiled kernels are reused across processes (docs/tech-notes.md §7).
* no fastmath: results are reproducible bit for bit and NaN checks keep working (docs/tech-notes.md §9, §11).
* ``error_model="numpy"``: a division by zero yields inf instead of raising inside a
  kernel; the solver's guards catch non-finite values before they reach a transform.
* ``MAGICA_NO_CACHE=1`` disables the cache (read-only installs without NUMBA_CACHE_DIR).
* LLVM inline threshold ``INLINE_THRESHOLD`` (LLVM's default is 225): numba compiles each
  helper as a function and leaves inlining to LLVM; a lane loop of the batched steps
  (``solver/batched``) vectorises only once its per-element maths (a slerp with polynomial
  trigonometry is ~300 instructions) is inlined into it. Process-wide (LLVM has one option
  table); part of the cache key because this file is.
"""
from __future__ import annotations

import os

import llvmlite.binding as _llvm
import numba

INLINE_THRESHOLD = 2000
_llvm.set_option("magica_py", f"-inline-threshold={INLINE_THRESHOLD}")
# a lane loop reads and writes a dozen arrays that LLVM cannot prove distinct: it vectorises
# behind runtime overlap checks, more than its default budget of 8 (per loop, run once)
_llvm.set_option("magica_py", "-runtime-memory-check-threshold=256")
_llvm.set_option("magica_py", "-vectorize-memory-check-threshold=1024")

CACHE = os.environ.get("MAGICA_NO_CACHE", "0") != "1"
JIT_OPTIONS = {"cache": CACHE, "fastmath": False, "error_model": "numpy", "nogil": True}


def kernel(fn=None, **overrides):
    """Decorate a numba kernel or helper with the project's JIT options."""
    options = dict(JIT_OPTIONS)
    options.update(overrides)
    if fn is None:
        return lambda f: numba.njit(**options)(f)
    return numba.njit(**options)(fn)
