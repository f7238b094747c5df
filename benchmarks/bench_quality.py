"""Quality mode against faithful mode (issue 8): frame-rate spread, stretch, penetration,
convergence and cost, for every inextensibility candidate, on the same scenes.

    python benchmarks/bench_quality.py                   # everything (a few minutes)
    python benchmarks/bench_quality.py --part candidates # stretch/penetration/cost per candidate
    python benchmarks/bench_quality.py --part spread     # frame-rate spread 30/60/144/240 fps
    python benchmarks/bench_quality.py --part convergence

Built on the bench harness (``magica_py.bench.variants``: a variant is a scene + parameter
overrides + frequency + fps). Scenes: the tail and character showcases, the hard cases
``violent_50rad`` (50 rad/s spin) and ``chain20_g100`` (``extreme_parameters`` with a 20-bone
1 m chain and gravity 100 m/s^2 written past the [0, 20] validation range, as the stability
harness does). Costs are ms per frame of the whole player loop (median of interleaved runs).
"""
from __future__ import annotations

import argparse
import math
import pathlib
import sys
import tempfile

import numpy as np
import yaml

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from magica_py.bench import metrics as M  # noqa: E402
from magica_py.bench.reference import fit_order  # noqa: E402
from magica_py.bench.variants import Variant, resolve_scene_path, run_variant, time_interleaved  # noqa: E402

FAITHFUL = {}
QUALITY = {"solver.mode": "quality"}
CANDIDATES = {
    "faithful": FAITHFUL,
    "frequency_consistent": {"solver.rate_mode": "frequency_consistent"},
    "q_none": {**QUALITY, "solver.inextensibility": "none", "solver.distance_velocity": "attenuated"},
    "q_full_velocity": {**QUALITY, "solver.inextensibility": "none", "solver.distance_velocity": "full"},
    "q_iterations4": {**QUALITY, "solver.inextensibility": "iterations", "solver.distance_iterations": 4},
    "q_iterations8": {**QUALITY, "solver.inextensibility": "iterations", "solver.distance_iterations": 8},
    "q_tether": {**QUALITY, "solver.inextensibility": "tether"},
    "q_ftl": {**QUALITY, "solver.inextensibility": "ftl"},
    "q_ftl_tether": {**QUALITY, "solver.inextensibility": "ftl_tether"},
    "q_ftl_edges2": {**QUALITY, "solver.inextensibility": "ftl_edges", "solver.distance_iterations": 2},
    "q_ftl_edges4": {**QUALITY, "solver.inextensibility": "ftl_edges", "solver.distance_iterations": 4},
    "q_no_collision_last": {**QUALITY, "solver.collision_last": "disabled"},
    "quality": QUALITY,
}
FPS_SET = (30, 60, 144, 240)


def chain20_scene(folder: pathlib.Path) -> str:
    """``configs/hard/extreme_parameters.yaml`` with a 20-bone, 1 m chain."""
    doc = yaml.safe_load((ROOT / "configs" / "hard" / "extreme_parameters.yaml").read_text())
    doc["scene"]["name"] = "chain20_g100"
    doc["scene"]["duration"] = 4.0
    chain = doc["rigs"][0]["parts"][0]["chain"]
    chain["bones"] = 20
    chain["length"] = 1.0
    path = folder / "chain20_g100.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return str(path)


def tail_sphere_scene(folder: pathlib.Path, mode: str = "point") -> str:
    """``configs/tail_orbit.yaml`` at 1 rev/s with a sphere (r 0.12 m) on the tail's path. The
    fixed root passes 5 cm from the sphere's centre, inside it: the first particles are pushed
    out while their root is inside, so collision and inextensibility conflict (hard case)."""
    doc = yaml.safe_load((ROOT / "configs" / "tail_orbit.yaml").read_text())
    doc["scene"]["name"] = f"tail_sphere_{mode}"
    doc["animation"][0]["orbit"]["period"] = 1.0
    doc["rigs"][0]["bones"].append({"name": "ball", "position": [-0.45, 0.95, 0.2]})
    doc["colliders"] = [{"name": "ball_col", "transform": "ball", "sphere": {"radius": 0.12}}]
    doc["cloths"][0]["colliders"] = ["ball_col"]
    doc["cloths"][0]["collision_mode"] = mode
    doc.pop("output", None)
    path = folder / f"tail_sphere_{mode}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return str(path)


