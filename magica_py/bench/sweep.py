"""The frequency sweep of ``magica-py bench``: families, their references, errors and timings.

A *family* is a series of the plot: a set of parameter overrides swept over simulation
frequencies (``FAMILIES``: MagicaCloth2's faithful mode, the faithful solver with
frequency-consistent rates, quality mode; more with ``--family``). Each family is measured
against the converged reference of its own model (``reference_parameters``): the same
parameters at ``REFERENCE_FREQUENCY`` with frequency-consistent rates (the faithful mode's
SimulationPower rates are not a discretisation of one model, so its reference is the
frequency-consistent model, identical to it at 90 Hz). A reference serves every family that
shares it and is checked against itself at ``CHECK_FREQUENCY`` and at half its frequency
(whether its residual falls); each family gets its own verdict (``short_horizon.resolution_check``).

Per row (scene, family, frequency): the short-horizon error (``short_horizon``), the
long-horizon error over the frames the reference resolves (``reference.resolved_error``),
stretch, penetration, and the time per frame (median and quartiles of interleaved repeats).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np

FAMILIES = {
    "faithful": {"solver.rate_mode": "magica"},
    "frequency_consistent": {"solver.rate_mode": "frequency_consistent"},
    "quality": {"solver.mode": "quality"},
}
FAMILY_NOTES = {
    "faithful": "MagicaCloth2's BoneCloth (per-step rates scaled by SimulationPower)",
    "frequency_consistent": "the faithful solver with frequency-consistent per-step rates",
    "quality": "quality mode (docs/quality-mode.md)",
}
FPS_SET = (30, 60, 144, 240)


def reference_parameters(params: dict) -> dict:
    """The parameters of a family's converged reference: its own, with frequency-consistent
    per-step rates (quality mode implies them; faithful mode's rates are switched)."""
    out = dict(params)
    out["solver.rate_mode"] = "frequency_consistent"
    return out


def reference_name(params: dict) -> str:
    """A short name of a reference's parameters ("frequency_consistent", "quality", or the
    overrides written out)."""
    for name, family in FAMILIES.items():
        if name != "faithful" and reference_parameters(family) == params:
            return name
    return ",".join(f"{k}={v}" for k, v in sorted(params.items()))


class LoadMonitor:
    """Samples of the 1-minute load average during a run (``os.getloadavg``). The load counts
    this benchmark's own process; ``high`` when a sample exceeded ``1 + (cores - 1) / 2``, i.e.
    other processes wanted at least half of the other cores: a timed loop then loses its core
    part of the time."""

    def __init__(self):
        self.samples: list[float] = []
        self.cores = os.cpu_count() or 1
        self.sample()

    def sample(self) -> None:
        try:
            self.samples.append(float(os.getloadavg()[0]))
        except OSError:            # not available on this platform
            pass

    @property
    def threshold(self) -> float:
        return 1.0 + (self.cores - 1) / 2.0

    @property
    def high(self) -> bool:
        return bool(self.samples) and max(self.samples) > self.threshold

    def describe(self) -> str:
        if not self.samples:
            return "load average not available"
        text = (f"1-minute load average {min(self.samples):.1f}-{max(self.samples):.1f} over "
                f"{len(self.samples)} samples ({self.cores} logical cores)")
        if self.high:
            text += (f". **The machine was loaded** (above {self.threshold:g}): other processes took cores "
                     "during the timed runs, so times are inflated and spread; compare rows of this run with "
                     "each other (their repeats were interleaved), not with other runs")
        return text


@dataclass
class ReferenceRuns:
    """A reference and its check for one scene: the run at ``frequency`` cut into windows, the
    long-horizon residual per frame, the short-horizon residual (the same windows run at
    ``check_frequency``, twice the frequency) and the same windows at ``half_frequency``."""

    name: str
    parameters: dict
    run: object                       # RunResult at REFERENCE_FREQUENCY
    windows: object                   # short_horizon.ReferenceWindows
    long_residual_rms: np.ndarray     # (F,) fraction of the chain, frequency vs check_frequency
    long_residual_max: np.ndarray     # (F,)
    short_residual: object            # short_horizon.WindowErrors of the check frequency's windows
    frequency: int = 11520            # Hz of the reference run
    check_frequency: int = 23040      # Hz of its check
    half_residual: object = None      # short_horizon.WindowErrors of the half frequency's windows
    half_frequency: int = 5760

    @property
    def order(self) -> float:
        """Observed order of the reference (``short_horizon.reference_order``)."""
        from magica_py.bench import short_horizon as S

        half = math.nan if self.half_residual is None else self.half_residual.mean_rms
        return S.reference_order(half, self.short_residual.mean_rms)


def run_references(base, families: dict, frames_per_window: int, progress=None,
                   frequency: int | None = None) -> dict:
    """One ``ReferenceRuns`` per distinct reference of ``families`` (keyed by its name), at
    ``frequency`` (default ``REFERENCE_FREQUENCY``) checked at twice that (default
    ``CHECK_FREQUENCY``) and at half of it."""
    from magica_py.bench import metrics as M
    from magica_py.bench import reference as REF
    from magica_py.bench import short_horizon as S
    from magica_py.bench.variants import run_variant

    reference_frequency = int(frequency or REF.REFERENCE_FREQUENCY)
    check_frequency = REF.CHECK_FREQUENCY if frequency is None else 2 * reference_frequency
    refs = {}
    for params in families.values():
        rp = reference_parameters(params)
        name = reference_name(rp)
        if name in refs:
            continue
        v = base.with_(label=f"{base.label}@ref:{name}", frequency=reference_frequency, parameters=rp,
                       family=f"reference {name}")
        run, windows = S.run_reference(v, frames_per_window, progress=progress)
        check_v = v.with_(label=f"{base.label}@check:{name}", frequency=check_frequency)
        check = run_variant(check_v, progress=progress)
        g = run.geometry
        res_rms, res_max = M.frame_errors(check.positions, run.positions, g.length_scale, g.moving)
        short = S.candidate_window_errors(check_v, windows)
        half_frequency = max(1, reference_frequency // 2)
        half = S.candidate_window_errors(v.with_(label=f"{base.label}@half:{name}", frequency=half_frequency), windows)
        refs[name] = ReferenceRuns(name, rp, run, windows, res_rms, res_max, short, reference_frequency,
                                   check_frequency, half, half_frequency)
    return refs


def sweep_job(item):
    """One variant of the sweep (a batch job): its run against its reference over the whole
    run (per-frame errors) and over the short-horizon windows. Returns ``(run without
    positions, RMS error per frame, max error per frame, WindowErrors)``."""
    from magica_py.bench import metrics as M
    from magica_py.bench import short_horizon as S
    from magica_py.bench.variants import run_variant

    variant, windows = item
    run = run_variant(variant)
    g = windows.geometry
    err_rms, err_max = M.frame_errors(run.positions, windows.positions, g.length_scale, g.moving)
    run.positions = None                  # keep memory flat over the sweep (and the result small)
    short = S.candidate_window_errors(variant, windows)
    return run, err_rms, err_max, short


@dataclass
class SceneResult:
    rows: list = field(default_factory=list)
    references: list = field(default_factory=list)   # dicts for the report
    checks: list = field(default_factory=list)       # short_horizon.ResolutionCheck
    families: list = field(default_factory=list)     # per-family summaries
    horizon: float = 0.25                            # s, the short-horizon window (whole frames)


def family_rows(rows, scene, family):
    return sorted((r for r in rows if r["scene"] == scene and r["family"] == family), key=lambda r: r["frequency"])


def summarise_scene(scene: str, rows: list, refs: dict, family_refs: dict, spreads: dict,
                    scene_frequency: int) -> SceneResult:
    """References, resolution checks and per-family summaries of one scene's rows."""
    from magica_py.bench import short_horizon as S
    from magica_py.bench.reference import fit_order

    out = SceneResult(rows=[r for r in rows if r["scene"] == scene])
    verdicts = {}
    for name, ref in refs.items():
        g = ref.run.geometry
        residual = ref.short_residual.mean_rms
        half = ref.half_residual.mean_rms if ref.half_residual is not None else math.nan
        users = [r for r in out.rows if family_refs[r["family"]] == name]
        for r in users:
            r["resolved"] = "yes" if S.point_resolved(r["short_error"] / 100, residual, half) else "NO"
        for family in dict.fromkeys(r["family"] for r in users):
            errors = {f"{r['family']} {r['frequency']} Hz": r["short_error"] / 100 for r in users
                      if r["family"] == family}
            verdicts[family] = S.resolution_check(
                f"{scene}/{family} against the {name} reference ({ref.frequency} Hz; check {ref.check_frequency}, "
                f"half {ref.half_frequency} Hz)", residual, errors, half_residual=half)
            out.checks.append(verdicts[family])
        out.references.append({
            "scene": scene, "reference": name, "chain_length": g.chain_length, "frames": ref.run.frames,
            "windows": int(ref.windows.starts.shape[0]), "window_frames": ref.windows.frames_per_window,
            "short_residual": 100 * residual, "short_residual_max": 100 * ref.short_residual.worst,
            "half_residual": 100 * half, "order": ref.order,
            "long_residual_rms": 100 * float(np.sqrt(np.mean(ref.long_residual_rms ** 2))),
            "long_residual_max": 100 * float(ref.long_residual_max.max()),
            "frequency": ref.frequency, "check_frequency": ref.check_frequency,
            "half_frequency": ref.half_frequency})
    for family in dict.fromkeys(r["family"] for r in out.rows):
        sel = family_rows(out.rows, scene, family)
        order, r2 = fit_order([r["frequency"] for r in sel], [r["short_error"] for r in sel])
        good = [r for r in sel if r.get("resolved") == "yes"]
        order_resolved, r2_resolved = fit_order([r["frequency"] for r in good], [r["short_error"] for r in good])
        at = [r for r in sel if r["frequency"] == scene_frequency] or sel[:1]
        row = at[0]
        check = verdicts.get(family)
        out.families.append({
            "scene": scene, "family": family, "reference": family_refs[family], "order": order, "r2": r2,
            "verdict": check.verdict if check is not None else "-",
            "margin": check.margin if check is not None else math.nan,
            "order_resolved": order_resolved, "r2_resolved": r2_resolved, "resolved_points": len(good),
            "points": len(sel),
            "frequency": row["frequency"], "short_error": row["short_error"], "spread": spreads.get(family),
            "max_edge_stretch": row["max_edge_stretch"], "max_root_stretch": row["max_root_stretch"],
            "max_penetration_mm": row["max_penetration_mm"], "ms_per_frame": row["ms_per_frame"]})
    return out


def frame_rate_spread(base, params: dict, frequency: int, length: float) -> float:
    """Tip spread (% of the chain) across ``FPS_SET`` render rates at ``frequency``."""
    from magica_py.bench import metrics as M
    from magica_py.bench.variants import run_variant

    recs = []
    for fps in FPS_SET:
        run = run_variant(base.with_(label=f"{base.label}/fps{fps}", fps=fps, frequency=frequency,
                                     parameters=dict(params)), record_positions=False)
        recs.append((run.times, run.tips))
    return 100 * M.frame_rate_spread(recs, length)


def sweep_row(scene, variant, run, err_rms, err_max, short, timing, res_rms) -> dict:
    """One row of the sweep table (errors and stretch in %, penetration in mm, times in ms)."""
    from magica_py.bench.reference import resolved_error

    window = resolved_error(err_rms, err_max, res_rms)
    q1, q3 = timing.quartiles
    return {
        "scene": scene, "family": variant.family, "frequency": run.frequency,
        "ms_per_frame": 1000 * timing.median, "ms_q1": 1000 * q1, "ms_q3": 1000 * q3,
        "ms_per_frame_min": 1000 * timing.minimum, "repeats": int(timing.per_frame.shape[0]),
        "particle_steps_per_s": timing.median_rate,
        "short_error": 100 * short.mean_rms, "short_max": 100 * short.worst,
        "long_error": 100 * window.rms if window.resolved else None,
        "coverage": 100 * window.coverage,
        "max_edge_stretch": 100 * float(run.edge_stretch.max()),
        "max_root_stretch": 100 * float(run.root_stretch.max()),
        "max_penetration_mm": 1000 * float(run.penetration.max()),
    }

