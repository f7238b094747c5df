"""``magica-py bench`` (speed against error) and ``magica-py stability`` (hard cases).

Both write to the git-ignored ``reports/`` folder and print a progress bar on a terminal.

bench, per showcase scene (``--scenes``, default tail_orbit and character_walk):

1. warm-up: every scene and family runs 0.1 s first (and each feature case and the crowd before
   their own timings), so that no timing includes a compile;
2. references: each family's own model at 11520 Hz (``--reference-frequency``;
   frequency-consistent rates, quality mode for quality), its state captured every 0.25 s
   (``--horizon``), checked against twice and half that frequency;
3. sweep: every frequency (``--frequencies``) x family (``--families``: faithful,
   frequency_consistent, quality; more with ``--family``), run as jobs of the batch machinery
   (``magica_py.batch.Executor``: in this process, or on Dask workers with ``--workers N`` /
   ``--scheduler ADDRESS``): the short-horizon error (the candidate restarted from the
   reference's state every 0.25 s, error at each window's end), the long-horizon error over
   the frames the reference resolves, stretch and penetration; time per frame as the median
   and quartiles of ``--repeats`` interleaved fresh runs;
4. the reference check, per family: the reference's short-horizon residual (against twice its
   frequency) must be 10x below the family's every error, and not be a floor (it falls as the
   reference's frequency doubles, or the half-frequency residual is 10x below the errors too).
   Verdicts, printed and written first in bench.md: resolved; NOT RESOLVED (the reference
   converges but is too coarse: exit status 1); UNRESOLVABLE (the reference does not converge
   at this horizon, so no finer reference would do: reported, exit status 0 unless
   ``--strict``);
5. frame-rate spread (30 / 60 / 144 / 240 fps at the scene frequency) per family;
6. the plain-numpy baseline of the single tail, side by side with the solver;
7. feature cost on the character (collision point / edge, bending, angle limit, colliders
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

from magica_py import atomic

FREQUENCIES = (30, 45, 60, 90, 120, 180, 360, 720)
SCENES = ("tail_orbit", "character_walk")


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

    def compile_watch(self, command: str):
        """A ``runner.CompileWatch`` that says, above the bar, when a first run starts compiling
        the solver, and takes the compile out of the bar's rate and ETA (quiet: says nothing)."""
        from magica_py.runner import CompileWatch

        if self.bar is None:
            return CompileWatch()
        return CompileWatch(announce=lambda text: self.bar.write(f"{command}: {text}"), on_end=self.bar.pause_ended)


