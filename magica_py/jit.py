"""The one place where JIT options are chosen (tests/test_jit_options.py checks every kernel).

* ``cache=True``: compiled kernels are reused across processes (docs/tech-notes.md §7).
* no fastmath: results are reproducible bit for bit and NaN checks keep working (docs/tech-notes.md §9, §11).
* ``error_model="numpy"``: a division by zero yields inf instead of raising inside a
  kernel; the solver's guards catch non-finite values before they reach a transform.
* ``nogil=True``: a kernel releases the GIL (the batch runner's threads, live viewers).
* ``MAGICA_NO_CACHE=1`` disables the cache (read-only installs without NUMBA_CACHE_DIR).
* ``MAGICA_STAGES`` (``stage_policy``): whether kernels with optional parts (the cloth frame's
  stages, the animation's driver kinds) are compiled with the parts a scene uses or with all.
* ``fewer_collections``: Python's garbage collector runs less often while numba compiles (the
  runner's compile watch, the first run's compile helper and a batch worker's warm-up enter it).

Only numba's documented options are used: nothing here changes LLVM's settings for the
process, so ``NUMBA_DISABLE_JIT=1`` and ``NUMBA_BOUNDSCHECK=1`` apply to every kernel.
"""
from __future__ import annotations

import gc
import os
import threading
from contextlib import contextmanager

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


# Which optional parts the kernels that have them are compiled with (environment variable
# MAGICA_STAGES): the cloth frame's optional stages (``ClothSystem.stage_switches``) and the
# animation's driver kinds (``Animation.kinds_used``). "used" (the default): the parts the
# scene uses, so that a scene neither compiles nor runs what it does not need. "all": every
# part whatever the scene, so that one compiled kernel serves every scene and every run-time
# change of parameters: for a process that runs many different scenes (the test suite, a
# batch of varied characters) or a tuning session that switches stages on and off, at the
# price of the parts' cheap checks where nothing asks. The bits are the same either way (a
# stage runs only where a block's parameters ask, a driver kind only for its drivers:
# docs/architecture.md, *Only the stages a scene uses are compiled*).
STAGE_POLICIES = ("used", "all")


def stage_policy() -> str:
    """The ``MAGICA_STAGES`` policy (``STAGE_POLICIES``); read each time switches are computed
    (a cloth system's stage switches, an animation's driver kinds), so a process can change it
    between systems."""
    value = os.environ.get("MAGICA_STAGES", "").strip().lower() or "used"
    if value not in STAGE_POLICIES:
        from magica_py.params import ParameterError   # params imports this module

        raise ParameterError("environment variable MAGICA_STAGES",
                             f"{os.environ['MAGICA_STAGES']!r}: expected 'used' (compile the optional stages and "
                             "driver kinds the scene uses; the default) or 'all' (compile every one, whatever "
                             "the scene)")
    return value


# Python's cyclic garbage collector while numba compiles. numba's compiler makes millions of
# objects that stay alive (types, typing results, IR, compiled libraries), and every full
# collection goes through all of them: on a first run of the tail scene in one process
# (``MAGICA_COMPILE_HELPER=0``), 27 full collections took 8.8 s and the young ones 2.2 s of a
# 92.8 s run. With these thresholds young objects are collected after 100,000 allocations
# instead of 700, and 3 full collections came instead of 27: 77.7 s (collections 4.2 s),
# peak memory about 6 % higher (``gc.disable()`` instead kept 370 MB more garbage;
# docs/BENCHMARKS.md, session 21). Entered around a compile only, restored after it.
COMPILE_GC_THRESHOLDS = (100_000, 10, 10)
_collections_lock = threading.Lock()
_collections_depth = 0
_collections_saved = None


@contextmanager
def fewer_collections():
    """Inside the block, Python's garbage collector uses ``COMPILE_GC_THRESHOLDS``; the
    thresholds in force before are restored when the last of the (possibly nested, possibly
    concurrent) blocks ends. Collection stays on: only its frequency changes."""
    global _collections_depth, _collections_saved
    with _collections_lock:
        if _collections_depth == 0:
            _collections_saved = gc.get_threshold()
            gc.set_threshold(*COMPILE_GC_THRESHOLDS)
        _collections_depth += 1
    try:
        yield
    finally:
        with _collections_lock:
            _collections_depth -= 1
            if _collections_depth == 0:
                gc.set_threshold(*_collections_saved)
