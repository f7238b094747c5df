"""``ClothSystem``: the LATE_UPDATE system that simulates every BoneCloth of a scene.

Python orchestrates, numba computes: a frame is one ``simulate_frame`` call over all blocks
(``solver/frame.py``) plus the hierarchy propagation, whatever the number of teams or
particles. Teams are the scene's cloths in order (``teams`` / ``team_names``); the layout
groups teams of identical structure and parameters into blocks, one team per lane
(``solver/blocks.py``, ``solver/lanes.py``).

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
* ``add_cloth(spec) -> team id`` / ``remove_cloth(team)`` — teams at runtime: a new team
  takes a free lane of a matching block or a new block whose chunks come from freed space
  first (``blocks.BlockLayout``); other teams' rows never move or change; a removed cloth's
  lane is freed and its bones are no longer restored nor written. A ``set_parameter`` that
  makes a team differ from its block's other lanes moves it to a block of its own kind, its
  state copied bit for bit.

Guards: a team reset by ``solver/guards.py`` raises ``("cloth_reset", {"cloth", "team",
"reason"})`` in ``ctx.events``. Metrics: ``cloth.steps`` (particle-steps this frame),
``cloth.simulation_steps`` (the most steps any team ran this frame),
``cloth.kernel`` (s in the numba call), ``cloth.propagate`` (s).
"""
from __future__ import annotations

import math
import time as _time
from functools import partial

import numba
import numpy as np

from magica_py.build.errors import BuildError
from magica_py.build.render_setup import negative_scale_message
from magica_py.jit import stage_policy
from magica_py.kernels import portable
from magica_py.params import default_parameters
from magica_py.runtime.team_time import SimulationTimeSettings, TeamTimeState, update_mode_code
from magica_py.solver import compile_helper
from magica_py.solver.balance import WorkerBalance
from magica_py.solver import state as st
from magica_py.solver.blocks import (
    BI_COLLIDERS, BI_N, LANES, PARTICLE_PARAMETERS, TI_ANCHOR, TI_CULLING_REFERENCE, BlockLayout,
)
from magica_py.solver.colliders import collider_shapes, fill_slots
from magica_py.solver.frame import (
    StageSwitches, Tables, begin_parallel_frame, end_parallel_frame, frame_input_values, hierarchy_arrays,
    lane_save_area, simulate_frame, simulate_worker, time_arrays, worker_table,
)
from magica_py.solver.frame_call import frame_arrays
from magica_py.solver.guards import GUARD_NON_FINITE, GUARD_SPEED
from magica_py.solver.parameters import (
    PARAMETER_COUNT, allocate_parameters, packed_row, particle_parameters_block, write_row,
)
from magica_py.solver.fields import grow
from magica_py.threads import FrameThreads
from magica_py.solver.views import TableView, team_model

FORCE_MODES = {"velocity_add": 1, "velocity_add_without_depth": 2, "velocity_change": 3,
               "velocity_change_without_depth": 4}
# the system's own copies in the frame kernel's hierarchy table (``frame.hierarchy_arrays``)
_BUILD_POSE_FIELDS = ("build_world_position", "build_world_rotation", "build_lossy_scale",
                      "build_local_to_world", "build_pose_pending")
GUARD_REASONS = {GUARD_NON_FINITE: "non-finite particle state", GUARD_SPEED: "particle speed above the guard bound"}
# the state tables, per pool of items (``blocks.BlockLayout`` capacities)
_STATE_TABLES = (("PS", st.PARTICLE, "particle"), ("CS", st.COLLIDER, "collider"),
                 ("TRS", st.TRIANGLE_STATE, "triangle"), ("EDS", st.EDGE_STATE, "edge"))


# "auto" runs the frame on numba's threads from this many teams and particles: below it the
# thread launches per frame (the frame's and the propagation's) cost more than they save
# (docs/BENCHMARKS.md)
AUTO_PARALLEL_TEAMS = 8
AUTO_PARALLEL_PARTICLES = 2000


