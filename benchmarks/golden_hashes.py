"""Golden hashes of the solver's results: the bit-identity check of every change.

    python benchmarks/golden_hashes.py            # print the hashes
    python benchmarks/golden_hashes.py --write    # store them in benchmarks/golden_hashes.json
    python benchmarks/golden_hashes.py --check    # compare with the stored ones (exit 1 if any differs)
    python benchmarks/golden_hashes.py --json     # every stage hash as JSON (tests/test_cpu_independence.py)

For each showcase scene (``configs/<name>.yaml``) the player runs ``--frames`` frames (200)
with the cloth system attached (faithful mode: the scenes' own settings, serial kernel, no
sink); then sha256 of the raw bytes of the final particle display positions
(``ClothSystem.particles.position``, float64) and of the bone transforms (the hierarchy's
local and world positions and rotations, float64) are taken. Any change of a single bit in
the solver's arithmetic changes them, so an optimisation that keeps them kept the maths.

The inputs of the solver are hashed stage by stage too, so that a difference says where it
comes from (docs/determinism.md):

* ``scene``: the rest pose after loading (rig generators, importers) and the collider set;
* ``model``: every field of the built cloth models (the build: proxy mesh, baselines,
  constraint data), one hash per field, taken of the teams' build models
  (``ClothSystem.models``) concatenated with global indices as the per-team solver's
  ``SolverModel`` did when the hashes were written (``solver_model``: its layout code,
  frozen in ``tests/reference_solver/solver/layout.py``), so that the stored hashes still
  name the build field that changed;
* ``animation``: the hierarchy's world pose after ``--frames`` frames of animation alone
  (drivers, clips and propagation, no cloth).

The sha256 of each scene file is stored too: when a config was edited since the hashes were
written, ``--check`` says so ("config changed") instead of blaming the solver; ``--config-dir``
runs the scenes from another folder (e.g. the committed configs exported with ``git show``).
"""
from __future__ import annotations

import argparse
import hashlib
import json
import pathlib
import platform
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent
GOLDEN = ROOT / "benchmarks" / "golden_hashes.json"
SCENES = ("tail_orbit", "character_walk", "crowd", "hitches_and_events")
# what each stage covers, for the failure message (in the order the data flows)
STAGES = (
    ("scene", "the rest pose and colliders after loading (config/, scene/rigs.py, io/ importers)"),
    ("model", "the built cloth model (build/: render setup, virtual mesh, proxy, constraints)"),
    ("animation", "the animated pose without cloth (scene/animation.py, io/clip.py, hierarchy propagation)"),
    ("particles", "the simulated particles (solver/)"),
    ("bones", "the bone transforms written back by the solver (solver/writeback.py)"),
)


def _sha(*arrays) -> str:
    import numpy as np

    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    return h.hexdigest()


def _pose(h) -> tuple:
    return h.local_position, h.local_rotation, h.world_position, h.world_rotation


def _model_hashes(model) -> dict[str, str]:
    """One short hash per numeric field of the solver model (a namedtuple of arrays)."""
    import numpy as np

    out = {}
    for name in model._fields:
        value = getattr(model, name)
        if isinstance(value, np.ndarray) and value.dtype.kind in "fiub":
            data = np.ascontiguousarray(value)
            out[name] = hashlib.sha256(data.tobytes() + str(data.dtype).encode()).hexdigest()[:16]
    return out


def solver_model(models):
    """The teams' build models (``ClothSystem.models``) as one ``SolverModel`` of global
    indices, the form the ``model`` stage hashes were written from: the per-team solver's
    layout (``tests/reference_solver/solver/layout.py``, frozen; the lane-form solver keeps
    the build models per team and packs them per block instead)."""
    if str(ROOT / "tests") not in sys.path:
        sys.path.insert(0, str(ROOT / "tests"))
    from reference_solver.solver.layout import SolverLayout

    layout = SolverLayout()
    for model in models:
        layout.add(model)
    return layout.model()


