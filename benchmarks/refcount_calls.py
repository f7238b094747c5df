"""How many numba reference counts (``NRT_incref`` / ``NRT_decref`` calls) a frame makes, and from
which compiled function (issue 15).

    python benchmarks/refcount_calls.py [SCENE] [--frames 20] [--set KEY=VALUE ...] [--top 15]

numba counts a reference (an atomic add in ``NRT_incref``, a subtract and test in
``NRT_decref``) for every array it copies into a variable or a function argument that its
reference-count pruning cannot prove redundant; a namedtuple of arrays counts once per array.
``frame_profile.py`` shows how much of a frame that costs (``NRT_incref`` / ``NRT_decref`` among
the sampled functions); this script counts the calls and says where they come from.

The scene (``configs/SCENE.yaml``, default ``tail_orbit``) runs in a child process: it loads,
warms up (30 frames), prints its pid and the addresses of every ``NRT_incref`` /
``NRT_decref`` copy in the package's compiled libraries, waits, and runs ``--frames`` frames.
``gdb`` attaches to it with a breakpoint on each of those addresses that prints the return
address and continues; each return address is then attributed to the compiled function that
holds it. Slow (a breakpoint hit costs tens of microseconds): keep ``--frames`` small for a
large scene (2 for the light scene: about 80,000 calls a frame).

Needs ``gdb`` with ptrace allowed (root here), ``nm`` and the numba internals
``frame_profile.library_functions`` reads: a benchmark script, nothing in the package uses it.
"""
from __future__ import annotations

import argparse
import bisect
import collections
import json
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
NRT = ("NRT_incref", "NRT_decref")


def child(scene_name: str, frames: int, overrides: tuple, table: str) -> None:
    """The simulation process: warm up, report pid and NRT addresses, wait for gdb, run."""
    sys.path.insert(0, str(ROOT))
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from numba.core.registry import CPUDispatcher

    from frame_profile import library_functions, short_name, warm_player

    _path, player = warm_player(scene_name, overrides)
    functions, seen = [], set()
    for name, module in list(sys.modules.items()):
        if not name.startswith("magica_py"):
            continue
        for value in list(vars(module).values()):
            if isinstance(value, CPUDispatcher) and value.overloads and id(value) not in seen:
                seen.add(id(value))
                functions += library_functions(value)
    functions = sorted(set(functions))
    with open(table, "w") as f:
        json.dump([(a, s, short_name(n)) for a, s, n in functions], f)
    nrt = sorted({a for a, _s, n in functions if n in NRT})
    print(os.getpid(), *(hex(a) for a in nrt), flush=True)
    sys.stdin.readline()   # the parent writes a line once gdb has attached
    player.run(frames)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene", nargs="?", default="tail_orbit")
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="scene override")
    ap.add_argument("--top", type=int, default=15)
    ap.add_argument("--child", metavar="TABLE", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.scene, args.frames, tuple(args.set), args.child)
        return
    for tool in ("gdb", "nm"):
        if shutil.which(tool) is None:
            raise SystemExit(f"refcount_calls.py needs {tool!r} on the PATH")
    with tempfile.TemporaryDirectory() as tmp:
        table = os.path.join(tmp, "functions.json")
        cmd = [sys.executable, __file__, args.scene, "--frames", str(args.frames), "--child", table]
        for s in args.set:
            cmd += ["--set", s]
        sim = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        first = sim.stdout.readline().split()
        if not first:
            raise SystemExit(f"the scene process ended before its frames (exit code {sim.wait()})")
        pid, addresses = first[0], first[1:]
        if not addresses:
            raise SystemExit("no NRT_incref / NRT_decref found in the package's compiled libraries")
        script = os.path.join(tmp, "gdb.cmd")
        with open(script, "w") as f:
            f.write(f"set pagination off\nattach {pid}\n")
            for a in addresses:
                f.write(f"break *{a}\ncommands\nsilent\nprintf \"RA %lx\\n\", *(long*)$rsp\ncontinue\nend\n")
            f.write("continue\n")
        gdb = subprocess.Popen(["gdb", "-q", "-batch", "-x", script], stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True)
        time.sleep(3.0)   # attached and the breakpoints set before the frames start
        sim.stdin.write("go\n")
        sim.stdin.flush()
        out, _ = gdb.communicate()
        sim.wait()
        with open(table) as f:
            functions = sorted(tuple(x) for x in json.load(f))
    starts = [a for a, _s, _n in functions]
    per_function = collections.Counter()
    calls = 0
    for line in out.splitlines():
        if not line.startswith("RA "):
            continue
        calls += 1
        ra = int(line.split()[1], 16)
        i = bisect.bisect_right(starts, ra) - 1
        inside = i >= 0 and ra < functions[i][0] + functions[i][1]
        per_function[functions[i][2] if inside else "(outside the package's compiled functions)"] += 1
    n = max(args.frames, 1)
    print(f"{args.scene}: {calls} reference-count calls in {args.frames} frames, {calls / n:.1f} a frame")
    print(f"{'a frame':>10}  called from")
    for name, c in per_function.most_common(args.top):
        print(f"{c / n:10.1f}  {name if len(name) <= 100 else name[:97] + '...'}")


if __name__ == "__main__":
    main()