def scenes(folder: pathlib.Path) -> dict:
    """name -> (yaml path, raw parameter overrides, duration s)."""
    return {
        "tail_orbit": (resolve_scene_path("tail_orbit"), {}, 4.0),
        "character_walk": (resolve_scene_path("character_walk"), {}, 4.0),
        "violent_50rad": (str(ROOT / "configs" / "hard" / "violent_50rad.yaml"), {}, 3.0),
        "chain20_g100": (chain20_scene(folder), {"gravity": 100.0}, 3.0),
        "tail_sphere": (tail_sphere_scene(folder, "point"), {}, 4.0),
        "tail_sphere_edge": (tail_sphere_scene(folder, "edge"), {}, 4.0),
    }


def variant(scene, name, params, frequency=None, fps=None) -> Variant:
    path, raw, duration = scene
    return Variant(f"{pathlib.Path(path).stem}/{name}", path, parameters=dict(params), raw_parameters=dict(raw),
                   frequency=frequency, fps=fps, duration=duration, family=name)


def run_candidates(all_scenes, names, repeats, say):
    rows = []
    for scene_name, scene in all_scenes.items():
        variants = [variant(scene, n, CANDIDATES[n]) for n in names]
        stats = []
        for v in variants:
            r = run_variant(v, record_positions=False)
            stats.append((100 * float(r.edge_stretch.max()), 100 * float(r.root_stretch.max()),
                          1000 * float(r.penetration.max()), bool(r.non_finite.any())))
        timing = time_interleaved(variants, repeats=repeats)
        base = timing[0][2]
        for n, s, (med, _rate, fastest) in zip(names, stats, timing):
            rows.append(dict(scene=scene_name, candidate=n, edge=s[0], root=s[1], pen=s[2], nan=s[3],
                             ms=1000 * med, ms_min=1000 * fastest, rel=fastest / base))
            say(f"{scene_name:15s} {n:20s} edge {s[0]:7.2f} %  root {s[1]:7.2f} %  pen {s[2]:6.2f} mm  "
                f"{1000 * med:.3f} ms/frame (min {1000 * fastest:.3f}, x{fastest / base:.2f}){'  NaN' if s[3] else ''}")
    return rows


COMMON_PERIOD = 1.0 / 6.0   # s: every 30 / 60 / 144 / 240 fps run has a frame at these times


def spread_at_common_times(records, length, start=0.0, period=COMMON_PERIOD) -> float:
    """Largest distance between the tips of runs at different frame rates at the times where
    every run has a frame (multiples of ``period`` from ``start`` on; no interpolation between
    frames), over ``length``. ``records``: ``[(times (F,), tips (F, K, 3))]``."""
    end = min(float(t[-1]) for t, _ in records)
    query = np.arange(max(1, math.ceil(start / period - 1e-9)), int(end / period + 1e-9) + 1) * period
    sampled = []
    for times, tips in records:
        idx = np.searchsorted(times, query - 1e-7)
        if np.any(np.abs(times[idx] - query) > 1e-6):
            raise ValueError("a run has no frame at a common time")
        sampled.append(tips[idx])
    worst = 0.0
    for a in range(len(sampled)):
        for b in range(a + 1, len(sampled)):
            worst = max(worst, float(np.linalg.norm(sampled[a] - sampled[b], axis=-1).max()))
    return worst / length


def frame_rate_records(scene, params, frequency=None):
    """``[(times, tips)]`` for the render rates of ``FPS_SET``, and the chain length."""
    recs = []
    length = None
    for fps in FPS_SET:
        r = run_variant(variant(scene, "fps", params, frequency=frequency, fps=fps), record_positions=False)
        recs.append((r.times, r.tips))
        length = r.geometry.chain_length
    return recs, length


