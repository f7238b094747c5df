"""Scene variants and the instrumented run behind the benchmark and the stability suite.

A ``Variant`` is "a scene + a dict of parameter overrides + a simulation frequency + a
render rate": everything the speed-against-error plot compares. Candidates of later modes
(quality mode, docs/quality-mode.md) are variants with their own ``family`` and parameters, so they
land on the same plot without code changes here.

``run_variant`` loads the scene (``config.load_scene``), builds the player
(``Player.for_scene``) and the cloth system exactly as ``magica-py run`` does, then steps it
frame by frame, timing only ``player.step()`` and recording what the metrics need:

* positions (F, N, 3): world positions of the simulated bones after write-back (what a user
  sees), optional because big scenes make it large;
* per-frame statistics (F,): max edge stretch, max root-distance stretch, max collider
  penetration, max display speed, max solver velocity, non-finite flag, guard resets.

Frequencies beyond MagicaCloth2's 150 Hz cap (180 ... 23040 Hz) and step counts beyond its
5-step cap are set on the system's time settings after construction: the scene format and
``SimulationTimeSettings`` clamp them (on purpose, for scenes), the benchmark must not.
"""
from __future__ import annotations

import dataclasses
import importlib
import math
import pathlib
import time as _time
from dataclasses import dataclass, field

import numpy as np

from magica_py.bench import metrics as M


@dataclass(frozen=True)
class Variant:
    """One configuration of a scene.

    ``scene``: YAML path; ``overrides``: ``--set`` strings applied before validation;
    ``parameters``: dotted parameter key -> value applied to every cloth (validated, e.g.
    ``{"solver.rate_mode": "frequency_consistent"}``); ``frequency``: simulation Hz (None:
    the scene's; beyond 150 allowed); ``fps``: render rate (None: the scene's);
    ``duration``: seconds of unscaled time to run (None: the scene's length);
    ``raw_parameters``: solver parameter-table field -> value written after validation
    (stress cases outside the documented ranges, e.g. ``{"gravity": 100.0}``);
    ``family``: the series on the plot (``magica``, ``frequency_consistent``, ...).
    """

    label: str
    scene: str
    overrides: tuple[str, ...] = ()
    parameters: dict = field(default_factory=dict)
    frequency: int | None = None
    fps: float | None = None
    duration: float | None = None
    raw_parameters: dict = field(default_factory=dict)
    family: str = ""

    def with_(self, **changes) -> "Variant":
        return dataclasses.replace(self, **changes)


@dataclass
class RunResult:
    """What one run of a variant recorded (arrays are per frame unless said)."""

    variant: Variant
    frames: int
    frequency: int
    times: np.ndarray                 # (F,) s, unscaled time at the end of each frame
    scaled_times: np.ndarray          # (F,) s, Unity Time.time
    positions: np.ndarray | None      # (F, N, 3) m, simulated bones after write-back
    tips: np.ndarray                  # (F, K, 3) m, the chain tips (moving particles without children)
    edge_stretch: np.ndarray          # (F,) max relative edge stretch (+ = longer)
    edge_compression: np.ndarray      # (F,) min relative edge stretch
    root_stretch: np.ndarray          # (F,) max relative root-distance stretch
    penetration: np.ndarray           # (F,) m, max depth inside collider + particle radius
    display_speed: np.ndarray         # (F,) m/s, max |dp|/dt of the bones (unscaled dt)
    display_step: np.ndarray          # (F,) m, max |dp| of the bones over the frame
    state_speed: np.ndarray           # (F,) m/s, max |velocity| of the solver state
    non_finite: np.ndarray            # (F,) bool: a NaN/inf in the state or the hierarchy
    guard_resets: np.ndarray          # (F,) int: cloth_reset events this frame
    frame_wall: np.ndarray            # (F,) s, wall time of player.step()
    particle_steps: np.ndarray        # (F,) particle-steps simulated this frame
    geometry: M.ChainGeometry
    particle_count: int
    events: list = field(default_factory=list)
    edge_stretch_mean: np.ndarray | None = None   # (F,) mean |relative edge stretch| over the edges

    @property
    def wall_per_frame(self) -> float:
        """Median wall time of a frame (s)."""
        return float(np.median(self.frame_wall)) if self.frame_wall.size else math.nan

    @property
    def particle_steps_per_second(self) -> float:
        total = float(self.frame_wall.sum())
        return float(self.particle_steps.sum()) / total if total > 0 else math.nan


