"""Where a first run's numba compile goes: per-function compile times of one scene's first
frames, with an empty kernel cache, from numba's documented event API (``numba:compile``).

    NUMBA_CACHE_DIR=$(mktemp -d) python benchmarks/compile_profile.py tail_orbit [FRAMES]

Times are inclusive (a function's compile includes the callees it compiles first), so read
the list as a tree: ``simulate_frame`` holds everything below it.

    NUMBA_CACHE_DIR=$(mktemp -d) python benchmarks/compile_profile.py tail_orbit 3 --passes

``--passes``: exclusive seconds per numba compiler pass and per function (a pass's time minus
the passes of the callees it compiled meanwhile, from the ``numba:run_pass`` events), and the
seconds spent inside LLVM (the ``numba:llvm_lock`` events: every call into llvmlite's
binding, i.e. LLVM's optimisation passes, machine-code emission, module parsing and linking),
in all and per function (the function whose pass was running: a kernel's own module includes
the callees numba linked into it, which LLVM optimises and emits again there).
With ``--all`` every function is listed, not the 25 slowest (the long tail: on the crowd, 247
of 287 functions take under 0.3 s each and 21 s together, docs/BENCHMARKS.md, session 29).

    NUMBA_CACHE_DIR=$(mktemp -d) python benchmarks/compile_profile.py tail_orbit 3 --signatures

``--signatures``: how many functions numba compiled, and every function compiled for more than
one signature with the argument types that differ (a literal constant or an int32 index makes
a signature of its own: docs/tech-notes.md §7).

The compile helper is left out (``MAGICA_COMPILE_HELPER=0``): everything compiles in this process.
"""
from __future__ import annotations

import collections
import os
import pathlib
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent


def repeated_signatures(signatures) -> dict[str, list[tuple[str, ...]]]:
    """{function: its distinct argument-type tuples} of the functions compiled for more than one
    signature; ``signatures`` is ``(function name, argument types as strings)`` per compile
    (also used by ``tests/test_jit_off.py``)."""
    seen: dict[str, set] = {}
    for name, args in signatures:
        seen.setdefault(name, set()).add(tuple(args))
    return {name: sorted(args) for name, args in seen.items() if len(args) > 1}


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    passes = "--passes" in argv
    signatures = "--signatures" in argv
    every = "--all" in argv
    argv = [a for a in argv if a not in ("--passes", "--signatures", "--all")]
    if not argv:
        print(__doc__)
        return 2
    scene_name = argv[0]
    frames = int(argv[1]) if len(argv) > 1 else 3
    sys.path.insert(0, str(ROOT))
    os.environ["MAGICA_COMPILE_HELPER"] = "0"   # every compile in this process, where the events are seen
    from numba.core import event

    seconds: dict[str, float] = collections.defaultdict(float)
    compiled: list[tuple[str, tuple[str, ...]]] = []   # (function, argument types) per compile

    class Listener(event.Listener):
        def __init__(self):
            self.started = {}

        def on_start(self, ev):
            self.started[id(ev.data["dispatcher"]), str(ev.data["args"])] = time.perf_counter()

        def on_end(self, ev):
            dispatcher = ev.data["dispatcher"]
            start = self.started.pop((id(dispatcher), str(ev.data["args"])), None)
            if start is not None:
                fn = dispatcher.py_func
                seconds[f"{fn.__module__}.{fn.__qualname__}"] += time.perf_counter() - start
                compiled.append((f"{fn.__module__}.{fn.__qualname__}", tuple(str(a) for a in ev.data["args"])))

    event.register("numba:compile", Listener())
    pass_seconds: dict[str, float] = collections.defaultdict(float)
    function_seconds: dict[str, float] = collections.defaultdict(float)
    llvm = [0.0, 0, None]   # seconds, calls, start of the current call
    llvm_seconds: dict[str, float] = collections.defaultdict(float)   # per function

    class Passes(event.Listener):
        """Exclusive pass times: a stack of (pass, function, start, seconds of nested passes)."""

        def __init__(self):
            self.stack = []

        def on_start(self, ev):
            self.stack.append([ev.data["name"], time.perf_counter(), 0.0])

        def on_end(self, ev):
            name, start, nested = self.stack.pop()
            spent = time.perf_counter() - start
            if self.stack:
                self.stack[-1][2] += spent
            pass_name, _, function = name.partition(" [")
            pass_seconds[pass_name] += spent - nested
            function_seconds[function.rstrip("]")] += spent - nested

    class Llvm(event.Listener):
        def on_start(self, ev):
            llvm[2] = time.perf_counter()

        def on_end(self, ev):
            spent = time.perf_counter() - llvm[2]
            llvm[0] += spent
            llvm[1] += 1
            if pass_stack.stack:   # the function whose compiler pass called into LLVM
                llvm_seconds[pass_stack.stack[-1][0].partition(" [")[2].rstrip("]")] += spent

    pass_stack = Passes()
    if passes:
        event.register("numba:run_pass", pass_stack)
        event.register("numba:llvm_lock", Llvm())
    wall, cpu = time.perf_counter(), time.process_time()
    from magica_py.config import load_scene
    from magica_py.runtime.player import Player
    from magica_py.solver.system import ClothSystem

    scene = load_scene(ROOT / "configs" / f"{scene_name}.yaml")
    player = Player.for_scene(scene)
    ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings).attach(player)
    player.run(frames)
    print(f"{scene_name}: wall {time.perf_counter() - wall:.1f} s, cpu {time.process_time() - cpu:.1f} s")
    if signatures:
        print(f"{len(compiled)} compiles of {len({name for name, _ in compiled})} functions")
        for name, sigs in sorted(repeated_signatures(compiled).items(), key=lambda kv: -len(kv[1])):
            differ = [i for i in range(len(sigs[0])) if len({sig[i] for sig in sigs}) > 1]
            print(f"{len(sigs):4d}  {name}: argument {', '.join(str(i) for i in differ)}")
            for sig in sigs:
                print(f"        {', '.join(sig[i] for i in differ)}")
        return 0
    if passes:
        print(f"inside LLVM: {llvm[0]:.1f} s over {llvm[1]} calls into llvmlite's binding; by function:")
        for name, s in sorted(llvm_seconds.items(), key=lambda kv: -kv[1])[:10]:
            print(f"{s:8.2f} s  {name}")
        print("exclusive seconds per compiler pass:")
        for name, s in sorted(pass_seconds.items(), key=lambda kv: -kv[1])[:8]:
            print(f"{s:8.2f} s  {name}")
        print(f"exclusive seconds per function ({len(function_seconds)} functions):")
        for name, s in sorted(function_seconds.items(), key=lambda kv: -kv[1])[:None if every else 25]:
            print(f"{s:8.2f} s  {name}")
        return 0
    for name, s in sorted(seconds.items(), key=lambda kv: -kv[1])[:40]:
        print(f"{s:8.2f} s  {name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
