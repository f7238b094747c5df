"""Golden hashes of the solver's results: the bit-identity check of every speed change.

    python benchmarks/golden_hashes.py            # print the hashes
    python benchmarks/golden_hashes.py --write    # store them in benchmarks/golden_hashes.json
    python benchmarks/golden_hashes.py --check    # compare with the stored ones (exit 1 if any differs)

For each showcase scene (``configs/<name>.yaml``) the player runs ``--frames`` frames (200)
with the cloth system attached (faithful mode: the scenes' own settings, serial kernel, no
sink); then sha256 of the raw bytes of the final particle display positions
(``ClothSystem.particles.position``, float64) and of the bone transforms (the hierarchy's
local and world positions and rotations, float64) are taken. Any change of a single bit in
the solver's arithmetic changes them, so an optimisation that keeps them kept the maths.

The sha256 of each scene file is stored too: when a config was edited since the hashes were
written, ``--check`` says so ("config changed") instead of blaming the solver; ``--config-dir``
runs the scenes from another folder (e.g. the committed configs exported with ``git show``).
"""
from __future__ import annotations

import argparse
import hashlib
import json
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent
GOLDEN = ROOT / "benchmarks" / "golden_hashes.json"
SCENES = ("tail_orbit", "character_walk", "crowd", "hitches_and_events")


def _sha(*arrays) -> str:
    import numpy as np

    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    return h.hexdigest()


def scene_hashes(name: str, frames: int = 200, config_dir: pathlib.Path = ROOT / "configs") -> dict:
    from magica_py.config import load_scene
    from magica_py.runtime.player import Player
    from magica_py.solver.system import ClothSystem

    path = config_dir / f"{name}.yaml"
    scene = load_scene(path)
    player = Player.for_scene(scene)
    system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings).attach(player)
    player.run(frames)
    h = scene.hierarchy
    return {"particles": _sha(system.particles.position),
            "bones": _sha(h.local_position, h.local_rotation, h.world_position, h.world_rotation),
            "config": hashlib.sha256(path.read_bytes()).hexdigest()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--scenes", nargs="+", default=list(SCENES))
    ap.add_argument("--config-dir", type=pathlib.Path, default=ROOT / "configs")
    mode = ap.add_mutually_exclusive_group()
    mode.add_argument("--check", action="store_true", help="compare with benchmarks/golden_hashes.json")
    mode.add_argument("--write", action="store_true", help="store the hashes in benchmarks/golden_hashes.json")
    args = ap.parse_args(argv)
    stored = json.loads(GOLDEN.read_text()) if GOLDEN.exists() else {}
    key = f"frames={args.frames}"
    result = {name: scene_hashes(name, args.frames, args.config_dir) for name in args.scenes}
    failures = 0
    for name, hashes in result.items():
        line = f"{name:20s} particles {hashes['particles'][:16]}  bones {hashes['bones'][:16]}"
        if args.check:
            expected = stored.get(key, {}).get(name)
            if expected is None:
                line += "  NO GOLDEN"
                failures += 1
            elif all(expected.get(k) == hashes[k] for k in ("particles", "bones")):
                line += "  ok"
            else:
                bad = [k for k in ("particles", "bones") if hashes[k] != expected.get(k)]
                line += "  DIFFERS (" + ", ".join(bad) + ")"
                if expected.get("config", hashes["config"]) != hashes["config"]:
                    line += ": the config changed since the hashes were written"
                failures += 1
        print(line)
    if args.write:
        stored.setdefault(key, {}).update(result)
        GOLDEN.write_text(json.dumps(stored, indent=2, sort_keys=True) + "\n")
        print(f"written to {GOLDEN.relative_to(ROOT)}")
    if args.check:
        print("all identical" if failures == 0 else f"{failures} scene(s) differ")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    raise SystemExit(main())
