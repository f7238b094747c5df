"""Converged references and the windows where they are good enough (docs/BENCHMARKS.md).

The reference of a scene is the same scene at ``REFERENCE_FREQUENCY`` (11520 Hz) in the
frequency-consistent mode; its own error is estimated by the *residual* against the same
scene at ``CHECK_FREQUENCY`` (23040 Hz). Collisions, teleports and fast swinging make
trajectories chaotic, so two fine references can drift apart by a large fraction of the
chain: a trajectory error is only reported over the frames where the reference residual is
under a tenth of the error being reported (``resolved_error``). Elsewhere the statistics
that stay meaningful (stretch, penetration, speed, settling) are used instead.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

REFERENCE_FREQUENCY = 11520  # docs/BENCHMARKS.md, *Where the reference residual comes from*: why 11520
CHECK_FREQUENCY = 23040
RESOLUTION_RATIO = 0.1     # reference residual must stay below this fraction of the error


@dataclass(frozen=True)
class ResolvedError:
    """A trajectory error restricted to the frames where the reference resolves it.

    ``rms`` / ``max``: over the ``mask`` frames (fraction of chain length; nan when no
    frame qualifies); ``coverage``: fraction of frames in the mask; ``residual_rms``: the
    reference residual over the same frames; ``resolved``: at least one frame qualifies.
    """

    rms: float
    max: float
    coverage: float
    residual_rms: float
    mask: np.ndarray

    @property
    def resolved(self) -> bool:
        return bool(self.mask.any())


def resolved_error(error_rms: np.ndarray, error_max: np.ndarray, residual_rms: np.ndarray,
                   ratio: float = RESOLUTION_RATIO, iterations: int = 20) -> ResolvedError:
    """Error over the frames where ``residual_rms(t) < ratio x E``, E being the RMS error
    reported over those same frames (a fixed point, found by iteration from all frames).

    Per-frame arrays (F,): the variant's RMS and max error against the reference, and the
    reference's RMS residual against the check run, all normalised by chain length.
    Frames where the variant itself matches the reference to within the residual are
    kept only when the fixed point allows them: the reported error is then a bound the
    reference can vouch for."""
    error_rms = np.asarray(error_rms, dtype=np.float64)
    error_max = np.asarray(error_max, dtype=np.float64)
    residual_rms = np.asarray(residual_rms, dtype=np.float64)
    mask = np.ones(error_rms.shape[0], dtype=bool)
    for _ in range(iterations):
        if not mask.any():
            break
        e = math.sqrt(float(np.mean(error_rms[mask] ** 2)))
        new = residual_rms < ratio * e
        if np.array_equal(new, mask):
            break
        mask = new
    if not mask.any():
        return ResolvedError(math.nan, math.nan, 0.0, math.nan, mask)
    rms = math.sqrt(float(np.mean(error_rms[mask] ** 2)))
    return ResolvedError(rms, float(error_max[mask].max()), float(mask.mean()),
                         math.sqrt(float(np.mean(residual_rms[mask] ** 2))), mask)


def fit_order(frequencies, errors) -> tuple[float, float]:
    """Least-squares slope of ``log(error)`` against ``log(step size)``: the observed order
    p in ``error ~ C h^p`` (h = 1/frequency), and the coefficient of determination R^2.
    Non-finite or non-positive errors are ignored; nan when fewer than two remain."""
    f = np.asarray(frequencies, dtype=np.float64)
    e = np.asarray(errors, dtype=np.float64)
    ok = np.isfinite(e) & (e > 0) & np.isfinite(f) & (f > 0)
    if ok.sum() < 2:
        return math.nan, math.nan
    x = np.log(1.0 / f[ok])
    y = np.log(e[ok])
    slope, intercept = np.polyfit(x, y, 1)
    fit = slope * x + intercept
    ss_res = float(np.sum((y - fit) ** 2))
    ss_tot = float(np.sum((y - y.mean()) ** 2))
    r2 = 1.0 - ss_res / ss_tot if ss_tot > 0 else 1.0
    return float(slope), r2
