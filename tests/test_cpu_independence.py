"""Results do not depend on which SIMD code numpy, OpenBLAS or the C library pick on this CPU
(docs/determinism.md).

Each showcase is built and simulated for a few frames in a subprocess under environment
variables that make numpy (``NPY_DISABLE_CPU_FEATURES``), OpenBLAS (``OPENBLAS_CORETYPE``) and
glibc's libm (``GLIBC_TUNABLES``) take the code paths of an older or different CPU; every
stage hash (rest pose, built model, animation, particles, bones) must equal the run with the
machine's own choices. A probe in each subprocess checks that the variable did change those
libraries' bits (else the variant proves nothing on this machine and says so).

A static check keeps the code that feeds the model or the state free of the calls whose bits
depend on that dispatch (numpy transcendental ufuncs, BLAS / LAPACK, libm through ``math``).
"""
import ast
import json
import os
import pathlib
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "magica_py"
FRAMES = 12

# packages whose results feed a cloth model or the simulation state
STATE_PACKAGES = ("build", "scene", "io", "config", "params", "runtime", "solver", "kernels")
# tools inside those packages that feed nothing (a timing / comparison script)
NOT_STATE = {"io/bench.py"}
TRANSCENDENTAL = {
    "sin", "cos", "tan", "arcsin", "arccos", "arctan", "arctan2", "exp", "expm1", "exp2", "log",
    "log1p", "log2", "log10", "power", "float_power", "sinh", "cosh", "tanh", "arcsinh", "arccosh",
    "arctanh", "hypot", "cbrt", "asin", "acos", "atan", "atan2", "pow"}
BLAS = {"dot", "matmul", "einsum", "inner", "vdot", "tensordot", "outer", "linalg"}


def _is_kernel(fn: ast.FunctionDef) -> bool:
    for d in fn.decorator_list:
        target = d.func if isinstance(d, ast.Call) else d
        if isinstance(target, ast.Name) and target.id == "kernel":
            return True
    return False


ALLOW = "# cpu-independent:"   # a line that says why its call is exact (e.g. integer arithmetic)


def dispatched_maths(path: pathlib.Path) -> list[str]:
    """Calls in a module whose bits depend on the CPU's dispatch, as 'line: what' (a line
    marked ``# cpu-independent: <reason>`` is left out)."""
    text = path.read_text(encoding="utf-8")
    allowed = {n for n, line in enumerate(text.splitlines(), 1) if ALLOW in line}
    tree = ast.parse(text)
    in_kernel = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef) and _is_kernel(node):
            in_kernel.update(id(sub) for sub in ast.walk(node))
    found = []
    for node in ast.walk(tree):
        what = None
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
            if node.value.id in ("np", "numpy") and (node.attr in TRANSCENDENTAL or node.attr in BLAS):
                what = f"np.{node.attr}"
            elif node.value.id == "math" and node.attr in TRANSCENDENTAL:
                what = f"math.{node.attr} (libm)"
        elif isinstance(node, ast.BinOp) and isinstance(node.op, ast.MatMult):
            what = "@ (BLAS)"
        elif isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow):
            integer_exponent = isinstance(node.right, ast.Constant) and type(node.right.value) is int
            integer_base = isinstance(node.left, ast.Constant) and type(node.left.value) is int
            if not integer_exponent:
                what = "** with a non-integer exponent (libm pow)"
            elif id(node) not in in_kernel and not integer_base:
                what = "** on a Python float (libm pow; use x * x or np.square)"
        if what and node.lineno not in allowed:
            where = path.relative_to(PACKAGE).as_posix() if path.is_relative_to(PACKAGE) else path.name
            found.append(f"{where}:{node.lineno}: {what}")
    return found


def test_code_that_feeds_the_state_calls_no_cpu_dispatched_maths():
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        if rel.split("/")[0] in STATE_PACKAGES and rel not in NOT_STATE:
            found += dispatched_maths(path)
    assert not found, ("use magica_py.kernels.portable instead (docs/determinism.md):\n" + "\n".join(found))


