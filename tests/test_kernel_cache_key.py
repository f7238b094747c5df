"""The numba cache folder is keyed on every module a compiled kernel can depend on
(``magica_py._kernel_sources``): numba keys its own cache on a kernel's file only, so a module
whose constants or helpers a kernel freezes (the solver's row layout in ``solver/state.py``)
must be part of the key, or an edit to it would keep running kernels compiled against the old
layout."""
import pathlib

import magica_py
from magica_py import _imported_modules, _kernel_sources


def test_imported_modules_include_the_names_of_a_from_import():
    text = ("from magica_py.solver import state as st, blocks as bk\n"
            "from magica_py.solver.lanes import (LANES,  # a comment\n    get1)  # another\n"
            "import magica_py.kernels.trig\n"
            "from magica_py import jit\n"
            "    from magica_py.params import ParameterError   # a late import\n"
            "import numpy as np\n")
    assert sorted(_imported_modules(text)) == sorted([
        ("solver",), ("solver", "state"), ("solver", "blocks"),
        ("solver", "lanes"), ("solver", "lanes", "LANES"), ("solver", "lanes", "get1"),
        ("kernels", "trig"),
        ("jit",),
        ("params",), ("params", "ParameterError")])


def _write(root: pathlib.Path, files: dict[str, str]) -> None:
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


def test_a_layout_module_imported_by_name_is_part_of_the_key(tmp_path):
    _write(tmp_path, {
        "__init__.py": "",
        "solver/__init__.py": "",
        "solver/state.py": "POSITION = 0\n",                     # no kernel of its own
        "solver/stage.py": "from magica_py.solver import state as st\n\n@kernel\ndef f(a):\n    return a[st.POSITION]\n",
        "cli.py": "from magica_py.solver import stage\n",       # no kernel, not imported by one
    })
    keyed = {p.relative_to(tmp_path).as_posix() for p in _kernel_sources(tmp_path)}
    assert keyed == {"solver/stage.py", "solver/__init__.py", "solver/state.py"}


def test_the_solvers_row_layout_is_part_of_the_packages_key():
    root = pathlib.Path(magica_py.__file__).resolve().parent
    keyed = {p.relative_to(root).as_posix() for p in _kernel_sources(root)}
    assert {"solver/state.py", "solver/blocks.py", "solver/lanes.py", "solver/parameters.py"} <= keyed
    assert "cli.py" not in keyed
