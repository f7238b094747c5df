"""The player loop: one rendered frame = every phase of the schedule, in order (docs/solver.md §A.2).

``Player.step()``:

1. ``time_manager.advance(time_source.next_delta())`` -> ``UnityTime`` (``runtime.clock``).
2. RESTORE, FIXED_UPDATE x ``time.fixed_update_count`` (``ctx.fixed_update_index`` = 0..k-1,
   ``ctx.fixed_time`` = that step's fixed clock; ``ctx.counters.fixed_update_count`` += 1 after
   each, as MagicaCloth2's TimeManager.AfterFixedUpdate does; with no system in the phase only
   the counter advances), UPDATE, LATE_UPDATE,
   RENDER_WRITE, AFTER_RENDERING. The wall time of each phase is recorded in
   ``ctx.metrics["time.<phase>"]`` (seconds; FIXED_UPDATE summed over its runs; a phase with
   no system records 0.0 untimed, its few instructions counted in the next phase's time;
   inside UPDATE ``animation.drivers`` and ``animation.propagate`` split the animation
   system), and with
   ``player.profile_systems = True`` each system's in ``ctx.metrics["time.system.<name>"]``.
   An exception escaping a system gets a note naming the system, phase and frame.
3. Events raised this frame (``ctx.events``, ``(kind, payload)``) are dispatched to the
   handlers in ``player.event_handlers`` at the end of the frame, so a time-scale change
   takes effect on the next frame's delta time. Built in: ``("time_scale", value)`` sets
   Unity's ``Time.timeScale``. Unknown kinds are left to the systems that read ``ctx.events``.

The player knows nothing about the config package: ``scene`` is any object; the default
systems use ``scene.hierarchy`` (``restore_rest_pose``, ``propagate``) and, when present,
``scene.animation.apply(hierarchy, ctx)``. The UPDATE system propagates the subtrees of the
driven bones (``scene.animation.driven``) and of the restored bones only (a precomputed plan,
``scene/propagation.py``): a system that writes the local pose of another bone propagates it
itself (``hierarchy.propagate()``, or a plan of its own).
"""
from __future__ import annotations

import time as _time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from magica_py.runtime.clock import FrameTimeSource, TimeManager, UnityTime, time_from_settings
from magica_py.runtime.phases import Phase, Schedule, System

PHASE_METRIC = {phase: f"time.{phase.name.lower()}" for phase in Phase}
_NUMBERS = (int, float, np.integer, np.floating)   # metrics that are summed over a run


@dataclass
class FrameCounters:
    """Counters that live across frames, like MagicaCloth2's static TimeManager counters."""

    fixed_update_count: int = 0  # FixedUpdates since the last AFTER_RENDERING reset


@dataclass
class FrameContext:
    """What every system of one frame sees."""

    frame: int                   # 0-based index of this frame in the run
    time: UnityTime
    scene: Any
    counters: FrameCounters
    events: list = field(default_factory=list)    # (kind, payload) raised this frame
    metrics: dict = field(default_factory=dict)   # name -> float, fresh every frame
    fixed_update_index: int | None = None         # 0..k-1 inside FIXED_UPDATE, else None
    fixed_time: float | None = None               # fixed clock of the current FixedUpdate
    phase: Phase | None = None                    # phase being run


@dataclass
class RunSummary:
    frames: int
    wall_time: float                           # s, whole run
    totals: dict                               # metric name -> sum over the run's frames

    @property
    def wall_time_per_frame(self) -> float:
        return self.wall_time / self.frames if self.frames else 0.0


def _apply_time_scale(player: "Player", payload) -> None:
    player.time_manager.time_scale = float(payload)


