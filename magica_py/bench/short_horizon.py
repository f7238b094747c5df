"""Short-horizon (re-synchronised) error: an error that exists at every frequency (docs/BENCHMARKS.md).

A scene whose motion is chaotic (a tail orbiting through a sphere, a skirt against legs) has
no long-horizon trajectory reference: two fine references drift apart. Over a short horizon
they do not. The run is cut into windows of ``frames_per_window`` frames (about 0.25 s); at
the start of every window the candidate restarts from the reference's full state (particles,
velocities, step history, team clocks, poses, animation cursor: ``Player.restore(snapshot,
keep_model=True)``, which keeps the candidate's own parameters and simulation frequency) and
runs the window's frames; its error is measured at the window's end. The reported error is
the mean over the windows of the RMS over the moving bones of ``|p - p_ref| / chain length``
(``WindowErrors.mean_rms``), with the max over windows and bones beside it.

The reference must resolve that horizon (``resolution_check``, one per family): its own
residual, the same windows run at twice its frequency from the same snapshots, has to be at
least ``1/RESOLUTION_RATIO`` (10x) below the smallest error of the family, and that residual
must not be a floor: either it falls when the reference's frequency doubles (the windows run
at half its frequency differ from it by at least ``2^MIN_REFERENCE_ORDER`` times the
residual), or the half-frequency residual too is 10x below the error (the three references
agree to a tenth of it). A residual that does not fall measures the model's own dependence on
the step, not the reference's step error, and no finer reference makes it smaller: a family
that fails the check against such a reference is reported *unresolvable*, with the measured
order, not as a reference too coarse.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from magica_py.bench import metrics as M

HORIZON = 0.25              # s, target window length (a whole number of frames is used)
RESOLUTION_RATIO = 0.1      # the reference's residual must stay below this fraction of every error
MIN_REFERENCE_ORDER = 0.5   # the reference's residual must fall at least 2^0.5 x per doubling of its frequency

RESOLVED = "resolved"
NOT_RESOLVED = "not resolved"       # the reference converges but is too coarse: a finer one would do
UNRESOLVABLE = "unresolvable"       # the reference does not converge at this horizon: no finer one helps


def window_frames(fps: float, horizon: float = HORIZON) -> int:
    """Frames per window: the whole number of frames closest to ``horizon`` at ``fps`` (>= 1)."""
    return max(1, int(round(horizon * float(fps))))


def window_starts(frames: int, frames_per_window: int) -> np.ndarray:
    """Start frames (0, N, 2N, ...) of the windows that fit entirely in ``frames`` frames."""
    if frames_per_window < 1:
        raise ValueError(f"frames_per_window: expected >= 1, got {frames_per_window}")
    return np.arange(0, frames - frames_per_window + 1, frames_per_window, dtype=np.int64)


@dataclass
class ReferenceWindows:
    """A reference run cut into windows: ``snapshots[k]`` is the reference's state before
    frame ``starts[k]``; ``positions`` (F, N, 3) m are its bones after every frame (the window
    ends are ``starts + frames_per_window - 1``); ``geometry`` its rest geometry."""

    starts: np.ndarray
    frames_per_window: int
    snapshots: list
    positions: np.ndarray
    geometry: M.ChainGeometry

    @property
    def ends(self) -> np.ndarray:
        return self.starts + self.frames_per_window - 1

    def end_positions(self) -> np.ndarray:
        """(W, N, 3) m: the reference's bones at the end of each window."""
        return self.positions[self.ends]


@dataclass(frozen=True)
class WindowErrors:
    """Per-window errors at the window ends (fractions of the chain length): ``rms`` (W,) over
    the moving bones, ``max`` (W,) over them."""

    rms: np.ndarray
    max: np.ndarray

    @property
    def mean_rms(self) -> float:
        """The short-horizon error: mean over windows of the RMS over bones."""
        return float(np.mean(self.rms)) if self.rms.size else math.nan

    @property
    def worst(self) -> float:
        """Max over windows and bones."""
        return float(np.max(self.max)) if self.max.size else math.nan


def run_reference(variant, frames_per_window: int, progress=None):
    """Run ``variant`` (the reference) to its end, capturing its state at every window start.
    Returns ``(RunResult, ReferenceWindows)``."""
    from magica_py.bench.variants import prepare, run_variant

    p = prepare(variant)
    starts = window_starts(p.frames, frames_per_window)
    wanted = set(int(s) for s in starts)
    snapshots = []

    def capture(frame, _time, player, _system):
        if frame in wanted:
            snapshots.append(player.capture())

    run = run_variant(variant, prepared=p, progress=progress, before_frame=capture)
    return run, ReferenceWindows(starts, frames_per_window, snapshots, run.positions, run.geometry)


