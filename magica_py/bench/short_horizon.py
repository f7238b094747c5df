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

The reference must resolve that horizon: its own residual, the same windows run at
``CHECK_FREQUENCY`` from the same snapshots, has to be at least ``1/RESOLUTION_RATIO`` (10x)
below the smallest error reported against it (``resolution_check``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from magica_py.bench import metrics as M

HORIZON = 0.25              # s, target window length (a whole number of frames is used)
RESOLUTION_RATIO = 0.1      # the reference's residual must stay below this fraction of every error


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


@dataclass(frozen=True)
class ResolutionCheck:
    """Whether a reference resolves the errors reported against it: ``residual`` (the
    reference's own short-horizon error against ``CHECK_FREQUENCY``, fraction of the chain)
    at most ``ratio`` x ``smallest`` (the smallest error reported against it)."""

    label: str
    residual: float
    smallest: float
    smallest_of: str
    ratio: float = RESOLUTION_RATIO

    @property
    def ok(self) -> bool:
        return (math.isfinite(self.residual) and math.isfinite(self.smallest)
                and self.residual <= self.ratio * self.smallest)

    @property
    def margin(self) -> float:
        """smallest error / residual (>= 1/ratio when the check passes)."""
        return self.smallest / self.residual if self.residual > 0 else math.inf

    def message(self) -> str:
        verdict = "resolves" if self.ok else "DOES NOT RESOLVE"
        return (f"reference {self.label} {verdict} the errors reported against it: residual "
                f"{100 * self.residual:.3g} % of the chain, smallest error {100 * self.smallest:.3g} % "
                f"({self.smallest_of}), ratio {self.margin:.1f} (needs >= {1 / self.ratio:g})")


def resolution_check(label: str, residual: float, errors: dict, ratio: float = RESOLUTION_RATIO) -> ResolutionCheck:
    """The check for one reference: ``errors`` maps a candidate's label to its short-horizon
    error (fraction of the chain); non-finite errors are ignored (none left: not resolved)."""
    finite = {k: float(v) for k, v in errors.items() if v is not None and math.isfinite(float(v))}
    if not finite:
        return ResolutionCheck(label, float(residual), math.nan, "no error", ratio)
    name = min(finite, key=finite.get)
    return ResolutionCheck(label, float(residual), finite[name], name, ratio)