def test_the_static_check_sees_each_kind_of_call(tmp_path):
    sample = tmp_path / "sample.py"
    sample.write_text("import math\nimport numpy as np\n"
                      "a = np.arccos(0.5)\nb = np.linalg.inv(m)\nc = m @ m\nd = math.exp(1.0)\n"
                      "e = x ** 0.5\nf = x ** 2\ng = 2 ** 10\nh = np.square(x)\n"
                      "k = np.dot(counts, sizes)  # cpu-independent: integers\n")
    found = dispatched_maths(sample)
    assert sorted(int(line.split(":")[1]) for line in found) == [3, 4, 5, 6, 7, 8]


# the subprocess: stage hashes of every showcase, plus probes of the libraries' bits
PROBE = """
import hashlib, json, math, sys
import numpy as np
sys.path.insert(0, {root!r})
import importlib.util
spec = importlib.util.spec_from_file_location("golden_hashes", {golden!r})
golden = importlib.util.module_from_spec(spec); spec.loader.exec_module(golden)
x = np.linspace(-0.999, 0.999, 4001)
m = np.random.default_rng(1).normal(size=(64, 64))
def h(a): return hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()[:16]
probe = {{"numpy": h(np.arccos(x)) + h(np.sin(x * 3.0)) + h(np.arctan2(x, 0.5)),
          "openblas": h(np.linalg.inv(m)) + h(m @ m),
          "libm": h(np.array([math.sin(v * 3.0) + math.exp(v) for v in x]))}}
result = {{name: golden.scene_hashes(name, {frames}) for name in golden.SCENES}}
print(json.dumps({{"probe": probe, "result": result}}))
"""

VARIANTS = {
    # the stand-in for a machine without AVX-512
    "numpy without AVX-512": {"NPY_DISABLE_CPU_FEATURES": "AVX512_ICL X86_V4"},
    "numpy baseline SIMD only": {"NPY_DISABLE_CPU_FEATURES": "X86_V3 X86_V4 AVX512_ICL AVX512_SPR"},
    "OpenBLAS generic kernels": {"OPENBLAS_CORETYPE": "Prescott"},
    "glibc libm without FMA/AVX2": {"GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX2,-FMA"},
}


def run_variant(env_changes: dict) -> dict:
    env = dict(os.environ)
    env.update(env_changes)
    code = PROBE.format(root=str(ROOT), golden=str(ROOT / "benchmarks" / "golden_hashes.py"), frames=FRAMES)
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=3600)
    assert done.returncode == 0, f"{env_changes}: subprocess failed:\n{done.stderr[-3000:]}"
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def runs():
    """The machine's own run first (it fills numba's cache when the suite starts cold), then
    the variants two at a time (2 cores), loading the cached kernels."""
    from concurrent.futures import ThreadPoolExecutor

    machine = run_variant({})
    with ThreadPoolExecutor(max_workers=2) as pool:
        futures = {name: pool.submit(run_variant, env) for name, env in VARIANTS.items()}
        return {"machine": machine, **{name: future.result() for name, future in futures.items()}}


def golden_module():
    import importlib.util

    spec = importlib.util.spec_from_file_location("golden_hashes", ROOT / "benchmarks" / "golden_hashes.py")
    golden = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(golden)
    return golden


@pytest.mark.parametrize("variant", list(VARIANTS))
def test_showcases_give_the_same_bits_whatever_the_dispatch(variant, runs):
    golden = golden_module()
    machine, other = runs["machine"], runs[variant]
    differences = []
    for name, expected in machine["result"].items():
        differences += golden.compare(name, expected, other["result"][name])
    assert not differences, f"{variant} ({VARIANTS[variant]}):\n" + "\n".join(differences)
    changed = [lib for lib in ("numpy", "openblas", "libm") if other["probe"][lib] != machine["probe"][lib]]
    if not changed:
        pytest.skip(f"{variant}: same bits, but the variables changed no library's bits on this machine "
                    "(nothing to prove here)")