def candidate_window_errors(variant, reference: ReferenceWindows, prepared=None) -> WindowErrors:
    """Restart ``variant`` from the reference's state at every window start (its own
    parameters, frequency and frame rate kept), run the window's frames, and measure its
    bones against the reference's at the window's end."""
    from magica_py.bench.variants import prepare

    p = prepared or prepare(variant)
    player, hierarchy = p.player, p.scene.hierarchy
    nodes = np.asarray(p.system.model.transform_index, dtype=np.int64)
    ends = np.zeros((reference.starts.shape[0],) + reference.positions.shape[1:])
    for k, snapshot in enumerate(reference.snapshots):
        player.restore(snapshot, keep_model=True)
        for _ in range(reference.frames_per_window):
            player.step()
        ends[k] = hierarchy.world_position[nodes]
    g = reference.geometry
    rms, worst = M.frame_errors(ends, reference.end_positions(), g.length_scale, g.moving)
    return WindowErrors(rms, worst)


def reference_order(half_residual: float, residual: float) -> float:
    """The reference's observed order from its windows at half and twice its frequency:
    ``log2(half_residual / residual)`` (1 for a first-order reference; 0 or below when the
    residual does not fall as the frequency doubles). nan when either is missing or zero."""
    if not (math.isfinite(half_residual) and math.isfinite(residual)) or half_residual <= 0 or residual <= 0:
        return math.nan
    return math.log2(half_residual / residual)


@dataclass(frozen=True)
class ResolutionCheck:
    """Whether a reference resolves the errors of one family reported against it:
    ``residual`` (the reference's short-horizon error against twice its frequency, fraction
    of the chain) at most ``ratio`` x ``smallest`` (the family's smallest error), and the
    residual not a floor: ``half_residual`` (against half its frequency; nan when not
    measured) at least ``2^min_order`` x ``residual``, or itself at most ``ratio`` x
    ``smallest``."""

    label: str
    residual: float
    smallest: float
    smallest_of: str
    ratio: float = RESOLUTION_RATIO
    half_residual: float = math.nan
    min_order: float = MIN_REFERENCE_ORDER

    @property
    def order(self) -> float:
        """The reference's observed order (``reference_order``; nan when not measured)."""
        return reference_order(self.half_residual, self.residual)

    @property
    def fine_enough(self) -> bool:
        """The residual is ``1/ratio`` x below the smallest error."""
        return resolves(self.smallest, self.residual, self.ratio)

    @property
    def converges(self) -> bool:
        """The residual falls as the reference's frequency doubles (True when not measured)."""
        return not self.order < self.min_order

    @property
    def ok(self) -> bool:
        return self.verdict == RESOLVED

    @property
    def verdict(self) -> str:
        """``RESOLVED``; ``UNRESOLVABLE`` when it is not and the reference does not converge;
        ``NOT_RESOLVED`` when the reference converges but its residual is too large."""
        if self.fine_enough and (self.converges or resolves(self.smallest, self.half_residual, self.ratio)):
            return RESOLVED
        return NOT_RESOLVED if self.converges else UNRESOLVABLE

    @property
    def margin(self) -> float:
        """smallest error / residual (>= 1/ratio when the check passes)."""
        return self.smallest / self.residual if self.residual > 0 else math.inf

    def message(self) -> str:
        order = "" if math.isnan(self.order) else (f", reference order {self.order:.2f} (residual at half its "
                                                   f"frequency {100 * self.half_residual:.3g} %)")
        head = {RESOLVED: "resolved", NOT_RESOLVED: "NOT RESOLVED (the reference converges: a finer one is needed)",
                UNRESOLVABLE: "UNRESOLVABLE (the reference does not converge at this horizon: its residual does not "
                              "fall as its frequency doubles, order below "
                              f"{self.min_order:g}, so a finer reference is not expected to resolve it)"}[self.verdict]
        return (f"{self.label}: {head}: residual {100 * self.residual:.3g} % of the chain, smallest error "
                f"{100 * self.smallest:.3g} % ({self.smallest_of}), ratio {self.margin:.1f} (needs >= "
                f"{1 / self.ratio:g}){order}")


def resolves(error: float, residual: float, ratio: float = RESOLUTION_RATIO) -> bool:
    """``residual <= ratio * error``, both finite."""
    return math.isfinite(error) and math.isfinite(residual) and residual <= ratio * error


def point_resolved(error: float, residual: float, half_residual: float = math.nan,
                   ratio: float = RESOLUTION_RATIO, min_order: float = MIN_REFERENCE_ORDER) -> bool:
    """One error (a row of the sweep) by the same rule as ``ResolutionCheck.verdict``."""
    return ResolutionCheck("", residual, error, "", ratio, half_residual, min_order).ok


def resolution_check(label: str, residual: float, errors: dict, ratio: float = RESOLUTION_RATIO,
                     half_residual: float = math.nan) -> ResolutionCheck:
    """The check for one family against its reference: ``errors`` maps a candidate's label to
    its short-horizon error (fraction of the chain); non-finite errors are ignored (none left:
    not resolved); ``half_residual``: the reference's windows at half its frequency against it."""
    finite = {k: float(v) for k, v in errors.items() if v is not None and math.isfinite(float(v))}
    if not finite:
        return ResolutionCheck(label, float(residual), math.nan, "no error", ratio, float(half_residual))
    name = min(finite, key=finite.get)
    return ResolutionCheck(label, float(residual), finite[name], name, ratio, float(half_residual))
