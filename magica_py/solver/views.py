"""Team-ordered views of the solver's packed tables, for readers outside the solver.

The kernels work on blocks of lanes (``solver/lanes.py``, ``solver/blocks.py``); sinks,
metrics, the API and tests read one team's particles after another. These views give them
that order without copying the whole state each frame:

* ``team_model(models)``: the live teams' build models concatenated in team-id order, with
  global particle indices (``team_particle_start/count`` per team id; a removed team has
  count 0): ``transform_index``, ``attribute``, ``parent``, ``root_index``, ``depth``,
  ``edges``, ``triangles``, ``particle_team``, ... (read-only, rebuilt when teams change);
* ``ParticleView``: ``view.next_pos`` is the (N, 3) array of every live particle in that
  order, gathered from the packed state when read (a copy: write with
  ``ClothSystem.write_particles``);
* ``TeamView``: ``view.velocity_weight`` is the (teams,) array by team id (0 for a removed
  team), likewise ``ColliderView`` for the collider slots of each team in turn.
"""
from __future__ import annotations

from collections import namedtuple

import numpy as np

from magica_py.solver.lanes import LANES

TEAM_MODEL_FIELDS = (
    "team_particle_start", "team_particle_count", "team_edge_start", "team_edge_count",
    "team_triangle_start", "team_triangle_count", "team_component_transform", "team_init_scale",
    "team_collider_start", "team_collider_count",
    "particle_team", "transform_index", "attribute", "parent", "root_index", "depth", "local_position",
    "child_count", "edges", "triangles", "live_teams")
TeamModel = namedtuple("TeamModel", TEAM_MODEL_FIELDS)


def team_model(models, collider_counts) -> TeamModel:
    """The concatenated team-ordered model of ``models`` (None for a removed team) with
    ``collider_counts`` collider slots per team."""
    parts = {name: [] for name in ("particle_team", "transform_index", "attribute", "parent", "root_index", "depth",
                                   "local_position", "child_count", "edges", "triangles")}
    teams = len(models)
    start = np.zeros(teams, np.int32)
    count = np.zeros(teams, np.int32)
    e_start, e_count = np.zeros(teams, np.int32), np.zeros(teams, np.int32)
    t_start, t_count = np.zeros(teams, np.int32), np.zeros(teams, np.int32)
    c_start, c_count = np.zeros(teams, np.int32), np.zeros(teams, np.int32)
    component = np.full(teams, -1, np.int32)
    init_scale = np.ones((teams, 3))
    at = edges_at = tris_at = colliders_at = 0
    for t, m in enumerate(models):
        start[t], e_start[t], t_start[t], c_start[t] = at, edges_at, tris_at, colliders_at
        if m is None:
            continue
        n = int(m.particle_count)
        count[t] = n
        parent = np.asarray(m.parent, np.int64)
        root = np.asarray(m.root_index, np.int64)
        edges = np.asarray(m.edges, np.int64).reshape(-1, 2)
        tris = np.asarray(getattr(m, "triangles", np.zeros((0, 3))), np.int64).reshape(-1, 3)
        parts["particle_team"].append(np.full(n, t, np.int32))
        parts["transform_index"].append(np.asarray(m.transform_index, np.int32))
        parts["attribute"].append(np.asarray(m.attribute, np.uint8))
        parts["parent"].append(np.where(parent >= 0, parent + at, -1).astype(np.int32))
        parts["root_index"].append(np.where(root >= 0, root + at, -1).astype(np.int32))
        parts["depth"].append(np.asarray(m.depth, np.float64))
        parts["local_position"].append(np.asarray(m.local_position, np.float64).reshape(-1, 3))
        parts["child_count"].append(np.asarray(m.child_count, np.int32))
        parts["edges"].append((edges + at).astype(np.int32))
        parts["triangles"].append((tris + at).astype(np.int32))
        e_count[t], t_count[t] = len(edges), len(tris)
        c_count[t] = int(collider_counts[t])
        component[t] = int(m.component_transform)
        init_scale[t] = np.asarray(m.init_scale, np.float64).reshape(3)
        at += n
        edges_at += len(edges)
        tris_at += len(tris)
        colliders_at += int(collider_counts[t])
    empty = {"local_position": np.zeros((0, 3)), "edges": np.zeros((0, 2), np.int32),
             "triangles": np.zeros((0, 3), np.int32), "depth": np.zeros(0), "attribute": np.zeros(0, np.uint8)}
    arrays = {name: (np.concatenate(v) if v else empty.get(name, np.zeros(0, np.int32))) for name, v in parts.items()}
    arrays.update(team_particle_start=start, team_particle_count=count, team_edge_start=e_start,
                  team_edge_count=e_count, team_triangle_start=t_start, team_triangle_count=t_count,
                  team_component_transform=component, team_init_scale=init_scale, team_collider_start=c_start,
                  team_collider_count=c_count,
                  live_teams=np.asarray([t for t, m in enumerate(models) if m is not None], np.int32))
    for a in arrays.values():
        a.flags.writeable = False
    return TeamModel(**arrays)


class _Gather:
    """Index arrays that take one field of a packed table to team order: ``items`` (K,) the
    table rows and ``lanes`` (K,) the lanes, one entry per item in team order. A field's flat
    indices are made once per field (``np.take`` of them is one pass over the values)."""

    def __init__(self, table, items: np.ndarray, lanes: np.ndarray, owner, valid=None):
        self._table = table
        self._items = items
        self._lanes = lanes
        self._owner = owner
        self._valid = valid   # entries with no item (a removed team) read as 0
        self._flat: dict[tuple[str, int], np.ndarray] = {}

    def _indices(self, name, width):
        key = (name, width)
        flat = self._flat.get(key)
        if flat is None:
            first, size, _kind, _doc = self._table.fields[name]
            cols = (first + np.arange(size))[None, :] * LANES + self._lanes[:, None]
            flat = self._items[:, None] * width + cols
            self._flat[key] = flat
        return flat

    def read(self, name):
        array = self._owner()
        size = self._table.fields[name][1]
        if not len(self._items):
            out = np.zeros((0, size))
        else:
            out = np.take(array.reshape(-1), self._indices(name, array.shape[1]))
        if self._valid is not None:
            out[~self._valid] = 0.0
        return out[:, 0].copy() if size == 1 else out

    def write(self, name, values):
        array = self._owner()
        size = self._table.fields[name][1]
        flat = self._indices(name, array.shape[1])
        array.reshape(-1)[flat] = np.asarray(values, dtype=np.float64).reshape(len(self._items), size)


class TableView:
    """``view.<field>``: one field of a packed table in team order (module docstring)."""

    def __init__(self, table, items, lanes, owner, kinds=None, valid=None):
        object.__setattr__(self, "_gather", _Gather(table, np.asarray(items, np.int64), np.asarray(lanes, np.int64),
                                                    owner, valid))
        object.__setattr__(self, "_table", table)
        object.__setattr__(self, "_kinds", kinds or {})

    def __getattr__(self, name):
        if name.startswith("_") or name not in self._table.fields:
            raise AttributeError(f"{self._table.name} has no field {name!r}")
        values = self._gather.read(name)
        dtype = self._kinds.get(name)
        return values.astype(dtype) if dtype is not None else values

    def __dir__(self):
        return list(self._table.fields)

    @property
    def fields(self):
        return tuple(self._table.fields)
