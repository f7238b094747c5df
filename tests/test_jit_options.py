"""Every numba kernel of the package is compiled with the project's options (``jit.py``):
no fastmath (reproducible bits, NaN checks that work), numpy error model, the on-disk cache;
and importing the package changes no LLVM option of the process."""
import importlib
import pathlib
import pkgutil

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


def test_importing_the_package_sets_no_process_wide_llvm_option():
    import ast

    root = pathlib.Path(magica_py.__file__).parent
    offenders = []
    for path in root.rglob("*.py"):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and node.attr in ("set_option", "entry_point", "overloads"):
                offenders.append(f"{path.relative_to(root)}:{node.lineno} .{node.attr}")
    assert not offenders, offenders


def test_fewer_collections_restores_the_thresholds_when_the_last_block_ends():
    import gc

    before = gc.get_threshold()
    with jit.fewer_collections():
        assert gc.get_threshold() == jit.COMPILE_GC_THRESHOLDS
        with jit.fewer_collections():            # nested (a compile inside a compile)
            assert gc.get_threshold() == jit.COMPILE_GC_THRESHOLDS
        assert gc.get_threshold() == jit.COMPILE_GC_THRESHOLDS   # the outer block still runs
    assert gc.get_threshold() == before
    try:
        with jit.fewer_collections():
            raise KeyError("inside")
    except KeyError:
        pass
    assert gc.get_threshold() == before and gc.isenabled()
