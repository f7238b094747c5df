"""Every numba kernel of the package is compiled with the project's options (``jit.py``):
no fastmath (reproducible bits, NaN checks that work), numpy error model (no exception paths
in the lane loops), the on-disk cache; and the LLVM options the batched steps rely on are set."""
import importlib
import pathlib
import pkgutil

import llvmlite.binding  # noqa: F401  (the options live in LLVM's table)
from numba.core.registry import CPUDispatcher

import magica_py
from magica_py import jit

SKIP = ("magica_py.cli", "magica_py.__main__")


def _dispatchers():
    root = pathlib.Path(magica_py.__file__).parent
    found = {}
    for info in pkgutil.walk_packages([str(root)], prefix="magica_py."):
        if info.name.startswith(SKIP):
            continue
        module = importlib.import_module(info.name)
        for name, value in vars(module).items():
            if isinstance(value, CPUDispatcher) and value.py_func.__module__ == info.name:
                found[f"{info.name}.{name}"] = value
    return found


def test_every_kernel_uses_the_project_jit_options():
    kernels = _dispatchers()
    assert len(kernels) > 100  # the walk found the solver, build and scene kernels
    wrong = {name: d.targetoptions for name, d in kernels.items()
             if d.targetoptions.get("fastmath", False) or d.targetoptions.get("error_model") != "numpy"
             or (type(d._cache).__name__ != "NullCache") != jit.CACHE}
    assert not wrong, wrong


def test_the_inline_threshold_is_raised_for_the_lane_loops():
    assert jit.INLINE_THRESHOLD >= 1000
