"""``ClothSystem``: the LATE_UPDATE system that simulates every BoneCloth of a scene.

Python orchestrates, numba computes: a frame is one ``simulate_frame`` call over all teams
(``solver/frame.py``) plus the hierarchy propagation, whatever the number of teams or
particles. Teams are the scene's cloths in order (``teams`` / ``team_names``).

Runtime control (all take effect at the next frame, none resets the simulation unless said):

* ``set_parameter(cloth, key, value)`` — also the ``("set_parameter", {cloth, key, value})``
  event raised by animation; ``cloth`` is a cloth name (every instance of an instanced cloth
  whose name matches, ``name#i`` for one instance) or a team id;
* ``reset_cloth(cloth, keep_pose=False)`` — MagicaCloth2's ResetCloth (Reset + TimeReset, or
  KeepTeleport when keep_pose);
* ``set_enabled(cloth, enabled)`` (disable mode Reset: re-enabling resets), ``set_time_scale``,
  ``add_force(cloth, direction, speed, mode)``;
* ``wind.set_zone(name, enabled=None, main=None)`` (``wind``: the scene's ``wind.zones.WindField``,
  None without wind zones) — also the ``("wind", {zone, enabled, main})`` event raised by animation;
* ``add_cloth(spec) -> team id`` / ``remove_cloth(team)`` — teams at runtime:
  chunks of the global SoA are allocated from freed space first and freed on removal
  (``layout.SolverLayout``); other teams' rows never move or change; the frame kernel visits
  ``model.live_teams`` only; a removed cloth's bones are no longer restored nor written.

Guards: a team reset by ``solver/guards.py`` raises ``("cloth_reset", {"cloth", "team",
"reason"})`` in ``ctx.events``. Metrics: ``cloth.steps`` (particle-steps this frame),
``cloth.simulation_steps`` (the most steps any team ran this frame),
``cloth.kernel`` (s in the numba call), ``cloth.propagate`` (s).
"""
from __future__ import annotations

import time as _time

import numba
import numpy as np

from magica_py.params import default_parameters
from reference_solver.runtime.team_time import SimulationTimeSettings, TeamTimeState, update_mode_code
from reference_solver.solver.colliders import fill_slots
from reference_solver.solver.fields import F64
from reference_solver.solver.frame import (
    StageSwitches, frame_input_values, hierarchy_arrays, simulate_frame, simulate_frame_parallel, time_arrays, worker_table,
)
from reference_solver.solver.tables import kernel_tables
from reference_solver.solver.guards import GUARD_NON_FINITE, GUARD_SPEED
from reference_solver.solver.fields import grow
from reference_solver.solver.layout import ChunkAllocator, SolverLayout
from reference_solver.solver.parameters import allocate_parameters, write_row
from reference_solver.solver.state import (
    allocate_state, free_collider_rows, free_particle_rows, free_team_row, grow_state,
)
from magica_py.kernels import portable

FORCE_MODES = {"velocity_add": 1, "velocity_add_without_depth": 2, "velocity_change": 3,
               "velocity_change_without_depth": 4}
# the system's own copies in the frame kernel's hierarchy table (``frame.hierarchy_arrays``)
_BUILD_POSE_FIELDS = ("build_world_position", "build_world_rotation", "build_lossy_scale",
                      "build_local_to_world", "build_pose_pending", "ramp_from_build")
GUARD_REASONS = {GUARD_NON_FINITE: "non-finite particle state", GUARD_SPEED: "particle speed above the guard bound"}


# "auto" runs the frame on numba's threads from this many teams and particles: below it the
# two thread launches per frame cost more than they save (single tail: 40 -> 49 us per frame
# on 2 threads; crowd, 200 teams: 10.8 -> 6.7 ms; docs/BENCHMARKS.md)
AUTO_PARALLEL_TEAMS = 8
AUTO_PARALLEL_PARTICLES = 2000


