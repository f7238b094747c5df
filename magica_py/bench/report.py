"""Tables (markdown, CSV) and the Pareto plot of ``magica-py bench`` / ``magica-py stability``.

Rows are plain dicts; ``COLUMNS`` fixes their order and headers. Files go to a git-ignored
``reports/`` folder (``default_report_dir``); the committed summaries in docs/ are written
by hand from these.
"""
from __future__ import annotations

import csv
import math
import pathlib
import time

import numpy as np

from magica_py import atomic

BENCH_COLUMNS = (
    ("scene", "scene", "{}"),
    ("family", "family", "{}"),
    ("frequency", "Hz", "{}"),
    ("ms_per_frame", "ms/frame (median)", "{:.3f}"),
    ("ms_q1", "q1", "{:.3f}"),
    ("ms_q3", "q3", "{:.3f}"),
    ("particle_steps_per_s", "particle-steps/s", "{:.3g}"),
    ("short_error", "short-horizon error (% L)", "{:.3g}"),
    ("short_max", "short-horizon max (% L)", "{:.3g}"),
    ("resolved", "resolved", "{}"),
    ("long_error", "long-horizon error (% L)", "{:.3g}"),
    ("coverage", "long window (% frames)", "{:.0f}"),
    ("max_edge_stretch", "max edge stretch (%)", "{:.2f}"),
    ("max_root_stretch", "max root stretch (%)", "{:.2f}"),
    ("max_penetration_mm", "max penetration (mm)", "{:.2f}"),
)
BENCH_CSV_COLUMNS = BENCH_COLUMNS + (("ms_per_frame_min", "", ""), ("repeats", "", ""))

STABILITY_COLUMNS = (
    ("case", "case", "{}"),
    ("finite", "finite", "{}"),
    ("max_speed", "max speed (m/s) [bound]", "{}"),
    ("max_stretch", "max edge stretch (%) [bound]", "{}"),
    ("max_root_stretch", "max root stretch (%)", "{:.1f}"),
    ("penetration", "penetration after stop (mm) [bound]", "{}"),
    ("settle", "back to rest (s) [stated]", "{}"),
    ("guard_resets", "guard resets", "{}"),
    ("ms_per_frame", "ms/frame", "{:.3f}"),
    ("verdict", "verdict", "{}"),
)


def default_report_dir() -> pathlib.Path:
    """``reports/`` in the current folder (where the user ran the command, not beside the package)."""
    return pathlib.Path.cwd() / "reports"


def format_cell(value, fmt: str) -> str:
    if value is None:
        return "-"
    if isinstance(value, float) and not math.isfinite(value):
        return "inf" if value > 0 else ("-inf" if value < 0 else "n/a")
    try:
        return fmt.format(value)
    except (ValueError, TypeError):
        return str(value)


def markdown_table(rows: list[dict], columns) -> str:
    """A GitHub markdown table of ``rows`` (dicts keyed by the first element of each column)."""
    head = "| " + " | ".join(c[1] for c in columns) + " |"
    rule = "|" + "|".join("---" for _ in columns) + "|"
    body = ["| " + " | ".join(format_cell(r.get(c[0]), c[2]) for c in columns) + " |" for r in rows]
    return "\n".join([head, rule] + body)


def write_csv(path, rows: list[dict], columns) -> None:
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic.replacing(path) as tmp, tmp.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow([c[0] for c in columns])
        for r in rows:
            w.writerow(["" if r.get(c[0]) is None else r.get(c[0]) for c in columns])