def scene_hashes(name: str, frames: int = 200, config_dir: pathlib.Path = ROOT / "configs") -> dict:
    from magica_py.config import load_scene
    from magica_py.runtime.player import Player
    from magica_py.solver.system import ClothSystem

    path = config_dir / f"{name}.yaml"
    # animation alone, on a scene of its own (the cloth system would write cloth bones)
    bare = load_scene(path)
    Player.for_scene(bare).run(frames)
    animation = _sha(*_pose(bare.hierarchy))

    scene = load_scene(path)
    h = scene.hierarchy
    c = scene.colliders
    rest = _sha(*_pose(h), h.lossy_scale, c.center, c.radius, c.end_radius, c.length)
    player = Player.for_scene(scene)
    system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings).attach(player)
    model = _model_hashes(solver_model(system.models))
    player.run(frames)
    return {"particles": _sha(system.particles.position),
            "bones": _sha(*_pose(h)),
            "stages": {"scene": rest, "model": model, "animation": animation},
            "config": hashlib.sha256(path.read_bytes()).hexdigest()}


def machine() -> str:
    """The facts a difference may come from: CPU, C library, numpy / numba and numpy's dispatch."""
    import numba
    import numpy as np

    cpu = platform.processor() or platform.machine()
    try:
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        from numpy.lib.introspect import opt_func_info
        simd = sorted({t for f in opt_func_info(func_name="arccos").values()
                       for d in f.values() for t in [d.get("current")] if t})
    except Exception:  # numpy < 2.1 has no introspection
        simd = ["?"]
    return (f"cpu {cpu}; {' '.join(platform.libc_ver())}; numpy {np.__version__} "
            f"(arccos dispatch {','.join(simd)}); numba {numba.__version__}")


def compare(name: str, expected: dict, got: dict) -> list[str]:
    """The stages whose hashes differ, each with what it covers (empty when identical).

    A difference is reported at the first stage where it appears; later stages that differ
    too are named as following from it."""
    lines = []
    first = None
    for stage, what in STAGES:
        if stage in ("particles", "bones"):
            want, have = expected.get(stage), got.get(stage)
        else:
            want = expected.get("stages", {}).get(stage)
            have = got.get("stages", {}).get(stage)
        if want is None:
            continue
        if want == have:
            continue
        detail = ""
        if stage == "model":
            fields = sorted(k for k in set(want) | set(have) if want.get(k) != have.get(k))
            detail = f" (fields: {', '.join(fields)})"
        if first is None:
            first = stage
            lines.append(f"{name}: first difference in stage '{stage}': {what}{detail}")
        else:
            lines.append(f"{name}:   stage '{stage}' differs too (may follow from '{first}'){detail}")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--scenes", nargs="+", default=list(SCENES))
    ap.add_argument("--config-dir", type=pathlib.Path, default=ROOT / "configs")
    mode = ap.add_mutually_exclusive_group()
    mode.add_argument("--check", action="store_true", help="compare with benchmarks/golden_hashes.json")
    mode.add_argument("--write", action="store_true", help="store the hashes in benchmarks/golden_hashes.json")
    mode.add_argument("--json", action="store_true", help="print every stage hash as JSON on stdout")
    args = ap.parse_args(argv)
    result = {name: scene_hashes(name, args.frames, args.config_dir) for name in args.scenes}
    if args.json:
        print(json.dumps(result, sort_keys=True))
        return 0
    stored = json.loads(GOLDEN.read_text()) if GOLDEN.exists() else {}
    key = f"frames={args.frames}"
    failures = []
    for name, hashes in result.items():
        line = f"{name:20s} particles {hashes['particles'][:16]}  bones {hashes['bones'][:16]}"
        if args.check:
            expected = stored.get(key, {}).get(name)
            if expected is None:
                line += "  NO GOLDEN"
                failures.append(f"{name}: no golden hashes for {key}")
            else:
                diff = compare(name, expected, hashes)
                if not diff:
                    line += "  ok"
                else:
                    line += "  DIFFERS"
                    if expected.get("config", hashes["config"]) != hashes["config"]:
                        diff.insert(0, f"{name}: the config changed since the hashes were written")
                    failures += diff
        print(line)
    if args.write:
        stored.setdefault(key, {}).update(result)
        GOLDEN.write_text(json.dumps(stored, indent=2, sort_keys=True) + "\n")
        print(f"written to {GOLDEN.relative_to(ROOT)}")
    if args.check:
        if failures:
            print("\n".join(failures))
            print(f"this machine: {machine()}")
            print("see docs/determinism.md for what is promised across machines")
        print("all identical" if not failures else f"{len({f.split(':')[0] for f in failures})} scene(s) differ")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    raise SystemExit(main())
