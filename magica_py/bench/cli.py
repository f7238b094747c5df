"""``magica-py bench`` (speed against error) and ``magica-py stability`` (hard cases).

Both write to the git-ignored ``reports/`` folder and print a progress bar on a terminal.

bench, per showcase scene (``--scenes``, default tail_orbit and character_walk):

1. converged reference: 1440 Hz frequency-consistent, checked against 2880 Hz (residual);
2. sweep: every frequency (``--frequencies``) x mode (``magica``, ``frequency_consistent``),
   run as jobs of the batch machinery (``magica_py.batch.Executor``: in this process, or on
   Dask workers with ``--workers N`` / ``--scheduler ADDRESS``):
   time per frame (median of ``--repeats`` runs after JIT warm-up), particle-steps/s,
   RMS / max position error over the frames the reference resolves, stretch, penetration,
   speed and settling;
3. frame-rate spread (30 / 60 / 144 / 240 fps at the scene frequency) per mode;
4. the plain-numpy baseline of the single tail, side by side with the solver;
5. feature cost on the character (collision point / edge, bending, angle limit, colliders
   0 / 4 / 16) and the crowd's particle-steps per second.

Outputs: ``bench.md``, ``bench.csv``, ``pareto.png`` in ``--out``.
"""
from __future__ import annotations

import argparse
import math
import platform
import sys
import time

import numpy as np

MODES = ("magica", "frequency_consistent")
FREQUENCIES = (30, 45, 60, 90, 120, 150, 180, 360, 720)
SCENES = ("tail_orbit", "character_walk")
FPS_SET = (30, 60, 144, 240)
REST_SPEED = 0.02            # m/s: "at rest" for the settling time
ENVELOPE_WINDOW = 15         # frames of running maximum for the kinetic-energy envelope


class Progress:
    """Progress over a known total of frames, drawn with the CLI's progress bar."""

    def __init__(self, total: int, quiet: bool = False):
        from magica_py.runner import FrameProgress

        self.bar = None if quiet else FrameProgress(total, delay=0.5)
        self.done = 0
        self.base = 0

    def run_callback(self):
        self.base = self.done

        def cb(done, total):
            self.done = self.base + done
            if self.bar is not None:
                self.bar.update(self.done)
        return cb

    def add(self, frames: int) -> None:
        self.done += frames
        if self.bar is not None:
            self.bar.update(self.done)

    def close(self):
        if self.bar is not None:
            self.bar.close()


def _variant_frames(variant) -> int:
    from magica_py.bench.variants import prepare

    return prepare(variant).frames


