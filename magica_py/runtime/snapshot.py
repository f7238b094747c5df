"""Capture and restore the whole simulation state of a player, bit for bit.

``capture(player) -> Snapshot`` copies everything a later frame reads: the player's clock
(time source position, Unity time manager, fixed-update counters, frame index), the scene's
transform hierarchy (every pose array), the animation's event cursor and teleport offsets, and
the state of every system in the schedule that keeps one (``capture_state`` /
``restore_state``: ``ClothSystem`` keeps its particles, teams, colliders, parameters, team
clocks and build pose). ``restore(player, snapshot)`` writes it back in place, so running the
same frames again gives the same bits (``tests/test_snapshot.py``). Uses: restarting a
candidate from a reference's state (``magica-py bench``'s short-horizon error), replays,
batch jobs that fork from a common warm-up.

``restore(player, snapshot, keep_model=True)`` restores where the simulation *is* and keeps
what this player *simulates*: a candidate restarted from a reference's state (the bench's
short-horizon error, ``docs/BENCHMARKS.md``). It writes the clock's position (the time
manager: frame count, game and unscaled time, fixed-update base), the poses, the animation
cursor and each system's evolving state (``ClothSystem``: particles, teams, colliders, team
clocks, build pose, frame count) and keeps this player's model: each system's
``MODEL_STATE`` parts (``ClothSystem``: its parameter table, runtime parameter overrides and
collision modes), the player's frame-time source (frame rate or frame-time list, with its
position) and the systems' time settings (simulation frequency and step cap; those are never
in a snapshot). The team clocks (``TeamTimeState``) hold times in seconds, not step counts, so
they carry over to another frequency as they are: the candidate's next step comes ``1/f``
after the last step the snapshot's run took (``now_update_time``), and its planned step count
is ``trunc((time + frame delta - now_update_time) * f)`` (+ 1e-6 in exact timing): the phase
of its step grid is the snapshot's. Another frame rate continues from the snapshot's game time with its own frame
delta, so the snapshot must be taken at a time on the candidate's frame grid (the bench's
windows are 0.25 s: a whole number of frames at 30, 60, 144 and 240 fps).

What a snapshot is not: it does not hold structure. Restoring after cloths were added or
removed, or into another scene, is refused with a clear error. Sinks (recordings) are outside
the simulation and are not rewound.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any

import numpy as np


class SnapshotError(ValueError):
    """A snapshot that cannot be restored into this player (another scene or structure)."""


@dataclass(frozen=True)
class Snapshot:
    """The state of a player and its systems after ``frame`` frames (``time`` s of game time)."""

    frame: int
    time: float
    parts: dict = field(repr=False)     # owner name -> its state (arrays copied, objects deep-copied)

    @property
    def nbytes(self) -> int:
        """Bytes held by the snapshot's arrays."""
        total = 0
        stack = list(self.parts.values())
        while stack:
            item = stack.pop()
            if isinstance(item, np.ndarray):
                total += item.nbytes
            elif isinstance(item, dict):
                stack.extend(item.values())
            elif isinstance(item, (list, tuple)):
                stack.extend(item)
        return total


def array_state(obj, names=None) -> dict[str, np.ndarray]:
    """Copies of ``obj``'s numpy-array attributes (all of them, or ``names``)."""
    items = vars(obj) if names is None else {n: getattr(obj, n) for n in names}
    return {name: value.copy() for name, value in items.items() if isinstance(value, np.ndarray)}


def restore_arrays(owner: str, target: dict[str, np.ndarray], saved: dict[str, np.ndarray]) -> None:
    """Copy ``saved`` into the live arrays ``target`` in place (their users keep their views)."""
    for name, value in saved.items():
        live = target.get(name)
        if live is None or live.shape != value.shape or live.dtype != value.dtype:
            have = "missing" if live is None else f"{live.shape} {live.dtype}"
            raise SnapshotError(f"{owner}.{name}: the snapshot holds {value.shape} {value.dtype}, "
                                f"this player has {have} (a snapshot restores state into the same "
                                "scene and cloths it was taken from)")
    for name, value in saved.items():
        np.copyto(target[name], value)


def table_state(table) -> dict[str, np.ndarray]:
    """Copies of every array of a namedtuple table."""
    return {name: getattr(table, name).copy() for name in table._fields
            if isinstance(getattr(table, name), np.ndarray)}


def table_arrays(table) -> dict[str, np.ndarray]:
    return {name: getattr(table, name) for name in table._fields if isinstance(getattr(table, name), np.ndarray)}