def frame_rate_spread(scene, params, frequency=None) -> tuple[float, float, float]:
    """Spread (% of the chain) at common frame times over the whole run and from 1 s on
    (after the start-up transient of the first reset), and the bench's interpolated metric."""
    recs, length = frame_rate_records(scene, params, frequency)
    return (100 * spread_at_common_times(recs, length), 100 * spread_at_common_times(recs, length, start=1.0),
            100 * M.frame_rate_spread(recs, length))


def convergence(scene, params, frequencies, reference_frequency, say) -> dict:
    """RMS error (% chain, all frames) against the same parameters at ``reference_frequency``."""
    ref = run_variant(variant(scene, "ref", params, frequency=reference_frequency))
    g = ref.geometry
    out = {}
    for f in frequencies:
        r = run_variant(variant(scene, "conv", params, frequency=f))
        rms, _mx = M.frame_errors(r.positions, ref.positions, g.length_scale, g.moving)
        out[f] = 100 * float(np.sqrt(np.mean(rms ** 2)))
        say(f"    {f:5d} Hz: RMS error {out[f]:.3f} % of the chain")
    order, r2 = fit_order(list(out), list(out.values()))
    say(f"    fitted order p = {order:.2f} (R^2 {r2:.2f})")
    return {"errors": out, "order": order, "r2": r2}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", default="all", choices=("all", "candidates", "spread", "convergence", "errors"))
    ap.add_argument("--candidates", default=",".join(CANDIDATES))
    ap.add_argument("--scenes", default=None, help="comma-separated subset of the scenes")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args(argv)

    def say(text):
        print(text, flush=True)

    with tempfile.TemporaryDirectory() as tmp:
        all_scenes = scenes(pathlib.Path(tmp))
        if args.scenes:
            all_scenes = {k: v for k, v in all_scenes.items() if k in args.scenes.split(",")}
        if args.part in ("all", "candidates"):
            say("## candidates (90 Hz, scene fps): max edge stretch, max root stretch, max penetration, cost")
            run_candidates(all_scenes, [c for c in args.candidates.split(",") if c], args.repeats, say)
        if args.part in ("all", "spread"):
            say("## frame-rate spread, 90 Hz, 30/60/144/240 fps, % of chain length: at common frame times "
                "(whole run | from 1 s on) and the bench metric (tips interpolated every 1/120 s)")
            for name in ("tail_orbit", "character_walk"):
                if name not in all_scenes:
                    continue
                for mode, params in (("faithful", FAITHFUL), ("quality", QUALITY),
                                     ("quality_smoothing_0", {**QUALITY, "inertia.movement_inertia_smoothing": 0.0})):
                    whole, late, bench = frame_rate_spread(all_scenes[name], params)
                    say(f"{name:15s} {mode:20s} {whole:7.3f} | {late:7.3f}   bench {bench:7.3f}")
        if args.part in ("all", "errors"):
            say("## trajectory error at 90 Hz against the same candidate at 1440 Hz (RMS, % of the chain, 2 s)")
            for name in ("tail_orbit", "character_walk", "violent_50rad"):
                if name not in all_scenes:
                    continue
                s = all_scenes[name]
                s = (s[0], s[1], 2.0)
                for cand in [c for c in args.candidates.split(",") if c]:
                    params = CANDIDATES[cand]
                    ref = run_variant(variant(s, "ref", params, frequency=1440))
                    run = run_variant(variant(s, "e", params, frequency=90))
                    g = ref.geometry
                    rms, _mx = M.frame_errors(run.positions, ref.positions, g.length_scale, g.moving)
                    say(f"{name:15s} {cand:20s} {100 * float(np.sqrt(np.mean(rms ** 2))):7.2f} %")
        if args.part in ("all", "convergence"):
            say("## convergence: RMS error against the same mode at 1440 Hz (all frames)")
            for name in ("tail_orbit", "character_walk"):
                if name not in all_scenes:
                    continue
                s = all_scenes[name]
                s = (s[0], s[1], 2.0)
                for mode, params in (("frequency_consistent", CANDIDATES["frequency_consistent"]),
                                     ("quality", QUALITY)):
                    say(f"  {name} / {mode}")
                    convergence(s, params, (60, 90, 150, 360), 1440, say)
    return 0


if __name__ == "__main__":
    sys.exit(main())
