"""How much of each stage kernel LLVM vectorised: packed against scalar double instructions.

    NUMBA_CACHE_DIR=$(mktemp -d) python benchmarks/stage_vectors.py [SCENE] [--set KEY=VALUE ...]

The scene (``configs/SCENE.yaml``, default ``light_chains``) is built and run for a few frames;
then each stage driver of ``bench_stages.py`` that the scene uses is compiled for it and its
machine code (numba's ``inspect_asm``) is read: per stage, the number of scalar double
instructions (``...sd``) and of packed ones by register width (``xmm``: 2 doubles, ``ymm``: 4,
``zmm``: 8), and the calls left in it. The counts are of the code, not of what runs: a lane
loop that vectorised shows as packed instructions, its scalar remainder and the per-block work
around it as scalar ones. numba cannot show the code of a kernel it loaded from its cache, so run
it with an empty ``NUMBA_CACHE_DIR`` (it says so when a stage's code is not available).
"""
from __future__ import annotations

import argparse
import collections
import pathlib
import re
import sys
import warnings

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
ROOT = pathlib.Path(__file__).resolve().parent.parent
INSTRUCTION = re.compile(r"\bv?\w+?(pd|sd)\s[^\n]*?%([xyz])mm")


def counts(asm: str) -> collections.Counter:
    """Scalar (``sd``) and packed (``pd-x`` / ``pd-y`` / ``pd-z``) double instructions and calls."""
    c = collections.Counter()
    for kind, register in INSTRUCTION.findall(asm):
        c["sd" if kind == "sd" else f"pd-{register}"] += 1
    c["calls"] = len(re.findall(r"\bcall", asm))
    return c


def main(argv=None) -> int:
    import bench_stages as bs
    from magica_py.config import load_scene
    from magica_py.runtime.player import Player
    from magica_py.solver.system import ClothSystem

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", nargs="?", default="light_chains")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="scene override")
    args = ap.parse_args(argv)
    scene = load_scene(ROOT / "configs" / f"{args.scene}.yaml", overrides=args.set)
    player = Player.for_scene(scene)
    system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings).attach(player)
    player.run(3)
    T, h = system.tables, system._hierarchy
    quality, zones = system.stages.quality, system._wind_zones()
    print(f"{args.scene}: double instructions in each stage's code (scalar, packed by width) and calls")
    print(f"{'':5s} {'stage':32s} {'scalar':>7s} {'xmm':>6s} {'ymm':>6s} {'zmm':>6s} {'calls':>6s}")
    cached = 0
    for kind, stages in (("step", bs.STEP_STAGES), ("frame", bs.FRAME_STAGES)):
        for name, fn, switch in stages:
            if not bs._used(system, switch):
                continue
            fn(T, h, quality, zones, 1)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                c = counts("\n".join(fn.inspect_asm().values()))
            if sum(c.values()) == 0:
                cached += 1
                print(f"{kind:5s} {name:32s} (loaded from the cache: no code to read)")
                continue
            print(f"{kind:5s} {name:32s} {c['sd']:7d} {c['pd-x']:6d} {c['pd-y']:6d} {c['pd-z']:6d} {c['calls']:6d}")
    if cached:
        print("run with an empty NUMBA_CACHE_DIR to see the stages loaded from the cache")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