def pareto_front(points: list[tuple[float, float]]) -> list[int]:
    """Indices of the points not dominated in (cost, error), both lower-is-better, sorted by
    cost. Points with a non-finite coordinate are ignored."""
    ok = [i for i, (c, e) in enumerate(points) if math.isfinite(c) and math.isfinite(e)]
    ok.sort(key=lambda i: (points[i][0], points[i][1]))
    front, best = [], math.inf
    for i in ok:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def bench_markdown(results: list, extra: dict, header: str) -> str:
    """``bench.md``: the reference check first, then references, families, the sweep and the extras."""
    from magica_py.bench import short_horizon as S
    from magica_py.bench.reference import CHECK_FREQUENCY, REFERENCE_FREQUENCY

    refs = [r for res in results for r in res.references]
    ref_hz, check_hz = ((refs[0]["frequency"], refs[0]["check_frequency"]) if refs
                        else (REFERENCE_FREQUENCY, CHECK_FREQUENCY))
    half_hz = refs[0]["half_frequency"] if refs else REFERENCE_FREQUENCY // 2
    horizon = results[0].horizon if results else S.HORIZON
    checks = [c for res in results for c in res.checks]
    counts = {v: sum(1 for c in checks if c.verdict == v) for v in (S.RESOLVED, S.NOT_RESOLVED, S.UNRESOLVABLE)}
    lines = [f"# magica-py bench ({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())})", "", header, ""]
    lines += ["## Reference check", "",
              f"Per family: **{counts[S.RESOLVED]} resolved, {counts[S.NOT_RESOLVED]} not resolved (a finer reference "
              f"would do: exit status 1), {counts[S.UNRESOLVABLE]} unresolvable** (the reference does not converge at "
              f"this horizon). A family is resolved when its reference's {ref_hz}-vs-{check_hz} Hz short-horizon "
              f"residual is {1 / S.RESOLUTION_RATIO:g}x below every error of the family and is not a floor: it falls "
              f"as the reference's frequency doubles (observed order >= {S.MIN_REFERENCE_ORDER:g}, from the "
              f"{half_hz}-vs-{ref_hz} Hz residual) or the {half_hz}-vs-{ref_hz} Hz residual too is "
              f"{1 / S.RESOLUTION_RATIO:g}x below the errors. Rows marked 'NO' in 'resolved' (hollow in pareto.png) "
              "contain the reference's own error or its model's frequency dependence at more than a tenth of their "
              "size: they are not measurements of the candidate's error alone.", ""]
    lines += [f"- {c.message()}" for c in checks]
    lines += ["", "## Definitions", "",
              f"Short-horizon error: every {horizon:g} s (the whole number of frames nearest to it) the candidate "
              "restarts from its reference's full state "
              "(particles, velocities, step history, team clocks, poses; its own parameters, frequency and frame rate "
              "kept) and runs to the window's end; the error is the mean over the windows of the RMS over the moving "
              f"bones of |p - p_ref| / chain length at the window's end. Reference: the family's model at "
              f"{ref_hz} Hz with frequency-consistent rates (faithful mode: the frequency-consistent model); "
              f"its residual is the same windows run at {check_hz} Hz, its half residual at {half_hz} Hz. "
              "Long-horizon error: RMS over the "
              "frames where the reference's own long-horizon residual is under a tenth of the error (window). "
              "Times: whole player loop per frame, median and quartiles (q1, q3) of interleaved fresh runs after a "
              "warm-up. Stretch and penetration over every frame of the displayed bones.", "",
              "## References", "",
              f"| scene | reference | chain length (m) | frames | windows x frames | short-horizon residual, {ref_hz} vs "
              f"{check_hz} Hz (% L) | residual max (% L) | {half_hz} vs {ref_hz} Hz (% L) | reference order "
              "| long-horizon residual RMS / max (% L) |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for res in results:
        for r in res.references:
            lines.append(f"| {r['scene']} | {r['reference']} | {r['chain_length']:.3f} | {r['frames']} | "
                         f"{r['windows']} x {r['window_frames']} | {r['short_residual']:.3g} | "
                         f"{r['short_residual_max']:.3g} | {r['half_residual']:.3g} | {format_cell(r['order'], '{:.2f}')} | "
                         f"{r['long_residual_rms']:.3g} / {r['long_residual_max']:.3g} |")
    lines += ["", "## Families (error ~ h^p fitted over the sweep, and over its resolved points only; the rest at "
                  "the scene's frequency)", "",
              "| scene | family | reference | verdict (smallest error / residual) | order p (R^2), all points "
              "| p (R^2), resolved points | Hz "
              "| short-horizon error (% L) | frame-rate spread (% L) "
              "| max edge stretch (%) | max root stretch (%) | max penetration (mm) | ms/frame |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for res in results:
        for f in res.families:
            spread = "-" if f["spread"] is None else f"{f['spread']:.2f}"
            resolved = (f"{f['order_resolved']:.2f} ({f['r2_resolved']:.2f}), {f['resolved_points']} of {f['points']}"
                        if f["resolved_points"] >= 2 else f"- ({f['resolved_points']} of {f['points']})")
            lines.append(f"| {f['scene']} | {f['family']} | {f['reference']} | {f['verdict']} ({f['margin']:.1f}) | "
                         f"{f['order']:.2f} ({f['r2']:.2f}) | "
                         f"{resolved} | {f['frequency']} | {f['short_error']:.3g} | {spread} | {f['max_edge_stretch']:.2f} | "
                         f"{f['max_root_stretch']:.2f} | {f['max_penetration_mm']:.2f} | {f['ms_per_frame']:.3f} |")
    lines += ["", "(frame-rate spread: the chain tips across 30/60/144/240 fps at the scene's frequency, max over "
                  "time.)", "", "## Sweep", "", markdown_table([r for res in results for r in res.rows], BENCH_COLUMNS)]
    for res in results:
        for scene in dict.fromkeys(r["scene"] for r in res.rows):
            front = pareto_front([(r["ms_per_frame"], r["short_error"]) for r in res.rows])
            lines += ["", f"Pareto front of {scene} (ms/frame against short-horizon error): " + " -> ".join(
                f"{res.rows[i]['family']} {res.rows[i]['frequency']} Hz ({res.rows[i]['ms_per_frame']:.3f} ms, "
                f"{res.rows[i]['short_error']:.3g} %)" for i in front)]
    lines += extras_markdown(extra)
    return "\n".join(lines) + "\n"



def extras_markdown(extra: dict) -> list:
    lines = []
    if "numpy" in extra:
        n = extra["numpy"]
        lines += ["", "## Plain-numpy baseline (tail_orbit, 90 Hz, whole frame loop)", "",
                  f"magica_py {n['ours_ms']:.3f} ms/frame; numpy {n['numpy_ms']:.3f} ms/frame "
                  f"(numpy step alone {n['numpy_step_ms']:.3f}); ratio x{n['ratio']:.1f}"]
    if "features" in extra:
        lines += ["", "## Feature cost (character_walk, 90 Hz, faithful mode)", "",
                  "| configuration | ms/frame (median) | ms/frame (min) | relative (min) | particle-steps/s |",
                  "|---|---|---|---|---|"]
        lines += [f"| {f['feature']} | {f['ms_per_frame']:.3f} | {f['ms_min']:.3f} | {f['relative']:.2f} | "
                  f"{f['steps_per_s']:.3g} |" for f in extra["features"]]
    if "crowd" in extra:
        c = extra["crowd"]
        lines += ["", f"Crowd (100 characters, 7,800 particles, 90 Hz): {c['ms_per_frame']:.2f} ms/frame, "
                      f"{c['steps_per_s']:.3g} particle-steps/s."]
    return lines


TICK_MANTISSAS = ((1.0,), (1.0, 2.0, 5.0), (1.0, 2.0, 3.0, 5.0, 7.0), (1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0))


def log_tick_values(lo: float, hi: float, most: int = 7) -> list:
    """Tick values for a log axis from ``lo`` to ``hi``: the densest of the mantissa sets
    1 / 1-2-5 / 1-2-3-5-7 / 1-1.5-2-2.5-3-4-...-8 (times powers of ten) that puts at most
    ``most`` ticks in the range (the sparsest when none does)."""
    if not (lo > 0 and hi > lo):
        return []
    best = None
    for mantissas in TICK_MANTISSAS:
        values = [m * 10.0 ** k for k in range(math.floor(math.log10(lo)) - 1, math.ceil(math.log10(hi)) + 1)
                  for m in mantissas]
        values = sorted(v for v in values if lo <= v <= hi)
        if best is None or len(values) <= most:
            best = values
        if len(values) > most:
            break
    return best


def log_ticks(ax, axis: str) -> None:
    """Readable log-axis ticks: plain decimal labels at ``log_tick_values`` of the axis's
    final limits, minor ticks unlabelled, so that labels never run together."""
    from matplotlib import ticker

    lo, hi = (ax.get_xlim() if axis == "x" else ax.get_ylim())
    target = ax.xaxis if axis == "x" else ax.yaxis
    target.set_major_locator(ticker.FixedLocator(log_tick_values(lo, hi)))
    target.set_major_formatter(ticker.FuncFormatter(lambda v, _pos: f"{v:g}"))
    target.set_minor_locator(ticker.LogLocator(base=10.0, subs=tuple(range(1, 10))))
    target.set_minor_formatter(ticker.NullFormatter())
    (ax.set_xlim if axis == "x" else ax.set_ylim)(lo, hi)


def label_points(ax, points, labels, fontsize=7) -> int:
    """Write ``labels`` beside ``points`` (data coordinates) where they fit: a label is dropped
    when its box would overlap a label already placed or another point's marker. Returns how
    many were placed."""
    fig = ax.figure
    renderer = fig.canvas.get_renderer()
    to_px = ax.transData.transform
    markers = [to_px(p) for p in points]
    placed, count = [], 0
    for k, (p, text) in enumerate(zip(points, labels)):
        for dx, dy, ha, va in ((4, 4, "left", "bottom"), (4, -4, "left", "top"), (-4, 4, "right", "bottom"),
                               (-4, -4, "right", "top")):
            t = ax.annotate(text, p, xytext=(dx, dy), textcoords="offset points", fontsize=fontsize,
                            ha=ha, va=va, color="0.25")
            box = t.get_window_extent(renderer).expanded(1.05, 1.1)
            hits_marker = any(box.x0 - 3 <= m[0] <= box.x1 + 3 and box.y0 - 3 <= m[1] <= box.y1 + 3
                              for j, m in enumerate(markers) if j != k)
            inside = ax.get_window_extent(renderer).contains(box.x0, box.y0) and \
                ax.get_window_extent(renderer).contains(box.x1, box.y1)
            if not hits_marker and inside and not any(box.overlaps(b) for b in placed):
                placed.append(box)
                count += 1
                break
            t.remove()
    return count


def pareto_plot(path, results: list, title: str = "speed against short-horizon error") -> None:
    """One panel per scene, log-log: median wall time per frame (error bars: quartiles of the
    repeats) against the short-horizon error, one series per family (its frame-rate spread in
    the legend); hollow markers where the reference does not resolve the error (it is under
    10x the reference's residual, drawn dotted); the scene's Pareto front dashed, in the
    legend; frequencies written beside the points where they fit (all of them are in bench.md)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    panels = [res for res in results if res.rows]
    fig, axes = plt.subplots(1, max(1, len(panels)), figsize=(6.6 * max(1, len(panels)), 7.0), squeeze=False)
    markers = "osD^vp*hX"
    family_names = list(dict.fromkeys(r["family"] for res in panels for r in res.rows))
    colours = {f: plt.cm.tab10(i % 10) for i, f in enumerate(family_names)}
    to_label = []
    for ax, res in zip(axes[0], panels):
        scene = res.rows[0]["scene"]
        spreads = {f["family"]: f["spread"] for f in res.families}
        verdicts = {f["family"]: f.get("verdict") for f in res.families}
        points, labels = [], []
        for i, family in enumerate(family_names):
            sel = sorted((r for r in res.rows if r["family"] == family and r["short_error"] > 0),
                         key=lambda r: r["frequency"])
            if not sel:
                continue
            x = np.array([r["ms_per_frame"] for r in sel])
            y = np.array([r["short_error"] for r in sel])
            xerr = np.array([[r["ms_per_frame"] - r["ms_q1"] for r in sel], [r["ms_q3"] - r["ms_per_frame"] for r in sel]])
            spread = spreads.get(family)
            name = family if not verdicts.get(family) else f"{family} ({verdicts[family]})"
            name = name if spread is None else f"{name}: frame-rate spread {spread:.2g} % of the chain"
            c = colours[family]
            ax.errorbar(x, y, xerr=np.maximum(xerr, 0), color=c, linewidth=1.2, elinewidth=0.8, capsize=2,
                        marker=None, label=None, zorder=2)
            resolved = np.array([r.get("resolved", "yes") == "yes" for r in sel])
            ax.plot(x, y, color=c, linewidth=1.2, zorder=2)
            # one legend entry per family: filled when some of its points are resolved, hollow otherwise
            ax.scatter(x[resolved], y[resolved], color=c, marker=markers[i % len(markers)], s=30, zorder=3,
                       label=name if resolved.any() else None)
            ax.scatter(x[~resolved], y[~resolved], facecolors="white", edgecolors=[c], marker=markers[i % len(markers)],
                       s=30, zorder=3, label=None if resolved.any() else name)
            points += list(zip(x, y))
            labels += [f"{r['frequency']}" for r in sel]
        for ref in res.references:       # in the legend: a text on the line collides with the points' labels
            level = 10 * ref["short_residual"]
            colour = colours.get(ref["reference"], "0.4")
            pair = (f" ({ref['frequency']} vs {ref['check_frequency']} Hz)"
                    if "frequency" in ref and "check_frequency" in ref else "")
            ax.axhline(level, color=colour, linestyle=":", linewidth=1.2, zorder=1,
                       label=f"dotted: 10x the residual of the {ref['reference']} reference{pair}")
        front = pareto_front([(r["ms_per_frame"], r["short_error"]) for r in res.rows])
        if len(front) > 1:       # a wide grey band behind the series: the points on the front stand out
            ax.plot([res.rows[i]["ms_per_frame"] for i in front], [res.rows[i]["short_error"] for i in front],
                    color="black", alpha=0.22, linewidth=7, solid_capstyle="round", zorder=1, label="Pareto front")
        if any(r.get("resolved") == "NO" for r in res.rows):
            ax.scatter([], [], facecolors="white", edgecolors="0.3", marker="o", s=30,
                       label="hollow: not resolved (under 10x the reference's residual, or the reference "
                             "does not converge)")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.margins(x=0.08, y=0.1)
        ax.figure.canvas.draw()
        log_ticks(ax, "x")
        log_ticks(ax, "y")
        ax.set_xlabel("wall time per rendered frame, ms (median; bars: quartiles of the repeats)")
        ax.set_ylabel("short-horizon error, % of the chain length")
        ax.set_title(f"{scene} (labels: simulation Hz)", fontsize=10)
        ax.grid(True, which="major", linewidth=0.4)
        ax.grid(True, which="minor", linewidth=0.15)
        ax.legend(fontsize=7.5, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=1, frameon=False)
        to_label.append((ax, points, labels))
    fig.suptitle(title)
    fig.tight_layout()
    fig.canvas.draw()
    for ax, points, labels in to_label:        # after the layout: the boxes are final
        label_points(ax, points, labels)
    atomic.save_figure(fig, path, dpi=110)
    plt.close(fig)