def choose_threads(parallel, setting, teams: int, particles: int) -> int:
    """Threads the frame kernel deals its blocks to: ``parallel`` True / False forces numba's
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


def _timed_worker(seconds: list, start: float, head: tuple, worker: int, stages) -> None:
    """Thread ``worker``'s run of a parallel frame (``simulate_worker``); the time it ends,
    counted from ``start`` (when the threads were handed their runs: a thread's wake-up counts
    too), into ``seconds[worker]``, the measure ``WorkerBalance`` deals the next frame's blocks
    by."""
    try:
        simulate_worker(*head, worker, *stages)
    finally:
        seconds[worker] = _time.perf_counter() - start


class ClothSystem:
    """Simulates ``cloth_specs`` (``scene.ClothSpec``-like) on ``hierarchy``.

    ``models`` may be given (prebuilt ``build.ClothModel`` in the same order); otherwise each
    spec is built with ``build.build_cloth`` from the hierarchy's current (rest) pose.
    Threads: ``parallel=True`` spreads blocks over numba's threads, ``False`` keeps one;
    ``None`` (the default) follows the scene's ``threads`` setting (``settings.threads``:
    ``"auto"`` or a count; ``choose_threads``): the same results bit for bit either way. Only the stages
    the live teams use are compiled and called (``stage_switches``). After the write-back the
    hierarchy is propagated over the subtrees of the cloth bones only (a plan rebuilt when teams
    change); with ``parallel=True`` over the numba threads too (``hierarchy.threads``).

    Reading the state: ``positions(cloth)``, and the team-ordered views ``model``,
    ``particles``, ``teams``, ``collider_state`` (``solver/views.py``); ``write_particles``
    and ``write_team`` change it.
    """

    name = "cloth"

    def __init__(self, hierarchy, cloth_specs, colliders=None, settings=None, models=None,
                 parallel: bool | None = None, wind=()):
        from magica_py.build import build_cloth
        from magica_py.wind.zones import WindField

        self.wind = WindField(wind) if len(wind) else None   # the scene's wind zones (magica_py/wind)
        self.hierarchy = hierarchy
        self.specs = list(cloth_specs)
        self.colliders = colliders
        self.time_settings = SimulationTimeSettings.from_scene_settings(settings or {})
        self._scene_update_mode = getattr(settings, "update_mode", None) if settings is not None else None
        self.team_names = [str(getattr(s, "name", f"cloth{i}")) for i, s in enumerate(self.specs)]
        team_count = len(self.specs)
        self.team_parameters = [getattr(s, "parameters", None) or {} for s in self.specs]
        self.collision_modes = [getattr(s, "collision_mode", None) for s in self.specs]
        self.parameters = allocate_parameters(team_count)   # per team id: the source of the block rows
        for t in range(team_count):
            self._write_parameters(t)
        # a first run: a helper process starts compiling the step's stages now, beside the build
        self._helper = compile_helper.start_early(self, settings, parallel, wind) if team_count else None
        if models is None:
            models = [build_cloth(hierarchy, spec) for spec in self.specs]
        self.models = list(models)
        self._check_positive_scale(hierarchy)
        self.layout = BlockLayout()
        self.PS = st.PARTICLE.allocate(0)
        self.CS = st.COLLIDER.allocate(0)
        self.TRS = st.TRIANGLE_STATE.allocate(0)
        self.EDS = st.EDGE_STATE.allocate(0)
        self.TS = st.TEAM.allocate(0)
        self.P = np.zeros((0, PARAMETER_COUNT))
        self.PP = PARTICLE_PARAMETERS.allocate(0)
        self.time_state = TeamTimeState.allocate(team_count)
        for t, (spec, model) in enumerate(zip(self.specs, self.models)):
            self._place(t, spec, model)
            self._activate(t)
        self._time = time_arrays(self.time_state)
        self._hierarchy = hierarchy_arrays(hierarchy)
        self._source_hierarchy = hierarchy   # attach() checks that the player moves these bones
        self.frame_count = 0
        self._player = None
        self.threads = choose_threads(parallel, getattr(settings, "threads", "auto") if settings is not None else "auto",
                                      team_count, sum(int(m.particle_count) for m in self.models))
        self.parallel = self.threads > 1
        self._frame_values = frame_input_values()
        self._frame_arrays_of = None     # (tables, clocks, hierarchy) the frame's StructRef was made of
        self._frame_arrays_made = None
        self._first_call = True   # (_call_frame)
        self._pool = None         # the threads of a parallel frame, made at the first (_parallel_frame)
        if self.parallel:  # the hierarchy propagation spreads over the same threads
            hierarchy.threads = max(hierarchy.threads, self.threads)
        self._tables_changed(register=False)

    # ------------------------------------------------------------------ placement
    def _key_extra(self, team: int) -> bytes:
        """What a team's block lanes must share besides the topology: its parameter row."""
        return packed_row(self.parameters, team).tobytes()

    def _place(self, team: int, spec, model, state=None) -> None:
        """Put team ``team`` into a lane (``BlockLayout.add``) and write its per-lane data;
        ``state``: columns saved by ``_lane_state`` (a move), else fresh state."""
        indices = self._collider_indices(spec)
        shapes = collider_shapes(self.colliders, indices) if indices else []
        nodes = [int(self.colliders.transform[ci]) for ci in indices]
        row = packed_row(self.parameters, team)
        got = self.layout.add(model, row.tobytes(), shapes, nodes, team=team)
        assert got == team
        self._fit_state()
        b, lane = self.layout.place(team)
        items = self.layout.slots(team)
        if state is None:
            for name, table, pool in _STATE_TABLES:
                table.reset_lanes(getattr(self, name), items[pool], lane)
            st.TEAM.reset_lanes(self.TS, b, lane)
            st.TEAM.write(self.TS, "enabled", [b], lane, [1.0])
            if indices:
                fill_slots(self.CS, items["collider"], lane, self.colliders, indices)
        else:
            self._write_lane_state(team, state)
        self._write_block_parameters(team, row)

    def _write_block_parameters(self, team: int, row=None) -> None:
        """Team ``team``'s parameters into its block: the block's row of ``P`` (shared by its
        lanes; ``row``: the team's ``packed_row`` when known), the lane's transform-valued
        parameters, the depth curves ``PP`` of the block."""
        b, lane = self.layout.place(team)
        self.P[b] = packed_row(self.parameters, team) if row is None else row
        self.layout.team_ints[b, TI_ANCHOR + lane] = int(self.parameters.anchor_transform[team])
        self.layout.team_ints[b, TI_CULLING_REFERENCE + lane] = int(self.parameters.culling_reference[team])
        particle_parameters_block(self.PP, self.layout.particle_model, self.P, self.layout.block_ints, b)

    def _fit_state(self) -> None:
        """The state tables at the layout's capacities (old rows kept, new rows fresh)."""
        def fit(array, table, rows):
            if array.shape[0] >= rows:
                return array
            new = table.allocate(max(rows, 2 * array.shape[0]))
            new[:array.shape[0]] = array
            return new

        for name, table, pool in _STATE_TABLES:
            setattr(self, name, fit(getattr(self, name), table, self.layout.capacity(pool)))
        self.PP = fit(self.PP, PARTICLE_PARAMETERS, self.layout.capacity("particle"))
        self.TS = fit(self.TS, st.TEAM, self.layout.block_count)
        if self.P.shape[0] < self.layout.block_count:
            grown = np.zeros((max(self.layout.block_count, 2 * self.P.shape[0]), PARAMETER_COUNT))
            grown[:self.P.shape[0]] = self.P
            self.P = grown

    def _lane_state(self, team: int) -> dict:
        """Copies of a team's columns of every state table (``_write_lane_state`` puts them back)."""
        b, lane = self.layout.place(team)
        items = self.layout.slots(team)
        out = {"TS": self.TS[b, lane::LANES].copy()}
        for name, _table, pool in _STATE_TABLES:
            out[name] = getattr(self, name)[items[pool], lane::LANES].copy()
        return out

    def _write_lane_state(self, team: int, state: dict) -> None:
        b, lane = self.layout.place(team)
        items = self.layout.slots(team)
        self.TS[b, lane::LANES] = state["TS"]
        for name, _table, pool in _STATE_TABLES:
            getattr(self, name)[items[pool], lane::LANES] = state[name]

    def _move_if_needed(self, team: int) -> None:
        """After a parameter change: a team whose row no longer matches its block's moves to a
        block of its new kind, its state and model columns copied bit for bit."""
        b, _lane = self.layout.place(team)
        if self.layout.blocks[b].key == self.layout.key_of(self.models[team], self._key_extra(team),
                                                           self._collider_shapes_of(team)):
            return
        state = self._lane_state(team)
        self.layout.remove(team)
        self._place(team, self.specs[team], self.models[team], state)

    def _move_teams(self, teams) -> bool:
        """``_move_if_needed`` for each of ``teams``, then their block's parameter rows written
        again; True when any of them changed block kind (the kernels' tables must follow)."""
        moved = False
        for t in teams:
            b, _lane = self.layout.place(t)
            before = self.layout.blocks[b].key
            self._move_if_needed(t)
            b, _lane = self.layout.place(t)
            moved = moved or self.layout.blocks[b].key != before
            self._write_block_parameters(t)
        return moved

    def _collider_shapes_of(self, team: int):
        indices = self._collider_indices(self.specs[team])
        return collider_shapes(self.colliders, indices) if indices else []

    # ------------------------------------------------------------------ registration
    def attach(self, player, scene=None) -> "ClothSystem":
        """Add the system to ``player``'s LATE_UPDATE and register the restored bones (every
        non-invalid bone of every cloth, docs/solver.md §A.2, §B.5)."""
        from magica_py.runtime.phases import Phase, System

        player_hierarchy = getattr(getattr(player, "scene", None), "hierarchy", None)
        if player_hierarchy is not None and player_hierarchy is not self._source_hierarchy:
            # the player would restore and propagate this system's bone indices in its own
            # hierarchy: out of range there, a write past the end of its arrays
            player_name = getattr(player.scene, "name", "?")
            scene_name = getattr(scene, "name", None) or "another scene"
            raise ValueError(f"attach_solver: the cloth system of {scene_name!r} is built on another hierarchy "
                             f"than the player's scene {player_name!r}; attach a scene to the player made "
                             f"from it (Player.for_scene(scene))")
        player.schedule.add(Phase.LATE_UPDATE, System(self.name, self.run))
        player.register_restored_bones(self.restored_bones(), owner=self)
        self._player = player
        return self

    def restored_bones(self) -> np.ndarray:
        """Bones of the cloths in use (Fixed or Move; invalid bones are left alone)."""
        m = self.model
        return np.unique(m.transform_index[(m.attribute & 0x03) != 0]).astype(np.int32)

    # ------------------------------------------------------------------ teams at runtime
    def add_cloth(self, spec, model=None) -> int:
        """Add a cloth at runtime; returns its team id (ids are not reused).

        The model is built (unless given) after putting the cloth's bones back to their rest
        local pose. It takes a free lane of a block of its kind, or a new block whose chunks
        come from the freed space first: other teams' rows never move and their state is not
        touched. The new team starts with Reset, like a team built with the scene, and its
        bones join the restored set."""
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
        team = len(self.models)
        self.specs.append(spec)
        self.models.append(model)
        self.team_names.append(str(getattr(spec, "name", f"cloth{team}")))
        self.team_parameters.append(getattr(spec, "parameters", None) or {})
        self.collision_modes.append(getattr(spec, "collision_mode", None))
        if self.parameters.gravity.shape[0] < team + 1:
            self.parameters = grow(type(self.parameters), self.parameters, {"team": max(team + 1, 2 * team)})
        self._write_parameters(team)
        if self.time_state.capacity < team + 1:
            self.time_state.resize(max(team + 1, 2 * self.time_state.capacity))
        self._place(team, spec, model)
        self._activate(team)
        self._tables_changed()
        return team

    def remove_cloth(self, team: int) -> None:
        """Remove a cloth at runtime: its lane is freed (the block's chunks with its last lane),
        its bones are neither restored nor written any more (they keep the last written pose).
        Other teams are not touched."""
        self._check_live(team)
        self.layout.remove(team)
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
        called where a block asks, None neither): from the teams' models, parameters and
        colliders, or every stage when ``MAGICA_STAGES=all`` (``jit.stage_policy``). Recomputed
        after any change of teams or parameters; a stage that becomes needed at run time
        compiles then (once per machine: the kernels are cached)."""
        m = self.model
        bends = [len(getattr(mm, "bend_vertices", ())) + len(getattr(mm, "volume_vertices", ()))
                 if mm is not None else 0 for mm in self.models]
        lines = [len(getattr(mm, "lines", ())) if mm is not None else 0 for mm in self.models]
        colliders = [int(c) for c in m.team_collider_count]
        return self._switches(self.live_teams, bends, lines, m.team_triangle_count, colliders)

    def expected_stage_switches(self) -> StageSwitches:
        """``stage_switches`` as far as the specs tell before the build: the same, except that a
        mesh cloth with triangle bending is assumed to have bending pairs and every cloth line
        and triangle rotations (what only its model tells). Used to start a first run's compile
        of the step's stages beside the build (``compile_helper.start_early``)."""
        from magica_py.build.constraints import wants_bending

        bends = [int(getattr(s, "connection_mode", "line") != "line" and wants_bending(self.team_parameters[t]))
                 for t, s in enumerate(self.specs)]
        colliders = [len(self._collider_indices(s)) for s in self.specs]
        ones = [1] * len(self.specs)
        return self._switches(list(range(len(self.specs))), bends, ones, ones, colliders)

    def _switches(self, teams, bends, lines, triangles, colliders) -> StageSwitches:
        """The stage switches of ``teams`` from the parameter rows and, per team id, the counts
        of bending pairs, lines, triangles and colliders (all on under ``MAGICA_STAGES=all``)."""
        if stage_policy() == "all":
            return StageSwitches(*([1] * len(StageSwitches._fields)))
        prm = self.parameters
        live = np.asarray(teams, dtype=np.int64)

        def any_of(values) -> int | None:
            return 1 if live.size and bool(np.any(np.asarray(values)[live])) else None

        colliding = np.asarray(colliders)[live] > 0 if live.size else np.zeros(0, bool)
        mode = prm.collision_mode[live] if live.size else np.zeros(0, np.int32)
        return StageSwitches(
            angle=any_of((prm.use_angle_limit != 0) | (prm.use_restoration != 0)),
            bending=any_of(np.asarray(bends) > 0),
            point_collision=1 if bool(np.any(colliding & (mode == 1))) else None,
            edge_collision=1 if bool(np.any(colliding & (mode == 2))) else None,
            motion=any_of((prm.use_max_distance != 0) | (prm.use_backstop != 0)),
            quality=any_of((prm.quality != 0) | (prm.inextensibility != 0) | (prm.collision_last != 0)
                           | (prm.time_based_smoothing != 0)),
            lines=any_of(np.asarray(lines) > 0),
            triangles=any_of(np.asarray(triangles) > 0),
            wind=1 if self.wind is not None else any_of(prm.wind_moving_wind > 0.01),
            colliders=1 if bool(np.any(colliding)) else None)

    def _tables_changed(self, register: bool = True) -> None:
        """After a change of teams: the team-ordered views, the kernels' tables, the work
        tables, the stage switches, the propagation plan and the restored bones."""
        collider_counts = [len(self._collider_indices(s)) if m is not None else 0
                           for s, m in zip(self.specs, self.models)]
        self.model = team_model(self.models, collider_counts)
        self._views()
        lay = self.layout
        blocks = np.asarray([b for b, blk in enumerate(lay.blocks) if blk is not None], dtype=np.int64)
        self.tables = Tables(self.PS, self.TS, self.CS, self.TRS, self.EDS, lay.particle_model, self.PP, lay.team_model,
                             lay.link_model, lay.triangle_model, lay.bend_model, lay.volume_model, self.P,
                             lay.block_ints, lay.topology, lay.particle_transform, lay.team_ints,
                             lay.collider_transform, blocks)
        self._time = time_arrays(self.time_state)
        most_n = int(lay.block_ints[blocks, BI_N].max()) if blocks.size else 1
        most_c = int(lay.block_ints[blocks, BI_COLLIDERS].max()) if blocks.size else 0
        self._save_area = lane_save_area(most_n, most_c, self.threads)
        self._workers = worker_table(max(lay.block_count, 1), self.threads)
        self._balance = WorkerBalance(self.threads)
        self._worker_seconds = [0.0] * self.threads   # the last parallel frame's run of each thread, s
        self.stages = self.stage_switches()
        self._written_plan = self.hierarchy.plan(self.restored_bones())
        if register and self._player is not None:
            self._player.unregister_restored_bones(self)
            self._player.register_restored_bones(self.restored_bones(), owner=self)

    def _views(self) -> None:
        """The team-ordered views of the state (``solver/views.py``)."""
        lay = self.layout
        live = self.live_teams
        g_items, g_lanes, c_items, c_lanes = [], [], [], []
        for t in live:
            b, lane = lay.place(t)
            slots = lay.slots(t)
            g_items.append(slots["particle"])
            g_lanes.append(np.full(len(slots["particle"]), lane))
            c_items.append(slots["collider"])
            c_lanes.append(np.full(len(slots["collider"]), lane))
        cat = (lambda parts: np.concatenate(parts) if parts else np.zeros(0, np.int64))
        team_b = np.array([lay.team_block[t] if lay.team_block[t] >= 0 else 0 for t in range(len(self.models))])
        team_l = np.array([lay.team_lane[t] if lay.team_lane[t] >= 0 else 0 for t in range(len(self.models))])
        valid = np.array([lay.team_block[t] >= 0 for t in range(len(self.models))], dtype=bool)
        self.particles = TableView(st.PARTICLE, cat(g_items), cat(g_lanes), lambda: self.PS,
                                   {"display_history": np.uint8, "accum_count": np.int32})
        self.teams = TableView(st.TEAM, team_b, team_l, lambda: self.TS,
                               {"reset": np.uint8, "time_reset": np.uint8, "keep_teleport": np.uint8,
                                "inertia_shift": np.uint8, "running": np.uint8, "active": np.uint8,
                                "enabled": np.uint8, "culled": np.uint8, "scale_suspended": np.uint8,
                                "guard_code": np.int32, "external_force_mode": np.int32,
                                "wind_zone_count": np.int32, "wind_zone_id": np.int32}, valid)
        self.collider_state = TableView(st.COLLIDER, cat(c_items), cat(c_lanes), lambda: self.CS,
                                        {"first_frame": np.uint8, "scale_suspend": np.uint8})

    def _activate(self, t: int) -> None:
        mode = self._parameter(t, "update_mode", default_parameters()["update_mode"])
        if str(mode) in ("normal", "animator_linkage") and self._scene_update_mode:
            mode = self._scene_update_mode
        self.time_state.activate(t, update_mode=update_mode_code(mode))
        self.write_team(t, "enabled", 1.0)

    def _collider_indices(self, spec) -> list[int]:
        if self.colliders is None:
            return []
        return [int(i) for i in (getattr(spec, "colliders", ()) or ())]

    # ------------------------------------------------------------------ state access
    def team_slots(self, team: int) -> tuple[int, int, np.ndarray]:
        """(block, lane, particle slots) of a live team."""
        b, lane = self.layout.place(team)
        return b, lane, self.layout.slots(team)["particle"]

    def read_particles(self, team: int, field: str) -> np.ndarray:
        """One field of a team's particles, (n,) or (n, k), particle order (a copy)."""
        _b, lane, g = self.team_slots(team)
        return st.PARTICLE.view(self.PS, field, g, lane)

    def write_particles(self, team: int, field: str, values) -> None:
        """Write one field of a team's particles ((n,) or (n, k) values, particle order)."""
        _b, lane, g = self.team_slots(team)
        st.PARTICLE.write(self.PS, field, g, lane, values)

    def read_team(self, team: int, field: str):
        b, lane = self.layout.place(team)
        v = st.TEAM.view(self.TS, field, [b], lane)
        return v[0]

    def write_team(self, team: int, field: str, value) -> None:
        b, lane = self.layout.place(team)
        st.TEAM.write(self.TS, field, [b], lane, np.asarray(value, dtype=np.float64).reshape(1, -1))

    # ------------------------------------------------------------------ frame
    def run(self, ctx) -> None:
        """The LATE_UPDATE system: apply pending events, simulate every team, propagate."""
        if ctx.events:
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

    def _write_time_constants(self, fi) -> None:
        """The frame inputs that follow from the time settings and the thread count alone,
        ``fi[4:13]`` (frame.FrameInputs' fields, in order), written when one of them changes
        (the power terms take two ``pow`` each; a write per frame would cost a microsecond of a
        single tail's frame)."""
        s = self.time_settings
        key = (s.frequency, s.max_steps_per_frame, s.global_time_scale, s.timing, self.threads, id(fi))
        if key != getattr(self, "_time_key", None):
            power = s.simulation_power
            fi[4:13] = (float(s.global_time_scale), float(s.simulation_delta_time), int(s.max_steps_per_frame),
                        int(s.timing_code), 90.0 / s.frequency, float(power[1]), float(power[2]), float(power[3]),
                        self.threads)
            self._time_key = key

    def step_frame(self, delta_time, unscaled_delta_time=None, fixed_delta_time=0.02,
                   fixed_update_count=0, events=None, metrics=None) -> None:
        """One frame of every team (usable without a player: tests, benchmarks)."""
        fi = self._frame_values   # frame.FrameInputs' fields, in order
        self._write_time_constants(fi)
        fi[0] = delta_time
        fi[1] = delta_time if unscaled_delta_time is None else unscaled_delta_time
        fi[2] = fixed_delta_time
        fi[3] = fixed_update_count
        clock = _time.perf_counter
        hierarchy = self.hierarchy
        hierarchy.flush()   # the kernel reads the world poses through kept references
        t0 = clock()
        if self.wind is not None:
            self.select_wind()
        most_steps, particle_steps, guarded = self._call_frame(fi)
        t1 = clock()
        if self._written_plan.threads != hierarchy.threads:
            self._written_plan = hierarchy.plan(self.restored_bones())
        # the subtrees of the bones written back, computed when next read (scene/hierarchy.py)
        hierarchy.propagate_later(self._written_plan)
        t2 = clock()
        self.frame_count += 1
        if guarded:
            for team in self.live_teams:
                code = int(self.read_team(team, "guard_code"))
                if code:
                    if events is not None:
                        events.append(("cloth_reset", {"cloth": self.team_names[team], "team": int(team),
                                                       "reason": GUARD_REASONS.get(code, "guard")}))
                    self.write_team(team, "guard_code", 0.0)
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
        teams = self.teams_of(cloth)
        for t in teams:
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
        if self._move_teams(teams):
            self._tables_changed()
        self.stages = self.stage_switches()  # a changed parameter may need another stage

    def reset_cloth(self, cloth, keep_pose: bool = False) -> None:
        for t in self.teams_of(cloth):
            if keep_pose:
                self.write_team(t, "keep_teleport", 1.0)
            else:
                self.write_team(t, "reset", 1.0)
                self.write_team(t, "time_reset", 1.0)
                self.time_state.reset([t])

    def set_enabled(self, cloth, enabled: bool) -> None:
        for t in self.teams_of(cloth):
            was = self.read_team(t, "enabled") != 0.0
            self.write_team(t, "enabled", 1.0 if enabled else 0.0)
            if enabled and not was:
                self.write_team(t, "reset", 1.0)

    def set_time_scale(self, cloth, value: float) -> None:
        for t in self.teams_of(cloth):
            self.time_state.set_time_scale(t, value)

    def add_force(self, cloth, direction, speed: float, mode: str = "velocity_add") -> None:
        """MagicaCloth.AddForce: an acceleration on every step of the next frame that runs."""
        try:
            d = np.asarray(direction, dtype=np.float64)
            speed = float(speed)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"add_force: expected direction (3 numbers) and speed (a number), "
                             f"got {direction!r}, {speed!r}") from exc
        if d.shape != (3,) or not np.isfinite(d).all():
            raise ValueError(f"add_force direction: expected 3 finite numbers, got {direction!r}")
        if not math.isfinite(speed):
            raise ValueError(f"add_force speed: expected a finite number (m/s), got {speed!r}")
        n = portable.norm(d)
        if mode not in FORCE_MODES:
            raise ValueError(f"add_force mode {mode!r}: expected one of {sorted(FORCE_MODES)}")
        for t in self.teams_of(cloth):
            self.write_team(t, "external_force", d / n * float(speed) if n > 1e-8 else np.zeros(3))
            self.write_team(t, "external_force_mode", float(FORCE_MODES[mode]))

    # ------------------------------------------------------------------ state capture
    def capture_state(self) -> dict:
        """Copies of everything the next frame reads (``runtime/snapshot.py``), team by team
        (so that a snapshot restores into a system whose blocks are grouped otherwise: the
        bench's candidates with other parameters): each live team's columns of the state
        tables, the parameter table, the team clocks, the build pose, the runtime overrides."""
        from magica_py.runtime.snapshot import table_state

        h = self._hierarchy
        return {
            "layout": self._layout_signature(),
            "lanes": {t: self._lane_state(t) for t in self.live_teams},
            "tables": {"parameters": table_state(self.parameters), "time": table_state(self._time)},
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
        restore_arrays(f"{self.name}.time", table_arrays(self._time), state["tables"]["time"])
        restore_arrays(f"{self.name}.parameters", table_arrays(self.parameters), state["tables"]["parameters"])
        restore_arrays(f"{self.name}.build_pose", {n: getattr(self._hierarchy, n) for n in _BUILD_POSE_FIELDS},
                       state["build_pose"])
        self.frame_count = state["frame_count"]
        self.team_parameters = list(state["team_parameters"])
        self.collision_modes = list(state["collision_modes"])
        moved = self._move_teams(self.live_teams)
        for t, lane_state in state["lanes"].items():
            self._write_lane_state(t, lane_state)
        if self.wind is not None and state.get("wind") is not None:
            self.wind.restore_state(state["wind"])
        if moved:
            self._tables_changed()
        self.stages = self.stage_switches()

    def _layout_signature(self) -> tuple:
        return (tuple(int(t) for t in self.live_teams),
                tuple(int(m.particle_count) for m in self.models if m is not None), tuple(self.team_names))

    # ------------------------------------------------------------------ queries
    def positions(self, cloth) -> np.ndarray:
        """Display positions (world, m) of one cloth's particles (a copy); a team not
        simulated this frame reports its bones' positions (``display_positions``)."""
        team = self.teams_of(cloth)[0]
        if self.read_team(team, "active") == 0.0:
            return self._bone_positions(team)
        return self.read_particles(team, "position")

    def _bone_positions(self, team: int) -> np.ndarray:
        """World positions of a team's bones (particle order)."""
        m = self.model
        start, count = int(m.team_particle_start[team]), int(m.team_particle_count[team])
        nodes = np.asarray(m.transform_index[start:start + count], np.int64)
        return np.array(self.hierarchy.world_position[nodes], dtype=np.float64)

    def display_positions(self) -> np.ndarray:
        """``particles.position`` of every live team (team order, (P, 3), world m), except that
        a team not simulated this frame (distance culled, disabled or scale-suspended:
        ``ACTIVE`` 0; docs/solver.md §H.1, §H.2) reports its bones' world positions: its
        bones are not written from the particles, which hold stale values (zeros for a team
        culled since its first frame), so the API, the recordings and their metrics show the
        bones as they are rather than a cloth at the origin with 100 % stretch."""
        position = self.particles.position
        m = self.model
        for team in np.flatnonzero(self.teams.active == 0):   # one gather of every team's flag
            if self.models[team] is None or int(m.team_particle_count[team]) == 0:
                continue
            start, count = int(m.team_particle_start[team]), int(m.team_particle_count[team])
            position[start:start + count] = self._bone_positions(team)
        return position

    # ------------------------------------------------------------------ internals
    def select_wind(self) -> None:
        """The wind zones' poses and the zones each team feels from this frame's transforms
        (``wind.zones.WindField.update``; nothing without wind zones). ``step_frame`` calls it
        before the frame kernel."""
        if self.wind is not None:
            self.wind.update(self.tables, self._hierarchy)

    def _wind_zones(self):
        return self.wind.kernel_table() if self.wind is not None else None

    def _call_frame(self, fi) -> tuple:
        """One numba call per frame: the serial or the parallel kernel, with the stage switches;
        returns the frame's counts (``frame.frame_counts``)."""
        if self._first_call:
            return self._first_frame_call(fi)
        zones = self._wind_zones()
        F = self._frame_arrays()
        if self.parallel:
            return self._parallel_frame(F, fi, zones)
        return simulate_frame(F, fi, self._save_area, zones, *self.stages)

    def _parallel_frame(self, F, fi, zones) -> tuple:
        """The frame on ``threads`` threads: ``begin_parallel_frame`` deals the blocks, each
        thread runs ``simulate_worker`` over its blocks (this one and the system's
        ``FrameThreads``; the kernels release the GIL), ``end_parallel_frame`` closes the frame
        (solver/frame.py). The first frame runs the workers one after the other in this thread,
        so that their kernel compiles here (the compile's announcement and timing, the compile
        helper)."""
        block_worker, worker_load, worker_share = self._workers
        workers = begin_parallel_frame(F, fi, block_worker, worker_load, worker_share)
        head = (F, fi, self._save_area, zones, block_worker)
        stages = self.stages
        pool = self._pool
        if pool is None:
            for w in range(workers):
                simulate_worker(*head, w, *stages)
            self._pool = FrameThreads(self.threads - 1)
        else:
            seconds = self._worker_seconds
            start = _time.perf_counter()
            pool.run([partial(_timed_worker, seconds, start, head, w, stages) for w in range(1, workers)])
            try:
                _timed_worker(seconds, start, head, 0, stages)
            finally:   # every thread's blocks finish before the frame closes or an error leaves
                pool.join()
            # the next frame's shares from the threads' speeds (the results do not depend on them)
            self._balance.update(seconds, worker_load, workers, worker_share)
        return end_parallel_frame(F, fi)

    def _first_frame_call(self, fi) -> tuple:
        """The system's first frame call: on a first run (the frame kernel not yet compiled in
        this process) a helper process compiles the step's stages meanwhile, while this process
        compiles the end of frame, then the frame kernel (``solver/compile_helper.py``)."""
        self._first_call = False
        kernel = simulate_worker if self.parallel else simulate_frame
        helper, self._helper = self._helper, None
        if helper is not None:
            helper = compile_helper.meet(helper, self._frame_arrays(), fi, self._save_area, self.stages)
        elif compile_helper.wanted(kernel):
            zones = self._wind_zones()
            helper = compile_helper.start(self._frame_arrays(), fi, self._save_area, zones, self.stages)
        try:
            return self._call_frame(fi)
        finally:
            compile_helper.finish(helper)

    def _frame_arrays(self):
        """The frame kernel's arrays in one StructRef (``frame_call.frame_arrays``), made again
        whenever the tables, the team clocks or the hierarchy's arrays are new objects."""
        key = (self.tables, self._time, self._hierarchy)
        made = self._frame_arrays_of
        if made is None or made[0] is not key[0] or made[1] is not key[1] or made[2] is not key[2]:
            self._frame_arrays_made = frame_arrays(*key)
            self._frame_arrays_of = key
        return self._frame_arrays_made

    def _parameter(self, team, key, default):
        params = self.team_parameters[team]
        try:
            value = params.get(key, default)
        except AttributeError:
            value = default
        return default if value is None else value

    def _check_positive_scale(self, hierarchy, pairs=None) -> None:
        """Negative scale is rejected (§H.7 allows a Python port to assume positive scale): the
        build refuses it at the rest pose; this checks the pose the system starts from, and
        models given to it."""
        for spec, model in (pairs if pairs is not None else zip(self.specs, self.models)):
            nodes = list(np.asarray(model.transform_index)) + [int(model.component_transform)]
            for node in nodes:
                if (hierarchy.lossy_scale[node] < 0.0).any():
                    where = getattr(spec, "document_path", "")
                    raise BuildError(getattr(spec, "name", "?"), (f"{where}: " if where else "")
                                     + negative_scale_message(hierarchy.names[node], hierarchy.lossy_scale[node],
                                                            "in the pose the cloth system starts from"))

    def _write_parameters(self, team: int) -> None:
        def resolve(name):
            return int(self.hierarchy.index(name))
        write_row(self.parameters, team, self.team_parameters[team], self.collision_modes[team], resolve)

    # queries for tests and sinks
    def collider_slots(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What each collider slot of ``collider_state`` is (team order, ``model.team_collider_start``
        / ``team_collider_count`` ranges): ``(team, collider_index, shape)``, (S,) int32 each: the
        slot's team, its collider's index in the scene's ``ColliderSet`` (slot k of a team is
        its cloth's k-th collider, §G.3), and that collider's shape (0 sphere, 1 capsule, 2 plane)."""
        team, index = [], []
        for t in self.live_teams:
            indices = self._collider_indices(self.specs[t])
            team += [t] * len(indices)
            index += indices
        team = np.asarray(team, dtype=np.int32)
        index = np.asarray(index, dtype=np.int32)
        shape = (np.asarray(self.colliders.shape, dtype=np.int32)[index] if index.size
                 else np.zeros(0, dtype=np.int32))
        return team, index, shape