class Player:
    """Runs ``scene`` frame by frame through ``schedule``."""

    def __init__(self, scene: Any, schedule: Schedule, time_source: FrameTimeSource,
                 time_manager: TimeManager | None = None):
        self.scene = scene
        self.schedule = schedule
        self.time_source = time_source
        self.time_manager = time_manager if time_manager is not None else TimeManager()
        self.counters = FrameCounters()
        self.frame = 0
        self.last_context: FrameContext | None = None
        self.metric_totals: dict[str, float] = {}
        self.event_handlers: dict[str, Callable[["Player", Any], None]] = {
            "time_scale": _apply_time_scale,
        }
        self.profile_systems = False  # True: also record ctx.metrics["time.system.<name>"]
        self._plan: tuple | None = None   # (schedule order, its walk): ``_frame_plan``

    def reset(self) -> None:
        """Back to frame 0: time source, time manager, counters and metric totals.

        Scene state (poses, animation events, cloth state) belongs to its owners."""
        self.time_source.reset()
        self.time_manager.reset()
        self.counters.fixed_update_count = 0
        self.frame = 0
        self.last_context = None
        self.metric_totals.clear()

    @classmethod
    def for_scene(cls, scene: Any, schedule: Schedule | None = None) -> "Player":
        """A player with ``default_schedule(scene)`` (unless given) and the frame-time source
        and time manager described by ``scene.settings`` (``clock.time_from_settings``)."""
        source, manager = time_from_settings(getattr(scene, "settings", None) or {})
        return cls(scene, schedule if schedule is not None else default_schedule(scene),
                   source, manager)

    # -- state capture (runtime/snapshot.py)
    def capture(self):
        """A ``Snapshot`` of the whole simulation state (clock, poses, animation, systems)."""
        from magica_py.runtime.snapshot import capture

        return capture(self)

    def restore(self, snapshot, keep_model: bool = False) -> None:
        """Back to ``snapshot``: the frames that follow give the same bits as after the capture.
        ``keep_model=True`` keeps this player's parameters and frame rate (``runtime/snapshot.py``)."""
        from magica_py.runtime.snapshot import restore

        restore(self, snapshot, keep_model=keep_model)

    # -- restore registry (kept on the schedule so systems built before the player see it)
    def register_restored_bones(self, indices, owner: object = None) -> None:
        """Bones (hierarchy indices) put back to their build-time local pose each RESTORE."""
        self.schedule.restore.register(indices, owner)

    def unregister_restored_bones(self, owner: object = None) -> None:
        self.schedule.restore.unregister(owner)

    @property
    def restored_bones(self) -> np.ndarray:
        return self.schedule.restore.indices

    def set_time_scale(self, value: float) -> None:
        """Unity ``Time.timeScale`` from the next frame on."""
        self.time_manager.time_scale = value

    # -- the loop
    def _run_phase(self, ctx: FrameContext, phase: Phase, systems: tuple) -> None:
        ctx.phase = phase
        profile = self.profile_systems
        clock = _time.perf_counter
        for system in systems:
            start = clock() if profile else 0.0
            try:
                system.run(ctx)
            except Exception as exc:
                exc.add_note(f"in system {system.name!r} ({phase.name}) at frame {ctx.frame}")
                raise
            if profile:
                key = f"time.system.{system.name}"
                ctx.metrics[key] = ctx.metrics.get(key, 0.0) + clock() - start

    def _frame_plan(self, order) -> tuple:
        """``order`` (``Schedule.order()``) as the walk ``step`` takes: ``(phase, metric name,
        systems, is FIXED_UPDATE)`` per phase, made once per schedule change."""
        plan = self._plan
        if plan is None or plan[0] is not order:
            walk = tuple((phase, PHASE_METRIC[phase], systems, phase is Phase.FIXED_UPDATE)
                         for phase, systems in order)
            plan = self._plan = (order, walk)
        return plan[1]

    def step(self) -> FrameContext:
        """Run one frame; returns its context. The frame walks the schedule as it was when the
        frame began: a system added or removed by a system takes effect from the next frame.

        A phase's time runs from the end of the previous phase with a system to the end of its
        own; a phase without a system records 0.0 and is not timed."""
        t = self.time_manager.advance(self.time_source.next_delta())
        ctx = FrameContext(self.frame, t, self.scene, self.counters)
        metrics = ctx.metrics
        walk = self._frame_plan(self.schedule.order())
        clock = _time.perf_counter
        mark = clock()
        for phase, metric, systems, fixed in walk:
            if not systems:
                if fixed:   # nobody listens (the usual schedule): only the count advances
                    self.counters.fixed_update_count += t.fixed_update_count
                metrics[metric] = 0.0
                continue
            if fixed:
                first_fixed = t.fixed_time - t.fixed_update_count * t.fixed_delta_time
                for k in range(t.fixed_update_count):
                    ctx.fixed_update_index = k
                    ctx.fixed_time = first_fixed + (k + 1) * t.fixed_delta_time
                    self._run_phase(ctx, phase, systems)
                    self.counters.fixed_update_count += 1  # TimeManager.AfterFixedUpdate
                ctx.fixed_update_index = None
                ctx.fixed_time = None
            else:
                self._run_phase(ctx, phase, systems)
            now = clock()
            metrics[metric] = now - mark
            mark = now
        ctx.phase = None
        if ctx.events:
            for kind, payload in ctx.events:
                handler = self.event_handlers.get(kind)
                if handler is not None:
                    handler(self, payload)
        totals = self.metric_totals
        total = totals.get
        for name, value in metrics.items():
            if type(value) is float:   # the common case first: a dozen metrics a frame
                totals[name] = total(name, 0.0) + value
            elif isinstance(value, _NUMBERS):
                totals[name] = total(name, 0.0) + float(value)
        self.frame += 1
        self.last_context = ctx
        return ctx

    def run(self, frames: int, progress: Callable[[int, int, FrameContext], None] | None = None
            ) -> RunSummary:
        """Run ``frames`` frames; ``progress(done, frames, ctx)`` is called after each."""
        if frames < 0:
            raise ValueError(f"frames: expected >= 0, got {frames}")
        start = _time.perf_counter()
        totals_before = dict(self.metric_totals)
        for i in range(frames):
            ctx = self.step()
            if progress is not None:
                progress(i + 1, frames, ctx)
        totals = {k: v - totals_before.get(k, 0.0) for k, v in self.metric_totals.items()}
        return RunSummary(frames=frames, wall_time=_time.perf_counter() - start, totals=totals)