def _stateful_systems(player) -> list[tuple[str, Any]]:
    """(name, owner) of the schedule's systems whose owner keeps state across frames."""
    from magica_py.runtime.phases import Phase

    found = []
    seen = set()
    for phase in Phase:
        for system in player.schedule.systems(phase):
            owner = getattr(system.run, "__self__", None)
            if owner is None or id(owner) in seen or not hasattr(owner, "capture_state"):
                continue
            seen.add(id(owner))
            found.append((f"system:{system.name}", owner))
    return found


def capture(player) -> Snapshot:
    """The state of ``player``, its scene and its stateful systems (see the module docstring)."""
    scene = player.scene
    parts: dict[str, Any] = {
        "player": {
            "frame": player.frame,
            "fixed_update_count": player.counters.fixed_update_count,
            "time_manager": copy.deepcopy(vars(player.time_manager)),
            "time_source": copy.deepcopy(vars(player.time_source)),
            "metric_totals": dict(player.metric_totals),
        },
    }
    hierarchy = getattr(scene, "hierarchy", None)
    if hierarchy is not None:
        if hasattr(hierarchy, "flush"):
            hierarchy.flush()          # a deferred propagation first: the saved poses agree
        parts["hierarchy"] = array_state(hierarchy)
    animation = getattr(scene, "animation", None)
    if animation is not None:
        parts["animation"] = {"next_event": getattr(animation, "next_event", 0),
                              "arrays": array_state(animation, ("offset_position", "offset_rotation"))}
    for name, owner in _stateful_systems(player):
        parts[name] = owner.capture_state()
    return Snapshot(frame=player.frame, time=float(player.time_manager.time), parts=parts)


# parts of a system's ``capture_state`` that say what it simulates (its model), not where the
# simulation is; ``restore(..., keep_model=True)`` keeps the live system's. ClothSystem's
# "tables" entry is a dict of tables, of which "parameters" is the model.
MODEL_STATE = {"tables": ("parameters",), "team_parameters": None, "collision_modes": None}


def with_live_model(owner, saved: dict) -> dict:
    """``saved`` (a system's captured state) with its ``MODEL_STATE`` parts replaced by the
    live ``owner``'s current ones (arrays copied)."""
    live = owner.capture_state()
    merged = dict(saved)
    for key, sub in MODEL_STATE.items():
        if key not in saved:
            continue
        if sub is None:
            merged[key] = live[key]
        else:
            merged[key] = dict(saved[key])
            for name in sub:
                if name in saved[key]:
                    merged[key][name] = live[key][name]
    return merged


def restore(player, snapshot: Snapshot, keep_model: bool = False) -> None:
    """Put ``player`` back to ``snapshot`` (taken from this player or one built the same way).

    ``keep_model``: restore the evolving state only and keep this player's parameters and
    frame-time source (a candidate restarted from a reference's state; module docstring)."""
    scene = player.scene
    systems = _stateful_systems(player)
    expected = {"player"} | {name for name, _ in systems}
    if getattr(scene, "hierarchy", None) is not None:
        expected.add("hierarchy")
    if getattr(scene, "animation", None) is not None:
        expected.add("animation")
    if set(snapshot.parts) != expected:
        raise SnapshotError(f"the snapshot holds {sorted(snapshot.parts)}, this player has {sorted(expected)}")
    if "hierarchy" in snapshot.parts:
        h = scene.hierarchy
        restore_arrays("hierarchy", {n: v for n, v in vars(h).items() if isinstance(v, np.ndarray)},
                       snapshot.parts["hierarchy"])
        if hasattr(h, "discard_deferred"):
            h.discard_deferred()       # the restored world poses are those of the saved locals
    if "animation" in snapshot.parts:
        saved = snapshot.parts["animation"]
        restore_arrays("animation", {n: getattr(scene.animation, n) for n in saved["arrays"]}, saved["arrays"])
        scene.animation.next_event = saved["next_event"]
    for name, owner in systems:
        saved = snapshot.parts[name]
        owner.restore_state(with_live_model(owner, saved) if keep_model else saved)
    saved = snapshot.parts["player"]
    player.frame = saved["frame"]
    player.counters.fixed_update_count = saved["fixed_update_count"]
    vars(player.time_manager).update(copy.deepcopy(saved["time_manager"]))
    if not keep_model:
        vars(player.time_source).update(copy.deepcopy(saved["time_source"]))
    player.metric_totals.clear()
    player.metric_totals.update(saved["metric_totals"])
    player.last_context = None
