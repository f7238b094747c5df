"""The hard-case stability suite (docs/STABILITY.md): cases, their stated bounds, evaluation.

Each case is a scene in ``configs/hard/`` plus what the harness does that a scene file
cannot (a timeScale pause, parameters past the validated ranges) and the bounds the run
must keep:

* no NaN or inf in the solver state or the hierarchy at any frame;
* the solver's particle speed (``velocity``, m/s) below ``max_speed``;
* edge stretch below ``max_stretch`` (relative, at every frame);
* after the collider stops moving (``disturbance_end``), no particle deeper than
  ``max_penetration`` inside "collider + particle radius";
* back to rest (every bone's display speed below ``rest_speed`` x scene scale) within
  ``settle_within`` seconds of unscaled time after ``disturbance_end``.

The bounds are stated from measurement (``magica-py stability``, docs/STABILITY.md). Where
MagicaCloth2's algorithm as specified cannot do better, the bound is the measured figure
with a margin, and ``note`` says why; it is not a target the solver met by design.
"""
from __future__ import annotations

import math
import pathlib
from dataclasses import dataclass, field

import numpy as np

from magica_py.bench import metrics as M
from magica_py.bench.variants import RunResult, Variant, prepare, run_variant

HARD_DIR = pathlib.Path(__file__).resolve().parents[2] / "configs" / "hard"


@dataclass(frozen=True)
class HardCase:
    name: str
    scene: str                        # file name in configs/hard
    disturbance_end: float            # s (unscaled): input motion is over from here on
    settle_within: float              # s after disturbance_end to be back at rest
    max_speed: float = 10.0           # m/s, solver particle speed bound
    max_stretch: float = 0.5          # relative edge stretch bound
    max_penetration: float = 0.002    # m, after disturbance_end (10 % of the default 0.02 radius)
    rest_speed: float = 0.02          # m/s at scale 1
    scale: float = 1.0                # scene scale (rest speed, penetration and bounds scale with it)
    raw_parameters: dict = field(default_factory=dict)
    time_scale_actions: tuple = ()    # ((unscaled time, Unity timeScale), ...) applied by the harness
    short_duration: float | None = None  # s, for the CI test (None: the whole scene)
    clock: str = "unscaled"           # "scaled": disturbance_end, settling and speeds in game time
    note: str = ""

    @property
    def path(self) -> str:
        return str(HARD_DIR / self.scene)

    def variant(self, duration: float | None = None, parameters: dict | None = None) -> Variant:
        return Variant(self.name, self.path, duration=duration, raw_parameters=dict(self.raw_parameters),
                       parameters=dict(parameters or {}), family="hard")


CASES: tuple[HardCase, ...] = (
    # name, scene, disturbance_end (s), settle_within (s, measured + ~30 %)
    HardCase("teleport_100m_reset", "teleport_100m_reset.yaml", 1.0, 7.0,
             note="Reset snaps to the build pose, which is not the equilibrium under gravity: the chain "
                  "then swings down like at the start"),
    HardCase("teleport_100m_off", "teleport_100m_off.yaml", 1.0, 7.0,
             note="no detection: the 5 m/s movement speed limit turns all but 5 m/s of the jump into a "
                  "rigid shift, so the chain barely notices"),
    HardCase("spin_180", "spin_180.yaml", 1.0, 6.0),
    HardCase("hitch", "hitch.yaml", 1.5, 7.0),
    HardCase("random_frame_times", "random_frame_times.yaml", 3.0, 7.0),
    HardCase("time_scale", "time_scale.yaml", 0.5, 7.0, time_scale_actions=((0.25, 0.0), (0.75, 1.0)),
             clock="scaled",
             note="game time: paused 0.25-0.75 s (unscaled), x0.1 from 1.0 s of game time on; settling "
                  "and speeds are measured in game time"),
    HardCase("chain_200", "chain_200.yaml", 0.5, 32.0, max_stretch=1.4, short_duration=2.0,
             note="finding: edges near the tip stretch by up to 110 % while the 4 m chain swings, and the "
                  "chain still stretches 5 % on average (11 % max) when hanging; MagicaCloth2's soft "
                  "distance constraint (docs/solver.md Appendix 4)"),
    HardCase("chains_1000", "chains_1000.yaml", 0.5, 6.0, short_duration=1.0),
    HardCase("zero_length_bones", "zero_length_bones.yaml", 0.5, 3.5),
    HardCase("scale_0_01", "scale_0_01.yaml", 0.5, 1.0, scale=0.01),
    HardCase("scale_100", "scale_100.yaml", 0.5, 3.5, scale=100.0, max_speed=1000.0),
    HardCase("engulfing_collider", "engulfing_collider.yaml", 1.0, 6.0),
    HardCase("extreme_parameters", "extreme_parameters.yaml", 0.5, 6.5, max_speed=50.0, max_stretch=0.8,
             note="20 links of 5 cm. Finding: edges stretch up to 62 % while the chain whips under gravity 20 "
                  "(docs/solver.md Appendix 4 measured +60 % for a gravity-20 whip); damping 0: only the constraints' "
                  "velocity attenuation and restoration take energy out"),
    HardCase("extreme_gravity_100", "extreme_parameters.yaml", 0.5, 3.0, max_speed=100.0, max_stretch=2.0,
             raw_parameters={"gravity": 100.0},
             note="gravity 100 m/s^2 is past MagicaCloth2's validated range [0, 20] (docs/solver.md §F.1): written "
                  "into the solver's parameter table after validation"),
    HardCase("speed_limit_off", "speed_limit_off.yaml", 2.0, 6.0, max_speed=50.0),
    HardCase("violent_50rad", "violent_50rad.yaml", 2.0, 7.0, max_stretch=2.0),
)