# ----------------------------------------------------------------------------- bench
def main_bench(argv) -> int:
    p = argparse.ArgumentParser(prog="magica-py bench", description=__doc__.replace("``", ""),
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenes", default=",".join(SCENES), help="comma-separated showcase scenes or YAML paths")
    p.add_argument("--frequencies", default=",".join(map(str, FREQUENCIES)), help="simulation Hz to sweep")
    p.add_argument("--modes", default=",".join(MODES), help="parameter modes (solver.rate_mode values)")
    p.add_argument("--family", action="append", default=[], metavar="NAME:KEY=VALUE[,KEY=VALUE...]",
                   help="an extra series swept like the modes, e.g. a quality-mode candidate: "
                        "'tight_tether:solver.rate_mode=frequency_consistent,tether.distance_compression=0.1' "
                        "(values parsed as YAML; repeatable)")
    p.add_argument("--repeats", type=int, default=9, help="timed runs per variant (median)")
    p.add_argument("--duration", type=float, default=None, help="seconds per run (default: the scene's)")
    p.add_argument("--out", default=None, help="report folder (default: reports/ in the current folder)")
    p.add_argument("--skip", default="", help="comma-separated parts to skip: fps,numpy,features,crowd")
    p.add_argument("--workers", type=int, default=0, metavar="N",
                   help="run the sweep's runs on a local Dask cluster of N workers (default 0: in this process; "
                        "the timings always run here, one at a time)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="run the sweep's runs on an existing Dask cluster")
    p.add_argument("--quiet", "-q", action="store_true")
    args = p.parse_args(argv)
    from magica_py.batch.executor import Executor

    executor = Executor(workers=None if args.scheduler else args.workers, scheduler=args.scheduler)
    with executor:
        return _bench(args, executor)


def sweep_job(item):
    """One run of the frequency sweep (a batch job): the variant's trajectory against the
    reference's; returns (run without positions, RMS error per frame, max error per frame,
    kinetic-energy envelope error)."""
    from magica_py.bench import metrics as M
    from magica_py.bench.variants import run_variant

    variant, ref_positions, length_scale, moving, team, ref_energy = item
    run = run_variant(variant)
    err_rms, err_max = M.frame_errors(run.positions, ref_positions, length_scale, moving)
    energy = M.kinetic_envelope(run.positions, run.times, moving, team, ENVELOPE_WINDOW)
    run.positions = None                  # keep memory flat over the sweep (and the result small)
    envelope = float(np.sqrt(np.mean((energy - ref_energy) ** 2))) / max(float(ref_energy.max()), 1e-12)
    return run, err_rms, err_max, envelope


def _bench(args, executor) -> int:
    from magica_py.bench import metrics as M
    from magica_py.bench import report as R
    from magica_py.bench.reference import CHECK_FREQUENCY, REFERENCE_FREQUENCY, fit_order, resolved_error
    from magica_py.bench.variants import Variant, resolve_scene_path, run_variant, time_interleaved

    out = R.default_report_dir() if args.out is None else __import__("pathlib").Path(args.out)
    scenes = [s for s in args.scenes.split(",") if s]
    freqs = [int(f) for f in args.frequencies.split(",") if f]
    modes = [m for m in args.modes.split(",") if m]
    skip = set(s for s in args.skip.split(",") if s)
    families = {m: {"solver.rate_mode": m} for m in modes}
    for text in args.family:
        name, params = parse_family(text)
        families[name] = params
    started = time.perf_counter()

    def say(text):
        if not args.quiet:
            print(text, file=sys.stderr, flush=True)

    say("magica-py bench: JIT warm-up (compiles the solver unless the numba cache is warm) ...")
    t0 = time.perf_counter()
    run_variant(Variant("warmup", resolve_scene_path("tail_orbit"), duration=0.1), record_positions=False)
    say(f"  warm-up {time.perf_counter() - t0:.1f} s")

    rows, orders, spreads, residuals, extra = [], [], [], [], {}
    for scene_name in scenes:
        path = resolve_scene_path(scene_name)
        base = Variant(scene_name, path, duration=args.duration)
        ref_v = base.with_(label=f"{scene_name}@ref", frequency=REFERENCE_FREQUENCY,
                           parameters={"solver.rate_mode": "frequency_consistent"}, family="reference")
        frames = _variant_frames(ref_v)
        sweep = [base.with_(label=f"{scene_name}/{m}/{f}", frequency=f, parameters=dict(params), family=m)
                 for m, params in families.items() for f in freqs]
        total = frames * (2 + len(sweep) * (1 + args.repeats))
        say(f"{scene_name}: reference {REFERENCE_FREQUENCY} Hz, check {CHECK_FREQUENCY} Hz, {len(sweep)} variants, "
            f"{frames} frames each")
        progress = Progress(total, args.quiet)
        ref = run_variant(ref_v, progress=progress.run_callback())
        check = run_variant(ref_v.with_(label=f"{scene_name}@check", frequency=CHECK_FREQUENCY),
                            progress=progress.run_callback())
        g = ref.geometry
        moving = g.moving
        ref_energy = M.kinetic_envelope(ref.positions, ref.times, moving, g.team, ENVELOPE_WINDOW)
        check_energy = M.kinetic_envelope(check.positions, check.times, moving, g.team, ENVELOPE_WINDOW)
        energy_residual = float(np.sqrt(np.mean((check_energy - ref_energy) ** 2))) / max(float(ref_energy.max()), 1e-12)
        res_rms, res_max = M.frame_errors(check.positions, ref.positions, g.length_scale, moving)
        residuals.append({"scene": scene_name, "residual_rms": float(np.sqrt(np.mean(res_rms ** 2))) * 100,
                          "residual_max": float(res_max.max()) * 100, "chain_length": g.chain_length,
                          "frames": ref.frames, "ref_stretch": float(ref.edge_stretch.max()) * 100,
                          "energy_residual": 100 * energy_residual})
        # the sweep's runs are jobs of the batch machinery (magica_py.batch.Executor): in this
        # process by default, on a LocalCluster with --workers N or a cluster with --scheduler
        runs = [None] * len(sweep)
        items = [(v, ref.positions, g.length_scale, moving, g.team, ref_energy) for v in sweep]
        for i, (run, err_rms, err_max, envelope) in executor.map(sweep_job, items, key_prefix="bench-sweep"):
            runs[i] = (sweep[i], run, err_rms, err_max, envelope)
            progress.add(frames)
        timings = time_interleaved(sweep, repeats=args.repeats, progress=lambda v: progress.add(frames))
        for (v, run, err_rms, err_max, envelope), (sec, rate, fastest) in zip(runs, timings):
            window = resolved_error(err_rms, err_max, res_rms)
            settle = M.settling_time(run.display_speed, run.times, REST_SPEED)
            rows.append({
                "scene": scene_name, "family": v.family, "frequency": run.frequency,
                "ms_per_frame": 1000 * sec, "particle_steps_per_s": rate, "ms_per_frame_min": 1000 * fastest,
                "rms_error": 100 * window.rms if window.resolved else None,
                "max_error": 100 * window.max if window.resolved else None,
                "coverage": 100 * window.coverage,
                "rms_error_all": 100 * float(np.sqrt(np.mean(err_rms ** 2))),
                "max_edge_stretch": 100 * float(run.edge_stretch.max()),
                "max_root_stretch": 100 * float(run.root_stretch.max()),
                "max_penetration_mm": 1000 * float(run.penetration.max()),
                "max_speed": float(run.state_speed.max()),
                "energy_envelope": 100 * envelope,
                "settle_s": settle,
            })
        progress.close()
        for m in families:
            sel = [r for r in rows if r["scene"] == scene_name and r["family"] == m]
            order, r2 = fit_order([r["frequency"] for r in sel],
                                  [r["rms_error"] if r["rms_error"] is not None else math.nan for r in sel])
            order_all, r2_all = fit_order([r["frequency"] for r in sel], [r["rms_error_all"] for r in sel])
            orders.append({"scene": scene_name, "mode": m, "order": order, "r2": r2,
                           "points": sum(1 for r in sel if r["rms_error"] is not None),
                           "order_all_frames": order_all, "r2_all": r2_all})
        if "fps" not in skip:
            for m, params in families.items():
                recs = []
                for fps in FPS_SET:
                    v = base.with_(label=f"{scene_name}/{m}/fps{fps}", fps=fps, parameters=dict(params))
                    run = run_variant(v, record_positions=False)
                    recs.append((run.times, run.tips))
                spreads.append({"scene": scene_name, "mode": m,
                                "spread": 100 * M.frame_rate_spread(recs, g.chain_length)})
                say(f"  frame-rate spread {scene_name} / {m}: {spreads[-1]['spread']:.2f} % of the chain")

    if "numpy" not in skip:
        extra["numpy"] = numpy_comparison(args.repeats, say)
    if "features" not in skip:
        extra["features"] = feature_costs(args.repeats, say)
    if "crowd" not in skip:
        extra["crowd"] = crowd_speed(say)

    out.mkdir(parents=True, exist_ok=True)
    R.write_csv(out / "bench.csv", rows, R.BENCH_COLUMNS + (("ms_per_frame_min", "", ""), ("rms_error_all", "", "")))
    R.pareto_plot(out / "pareto.png", rows)
    text = bench_markdown(rows, orders, spreads, residuals, extra, time.perf_counter() - started)
    (out / "bench.md").write_text(text)
    if not args.quiet:
        print(text)
        print(f"\nwritten: {out / 'bench.md'}, {out / 'bench.csv'}, {out / 'pareto.png'}")
    return 0


def parse_family(text: str) -> tuple[str, dict]:
    """``NAME:KEY=VALUE[,KEY=VALUE...]`` -> (NAME, {KEY: VALUE}); values are YAML."""
    import yaml

    if ":" not in text:
        raise SystemExit(f"magica-py bench: --family {text!r}: expected NAME:KEY=VALUE[,KEY=VALUE...]")
    name, rest = text.split(":", 1)
    params = {}
    for item in filter(None, rest.split(",")):
        if "=" not in item:
            raise SystemExit(f"magica-py bench: --family {text!r}: {item!r} is not KEY=VALUE")
        key, value = item.split("=", 1)
        params[key.strip()] = yaml.safe_load(value)
    return name.strip(), params


def numpy_comparison(repeats: int, say) -> dict:
    """The single tail: magica_py's whole frame loop against the plain-numpy step."""
    from magica_py.bench.numpy_baseline import run_numpy_tail
    from magica_py.bench.variants import Variant, load_variant_scene, resolve_scene_path, time_once

    v = Variant("tail_orbit/numpy", resolve_scene_path("tail_orbit"), frequency=90)
    ours_samples, walls, numpy_only = [], [], []
    for _ in range(max(1, repeats)):          # alternate the two so that machine load hits both
        ours_samples.append(time_once(v))
        scene = load_variant_scene(v)
        out = run_numpy_tail(scene, scene.settings.frame_count())
        walls.append(float(np.mean(out["wall"])))
        numpy_only.append(float(np.mean(out["numpy_wall"])))
    ours = float(np.median([o[0] for o in ours_samples]))
    rate = float(np.median([o[1] for o in ours_samples]))
    theirs = float(np.median(walls))
    result = {"ours_ms": 1000 * ours, "numpy_ms": 1000 * theirs, "numpy_step_ms": 1000 * float(np.median(numpy_only)),
              "ratio": theirs / ours if ours > 0 else math.nan, "ours_steps_per_s": rate}
    say(f"  numpy baseline: {result['numpy_ms']:.3f} ms/frame vs magica_py {result['ours_ms']:.3f} ms/frame "
        f"(x{result['ratio']:.1f})")
    return result


EXTRA_COLLIDERS = [
    f"{{name: extra_{i}, transform: {bone}, center: [{x}, {y}, 0.05], sphere: {{radius: 0.04}}}}"
    for i, (bone, x, y) in enumerate([("leg_l", 0, -0.1), ("leg_l", 0, -0.3), ("knee_l", 0, -0.1),
                                      ("leg_r", 0, -0.1), ("leg_r", 0, -0.3), ("knee_r", 0, -0.1),
                                      ("hips", 0.1, 0), ("hips", -0.1, 0), ("spine", 0, 0.05),
                                      ("chest", 0.1, 0.1), ("chest", -0.1, 0.1), ("neck", 0, 0.05)])]


def feature_costs(repeats: int, say) -> list[dict]:
    """Time per frame of the character scene with one feature changed at a time."""
    from magica_py.bench.variants import Variant, resolve_scene_path, time_interleaved

    path = resolve_scene_path("character_walk")
    base = Variant("character", path, frequency=90, family="feature")
    base_cols = "[head_col, thigh_l, thigh_r, ground]"
    all_names = "[head_col, thigh_l, thigh_r, ground, " + ", ".join(f"extra_{i}" for i in range(12)) + "]"
    colliders_16 = (
        "colliders=[{name: head_col, transform: head, center: [0, 0.08, 0], sphere: {radius: 0.11}}, "
        "{name: thigh_l, transform: leg_l, capsule: {radius: 0.07, end_radius: 0.055, length: 0.45, direction: y, "
        "aligned_on_center: false}}, {name: thigh_r, transform: leg_r, capsule: {radius: 0.07, end_radius: 0.055, "
        "length: 0.45, direction: y, aligned_on_center: false}}, {name: ground, position: [0, 0, 0], plane: {}}, "
        + ", ".join(EXTRA_COLLIDERS) + "]")
    cases = [
        ("point collision, 4 colliders (scene as is)", base),
        ("edge collision", base.with_(parameters={"collider_collision.mode": "edge"})),
        ("collision off (0 colliders)", base.with_(parameters={"collider_collision.mode": "none"})),
        ("16 colliders, both cloths", base.with_(overrides=(colliders_16, f"cloths.hair.colliders={all_names}",
                                                             f"cloths.skirt.colliders={all_names}"))),
        ("bending off", base.with_(parameters={"triangle_bending.stiffness": 0.0})),
        ("angle limit off", base.with_(parameters={"angle_limit.use": False})),
        ("angle restoration off", base.with_(parameters={"angle_restoration.use": False})),
    ]
    del base_cols
    timings = time_interleaved([v for _, v in cases], repeats=repeats)
    rows = []
    ref_min = timings[0][2]
    for (label, _), (sec, rate, fastest) in zip(cases, timings):
        rows.append({"feature": label, "ms_per_frame": 1000 * sec, "ms_min": 1000 * fastest,
                     "relative": fastest / ref_min, "steps_per_s": rate})
        say(f"  feature cost: {label}: {1000 * sec:.3f} ms/frame (min {1000 * fastest:.3f})")
    return rows


def crowd_speed(say) -> dict:
    from magica_py.bench.variants import Variant, resolve_scene_path, time_variant

    v = Variant("crowd", resolve_scene_path("crowd"), frequency=90, duration=1.0)
    ms, rate = time_variant(v, repeats=1)
    say(f"  crowd: {1000 * ms:.2f} ms/frame, {rate:.3g} particle-steps/s")
    return {"ms_per_frame": 1000 * ms, "steps_per_s": rate}


def machine_description() -> str:
    import os

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    import numba

    return (f"{cpu}, {os.cpu_count()} logical cores (shared), Python {platform.python_version()}, "
            f"numpy {np.__version__}, numba {numba.__version__}")


def bench_markdown(rows, orders, spreads, residuals, extra, elapsed) -> str:
    from magica_py.bench import report as R

    lines = [f"# magica-py bench ({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())})", "",
             f"Machine: {machine_description()}. Wall time of the whole run: {elapsed:.0f} s.", "",
             "Errors are % of the chain length, against the same scene at 1440 Hz (frequency-consistent), over "
             "the frames where the 1440-vs-2880 Hz residual is under a tenth of the reported error ('window'); "
             "'-' means no frame qualifies (the reference does not resolve that error). The energy envelope is the "
             "running maximum over 15 frames of the kinetic energy of each cloth's own swing (team mean velocity "
             "removed); its error is RMS over frames, % of the reference's peak.", "",
             "## References", "",
             "| scene | chain length (m) | frames | residual RMS (% L) | residual max (% L) | ref max edge stretch (%) "
             "| energy envelope residual (% of peak) |",
             "|---|---|---|---|---|---|---|"]
    for r in residuals:
        lines.append(f"| {r['scene']} | {r['chain_length']:.3f} | {r['frames']} | {r['residual_rms']:.3g} | "
                     f"{r['residual_max']:.3g} | {r['ref_stretch']:.2f} | {r['energy_residual']:.2g} |")
    lines += ["", "## Sweep", "", R.markdown_table(rows, R.BENCH_COLUMNS), "",
              "## Observed convergence order (error ~ h^p, h = 1/frequency)", "",
              "| scene | mode | p (resolved window) | R^2 | points | p (all frames) | R^2 |", "|---|---|---|---|---|---|---|"]
    for o in orders:
        lines.append(f"| {o['scene']} | {o['mode']} | {o['order']:.2f} | {o['r2']:.2f} | {o['points']} | "
                     f"{o['order_all_frames']:.2f} | {o['r2_all']:.2f} |")
    if spreads:
        lines += ["", "## Frame-rate independence (tip spread across 30/60/144/240 fps, % of chain length)", "",
                  "| scene | mode | spread |", "|---|---|---|"]
        lines += [f"| {s['scene']} | {s['mode']} | {s['spread']:.2f} |" for s in spreads]
    if "numpy" in extra:
        n = extra["numpy"]
        lines += ["", "## Plain-numpy baseline (tail_orbit, 90 Hz, whole frame loop)", "",
                  f"magica_py {n['ours_ms']:.3f} ms/frame; numpy {n['numpy_ms']:.3f} ms/frame "
                  f"(numpy step alone {n['numpy_step_ms']:.3f}); ratio x{n['ratio']:.1f}"]
    if "features" in extra:
        lines += ["", "## Feature cost (character_walk, 90 Hz, magica mode)", "",
                  "| configuration | ms/frame (median) | ms/frame (min) | relative (min) | particle-steps/s |",
                  "|---|---|---|---|---|"]
        lines += [f"| {f['feature']} | {f['ms_per_frame']:.3f} | {f['ms_min']:.3f} | {f['relative']:.2f} | "
                  f"{f['steps_per_s']:.3g} |"
                  for f in extra["features"]]
    if "crowd" in extra:
        c = extra["crowd"]
        lines += ["", f"Crowd (100 characters, 7,800 particles, 90 Hz): {c['ms_per_frame']:.2f} ms/frame, "
                      f"{c['steps_per_s']:.3g} particle-steps/s."]
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------- stability
def main_stability(argv) -> int:
    from magica_py.bench import report as R
    from magica_py.bench.stability import CASES, case, run_case

    p = argparse.ArgumentParser(prog="magica-py stability",
                                description="Run the hard-case stability suite (configs/hard) and report "
                                            "finiteness, speed, stretch, penetration and return to rest.")
    p.add_argument("--case", action="append", default=[], help="run only this case (repeatable)")
    p.add_argument("--short", action="store_true", help="the CI-length version of each case")
    p.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                   help="a cloth parameter applied to every case (validated; VALUE is YAML), e.g. "
                        "solver.rate_mode=frequency_consistent; repeatable")
    p.add_argument("--out", default=None, help="report folder (default: reports/ in the current folder)")
    p.add_argument("--quiet", "-q", action="store_true")
    args = p.parse_args(argv)
    try:
        cases = [case(n) for n in args.case] if args.case else list(CASES)
    except KeyError as exc:
        print(f"magica-py stability: {exc.args[0]}", file=sys.stderr)
        return 2
    _, params = parse_family("params:" + ",".join(args.param))
    rows, failed = [], 0
    bar = Progress(len(cases), args.quiet)
    for c in cases:
        result, _ = run_case(c, c.short_duration if args.short else None, params)
        rows.append(stability_row(result))
        failed += bool(result.failures())
        bar.add(1)
    bar.close()
    out = R.default_report_dir() if args.out is None else __import__("pathlib").Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    table = R.markdown_table(rows, R.STABILITY_COLUMNS)
    R.write_csv(out / "stability.csv", rows, R.STABILITY_COLUMNS)
    (out / "stability.md").write_text(f"# magica-py stability ({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())})"
                                      f"\n\n{machine_description()}\n\n{table}\n")
    if not args.quiet:
        print(table)
        print(f"\n{len(rows) - failed}/{len(rows)} cases within their bounds; written {out / 'stability.md'}")
    return 0 if failed == 0 else 1


def stability_row(r) -> dict:
    c = r.case
    settle = ("n/a (run too short)" if not r.settle_checked else
              ("never" if not math.isfinite(r.settle_time) else f"{r.settle_time:.2f}")) + f" [{c.settle_within:g}]"
    fails = r.failures()
    return {"case": c.name, "finite": "yes" if r.finite else "NO",
            "max_speed": f"{r.max_speed:.3g} [{c.max_speed:g}]",
            "max_stretch": f"{100 * r.max_stretch:.1f} [{100 * c.max_stretch:g}]",
            "max_root_stretch": 100 * r.max_root_stretch,
            "penetration": f"{1000 * r.penetration_after:.2f} [{1000 * c.max_penetration * c.scale:g}]",
            "settle": settle, "guard_resets": r.guard_resets, "ms_per_frame": 1000 * r.wall_per_frame,
            "verdict": "ok" if not fails else "; ".join(fails)}


if __name__ == "__main__":  # pragma: no cover
    # python -m magica_py.bench.cli [bench|stability] ARGS: the same as magica-py bench / stability
    argv = sys.argv[1:]
    if argv and argv[0] == "stability":
        raise SystemExit(main_stability(argv[1:]))
    raise SystemExit(main_bench(argv[1:] if argv and argv[0] == "bench" else argv))
