"""The batch summary: one row per job, as Parquet and CSV (pyarrow), and the Pareto plot.

Columns (units in docs/batch.md): the job's labels (``scene``, ``clip``, ``override``,
``fps``, ``seed``, one ``set.<path>`` per swept path), ``job_id``, ``status``, ``error``,
the metrics ``METRIC_COLUMNS``, ``state_hash``, ``worker``, ``overrides``, ``rrd``, ``bake``.
"""
from __future__ import annotations

import math
from pathlib import Path

from magica_py import atomic

LABEL_COLUMNS = ("scene", "clip", "override", "fps", "seed")
METRIC_COLUMNS = ("frames", "particles", "max_stretch", "mean_stretch", "max_root_stretch", "max_penetration",
                  "mean_penetration", "max_speed", "mean_speed", "resets", "non_finite_frames", "particle_steps",
                  "warmup_s", "setup_s", "run_s", "job_s", "ms_per_frame", "ms_per_sim_second", "particle_steps_per_s")
TAIL_COLUMNS = ("state_hash", "worker", "overrides", "rrd", "bake", "error")
INTEGER = {"frames", "particles", "resets", "non_finite_frames", "seed"}


def columns_of(rows: list[dict]) -> list[str]:
    sets = sorted({k for r in rows for k in r if k.startswith("set.")})
    return ["job_id", *LABEL_COLUMNS, *sets, "status", *METRIC_COLUMNS, *TAIL_COLUMNS]


def to_table(rows: list[dict]):
    """A pyarrow Table with one row per job, columns in ``columns_of`` order."""
    import pyarrow as pa

    names = columns_of(rows)
    arrays = []
    for name in names:
        values = [r.get(name) for r in rows]
        if name in INTEGER:
            kind = pa.int64()
        elif name in METRIC_COLUMNS or name == "fps":
            kind = pa.float64()
        else:
            kind = pa.string()
            values = [None if v is None else str(v) for v in values]
        arrays.append(pa.array(values, type=kind))
    return pa.Table.from_arrays(arrays, names=names)


def write_summary(rows: list[dict], folder) -> tuple[Path, Path]:
    """``summary.parquet`` and ``summary.csv`` in ``folder`` (written under temporary names
    and renamed, so a reader never sees half a table)."""
    import pyarrow.csv as pacsv
    import pyarrow.parquet as pq

    folder = Path(folder)
    table = to_table(sorted(rows, key=_row_order))
    parquet, csv = folder / "summary.parquet", folder / "summary.csv"
    with atomic.replacing(parquet) as parquet_tmp, atomic.replacing(csv) as csv_tmp:
        pq.write_table(table, str(parquet_tmp))
        pacsv.write_csv(table, str(csv_tmp))
    return parquet, csv


def _row_order(row: dict):
    return tuple("" if row.get(k) is None else str(row.get(k)) for k in ("scene", "clip", "override")) + (
        float(row.get("fps") or 0.0), int(row.get("seed") or 0), row["job_id"])


def pareto_front(points: list[tuple[float, float]]) -> list[int]:
    from magica_py.bench.report import pareto_front as front

    return front(points)


def short_label(row: dict) -> str:
    parts = [str(row[k]) for k in ("override", "clip") if row.get(k)]
    parts += [f"{k[4:].split('.')[-1]}={row[k]}" for k in sorted(row) if k.startswith("set.")]
    if row.get("fps") is not None:
        parts.append(f"{row['fps']:g} fps")
    return ", ".join(parts) or row["job_id"]


def pareto_plot(rows: list[dict], path, metric: str = "max_stretch", cost: str = "ms_per_sim_second",
                title: str = "batch") -> Path:
    """``metric`` against ``cost`` for every finished job (one colour per scene), the Pareto
    front (lower is better on both) joined and labelled."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    ok = [r for r in rows if r.get("status") == "ok" and _finite(r.get(metric)) and _finite(r.get(cost))]
    fig, ax = plt.subplots(figsize=(8, 5.5))
    group = colour_key(ok)
    groups = sorted({str(r.get(group)) for r in ok})
    palette = plt.get_cmap("tab10" if len(groups) <= 10 else "tab20")
    for k, value in enumerate(groups):
        members = [r for r in ok if str(r.get(group)) == value]
        ax.scatter([r[cost] for r in members], [r[metric] for r in members], s=14, alpha=0.7,
                   color=palette(k % palette.N), label=f"{group} {value} ({len(members)} jobs)")
    points = [(float(r[cost]), float(r[metric])) for r in ok]
    front = pareto_front(points)
    if front:
        ax.plot([points[i][0] for i in front], [points[i][1] for i in front], "k--", linewidth=0.8,
                label="Pareto front")
        for i in front[:12]:
            ax.annotate(short_label(ok[i]), points[i], fontsize=6, xytext=(3, 3), textcoords="offset points")
    failed = sum(1 for r in rows if r.get("status") != "ok")
    ax.set_xlabel(_axis_label(cost))
    ax.set_ylabel(_axis_label(metric))
    ax.set_title(f"{title}: {len(ok)} jobs" + (f", {failed} failed (not shown)" if failed else ""))
    if ok and min(p[0] for p in points) > 0:
        ax.set_xscale("log")
    ax.grid(True, which="both", linewidth=0.3)
    if groups:
        ax.legend(fontsize=6, ncol=2 if len(groups) > 8 else 1)
    fig.tight_layout()
    atomic.save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path


def colour_key(rows: list[dict]) -> str:
    """The column whose values colour the points: the first of scene, override, clip, the
    swept paths, fps and seed that varies over ``rows``."""
    sets = sorted({k for r in rows for k in r if k.startswith("set.")})
    for key in ("scene", "override", "clip", *sets, "fps", "seed"):
        if len({str(r.get(key)) for r in rows}) > 1:
            return key
    return "scene"


UNITS = {"max_stretch": "relative", "mean_stretch": "relative", "max_root_stretch": "relative",
         "max_penetration": "m", "mean_penetration": "m", "max_speed": "m/s", "mean_speed": "m/s",
         "warmup_s": "s", "setup_s": "s", "run_s": "s", "job_s": "s", "ms_per_frame": "ms",
         "ms_per_sim_second": "ms of wall time per simulated second", "particle_steps_per_s": "1/s"}


def _axis_label(name: str) -> str:
    unit = UNITS.get(name)
    return f"{name} ({unit})" if unit else name


def _finite(value) -> bool:
    return isinstance(value, (int, float)) and math.isfinite(value)