# ----------------------------------------------------------------------------- scene + player
def load_variant_scene(variant: Variant):
    """The scene of ``variant`` with its overrides, render rate and parameters applied."""
    from magica_py.config import load_scene

    overrides = list(variant.overrides)
    if variant.fps is not None:
        overrides.append(f"scene.fps={variant.fps:g}")
    scene = load_scene(variant.scene, overrides)
    if variant.parameters:
        cloths = []
        for spec in scene.cloths:
            params = spec.parameters.with_changes(dict(variant.parameters),
                                                  where=f"{variant.label}: cloths.{spec.name}.parameters")
            changes = {"parameters": params}
            mode = variant.parameters.get("collider_collision.mode")
            if mode is not None and hasattr(spec, "collision_mode"):
                changes["collision_mode"] = str(mode)
            cloths.append(dataclasses.replace(spec, **changes))
        scene.cloths = cloths
    return scene


def steps_needed(settings, frequency: int) -> int:
    """Max steps per frame so that no simulated time is dropped at ``frequency``."""
    longest = max(settings.frame_times) if settings.frame_times else settings.nominal_frame_time()
    longest = min(longest, settings.maximum_delta_time) * max(settings.time_scale, 1.0)
    return max(int(settings.max_steps_per_frame), int(math.ceil(frequency * longest - 1e-9)) + 1)


def attach_cloth(player, scene, parallel=None):
    """Attach the cloth system the way ``magica-py run`` does (``magica_py.solver.attach``),
    and return it; falls back to ``ClothSystem(...).attach`` when the package has no
    ``attach`` yet. ``parallel``: as ``solver.attach`` (None: the scene's ``threads``)."""
    solver = importlib.import_module("magica_py.solver")
    attach = getattr(solver, "attach", None)
    if attach is not None:
        system = attach(player, scene, parallel=parallel)
        if system is not None and hasattr(system, "particles"):
            return system
        for systems in getattr(player.schedule, "systems", {}).values():
            for s in systems:
                owner = getattr(getattr(s, "run", None), "__self__", None)
                if owner is not None and hasattr(owner, "particles"):
                    return owner
        raise RuntimeError("magica_py.solver.attach did not return the ClothSystem and it cannot be found "
                           "in the schedule")
    from magica_py.solver.system import ClothSystem

    return ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings,
                       parallel=parallel).attach(player, scene)


def set_frequency(system, frequency: int, max_steps: int) -> None:
    """Run ``system`` at ``frequency`` Hz with up to ``max_steps`` steps per frame, past the
    scene format's caps (the time settings clamp at construction, not afterwards)."""
    ts = system.time_settings
    ts.frequency = int(frequency)
    ts.max_steps_per_frame = int(max_steps)


@dataclass
class Prepared:
    scene: object
    player: object
    system: object
    frames: int
    frequency: int


def prepare(variant: Variant) -> Prepared:
    from magica_py.runtime.player import Player

    scene = load_variant_scene(variant)
    player = Player.for_scene(scene)
    system = attach_cloth(player, scene)
    s = scene.settings
    frequency = int(variant.frequency or s.simulation_frequency)
    set_frequency(system, frequency, steps_needed(s, frequency))
    if variant.raw_parameters:
        apply_raw_parameters(system, variant.raw_parameters)
    if variant.duration is not None:
        frames = _frames_for(s, variant.duration)
    else:
        frames = s.frame_count() or int(round(10.0 / s.nominal_frame_time()))
    return Prepared(scene, player, system, int(frames), frequency)


def apply_raw_parameters(system, raw: dict) -> None:
    """Write ``raw`` (parameter-table field -> value, every team) into ``system``'s parameter
    table past validation. The kernels read the table packed per block (``ClothSystem.P``), so
    the values go in through the system's own path for a parameter table that changed: a
    ``capture_state`` whose table is edited, written back with ``restore_state`` (before the
    first frame the state itself is unchanged; a team whose row no longer matches its block's
    moves to a block of its kind)."""
    state = system.capture_state()
    table = state["tables"]["parameters"]
    for name, value in raw.items():
        if name not in table:
            raise KeyError(f"raw parameter {name!r}: no such field of the solver's parameter table")
        table[name][...] = value
    system.restore_state(state)


def _frames_for(settings, duration: float) -> int:
    if settings.frame_times:
        total, n = 0.0, 0
        while total < duration - 1e-12:
            total += settings.frame_times[n % len(settings.frame_times)]
            n += 1
        return max(n, 1)
    return max(1, int(math.ceil(duration / settings.nominal_frame_time() - 1e-9)))