def find_case(cases, name: str, what: str):
    """The case called ``name`` among ``cases`` (anything with a ``name``); a KeyError that
    lists them otherwise. ``what``: the kind of case, for the message."""
    for c in cases:
        if c.name == name:
            return c
    raise KeyError(f"no {what} case {name!r}; cases: {', '.join(c.name for c in cases)}")


def case(name: str) -> HardCase:
    return find_case(CASES, name, "hard")


@dataclass
class CaseResult:
    case: HardCase
    frames: int
    finite: bool
    max_speed: float              # m/s, solver state
    max_display_speed: float      # m/s, bones (includes teleports)
    max_stretch: float            # relative
    max_compression: float        # relative (most negative)
    max_root_stretch: float
    penetration_after: float      # m, max after disturbance_end (+ one frame)
    settle_time: float            # s after disturbance_end (inf: never)
    guard_resets: int
    wall_per_frame: float         # s, median
    settle_checked: bool = True   # the run lasted long enough to judge the return to rest

    def failures(self) -> list[str]:
        c = self.case
        out = []
        if not self.finite:
            out.append("non-finite values")
        if not self.max_speed <= c.max_speed:
            out.append(f"speed {self.max_speed:.3g} m/s > {c.max_speed:g}")
        if not self.max_stretch <= c.max_stretch:
            out.append(f"stretch {100 * self.max_stretch:.3g} % > {100 * c.max_stretch:g} %")
        if not self.penetration_after <= c.max_penetration * c.scale:
            out.append(f"penetration {1000 * self.penetration_after:.3g} mm > {1000 * c.max_penetration * c.scale:g} mm")
        if self.settle_checked and not self.settle_time <= c.settle_within:
            out.append(f"settles in {self.settle_time:.3g} s > {c.settle_within:g} s")
        return out


def time_scale_hook(actions):
    """A ``run_variant`` hook that sets Unity's timeScale at given unscaled times."""
    pending = sorted(actions)

    def hook(frame, unscaled_time, player, system):
        while pending and unscaled_time >= pending[0][0] - 1e-9:
            player.set_time_scale(pending.pop(0)[1])
    return hook


def run_case(c: HardCase, duration: float | None = None, parameters: dict | None = None
             ) -> tuple[CaseResult, RunResult]:
    """Run one hard case (its full scene, or ``duration`` seconds) and evaluate it;
    ``parameters`` (dotted key -> value) are applied to every cloth, e.g. a quality-mode
    candidate."""
    variant = c.variant(duration, parameters)
    hook = time_scale_hook(c.time_scale_actions) if c.time_scale_actions else None
    run = run_variant(variant, record_positions=False, before_frame=hook, prepared=prepare(variant))
    return evaluate(c, run), run


def evaluate(c: HardCase, run: RunResult) -> CaseResult:
    times = run.scaled_times if c.clock == "scaled" else run.times
    if c.clock == "scaled":
        dt = np.diff(times, prepend=0.0)
        speed = np.where(dt > 1e-12, run.display_step / np.where(dt > 1e-12, dt, 1.0), 0.0)
    else:
        speed = run.display_speed
    after = times > c.disturbance_end + 1e-9
    # the frame that crosses disturbance_end may still carry the last input motion
    if after.any():
        first = int(np.argmax(after))
        after[first] = False
    pen = float(run.penetration[after].max()) if after.any() else 0.0
    end = float(times[-1]) if times.size else 0.0
    if end < c.disturbance_end:
        settle = math.nan                      # the run stops before the disturbance is over
    else:
        settle = M.settling_time(speed, times, c.rest_speed * c.scale, after=c.disturbance_end)
    return CaseResult(
        case=c, frames=run.frames, finite=not bool(run.non_finite.any()),
        max_speed=float(run.state_speed.max(initial=0.0)),
        max_display_speed=float(speed.max(initial=0.0)),
        max_stretch=float(run.edge_stretch.max(initial=0.0)),
        max_compression=float(run.edge_compression.min(initial=0.0)),
        max_root_stretch=float(run.root_stretch.max(initial=0.0)),
        penetration_after=pen, settle_time=settle, guard_resets=int(run.guard_resets.sum()),
        wall_per_frame=run.wall_per_frame, settle_checked=end >= c.disturbance_end + c.settle_within - 1e-9)