# ----------------------------------------------------------------------------- bench
def main_bench(argv) -> int:
    from magica_py.bench.sweep import FAMILIES

    p = argparse.ArgumentParser(prog="magica-py bench", description=__doc__.replace("``", ""),
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenes", default=",".join(SCENES), help="comma-separated showcase scenes or YAML paths")
    p.add_argument("--frequencies", default=",".join(map(str, FREQUENCIES)), help="simulation Hz to sweep")
    p.add_argument("--families", default=",".join(FAMILIES),
                   help=f"built-in families to sweep (of {', '.join(FAMILIES)}; empty for none)")
    p.add_argument("--family", action="append", default=[], metavar="NAME:KEY=VALUE[,KEY=VALUE...]",
                   help="an extra series swept like the built-in ones, e.g. a quality-mode candidate: "
                        "'q_ftl:solver.mode=quality,solver.inextensibility=ftl' "
                        "(values parsed as YAML; repeatable)")
    p.add_argument("--reference-frequency", type=int, default=None, metavar="HZ",
                   help="frequency of the references (default 11520; checked at twice and half that): a finer "
                        "reference resolves smaller errors when it converges, at its cost")
    p.add_argument("--horizon", type=float, default=None, metavar="SECONDS",
                   help="short-horizon window (default 0.25 s; the whole number of frames nearest to it)")
    p.add_argument("--strict", action="store_true",
                   help="exit 1 for unresolvable families too (default: only for families a finer reference "
                        "would resolve)")
    p.add_argument("--repeats", type=int, default=7, help="timed runs per variant (median and quartiles)")
    p.add_argument("--duration", type=float, default=None, help="seconds per run (default: the scene's)")
    p.add_argument("--out", default=None, help="report folder (default: reports/ in the current folder)")
    p.add_argument("--skip", default="", help="comma-separated parts to skip: fps,numpy,features,crowd")
    p.add_argument("--workers", type=int, default=0, metavar="N",
                   help="run the sweep's runs on a local Dask cluster of N workers (default 0: in this process; "
                        "the timings always run here, one at a time)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="run the sweep's runs on an existing Dask cluster")
    p.add_argument("--quiet", "-q", action="store_true")
    args = p.parse_args(argv)
    if args.reference_frequency is not None and not 30 <= args.reference_frequency <= 11520:
        raise SystemExit(f"magica-py bench: --reference-frequency {args.reference_frequency}: expected 30-11520 Hz")
    if args.horizon is not None and not args.horizon > 0:
        raise SystemExit(f"magica-py bench: --horizon {args.horizon}: expected a positive number of seconds")
    families = {}
    for name in filter(None, args.families.split(",")):
        if name not in FAMILIES:
            raise SystemExit(f"magica-py bench: --families: unknown family {name!r} (expected some of "
                             f"{', '.join(FAMILIES)}; define others with --family)")
        families[name] = dict(FAMILIES[name])
    for text in args.family:
        name, params = parse_family(text)
        families[name] = params
    if not families:
        raise SystemExit("magica-py bench: no family to sweep (--families is empty and no --family given)")
    from magica_py.batch.executor import Executor

    executor = Executor(workers=None if args.scheduler else args.workers, scheduler=args.scheduler)
    with executor:
        return _bench(args, families, executor)


def _bench(args, families: dict, executor) -> int:
    from magica_py.bench import reference as REF
    from magica_py.bench import report as R
    from magica_py.bench import short_horizon as S
    from magica_py.bench import sweep as W
    from magica_py.bench.variants import Variant, prepare, resolve_scene_path, run_variant, time_repeats

    out = R.default_report_dir() if args.out is None else __import__("pathlib").Path(args.out)
    scenes = [s for s in args.scenes.split(",") if s]
    freqs = [int(f) for f in args.frequencies.split(",") if f]
    skip = set(s for s in args.skip.split(",") if s)
    started = time.perf_counter()
    load = W.LoadMonitor()

    def say(text):
        if not args.quiet:
            print(text, file=sys.stderr, flush=True)

    say("magica-py bench: warm-up (every scene and family for 0.1 s: compiles the solver unless the numba "
        "cache is warm) ...")
    t0 = time.perf_counter()
    for scene_name in scenes:
        for name, params in families.items():
            run_variant(Variant("warmup", resolve_scene_path(scene_name), parameters=dict(params), duration=0.1,
                                frequency=freqs[0]), record_positions=False)
    say(f"  warm-up {time.perf_counter() - t0:.1f} s")

    results, extra = [], {}
    for scene_name in scenes:
        base = Variant(scene_name, resolve_scene_path(scene_name), duration=args.duration)
        probe = prepare(base)
        frames, fps = probe.frames, probe.scene.settings.fps
        scene_frequency = probe.frequency
        del probe
        family_refs = {f: W.reference_name(W.reference_parameters(p)) for f, p in families.items()}
        n_refs = len(set(family_refs.values()))
        sweep = [base.with_(label=f"{scene_name}/{m}/{f}", frequency=f, parameters=dict(params), family=m)
                 for m, params in families.items() for f in freqs]
        total = frames * (3 * n_refs + len(sweep) * (2 + args.repeats))
        ref_hz = args.reference_frequency or REF.REFERENCE_FREQUENCY
        check_hz = 2 * args.reference_frequency if args.reference_frequency else REF.CHECK_FREQUENCY
        window = S.window_frames(fps, args.horizon or S.HORIZON)
        say(f"{scene_name}: {n_refs} reference(s) at {ref_hz} Hz checked at {check_hz} and {ref_hz // 2} Hz, "
            f"{len(sweep)} variants, "
            f"{frames} frames each, windows of {window} frames")
        progress = Progress(total, args.quiet)
        refs = W.run_references(base, families, window, progress=progress.run_callback(),
                                frequency=args.reference_frequency)
        progress.add(frames * n_refs)          # the check runs' windows
        # the sweep's runs are jobs of the batch machinery (magica_py.batch.Executor): in this
        # process by default, on a LocalCluster with --workers N or a cluster with --scheduler
        items = [(v, refs[family_refs[v.family]].windows) for v in sweep]
        runs = [None] * len(sweep)
        for i, result in executor.map(W.sweep_job, items, key_prefix="bench-sweep"):
            runs[i] = result
            progress.add(2 * frames)
        load.sample()
        def timed(_variant):           # the load is sampled after every timed run
            progress.add(frames)
            load.sample()

        timings = time_repeats(sweep, repeats=args.repeats, progress=timed)
        progress.close()
        rows = [W.sweep_row(scene_name, v, run, err_rms, err_max, short, timing,
                            refs[family_refs[v.family]].long_residual_rms)
                for v, (run, err_rms, err_max, short), timing in zip(sweep, runs, timings)]
        spreads = {}
        if "fps" not in skip:
            length = next(iter(refs.values())).run.geometry.chain_length
            for m, params in families.items():
                spreads[m] = W.frame_rate_spread(base, params, scene_frequency, length)
                say(f"  frame-rate spread {scene_name} / {m}: {spreads[m]:.2f} % of the chain")
        result = W.summarise_scene(scene_name, rows, refs, family_refs, spreads, scene_frequency)
        for check in result.checks:
            say(("  " if check.ok else "  WARNING: ") + check.message())
        result.horizon = window / fps
        results.append(result)

    if "numpy" not in skip:
        extra["numpy"] = numpy_comparison(args.repeats, say)
    if "features" not in skip:
        extra["features"] = feature_costs(args.repeats, say)
    if "crowd" not in skip:
        extra["crowd"] = crowd_speed(say)
    load.sample()

    out.mkdir(parents=True, exist_ok=True)
    rows = [r for res in results for r in res.rows]
    R.write_csv(out / "bench.csv", rows, R.BENCH_CSV_COLUMNS)
    R.pareto_plot(out / "pareto.png", results)
    elapsed = time.perf_counter() - started
    text = R.bench_markdown(results, extra, f"Machine: {machine_description()}. Wall time of the whole run: "
                                             f"{elapsed:.0f} s; {load.describe()}.")
    atomic.write_text(out / "bench.md", text)
    checks = [c for res in results for c in res.checks]
    if not args.quiet:
        print(text)
        print(f"\nwritten: {out / 'bench.md'}, {out / 'bench.csv'}, {out / 'pareto.png'}")
    return report_verdicts(checks, args.strict)


def report_verdicts(checks: list, strict: bool = False) -> int:
    """Print the families that are not resolved on stderr; the exit status: 1 when a family is
    NOT RESOLVED (a finer reference would resolve it), or with ``strict`` when any is not
    resolved; 0 otherwise (unresolvable families are reported, not failed)."""
    from magica_py.bench import short_horizon as S

    fixable = [c for c in checks if c.verdict == S.NOT_RESOLVED]
    unresolvable = [c for c in checks if c.verdict == S.UNRESOLVABLE]
    if fixable:
        print(f"magica-py bench: {len(fixable)} famil{'y is' if len(fixable) == 1 else 'ies are'} NOT RESOLVED "
              "by a converging reference (bench.md, 'Reference check'; a finer --reference-frequency would do):",
              file=sys.stderr)
        for c in fixable:
            print(f"  {c.message()}", file=sys.stderr)
    if unresolvable:
        print(f"magica-py bench: {len(unresolvable)} famil{'y is' if len(unresolvable) == 1 else 'ies are'} "
              "UNRESOLVABLE at this horizon (the reference does not converge; docs/BENCHMARKS.md):", file=sys.stderr)
        for c in unresolvable:
            print(f"  {c.message()}", file=sys.stderr)
    return 1 if fixable or (strict and unresolvable) else 0


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
    warm_up([v for _, v in cases])     # each case is its own set of stages: its own compile
    timings = time_interleaved([v for _, v in cases], repeats=repeats)
    rows = []
    ref_min = timings[0][2]
    for (label, _), (sec, rate, fastest) in zip(cases, timings):
        rows.append({"feature": label, "ms_per_frame": 1000 * sec, "ms_min": 1000 * fastest,
                     "relative": fastest / ref_min, "steps_per_s": rate})
        say(f"  feature cost: {label}: {1000 * sec:.3f} ms/frame (min {1000 * fastest:.3f})")
    return rows


def warm_up(variants) -> None:
    """Run each variant for 0.1 s, untimed, so that its timing never includes a compile (a
    variant whose stages differ from the sweep's compiles its own frame kernel)."""
    from magica_py.bench.variants import run_variant

    for v in variants:
        run_variant(v.with_(duration=0.1), record_positions=False)


def crowd_speed(say) -> dict:
    from magica_py.bench.variants import Variant, resolve_scene_path, time_variant

    v = Variant("crowd", resolve_scene_path("crowd"), frequency=90, duration=1.0)
    warm_up([v])
    ms, rate = time_variant(v, repeats=3)
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


# ----------------------------------------------------------------------------- stability
def main_stability(argv) -> int:
    from magica_py.bench import report as R
    from magica_py.bench.stability import CASES, case, run_case

    p = argparse.ArgumentParser(prog="magica-py stability",
                                description="Run the hard-case stability suite (configs/hard) and report "
                                            "finiteness, speed, stretch, penetration and return to rest; "
                                            "--suite mocap runs the motion-capture stress suite "
                                            "(configs/hard/mocap_*, both modes, 30/60/144/240 fps).")
    p.add_argument("--suite", choices=("hard", "mocap"), default="hard",
                   help="hard (default): the hard cases; mocap: the motion-capture stress suite "
                        "(writes stability_mocap.md / .csv)")
    p.add_argument("--case", action="append", default=[], help="run only this case (repeatable)")
    p.add_argument("--short", action="store_true",
                   help="the CI-length version of each case (mocap: 0.5 s per run)")
    p.add_argument("--mode", action="append", default=[], choices=("quality", "faithful"),
                   help="mocap suite: run only this mode (repeatable; default both)")
    p.add_argument("--fps", action="append", default=[], type=float, metavar="FPS",
                   help="mocap suite: run only this frame rate (repeatable; default 30, 60, 144, 240)")
    p.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                   help="a cloth parameter applied to every case (validated; VALUE is YAML), e.g. "
                        "solver.rate_mode=frequency_consistent; repeatable (mocap suite: every run, "
                        "solver.mode excepted)")
    p.add_argument("--out", default=None, help="report folder (default: reports/ in the current folder)")
    p.add_argument("--quiet", "-q", action="store_true")
    args = p.parse_args(argv)
    if args.suite == "mocap":
        return main_mocap(args)
    if args.mode or args.fps:
        print("magica-py stability: --mode and --fps belong to --suite mocap", file=sys.stderr)
        return 2
    try:
        cases = [case(n) for n in args.case] if args.case else list(CASES)
    except KeyError as exc:
        print(f"magica-py stability: {exc.args[0]}", file=sys.stderr)
        return 2
    _, params = parse_family("params:" + ",".join(args.param))
    rows, failed = [], 0
    bar = Progress(len(cases), args.quiet)
    with bar.compile_watch("magica-py stability"):
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
    atomic.write_text(out / "stability.md", f"# magica-py stability ({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())})"
                                            f"\n\n{machine_description()}\n\n{table}\n")
    if not args.quiet:
        print(table)
        print(f"\n{len(rows) - failed}/{len(rows)} cases within their bounds; written {out / 'stability.md'}")
    return 0 if failed == 0 else 1


def main_mocap(args) -> int:
    """``magica-py stability --suite mocap``: every case x mode x frame rate (docs/STABILITY.md)."""
    from magica_py.bench import mocap_suite as S
    from magica_py.bench import report as R

    try:
        cases = [S.case(n) for n in args.case] if args.case else list(S.CASES)
    except KeyError as exc:
        print(f"magica-py stability: {exc.args[0]}", file=sys.stderr)
        return 2
    _, params = parse_family("params:" + ",".join(args.param))
    if "solver.mode" in params:
        print("magica-py stability: --param solver.mode: the mocap suite sets the mode itself (use --mode)",
              file=sys.stderr)
        return 2
    bad = [f for f in args.fps if not 1.0 <= f <= 1000.0]
    if bad:
        print(f"magica-py stability: --fps {bad[0]:g}: expected a frame rate in [1, 1000]", file=sys.stderr)
        return 2
    modes = list(dict.fromkeys(args.mode)) or list(S.MODES)
    rates = list(dict.fromkeys(args.fps)) or list(S.FRAME_RATES)
    duration = 0.5 if args.short else None
    runs = [(c, m, f) for c in cases for m in modes for f in rates]
    total = sum(int(math.ceil((duration or c.duration) * f - 1e-9)) for c, m, f in runs)
    started = time.perf_counter()
    if not args.quiet:
        print(f"magica-py stability --suite mocap: {len(cases)} cases x {len(modes)} modes x {len(rates)} frame rates "
              f"= {len(runs)} runs, {total} frames", file=sys.stderr)
    bar = Progress(total, args.quiet)
    rows = []
    with bar.compile_watch("magica-py stability"):
        for c, m, f in runs:
            run = S.run_case(c, m, f, duration, progress=bar.run_callback(), parameters=params)
            rows.extend(S.run_rows(run))
    bar.close()
    elapsed = time.perf_counter() - started
    out = R.default_report_dir() if args.out is None else __import__("pathlib").Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    R.write_csv(out / "stability_mocap.csv", rows, S.CSV_COLUMNS)
    stamp = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    load = " ".join(f"{x:.1f}" for x in __import__("os").getloadavg())
    legend = " / ".join(m for m in S.MODES if m in modes)
    text = (f"# magica-py stability --suite mocap ({stamp})\n\n{machine_description()}; load average at the end "
            f"{load}; wall time {elapsed:.0f} s; {'0.5 s per run (--short)' if args.short else f'motion + {S.REST:g} s of rest per run'}"
            f"{'; parameters ' + ', '.join(f'{k}={v}' for k, v in params.items()) if params else ''}"
            f"\n\nEach cell: {legend}.\n\n{S.side_by_side_table(rows)}\n\n## Issue 16 bounds\n\n"
            f"{S.bound_summary(rows)}\n")
    atomic.write_text(out / "stability_mocap.md", text)
    if not args.quiet:
        print(text)
        print(f"written: {out / 'stability_mocap.md'}, {out / 'stability_mocap.csv'}")
    return 0


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