def choose_threads(parallel, setting, teams: int, particles: int) -> int:
    """Threads the frame kernel deals its teams to: ``parallel`` True / False forces numba's
    thread count / 1; otherwise the scene's ``threads`` setting: a count (at most numba's
    threads, ``NUMBA_NUM_THREADS``) or ``"auto"``: numba's threads when the scene has at
    least ``AUTO_PARALLEL_TEAMS`` teams and ``AUTO_PARALLEL_PARTICLES`` particles, else 1."""
    available = max(1, int(numba.get_num_threads()))
    if parallel is not None:
        return available if parallel else 1
    if setting == "auto":
        many = teams >= AUTO_PARALLEL_TEAMS and particles >= AUTO_PARALLEL_PARTICLES
        return available if many else 1
    return max(1, min(int(setting), available))


class ClothSystem:
    """Simulates ``cloth_specs`` (``scene.ClothSpec``-like) on ``hierarchy``.

    ``models`` may be given (prebuilt ``build.ClothModel`` in the same order); otherwise each
    spec is built with ``build.build_cloth`` from the hierarchy's current (rest) pose.
    Threads: ``parallel=True`` spreads teams over numba's threads, ``False`` keeps one;
    ``None`` (the default) follows the scene's ``threads`` setting (``settings.threads``:
    ``"auto"`` or a count; ``choose_threads``): the same results bit for bit either way. Only the stages
    the live teams use are compiled and called (``stage_switches``). After the write-back the
    hierarchy is propagated over the subtrees of the cloth bones only (a plan rebuilt when teams
    change); with ``parallel=True`` over the numba threads too (``hierarchy.threads``).
    """

    name = "cloth"

    def __init__(self, hierarchy, cloth_specs, colliders=None, settings=None, models=None,
                 parallel: bool | None = None, wind=()):
        from magica_py.build import build_cloth
        from reference_solver.wind.zones import WindField

        self.wind = WindField(wind) if len(wind) else None   # the scene's wind zones (magica_py/wind)

        self.hierarchy = hierarchy
        self.specs = list(cloth_specs)
        self.colliders = colliders
        self.time_settings = SimulationTimeSettings.from_scene_settings(settings or {})
        scene_update_mode = getattr(settings, "update_mode", None) if settings is not None else None
        if models is None:
            models = [build_cloth(hierarchy, spec) for spec in self.specs]
        self.models = list(models)
        self._check_positive_scale(hierarchy)
        self.team_names = [str(getattr(s, "name", f"cloth{i}")) for i, s in enumerate(self.specs)]
        self._scene_update_mode = scene_update_mode
        # chunked global model: one chunk per team and pool (layout.SolverLayout); collider
        # slots are chunked the same way
        self.layout = SolverLayout()
        for model in self.models:
            self.layout.add(model)
        self.model = self.layout.model()
        team_count = len(self.models)
        self._slots = ChunkAllocator()
        slots = [(t, self._collider_indices(spec)) for t, spec in enumerate(self.specs)]
        starts = [self._slots.allocate(len(indices)) for _t, indices in slots]
        self.particles, self.teams, self.collider_state = allocate_state(
            self.layout.capacity("particle"), team_count, self._slots.capacity, self.layout.capacity("triangle"),
            self.layout.capacity("edge"))
        for (t, indices), start in zip(slots, starts):
            self.teams.collider_start[t] = start
            self.teams.collider_count[t] = len(indices)
        if self._slots.capacity:
            fill_slots(self.collider_state, slots, colliders)
        self.parameters = allocate_parameters(team_count)
        self.team_parameters = [getattr(s, "parameters", None) or {} for s in self.specs]
        self.collision_modes = [getattr(s, "collision_mode", None) for s in self.specs]
        for t in range(team_count):
            self._write_parameters(t)
        self.time_state = TeamTimeState.allocate(team_count)
        for t in range(team_count):
            self._activate(t)
        self._time = time_arrays(self.time_state)
        self._hierarchy = hierarchy_arrays(hierarchy)
        self.frame_count = 0
        self._player = None
        self._tables = None
        self.threads = choose_threads(parallel, getattr(settings, "threads", "auto") if settings is not None else "auto",
                                      team_count, int(self.model.team_particle_count.sum()))
        self.parallel = self.threads > 1
        self._workers = worker_table(self.layout.team_count, self.threads)
        self._frame_values = frame_input_values()
        self.stages = self.stage_switches()
        if self.parallel:  # the hierarchy propagation spreads over the same threads
            hierarchy.threads = max(hierarchy.threads, self.threads)
        self._written_plan = hierarchy.plan(self.restored_bones())

    # ------------------------------------------------------------------ registration
    def attach(self, player, scene=None) -> "ClothSystem":
        """Add the system to ``player``'s LATE_UPDATE and register the restored bones (every
        non-invalid bone of every cloth, docs/solver.md §A.2, §B.5)."""
        from magica_py.runtime.phases import Phase, System

        player.schedule.add(Phase.LATE_UPDATE, System(self.name, self.run))
        player.register_restored_bones(self.restored_bones(), owner=self)
        self._player = player
        return self

    def restored_bones(self) -> np.ndarray:
        """Bones of the cloths in use (freed chunks have attribute 0: left out)."""
        m = self.model
        return np.unique(m.transform_index[(m.attribute & 0x03) != 0]).astype(np.int32)

    # ------------------------------------------------------------------ teams at runtime
    def add_cloth(self, spec, model=None) -> int:
        """Add a cloth at runtime; returns its team id (ids are not reused).

        The model is built (unless given) after putting the cloth's bones back to their rest
        local pose. Its chunks come from
        the freed space first, the pools grow otherwise: other teams' rows never move and their
        state is not touched. The new team starts with Reset, like a team built with the scene,
        and its bones join the restored set."""
        from magica_py.build import build_cloth

        if model is None:
            # build from the rest local pose of the cloth's bones (what RESTORE puts back each
            # frame), not from whatever pose they were left in
            h = self.hierarchy
            nodes = sorted({n for r in getattr(spec, "root_bones", ()) for n in h.descendants(int(r))})
            h.restore_rest_pose(np.asarray(nodes, dtype=np.int32))
            h.propagate()
            model = build_cloth(h, spec)
        self._check_positive_scale(self.hierarchy, [(spec, model)])
        team = self.layout.add(model)
        indices = self._collider_indices(spec)
        slot_start = self._slots.allocate(len(indices))
        self.particles, self.teams, self.collider_state = grow_state(
            self.particles, self.teams, self.collider_state, self.layout.capacity("particle"),
            self.layout.team_count, self._slots.capacity, self.layout.capacity("triangle"),
            self.layout.capacity("edge"))
        p0, pn = self.layout.chunks[team]["particle"]
        free_particle_rows(self.particles, p0, pn)   # a reused chunk starts fresh too
        free_team_row(self.teams, team)
        self.teams.collider_start[team] = slot_start
        self.teams.collider_count[team] = len(indices)
        if indices:
            free_collider_rows(self.collider_state, slot_start, len(indices))
            fill_slots(_rows(self.collider_state, slot_start, len(indices)), [(team, indices)], self.colliders)
        self.specs.append(spec)
        self.models.append(model)
        self.team_names.append(str(getattr(spec, "name", f"cloth{team}")))
        self.team_parameters.append(getattr(spec, "parameters", None) or {})
        self.collision_modes.append(getattr(spec, "collision_mode", None))
        if self.parameters.gravity.shape[0] < self.layout.team_count:
            self.parameters = grow(type(self.parameters), self.parameters, {"team": self.layout.team_count})
        self._write_parameters(team)
        if self.time_state.capacity < self.layout.team_count:
            self.time_state.resize(self.layout.team_count)
        self._activate(team)
        self._tables_changed()
        return team

    def remove_cloth(self, team: int) -> None:
        """Remove a cloth at runtime: its chunks are freed (rows reset), the frame kernel no
        longer visits it, its bones are neither restored nor written any more (they keep the
        last written pose). Other teams are not touched."""
        self._check_live(team)
        p0, pn = self.layout.chunks[team]["particle"]
        self.layout.remove(team)
        free_particle_rows(self.particles, p0, pn)
        s0, sn = int(self.teams.collider_start[team]), int(self.teams.collider_count[team])
        if sn:
            free_collider_rows(self.collider_state, s0, sn)
            self.collider_state.team[s0:s0 + sn] = -1
        self._slots.release(s0, sn)
        free_team_row(self.teams, team)
        self.teams.collider_count[team] = 0
        self.time_state.deactivate(team)
        self.models[team] = None
        self._tables_changed()

    @property
    def live_teams(self) -> list[int]:
        """Ids of the teams in use (ascending)."""
        return self.layout.live_teams

    def _check_live(self, team) -> None:
        if not isinstance(team, (int, np.integer)) or not 0 <= int(team) < len(self.models) \
                or self.models[int(team)] is None:
            raise KeyError(f"no cloth team {team} (teams in use: {self.live_teams})")

    def stage_switches(self) -> StageSwitches:
        """Which optional stages the live teams may run (``frame.StageSwitches``: 1 compiled and
        called where a team asks, None neither): from the teams' models, parameters and
        colliders. Recomputed after any change of teams or parameters; a stage that becomes
        needed at run time compiles then (once per machine: the kernels are cached)."""
        m, prm, live = self.model, self.parameters, np.asarray(self.live_teams, dtype=np.int64)

        def any_of(values) -> int | None:
            return 1 if live.size and bool(np.any(np.asarray(values)[live])) else None

        colliding = self.teams.collider_count[live] > 0 if live.size else np.zeros(0, bool)
        mode = prm.collision_mode[live] if live.size else np.zeros(0, np.int32)
        return StageSwitches(
            angle=any_of((prm.use_angle_limit != 0) | (prm.use_restoration != 0)),
            bending=any_of((m.team_bend_count > 0) | (m.team_volume_count > 0)),
            point_collision=1 if bool(np.any(colliding & (mode == 1))) else None,
            edge_collision=1 if bool(np.any(colliding & (mode == 2))) else None,
            motion=any_of((prm.use_max_distance != 0) | (prm.use_backstop != 0)),
            quality=any_of((prm.quality != 0) | (prm.inextensibility != 0) | (prm.collision_last != 0)
                           | (prm.time_based_smoothing != 0)),
            lines=any_of(m.team_has_lines != 0),
            triangles=any_of(m.team_triangle_count > 0),
            wind=1 if self.wind is not None else any_of(prm.wind_moving_wind > 0.01))

    def _tables_changed(self) -> None:
        """After add/remove: new model, new kernel tables (same types: the compiled entry point
        stays valid), restored bones re-registered with the player."""
        self.model = self.layout.model()
        self._time = time_arrays(self.time_state)
        self._tables = None
        if self._workers.team_worker.shape[0] < self.layout.team_count:
            self._workers = worker_table(self.layout.team_count, self.threads)
        self.stages = self.stage_switches()
        self._written_plan = self.hierarchy.plan(self.restored_bones())
        if self._player is not None:
            self._player.unregister_restored_bones(self)
            self._player.register_restored_bones(self.restored_bones(), owner=self)

    def _activate(self, t: int) -> None:
        mode = self._parameter(t, "update_mode", default_parameters()["update_mode"])
        if str(mode) in ("normal", "animator_linkage") and self._scene_update_mode:
            mode = self._scene_update_mode
        self.time_state.activate(t, update_mode=update_mode_code(mode))
        self.teams.enabled[t] = 1

    def _collider_indices(self, spec) -> list[int]:
        if self.colliders is None:
            return []
        return [int(i) for i in (getattr(spec, "colliders", ()) or ())]

    # ------------------------------------------------------------------ frame
    def run(self, ctx) -> None:
        """The LATE_UPDATE system: apply pending events, simulate every team, propagate."""
        for kind, payload in list(ctx.events):
            if kind == "set_parameter":
                self.set_parameter(payload["cloth"], payload["key"], payload["value"])
            elif kind == "wind" and self.wind is not None:
                self.wind.apply_event(payload)
        t = ctx.time
        counters = getattr(ctx, "counters", None)
        fixed_count = counters.fixed_update_count if counters is not None else t.fixed_update_count
        self.step_frame(t.delta_time, t.unscaled_delta_time, t.fixed_delta_time, fixed_count,
                        events=ctx.events, metrics=ctx.metrics)

    def _time_constants(self) -> tuple:
        """The frame inputs that follow from the time settings alone (recomputed when a
        setting changes: the power terms take two ``pow`` each)."""
        s = self.time_settings
        key = (s.frequency, s.max_steps_per_frame, s.global_time_scale, s.timing)
        if key != getattr(self, "_time_key", None):
            power = s.simulation_power
            self._time_values = (float(s.global_time_scale), float(s.simulation_delta_time),
                                 int(s.max_steps_per_frame), int(s.timing_code), 90.0 / s.frequency,
                                 float(power[1]), float(power[2]), float(power[3]))
            self._time_key = key
        return self._time_values

    def step_frame(self, delta_time, unscaled_delta_time=None, fixed_delta_time=0.02,
                   fixed_update_count=0, events=None, metrics=None) -> None:
        """One frame of every team (usable without a player: tests, benchmarks)."""
        (global_time_scale, dt, max_steps, timing, frequency_ratio, power_y, power_z,
         power_w) = self._time_constants()
        fi = self._frame_values   # frame.FrameInputs' fields, in order
        fi[0] = delta_time
        fi[1] = delta_time if unscaled_delta_time is None else unscaled_delta_time
        fi[2] = fixed_delta_time
        fi[3] = int(fixed_update_count)
        fi[4] = global_time_scale
        fi[5] = dt
        fi[6] = max_steps
        fi[7] = timing
        fi[8] = frequency_ratio
        fi[9] = power_y
        fi[10] = power_z
        fi[11] = power_w
        fi[12] = self.threads
        clock = _time.perf_counter
        self.hierarchy.flush()   # the kernel reads the world poses through kept references
        t0 = clock()
        self.select_wind()
        most_steps, particle_steps, guarded = self._call_frame(fi)
        t1 = clock()
        if self._written_plan.threads != self.hierarchy.threads:
            self._written_plan = self.hierarchy.plan(self.restored_bones())
        # the subtrees of the bones written back, computed when next read (scene/hierarchy.py)
        self.hierarchy.propagate_later(self._written_plan)
        t2 = clock()
        self.frame_count += 1
        if guarded:
            codes = self.teams.guard_code
            for team in np.nonzero(codes)[0]:
                if events is not None:
                    events.append(("cloth_reset", {"cloth": self.team_names[team], "team": int(team),
                                                   "reason": GUARD_REASONS.get(int(codes[team]), "guard")}))
            codes[:] = 0
        if metrics is not None:
            metrics["cloth.steps"] = float(particle_steps)
            metrics["cloth.simulation_steps"] = float(most_steps)
            metrics["cloth.kernel"] = t1 - t0
            metrics["cloth.propagate"] = t2 - t1

    # ------------------------------------------------------------------ control API
    def teams_of(self, cloth) -> list[int]:
        """Team ids of a cloth name (all instances), ``name#i``, or a team id."""
        if isinstance(cloth, (int, np.integer)):
            self._check_live(cloth)
            return [int(cloth)]
        name = str(cloth)
        found = [t for t, n in enumerate(self.team_names) if self.models[t] is not None and (
                 n == name or n.split("#")[0] == name or
                 (getattr(self.specs[t], "instance", None) is not None and f"{n}#{self.specs[t].instance}" == name))]
        if not found:
            raise KeyError(f"no cloth named {name!r} (cloths: {sorted(set(self.team_names))})")
        return found

    def set_parameter(self, cloth, key: str, value) -> None:
        """Change one parameter (dotted key) of a cloth from the next frame on, without reset."""
        for t in self.teams_of(cloth):
            params = self.team_parameters[t]
            if hasattr(params, "with_changes"):
                params = params.with_changes({key: value}, where=f"set_parameter[{self.team_names[t]}]")
            else:
                params = dict(params)
                params[key] = value
            self.team_parameters[t] = params
            if key == "collider_collision.mode":
                self.collision_modes[t] = str(value)
            self._write_parameters(t)
        self.stages = self.stage_switches()  # a changed parameter may need another stage

    def reset_cloth(self, cloth, keep_pose: bool = False) -> None:
        for t in self.teams_of(cloth):
            if keep_pose:
                self.teams.keep_teleport[t] = 1
            else:
                self.teams.reset[t] = 1
                self.teams.time_reset[t] = 1
                self.time_state.reset([t])

    def set_enabled(self, cloth, enabled: bool) -> None:
        for t in self.teams_of(cloth):
            was = self.teams.enabled[t] != 0
            self.teams.enabled[t] = 1 if enabled else 0
            if enabled and not was:
                self.teams.reset[t] = 1

    def set_time_scale(self, cloth, value: float) -> None:
        for t in self.teams_of(cloth):
            self.time_state.set_time_scale(t, value)

    def add_force(self, cloth, direction, speed: float, mode: str = "velocity_add") -> None:
        """MagicaCloth.AddForce: an acceleration on every step of the next frame that runs."""
        d = np.asarray(direction, dtype=F64)
        n = portable.norm(d)
        if mode not in FORCE_MODES:
            raise ValueError(f"add_force mode {mode!r}: expected one of {sorted(FORCE_MODES)}")
        for t in self.teams_of(cloth):
            self.teams.external_force[t] = d / n * float(speed) if n > 1e-8 else 0.0
            self.teams.external_force_mode[t] = FORCE_MODES[mode]

    # ------------------------------------------------------------------ state capture
    def capture_state(self) -> dict:
        """Copies of everything the next frame reads (``runtime/snapshot.py``): the particle,
        team, collider, parameter and team-clock tables, the build pose and first-frame flags,
        and the runtime parameter overrides."""
        from magica_py.runtime.snapshot import table_state

        h = self._hierarchy
        return {
            "layout": self._layout_signature(),
            "tables": {name: table_state(table) for name, table in self._state_tables().items()},
            "build_pose": {name: getattr(h, name).copy() for name in _BUILD_POSE_FIELDS},
            "frame_count": self.frame_count,
            "team_parameters": list(self.team_parameters),
            "collision_modes": list(self.collision_modes),
            "wind": self.wind.capture_state() if self.wind is not None else None,
        }

    def restore_state(self, state: dict) -> None:
        """Write a ``capture_state`` result back in place (the kernel tables keep their arrays)."""
        from magica_py.runtime.snapshot import SnapshotError, restore_arrays, table_arrays

        if state["layout"] != self._layout_signature():
            raise SnapshotError(f"cloth {self.name!r}: the snapshot was taken with teams "
                                f"{state['layout'][0]}, this system has {self._layout_signature()[0]} "
                                "(cloths added or removed since: a snapshot restores state, not structure)")
        tables = self._state_tables()
        for name, saved in state["tables"].items():
            restore_arrays(f"{self.name}.{name}", table_arrays(tables[name]), saved)
        restore_arrays(f"{self.name}.build_pose", {n: getattr(self._hierarchy, n) for n in _BUILD_POSE_FIELDS},
                       state["build_pose"])
        self.frame_count = state["frame_count"]
        self.team_parameters = list(state["team_parameters"])
        self.collision_modes = list(state["collision_modes"])
        if self.wind is not None and state.get("wind") is not None:
            self.wind.restore_state(state["wind"])
        self.stages = self.stage_switches()

    def _state_tables(self) -> dict:
        return {"particles": self.particles, "teams": self.teams, "colliders": self.collider_state,
                "parameters": self.parameters, "time": self._time}

    def _layout_signature(self) -> tuple:
        return (tuple(int(t) for t in self.live_teams), self.layout.capacity("particle"),
                self._slots.capacity, tuple(self.team_names))

    # ------------------------------------------------------------------ queries
    def team_particles(self, team: int) -> slice:
        start = int(self.model.team_particle_start[team])
        return slice(start, start + int(self.model.team_particle_count[team]))

    def positions(self, cloth) -> np.ndarray:
        """Display positions (world, m) of one cloth's particles (a copy)."""
        return self.particles.position[self.team_particles(self.teams_of(cloth)[0])].copy()

    # ------------------------------------------------------------------ internals
    def kernel_tables(self) -> tuple:
        """The seven tables (model, particles, parameters, teams, colliders, team time,
        hierarchy) as the stage kernels take them (``solver/tables.py``; built on first use and
        after any change of teams)."""
        return self._kernel_tables()[1]

    def _kernel_tables(self) -> tuple:
        if self._tables is None:
            self._tables = kernel_tables(self.model, self.particles, self.parameters, self.teams,
                                         self.collider_state, self._time, self._hierarchy)
        return self._tables

    def select_wind(self) -> None:
        """The wind zones' poses and the zones each team feels from this frame's transforms
        (``wind.zones.WindField.update``; nothing without wind zones). ``step_frame`` calls it
        before the frame kernel."""
        if self.wind is not None:
            self.wind.update(self._kernel_tables()[0])

    def _call_frame(self, fi) -> tuple:
        """One numba call per frame: the serial or the parallel kernel, with the stage switches;
        returns the frame's counts (``frame.frame_counts``)."""
        tables = self._kernel_tables()[0]
        if self.parallel:
            return simulate_frame_parallel(tables, fi, self._workers, *self.stages)
        return simulate_frame(tables, fi, *self.stages)

    def _parameter(self, team, key, default):
        params = self.team_parameters[team]
        try:
            value = params.get(key, default)
        except AttributeError:
            value = default
        return default if value is None else value

    def _check_positive_scale(self, hierarchy, pairs=None) -> None:
        """Negative scale is rejected (§H.7 allows a Python port to assume positive scale)."""
        for spec, model in (pairs if pairs is not None else zip(self.specs, self.models)):
            nodes = list(np.asarray(model.transform_index)) + [int(model.component_transform)]
            for node in nodes:
                if (hierarchy.lossy_scale[node] < 0.0).any():
                    where = getattr(spec, "document_path", "") or f"cloth {getattr(spec, 'name', '?')!r}"
                    raise ValueError(
                        f"{where}: transform {hierarchy.names[node]!r} has a negative scale "
                        f"{tuple(float(x) for x in hierarchy.lossy_scale[node])}; negative scale is not "
                        f"supported (MagicaCloth2 refuses it at build too, docs/solver.md §H.7): use positive scales")

    def _write_parameters(self, team: int) -> None:
        def resolve(name):
            return int(self.hierarchy.index(name))
        write_row(self.parameters, team, self.team_parameters[team], self.collision_modes[team], resolve)


def _rows(table, start: int, count: int):
    """The same namedtuple table restricted to rows ``start:start+count`` (views: writes land
    in ``table``)."""
    return type(table)(*(a[start:start + count] for a in table))