def rest_geometry(p: Prepared):
    """What the measurements of a prepared run share, taken at the rest pose before the first
    frame: (nodes, geometry, pairs): the bone of each particle ((N,) int64), the cloths'
    ``metrics.ChainGeometry`` with its rest lengths, and the (particle, collider) pairs the
    solver checks (``colliding_pairs``)."""
    h = p.scene.hierarchy
    h.propagate()
    nodes = np.asarray(p.system.model.transform_index, dtype=np.int64)
    geometry = M.chain_geometry(p.system.model, h.world_position[nodes].copy())
    return nodes, geometry, colliding_pairs(p.system, geometry)


def colliding_pairs(system, geometry: M.ChainGeometry) -> tuple[np.ndarray, np.ndarray]:
    """(particle, collider) index pairs the solver checks: the moving particles (fixed bones
    follow the animation; DisableCollision 0x10 excluded) of each cloth whose collision mode
    is not none, against that cloth's colliders."""
    team_cols = [list(getattr(spec, "colliders", ()) or ()) if getattr(spec, "collision_mode", "none") != "none"
                 else [] for spec in system.specs]
    pairs = M.particle_collider_pairs(geometry.team, team_cols)
    collides = geometry.moving & ((np.asarray(system.model.attribute) & 0x10) == 0)
    keep = collides[pairs[0]]
    return pairs[0][keep], pairs[1][keep]


# ----------------------------------------------------------------------------- the run
def run_variant(variant: Variant, record_positions: bool = True, progress=None,
                prepared: Prepared | None = None, before_frame=None) -> RunResult:
    """Run ``variant`` to its end and record the statistics (see the module docstring).

    ``progress(done, total)`` is called after each frame; ``before_frame(frame,
    unscaled_time, player, system)`` before each (harness actions such as a pause)."""
    p = prepared or prepare(variant)
    scene, player, system = p.scene, p.player, p.system
    model = system.model
    h = scene.hierarchy
    nodes, geometry, pairs = rest_geometry(p)
    radius_base = M.particle_radius(model, system.parameters)
    has_colliders = pairs[0].shape[0] > 0
    children = np.asarray(model.child_count)
    tips = np.nonzero(geometry.moving & (children == 0))[0]
    if tips.size == 0:
        tips = np.arange(min(1, nodes.shape[0]))

    f = p.frames
    n = nodes.shape[0]
    times = np.zeros(f)
    scaled = np.zeros(f)
    positions = np.zeros((f, n, 3)) if record_positions else None
    tip_track = np.zeros((f, tips.shape[0], 3))
    stretch = np.zeros(f)
    stretch_mean = np.zeros(f)
    compression = np.zeros(f)
    root_stretch = np.zeros(f)
    penetration = np.zeros(f)
    display_speed = np.zeros(f)
    display_step = np.zeros(f)
    state_speed = np.zeros(f)
    non_finite = np.zeros(f, dtype=bool)
    resets = np.zeros(f, dtype=np.int64)
    wall = np.zeros(f)
    steps = np.zeros(f)
    events = []
    ps = system.particles
    previous = h.world_position[nodes].copy()
    previous_time = 0.0
    clock = _time.perf_counter
    for i in range(f):
        if before_frame is not None:
            before_frame(i, previous_time, player, system)
        t0 = clock()
        ctx = player.step()
        wall[i] = clock() - t0
        steps[i] = float(ctx.metrics.get("cloth.steps", 0.0))
        times[i] = ctx.time.unscaled_time
        scaled[i] = ctx.time.time
        now = h.world_position[nodes]
        if positions is not None:
            positions[i] = now
        tip_track[i] = now[tips]
        velocity = ps.velocity   # the view gathers a copy of the packed state: once per frame
        bad = not (np.isfinite(now).all() and np.isfinite(ps.position).all()
                   and np.isfinite(velocity).all() and np.isfinite(ps.next_pos).all())
        non_finite[i] = bad
        es = M.edge_stretch(now, geometry)
        if es.size:
            stretch[i] = es.max()
            stretch_mean[i] = np.abs(es).mean()
            compression[i] = es.min()
        rs = M.root_distance_stretch(now, geometry)
        root_stretch[i] = rs.max() if rs.size else 0.0
        if has_colliders:
            shapes = scene.colliders.world_shapes(h)
            ratio = system.teams.component_scale_ratio
            radius = radius_base * np.where(ratio > 0, ratio, 1.0)[geometry.team]
            penetration[i] = M.penetration_depth(now, radius, pairs, shapes).max()
        dt = times[i] - previous_time
        if i > 0:  # frame 0 jumps from the build pose to the first animated pose
            display_step[i] = float(np.linalg.norm(now - previous, axis=1).max(initial=0.0))
            if dt > 1e-12:
                display_speed[i] = display_step[i] / dt
        state_speed[i] = float(np.sqrt((velocity * velocity).sum(axis=1)).max(initial=0.0))
        previous = now.copy()
        previous_time = times[i]
        for kind, payload in ctx.events:
            if kind == "cloth_reset":
                resets[i] += 1
                events.append((i, kind, payload))
        if progress is not None:
            progress(i + 1, f)
    return RunResult(variant, f, p.frequency, times, scaled, positions, tip_track, stretch, compression,
                     root_stretch, penetration, display_speed, display_step, state_speed, non_finite, resets, wall, steps,
                     geometry, n, events, edge_stretch_mean=stretch_mean)