# ----------------------------------------------------------------------------- default systems
class _MovingSubtrees:
    """The propagation plan of the UPDATE phase: the subtrees of the bones whose local pose
    changes every frame, i.e. the animation's driven bones (teleport targets included) and the
    bones put back to their rest pose in RESTORE; every node when the animation object does not
    list what it drives (no ``driven`` attribute). Every other node keeps the world pose of the
    last propagation. Rebuilt (outside the per-frame path) when the restore registry, the
    animation, the hierarchy or its thread count changes."""

    def __init__(self, registry):
        self.registry = registry
        self._key = None
        self._plan = None

    def plan(self, hierarchy, animation):
        key = (id(hierarchy), id(animation), self.registry.version, hierarchy.threads)
        if key != self._key:
            driven = getattr(animation, "driven", None)
            if animation is not None and driven is None:
                self._plan = hierarchy.plan()  # an animation that does not say what it drives
            else:
                nodes = [self.registry.indices]
                if driven is not None:
                    nodes.append(np.asarray(driven))
                self._plan = hierarchy.plan(np.concatenate(nodes).astype(np.int64))
            self._key = key
        return self._plan


def default_schedule(scene: Any) -> Schedule:
    """RESTORE ``restore_bones``, UPDATE ``animation``, AFTER_RENDERING ``reset_frame_counters``.

    The cloth system (LATE_UPDATE) and the sinks (RENDER_WRITE) are added by their owners.
    """
    if not hasattr(scene, "hierarchy"):
        raise TypeError(f"default_schedule: the scene must have a 'hierarchy' "
                        f"(TransformHierarchy), got {type(scene).__name__}")
    schedule = Schedule()
    registry = schedule.restore

    def restore_bones(ctx: FrameContext) -> None:
        indices = registry.indices
        if indices.size:
            ctx.scene.hierarchy.restore_rest_pose(indices)

    moving = _MovingSubtrees(registry)

    def animation(ctx: FrameContext) -> None:
        anim = getattr(ctx.scene, "animation", None)
        hierarchy = ctx.scene.hierarchy
        clock = _time.perf_counter
        t0 = clock()
        if anim is not None:
            anim.apply(hierarchy, ctx)
        t1 = clock()
        hierarchy.propagate(moving.plan(hierarchy, anim))
        ctx.metrics["animation.drivers"] = t1 - t0
        ctx.metrics["animation.propagate"] = clock() - t1

    def reset_frame_counters(ctx: FrameContext) -> None:
        ctx.metrics["frame.fixed_updates"] = float(ctx.counters.fixed_update_count)
        ctx.counters.fixed_update_count = 0  # TimeManager.AfterRenderring

    schedule.add(Phase.RESTORE, System("restore_bones", restore_bones))
    schedule.add(Phase.UPDATE, System("animation", animation))
    schedule.add(Phase.AFTER_RENDERING, System("reset_frame_counters", reset_frame_counters))
    return schedule
