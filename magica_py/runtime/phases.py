"""Frame phases as data: an ordered list of phases, an ordered list of systems in each.

The six phases mirror where MagicaCloth2 hooks Unity's PlayerLoop (docs/solver.md §A.2). Systems are
plain ``System(name, run)`` values with ``run(ctx: FrameContext) -> None``; the ``Player``
walks ``Phase`` in order and runs each phase's systems in their registered order (there is
one explicit, total order: no ambiguity between systems of a phase).

``Schedule`` also holds the *restore registry*: the hierarchy indices of bones that cloth
systems want put back to their build-time local pose every frame (``RESTORE``), keyed by
owner so that a cloth can unregister its bones when it is removed.
"""
from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Callable

import numpy as np


class Phase(IntEnum):
    """The phases of one rendered frame, in execution order."""

    RESTORE = 0
    """Unity ``afterEarlyUpdate`` (ClothManager.OnEarlyClothUpdate): bones that cloth writes
    get their build-time local position and rotation back, so last frame's simulated pose is
    not read as this frame's animation. Only restores: no animation, no simulation."""

    FIXED_UPDATE = 1
    """Unity ``FixedUpdate``, run 0..k times this frame (``ctx.time.fixed_update_count``, from
    fixedDeltaTime accumulation; ``ctx.fixed_update_index`` is the current one). Physics-rate
    drivers belong here (e.g. animators in AnimatePhysics mode). After each run the player
    increments ``ctx.counters.fixed_update_count`` (TimeManager.AfterFixedUpdate)."""

    UPDATE = 2
    """Unity ``Update`` and the Animator: animation drivers write local poses, then the
    hierarchy is propagated so that world poses are current for late update."""

    LATE_UPDATE = 3
    """Unity ``PreLateUpdate`` after ``ScriptRunBehaviourLateUpdate`` (MagicaCloth2's default
    ``AfterLateUpdate``): the cloth simulation reads transforms, runs team time and steps and
    writes bone poses back (§A.3). Game code that must see the simulated pose goes after
    the cloth system in this phase."""

    RENDER_WRITE = 4
    """Unity ``PostLateUpdate`` / rendering: output sinks log the frame. Nothing here may
    change the scene state."""

    AFTER_RENDERING = 5
    """Unity ``FinishFrameRendering`` (TimeManager.AfterRenderring): per-frame counters are
    reset (``fixed_update_count = 0``). Bookkeeping only."""


@dataclass(frozen=True)
class System:
    """A named step of a phase: ``run(ctx)`` is called once per phase execution."""

    name: str
    run: Callable[..., None]

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"System: expected a non-empty name, got {self.name!r}")
        if not callable(self.run):
            raise TypeError(f"System {self.name!r}: run must be callable, got {self.run!r}")


class RestoreRegistry:
    """Bones to restore each frame, the union of what each owner registered (sorted int32)."""

    def __init__(self):
        self._by_owner: dict[object, np.ndarray] = {}
        self._indices = np.zeros(0, dtype=np.int32)
        self.version = 0  # counts the changes (plans built from the indices compare it)

    def register(self, indices, owner: object = None) -> None:
        """Add ``indices`` (hierarchy node indices) under ``owner`` (added to what it had)."""
        new = np.asarray(indices, dtype=np.int64).ravel()
        if new.size and new.min() < 0:
            raise ValueError(f"restored bones: negative hierarchy index in {new.tolist()}")
        old = self._by_owner.get(owner, np.zeros(0, dtype=np.int64))
        self._by_owner[owner] = np.union1d(old, new)
        self._rebuild()

    def unregister(self, owner: object) -> None:
        self._by_owner.pop(owner, None)
        self._rebuild()

    def _rebuild(self) -> None:
        if self._by_owner:
            merged = np.unique(np.concatenate(list(self._by_owner.values())))
        else:
            merged = np.zeros(0)
        self._indices = np.ascontiguousarray(merged, dtype=np.int32)
        self.version += 1

    @property
    def indices(self) -> np.ndarray:
        """Sorted, unique int32 indices (do not modify)."""
        return self._indices


class Schedule:
    """Ordered systems per phase. Names are unique across the schedule."""

    def __init__(self):
        self._systems: dict[Phase, list[System]] = {phase: [] for phase in Phase}
        self.restore = RestoreRegistry()
        self._order: tuple | None = None   # ``order()``, made again after add / remove

    def add(self, phase: Phase, system: System, before: str | None = None,
            after: str | None = None) -> System:
        """Register ``system`` in ``phase``: at the end, or just before / after a named system
        of the same phase."""
        phase = Phase(phase)
        if not isinstance(system, System):
            raise TypeError(f"Schedule.add: expected a System, got {system!r}")
        if before is not None and after is not None:
            raise ValueError(f"system {system.name!r}: give 'before' or 'after', not both")
        if self.find(system.name) is not None:
            raise ValueError(f"system {system.name!r} is already scheduled in "
                             f"{self.find(system.name).name}")
        systems = self._systems[phase]
        anchor = before if before is not None else after
        self._order = None
        if anchor is None:
            systems.append(system)
            return system
        names = [s.name for s in systems]
        if anchor not in names:
            raise ValueError(f"system {system.name!r}: no system {anchor!r} in phase {phase.name} "
                             f"(it has {names})")
        i = names.index(anchor)
        systems.insert(i if before is not None else i + 1, system)
        return system

    def remove(self, name: str) -> System:
        for systems in self._systems.values():
            for i, s in enumerate(systems):
                if s.name == name:
                    self._order = None
                    return systems.pop(i)
        raise KeyError(f"no system named {name!r} in the schedule")

    def find(self, name: str) -> Phase | None:
        """The phase holding the system ``name``, or None."""
        for phase, systems in self._systems.items():
            if any(s.name == name for s in systems):
                return phase
        return None

    def systems(self, phase: Phase) -> tuple[System, ...]:
        systems = self._systems.get(phase)   # a Phase member: no enum lookup (every frame)
        if systems is None:
            systems = self._systems[Phase(phase)]
        return tuple(systems)

    def order(self) -> tuple[tuple[Phase, tuple[System, ...]], ...]:
        """``((phase, its systems), ...)`` for every phase in execution order: what the player
        walks each frame (kept until the next ``add`` / ``remove``)."""
        if self._order is None:
            self._order = tuple((phase, tuple(self._systems[phase])) for phase in Phase)
        return self._order

    def describe(self) -> list[tuple[str, list[str]]]:
        """``[(phase name, [system names in order]), ...]`` for every phase, in order."""
        return [(phase.name, [s.name for s in self._systems[phase]]) for phase in Phase]

    def __repr__(self) -> str:
        body = "; ".join(f"{p}: {', '.join(n) or '-'}" for p, n in self.describe())
        return f"Schedule({body})"
