"""Tables (markdown, CSV) and the Pareto plot of ``magica-py bench`` / ``magica-py stability``.

Rows are plain dicts; ``COLUMNS`` fixes their order and headers. Files go to a git-ignored
``reports/`` folder (``default_report_dir``); the committed summaries in docs/ are written
by hand from these.
"""
from __future__ import annotations

import csv
import math
import pathlib

BENCH_COLUMNS = (
    ("scene", "scene", "{}"),
    ("family", "mode", "{}"),
    ("frequency", "Hz", "{}"),
    ("ms_per_frame", "ms/frame", "{:.3f}"),
    ("particle_steps_per_s", "particle-steps/s", "{:.3g}"),
    ("rms_error", "RMS error (% L)", "{:.3g}"),
    ("max_error", "max error (% L)", "{:.3g}"),
    ("coverage", "window (% frames)", "{:.0f}"),
    ("max_edge_stretch", "max edge stretch (%)", "{:.2f}"),
    ("max_root_stretch", "max root stretch (%)", "{:.2f}"),
    ("max_penetration_mm", "max penetration (mm)", "{:.2f}"),
    ("max_speed", "max speed (m/s)", "{:.2f}"),
    ("energy_envelope", "energy envelope error (%)", "{:.2g}"),
    ("settle_s", "settling (s)", "{:.2f}"),
)

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
    with path.open("w", newline="") as fh:
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


def pareto_plot(path, rows: list[dict], title: str = "speed against error") -> None:
    """Two panels, log-log: time per frame against RMS trajectory error (where the reference
    resolves it) and against max edge stretch; one series per (scene, mode), points labelled
    with the frequency; the Pareto front of each scene dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, 2, figsize=(13, 5.5))
    series = {}
    for r in rows:
        series.setdefault((r["scene"], r["family"]), []).append(r)
    markers = "os^Dvp*hX"
    for k, ((scene, family), members) in enumerate(sorted(series.items())):
        members = sorted(members, key=lambda r: r["frequency"])
        for ax, key, scale in ((axes[0], "rms_error", 1.0), (axes[1], "max_edge_stretch", 1.0)):
            xs = [r["ms_per_frame"] for r in members]
            ys = [r.get(key) for r in members]
            pts = [(x, y * scale) for x, y in zip(xs, ys) if y is not None and math.isfinite(y) and y > 0]
            if not pts:
                continue
            ax.plot([p[0] for p in pts], [p[1] for p in pts], marker=markers[k % len(markers)], linestyle="-",
                    label=f"{scene} / {family}")
            for r in members:
                y = r.get(key)
                if y is not None and math.isfinite(y) and y > 0:
                    ax.annotate(str(r["frequency"]), (r["ms_per_frame"], y), fontsize=6,
                                xytext=(2, 2), textcoords="offset points")
    for scene in sorted({r["scene"] for r in rows}):
        members = [r for r in rows if r["scene"] == scene]
        pts = [(r["ms_per_frame"], r.get("rms_error") if r.get("rms_error") is not None else math.nan)
               for r in members]
        front = pareto_front(pts)
        if len(front) > 1:
            axes[0].plot([pts[i][0] for i in front], [pts[i][1] for i in front], "k--", linewidth=0.7)
    axes[0].set_ylabel("RMS position error / chain length (%) over the resolved window")
    axes[1].set_ylabel("max edge stretch (%)")
    for ax in axes:
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("wall time per rendered frame (ms)")
        ax.grid(True, which="both", linewidth=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