def time_once(variant: Variant, frames: int | None = None) -> tuple[float, float]:
    """One fresh run of ``variant``: mean wall time per frame of ``player.step()`` (s) and
    particle-steps per second; nothing but the player runs in the timed loop."""
    p = prepare(variant)
    count = p.frames if frames is None else min(frames, p.frames)
    steps = 0.0
    clock = _time.perf_counter
    step = p.player.step
    start = clock()
    for _ in range(count):
        steps += step().metrics.get("cloth.steps", 0.0)
    elapsed = clock() - start
    return elapsed / count, (steps / elapsed if elapsed > 0 else math.nan)


@dataclass(frozen=True)
class Timing:
    """Repeated timings of one variant: ``per_frame`` (R,) s per frame of each fresh run and
    ``rates`` (R,) particle-steps/s of each, in the order they ran."""

    per_frame: np.ndarray
    rates: np.ndarray

    @property
    def middle(self) -> int:
        """Index of the median run (the upper one of the two middle runs for an even count)."""
        return int(np.argsort(self.per_frame, kind="stable")[len(self.per_frame) // 2])

    @property
    def median(self) -> float:
        """Median s/frame of the repeats (the mean of the two middle runs for an even count)."""
        return float(np.median(self.per_frame))

    @property
    def minimum(self) -> float:
        return float(self.per_frame.min())

    @property
    def quartiles(self) -> tuple[float, float]:
        """First and third quartile of the repeats (s/frame): the spread shown as error bars."""
        return float(np.percentile(self.per_frame, 25)), float(np.percentile(self.per_frame, 75))

    @property
    def median_rate(self) -> float:
        """Particle-steps/s of the median run."""
        return float(self.rates[self.middle])


def time_repeats(variants: list, repeats: int = 9, frames: int | None = None, progress=None) -> list[Timing]:
    """``repeats`` fresh runs (``time_once``) of each variant, taken round robin (variant 1,
    2, ..., n, then again) so that load from other processes on a shared machine spreads over
    all variants instead of biasing one; one ``Timing`` per variant, in order."""
    samples = [[] for _ in variants]
    for _ in range(max(1, repeats)):
        for i, v in enumerate(variants):
            samples[i].append(time_once(v, frames))
            if progress is not None:
                progress(v)
    return [Timing(np.array([x[0] for x in s]), np.array([x[1] for x in s])) for s in samples]


def time_interleaved(variants: list, repeats: int = 9, frames: int | None = None, progress=None) -> list:
    """``time_repeats`` as ``[(median s/frame, particle-steps/s of that run, minimum s/frame)]``
    (the minimum is the better estimate of the cost when other processes only add time)."""
    return [(t.median, t.median_rate, t.minimum)
            for t in time_repeats(variants, repeats, frames, progress)]


def time_variant(variant: Variant, repeats: int = 3, frames: int | None = None) -> tuple[float, float]:
    """Median over ``repeats`` fresh runs of ``time_once`` (s/frame, particle-steps/s)."""
    return time_interleaved([variant], repeats, frames)[0][:2]


def resolve_scene_path(name: str) -> str:
    """``configs/<name>.yaml`` relative to the repository (or ``name`` when it is a path)."""
    path = pathlib.Path(name)
    if path.suffix in (".yaml", ".yml") and path.exists():
        return str(path)
    root = pathlib.Path(__file__).resolve().parents[2]
    candidate = root / "configs" / f"{name}.yaml"
    return str(candidate if candidate.exists() else path)
