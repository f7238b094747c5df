"""Where a first run's numba compile goes: per-function compile times of one scene's first
frames, with an empty kernel cache, from numba's documented event API (``numba:compile``).

    NUMBA_CACHE_DIR=$(mktemp -d) python benchmarks/compile_profile.py tail_orbit [FRAMES]

Times are inclusive (a function's compile includes the callees it compiles first), so read
the list as a tree: ``simulate_frame`` holds everything below it.
"""
from __future__ import annotations

import collections
import pathlib
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if not argv:
        print(__doc__)
        return 2
    scene_name = argv[0]
    frames = int(argv[1]) if len(argv) > 1 else 3
    sys.path.insert(0, str(ROOT))
    from numba.core import event

    seconds: dict[str, float] = collections.defaultdict(float)

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

    event.register("numba:compile", Listener())
    wall, cpu = time.perf_counter(), time.process_time()
    from magica_py.config import load_scene
    from magica_py.runtime.player import Player
    from magica_py.solver.system import ClothSystem

    scene = load_scene(ROOT / "configs" / f"{scene_name}.yaml")
    player = Player.for_scene(scene)
    ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings).attach(player)
    player.run(frames)
    print(f"{scene_name}: wall {time.perf_counter() - wall:.1f} s, cpu {time.process_time() - cpu:.1f} s")
    for name, s in sorted(seconds.items(), key=lambda kv: -kv[1])[:40]:
        print(f"{s:8.2f} s  {name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
