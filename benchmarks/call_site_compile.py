"""What a call site costs numba's compile: a called helper against one inlined at numba's level.

    python benchmarks/call_site_compile.py [--lines 10 60 120]

The solver's stages are written as calls of small helpers (``lanes.get3`` / ``put3`` and the
``kernels/math3d`` vector maths), a few thousand call sites in all. This script compiles, in a
fresh process each (no cache), a stage-like function of ``LINES`` lines of
``put3(A, g, c0, l, v_add(get3(A, g, c1, l), get3(A, g, c2, l)))`` inside a lane loop (four
call sites a line, the columns ``np.int64`` constants so that each helper has one signature),
once with the helpers compiled as functions of their own (the project's ``@kernel`` default:
LLVM inlines them) and once with ``inline="always"`` (numba splices their IR into the caller),
and prints the wall time of each compile. The difference between two ``--lines`` values, over
four times the difference of lines, is the cost of one call site.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import time

CHILD = r'''
import sys, time
import numba
import numpy as np

mode, lines = sys.argv[1], int(sys.argv[2])
options = dict(cache=False, nogil=True, error_model="numpy", forceinline=True)
if mode == "inlined":
    options["inline"] = "always"

@numba.njit(**options)
def get3(a, i, col, l):
    return (a[i, col + l], a[i, col + 16 + l], a[i, col + 32 + l])

@numba.njit(**options)
def put3(a, i, col, l, v):
    a[i, col + l] = v[0]
    a[i, col + 16 + l] = v[1]
    a[i, col + 32 + l] = v[2]

@numba.njit(**options)
def v_add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])

body = "\n".join(
    f"        put3(A, g, np.int64({48 * (k % 20)}), l, v_add(get3(A, g, np.int64({48 * ((k + 1) % 20)}), l), "
    f"get3(A, g, np.int64({48 * ((k + 2) % 20)}), l)))" for k in range(lines))
namespace = dict(get3=get3, put3=put3, v_add=v_add, np=np)
exec(f"def stage(A, g, w):\n    for l in range(w):\n{body}\n", namespace)
stage = numba.njit(cache=False, nogil=True, error_model="numpy")(namespace["stage"])
A = np.zeros((4, 20 * 48 + 64))
start = time.perf_counter()
stage(A, 1, 16)
print(f"{time.perf_counter() - start:.3f}")
'''


def compile_seconds(mode: str, lines: int) -> float:
    out = subprocess.run([sys.executable, "-c", CHILD, mode, str(lines)], check=True, capture_output=True,
                         text=True)
    return float(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lines", type=int, nargs="+", default=[10, 60, 120])
    args = ap.parse_args(argv)
    start = time.perf_counter()
    results = {}
    for lines in args.lines:
        for mode in ("called", "inlined"):
            results[mode, lines] = compile_seconds(mode, lines)
            print(f"{mode:8s} {lines:4d} lines ({4 * lines:4d} call sites): compile {results[mode, lines]:6.2f} s",
                  flush=True)
    first, last = min(args.lines), max(args.lines)
    if last > first:
        for mode in ("called", "inlined"):
            per_site = (results[mode, last] - results[mode, first]) / (4 * (last - first))
            print(f"{mode:8s} {per_site * 1e3:6.1f} ms a call site ({first} -> {last} lines)")
    print(f"({time.perf_counter() - start:.0f} s in all)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
