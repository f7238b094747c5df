"""Where a frame's time goes *inside* the compiled kernels, measured in the frame (issue 15).

    python benchmarks/frame_profile.py [SCENE] [--frames 300] [--threads 1] [--rate 2000]
                                       [--set KEY=VALUE ...] [--annotate FUNCTION] [--top 25]

``bench_solver.py --stages`` times each stage alone over every block: a stage then finds its
rows wherever the previous stage left them, not where the frame leaves them. This script samples
the frame itself: the scene (``configs/SCENE.yaml``, default ``light_chains``) is loaded and
warmed up (30 frames, from the numba cache when there is one), then Linux ``perf record`` is
attached to this process (``-p``) for ``--frames`` frames of ``player.step()`` and detached,
so that imports, compiles and warm-up are not sampled. Each sample's instruction address is
attributed to the compiled function that holds it: the functions of the frame kernel's
library (``simulate_frame``, or a parallel frame's ``simulate_worker``), of the animation's
``apply_drivers`` and of the hierarchy's propagation kernels; their names and sizes are read from
each library's object code (``nm -S``) and their addresses from the JIT. Everything else (the
Python interpreter, numpy, the C library, the kernel) is reported as one remainder.

Output: the share of the samples per function (``%frame``: of all samples, ``%kernels``: of the
samples in the mapped kernels) and, with ``--annotate NAME``, the hottest instructions of the
first function whose name contains NAME (``objdump`` of its bytes in memory) with their
sample counts. A sample's cost lands on the instruction *after* a stalled load, so a hot
``add`` right after a load is usually the load's cache miss.

Needs ``perf`` (``linux-tools``) with ``kernel.perf_event_paranoid`` allowing ``-p`` (root here)
and binutils' ``nm`` / ``objdump``. The addresses come from numba's compiled libraries
(``library.get_pointer_to_function``, the object code numba keeps for its cache): that is not
numba's documented API, which is why this is a benchmark script and nothing in the package
uses it; it may need adjusting with a numba release.
"""
from __future__ import annotations

import argparse
import bisect
import collections
import ctypes
import os
import pathlib
import re
import signal
import shutil
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent


def library_functions(dispatcher) -> list[tuple[int, int, str]]:
    """(address, size, symbol) of every function defined in each compiled overload of
    ``dispatcher`` (its library: the function and every callee linked into it)."""
    found = []
    for cres in dispatcher.overloads.values():
        library = cres.library
        # the library's optimised module (also kept when it came from the cache) emitted once
        # more: the same machine code as the JIT's, so the same function sizes
        obj = library._codegen._tm.emit_object(library._get_module_for_linking())
        with tempfile.NamedTemporaryFile(suffix=".o") as f:
            f.write(obj)
            f.flush()
            out = subprocess.run(["nm", "-S", "--defined-only", f.name], capture_output=True, text=True,
                                 check=True).stdout
        for line in out.splitlines():
            parts = line.split()
            if len(parts) != 4 or parts[2].lower() not in ("t", "w"):
                continue
            size, name = int(parts[1], 16), parts[3]
            try:
                address = library.get_pointer_to_function(name)
            except Exception:   # a symbol the JIT does not export by name
                continue
            if address and size:
                found.append((address, size, name))
    return found


def short_name(symbol: str) -> str:
    """``magica_py.solver.step.predict_block`` from numba's mangled symbol."""
    m = re.match(r"_ZN(.*?)B\d", symbol)
    if not m:
        return symbol
    parts, rest = [], m.group(1)
    while rest:
        n = re.match(r"(\d+)", rest)
        if not n:
            break
        k = int(n.group(1))
        parts.append(rest[len(n.group(1)):len(n.group(1)) + k])
        rest = rest[len(n.group(1)) + k:]
    return ".".join(parts) or symbol


def warm_player(scene_name: str, overrides=(), parallel: bool | None = None):
    """``(path, player)``: the scene (``configs/NAME.yaml`` for a bare name) with its cloth
    system (``parallel``: the system's own choice when None), after 30 warm-up frames (the
    compiles, from the numba cache when there is one)."""
    sys.path.insert(0, str(ROOT))
    from magica_py.config import load_scene
    from magica_py.runtime.player import Player
    from magica_py.solver.system import ClothSystem

    path = pathlib.Path(scene_name)
    if not path.suffix:
        path = ROOT / "configs" / f"{scene_name}.yaml"
    scene = load_scene(path, overrides=tuple(overrides))
    player = Player.for_scene(scene)
    ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings, parallel=parallel).attach(player)
    player.run(30)
    return path, player


