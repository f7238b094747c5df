"""magica_py: MagicaCloth2-style BoneCloth secondary motion in Python + numba.

Importing the package configures numba's on-disk cache before numba is imported (see
``_configure_numba_cache``); everything else is imported lazily so that ``magica-py --help``
stays fast. The package runs nothing on numba's parallel threading layers (its threads are
Python threads running ``nogil`` kernels: ``magica_py/threads.py``; it only reads their thread
count), so it sets no OpenMP variable.

The public API (docs/api.md), each name imported on first use (PEP 562):

* ``simulate(scene_or_path, frames=None, overrides=(), record=None)`` -> ``Simulation``:
  per-cloth arrays of particle positions and bone rotations over time, and the metrics;
* ``Session``: the same, frame by frame (``step()``, ``run(n)``, ``result()``, ``system``);
* ``load_scene(path, overrides)``, ``load_scene_text(text, overrides)``, ``ConfigError``;
* ``Player`` (``Player.for_scene(scene)``), ``attach_solver(player, scene)`` -> ``ClothSystem``
  (``set_parameter``, ``positions``, ``reset_cloth`` ...), ``Simulation``, ``ClothTrack``.
"""
from __future__ import annotations

import hashlib
import os
import pathlib
import re
import sys

__version__ = "0.1.0"


def _kernel_sources(root: pathlib.Path) -> list[pathlib.Path]:
    """The modules that define numba kernels, plus every package module they import.

    Only these can make a cached kernel stale (a kernel freezes the helpers and module
    constants it uses); editing the CLI, the YAML loader, the importers or the sinks keeps
    the compiled cache. Orchestration packages are followed only where they define kernels.
    """
    texts = {path: path.read_text(encoding="utf-8") for path in root.rglob("*.py")}
    orchestration = ("config", "cli.py", "bench", "io", "sinks")
    wanted = [path for path, text in texts.items() if "@kernel" in text or "@numba." in text or "@njit" in text]
    seen: set[pathlib.Path] = set()
    while wanted:
        path = wanted.pop()
        if path in seen:
            continue
        seen.add(path)
        for module in _imported_modules(texts[path]):
            base = root.joinpath(*module)
            for candidate in (base.with_suffix(".py"), base / "__init__.py"):
                if candidate in texts and candidate not in seen and (
                        candidate.relative_to(root).parts[0] not in orchestration):
                    wanted.append(candidate)
    return sorted(seen)


def _imported_modules(text: str) -> list[tuple[str, ...]]:
    """The package modules a source imports, as paths below the package: ``import
    magica_py.a.b`` and ``from magica_py.a.b import x`` give ``a/b``; the names of a ``from``
    import may be modules too (``from magica_py.solver import state as st`` gives ``solver``
    and ``solver/state``); a candidate that is not a file is skipped by the caller."""
    found = [tuple(m.split(".")) for m in re.findall(r"^\s*import\s+magica_py\.([\w.]+)", text, re.M)]
    for module, names in re.findall(r"^\s*from\s+magica_py((?:\.\w+)*)\s+import\s+(\([^)]*\)|[^\n]+)", text, re.M):
        parts = tuple(p for p in module.split(".") if p)
        if parts:
            found.append(parts)
        for name in re.split(r"[,\s()]+", re.sub(r"\bas\s+\w+", "", re.sub(r"#[^\n]*", "", names))):
            if name.isidentifier():
                found.append(parts + (name,))
    return found


def _configure_numba_cache() -> None:
    """Point NUMBA_CACHE_DIR at a folder keyed by a hash of the kernel sources.

    numba keys its cache on the kernel's own file only, so a kernel whose helper lives in
    another module keeps returning stale results after the helper changes (docs/tech-notes.md §7).
    Keying the cache folder on every kernel module (and what they import) makes any such
    edit start a fresh cache. A user-set NUMBA_CACHE_DIR is respected.
    """
    if os.environ.get("NUMBA_CACHE_DIR"):
        return
    root = pathlib.Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for path in _kernel_sources(root):
        digest.update(path.relative_to(root).as_posix().encode())
        digest.update(path.read_bytes())
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    os.environ["NUMBA_CACHE_DIR"] = os.path.join(base, "magica_py", "numba-" + digest.hexdigest()[:16])
    if "numba" in sys.modules:  # numba read its config already: make it read it again
        from numba.core import config

        config.reload_config()


_configure_numba_cache()


# name -> (module, attribute): the public API, imported on first access (PEP 562)
_PUBLIC = {
    "simulate": ("magica_py.api", "simulate"),
    "Session": ("magica_py.api", "Session"),
    "Simulation": ("magica_py.api", "Simulation"),
    "ClothTrack": ("magica_py.api", "ClothTrack"),
    "load_scene": ("magica_py.config", "load_scene"),
    "load_scene_text": ("magica_py.config", "load_scene_text"),
    "ConfigError": ("magica_py.config.errors", "ConfigError"),
    "Player": ("magica_py.runtime.player", "Player"),
    "attach_solver": ("magica_py.solver", "attach"),
    "ClothSystem": ("magica_py.solver.system", "ClothSystem"),
}
__all__ = sorted(_PUBLIC) + ["__version__"]


def __getattr__(name: str):
    target = _PUBLIC.get(name)
    if target is None:
        raise AttributeError(f"module 'magica_py' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(target[0]), target[1])
    globals()[name] = value  # later accesses skip this function
    return value


def __dir__():
    return sorted(set(globals()) | set(_PUBLIC))