def attach_perf(pid: int, rate: int, out: str) -> subprocess.Popen:
    proc = subprocess.Popen(["perf", "record", "-e", "cpu-clock", "-F", str(rate), "-p", str(pid), "-o", out],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    time.sleep(1.0)   # perf attaches to every thread before the frames start
    if proc.poll() is not None:
        raise SystemExit(f"perf record failed: {proc.stderr.read().decode().strip()}")
    return proc


def sample_addresses(data: str) -> list[int]:
    out = subprocess.run(["perf", "script", "-i", data, "-F", "ip"], capture_output=True, text=True).stdout
    return [int(line, 16) for line in (l.strip() for l in out.splitlines()) if line]


def annotate(function: tuple[int, int, str], counts: collections.Counter, top: int) -> None:
    address, size, name = function
    with tempfile.NamedTemporaryFile(suffix=".bin") as f:
        f.write(ctypes.string_at(address, size))
        f.flush()
        out = subprocess.run(["objdump", "-D", "-b", "binary", "-mi386:x86-64", f"--adjust-vma={address}", f.name],
                             capture_output=True, text=True, check=True).stdout
    lines = [(counts.get(int(m.group(1), 16), 0), line) for line in out.splitlines()
             if (m := re.match(r"\s*([0-9a-f]+):", line))]
    total = sum(c for c, _ in lines)
    print(f"\n{short_name(name)}: {total} samples; hottest instructions:")
    for c, line in sorted(lines, key=lambda x: -x[0])[:top]:
        if c:
            print(f"  {c:6d}  {line.strip()}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene", nargs="?", default="light_chains")
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--threads", type=int, default=1, help="1: the serial frame kernel; 2+: the parallel frame")
    ap.add_argument("--rate", type=int, default=2000, help="samples per second (perf -F)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="scene override")
    ap.add_argument("--annotate", metavar="FUNCTION", help="hottest instructions of this function")
    ap.add_argument("--top", type=int, default=25)
    args = ap.parse_args()
    for tool in ("perf", "nm", "objdump"):
        if shutil.which(tool) is None:
            raise SystemExit(f"frame_profile.py needs {tool!r} on the PATH")

    sys.path.insert(0, str(ROOT))
    import numba

    from magica_py.scene import animation, propagation
    from magica_py.solver import frame

    if args.threads > 1:
        numba.set_num_threads(args.threads)
    path, player = warm_player(args.scene, args.set, parallel=args.threads > 1)

    functions = []
    for dispatcher in (frame.simulate_frame, frame.simulate_worker, frame.begin_parallel_frame,
                       frame.end_parallel_frame, animation.apply_drivers, propagation.propagate_listed,
                       propagation.propagate_chunks):
        functions += library_functions(dispatcher)
    # a function linked into two libraries appears twice at two addresses: both are kept
    functions = sorted(set(functions))
    starts = [a for a, _s, _n in functions]

    with tempfile.TemporaryDirectory() as tmp:
        data = os.path.join(tmp, "perf.data")
        perf = attach_perf(os.getpid(), args.rate, data)
        t0 = time.perf_counter()
        player.run(args.frames)
        seconds = time.perf_counter() - t0
        perf.send_signal(signal.SIGINT)
        perf.wait()
        addresses = sample_addresses(data)

    per_function = collections.Counter()
    per_address = collections.Counter()
    for ip in addresses:
        i = bisect.bisect_right(starts, ip) - 1
        if i >= 0 and ip < starts[i] + functions[i][1]:
            per_function[short_name(functions[i][2])] += 1
            per_address[ip] += 1
    total = len(addresses)
    mapped = sum(per_function.values())
    print(f"{path.stem}: {args.frames} frames in {seconds:.2f} s ({seconds / args.frames * 1e3:.2f} ms a frame), "
          f"{args.threads} thread(s); {total} samples, {mapped} in the mapped kernels "
          f"({len(functions)} functions)")
    print(f"{'samples':>8} {'%frame':>7} {'%kernels':>8}  function")
    for name, c in per_function.most_common(args.top):
        print(f"{c:8d} {100 * c / max(total, 1):6.1f}% {100 * c / max(mapped, 1):7.1f}%  {name}")
    rest = total - mapped
    print(f"{rest:8d} {100 * rest / max(total, 1):6.1f}%  {'':8}  outside the kernels (Python, numpy, C library, OS)")
    if args.annotate:
        match = [f for f in functions if args.annotate in short_name(f[2]) and per_address.keys()
                 and any(f[0] <= ip < f[0] + f[1] for ip in per_address)]
        if not match:
            raise SystemExit(f"--annotate {args.annotate!r}: no sampled function of that name")
        annotate(max(match, key=lambda f: sum(c for ip, c in per_address.items() if f[0] <= ip < f[0] + f[1])),
                 per_address, args.top)


if __name__ == "__main__":
    main()
