"""The solver's tables as the frame kernel receives them.

Each table (model, particles, parameters, teams, colliders, team time, hierarchy) is a
namedtuple of numpy arrays (``solver/fields.py``). Passed as it is, numba types every array of
every table on every call (about 110 us a frame for ~300 arrays, measured) and copies the
whole tuple into each stage call. The kernels therefore receive each table as a numba
StructRef (``numba.experimental.structref``, the documented API: ``register``,
``define_proxy``): one pointer, the same field names, sharing the numpy arrays. Each kind of
table has its own StructRef type and proxy class, built once per table change by a cached
constructor kernel (``new_*``: ``Proxy(*fields)``, compiled once per machine and cached on disk).

With ``NUMBA_DISABLE_JIT=1`` the kernels run as Python and receive the namedtuples
themselves (attribute access is the same), so a stage can be stepped in a debugger.
"""
from __future__ import annotations

from collections import namedtuple

from numba import config, types
from numba.experimental import structref

from magica_py.jit import kernel


class _TableType(types.StructRef):
    """A solver table (fields: the namedtuple's names and array types)."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


# one StructRef type and proxy per kind of table (the cache pickles types by name, so they
# live at module level)
@structref.register
class SolverTablesType(_TableType):
    """The seven tables in one object: the frame kernel's one table argument."""


@structref.register
class ModelTableType(_TableType):
    pass


@structref.register
class ParticleTableType(_TableType):
    pass


@structref.register
class ParameterTableType(_TableType):
    pass


@structref.register
class TeamTableType(_TableType):
    pass


@structref.register
class ColliderTableType(_TableType):
    pass


@structref.register
class TimeTableType(_TableType):
    pass


@structref.register
class HierarchyTableType(_TableType):
    pass


class SolverTables(structref.StructRefProxy):
    """The seven kernel tables (fields ``SOLVER_TABLE_FIELDS``) for the frame kernel."""


class ModelTable(structref.StructRefProxy):
    """``layout.SolverModel`` for the kernels."""


class ParticleTable(structref.StructRefProxy):
    """``state.ParticleState`` for the kernels."""


class ParameterTable(structref.StructRefProxy):
    """``parameters.TeamParameters`` for the kernels."""


class TeamTable(structref.StructRefProxy):
    """``state.TeamState`` for the kernels."""


class ColliderTable(structref.StructRefProxy):
    """``state.ColliderState`` for the kernels."""


class TimeTable(structref.StructRefProxy):
    """``frame.TimeArrays`` (the runtime's team clocks) for the kernels."""


class HierarchyTable(structref.StructRefProxy):
    """``frame.HierarchyArrays`` for the kernels."""


def _define(proxy, type_class, namedtuple_class) -> None:
    structref.define_proxy(proxy, type_class, list(namedtuple_class._fields))


def _definitions():
    from reference_solver.solver.frame import HierarchyArrays, TimeArrays
    from reference_solver.solver.layout import SolverModel
    from reference_solver.solver.parameters import TeamParameters
    from reference_solver.solver.state import ColliderState, ParticleState, TeamState

    return ((ModelTable, ModelTableType, SolverModel), (ParticleTable, ParticleTableType, ParticleState),
            (ParameterTable, ParameterTableType, TeamParameters), (TeamTable, TeamTableType, TeamState),
            (ColliderTable, ColliderTableType, ColliderState), (TimeTable, TimeTableType, TimeArrays),
            (HierarchyTable, HierarchyTableType, HierarchyArrays))


SOLVER_TABLE_FIELDS = ("model", "particles", "parameters", "teams", "colliders", "time", "hierarchy")
# the JIT-off stand-in of ``SolverTables`` (attribute access is the same)
SolverTablesTuple = namedtuple("SolverTablesTuple", SOLVER_TABLE_FIELDS)
_defined = False


def _ensure_defined() -> None:
    global _defined
    if not _defined:
        for proxy, type_class, namedtuple_class in _definitions():
            _define(proxy, type_class, namedtuple_class)
        _define(SolverTables, SolverTablesType, SolverTablesTuple)
        _defined = True


@kernel
def new_solver_tables(*tables):
    return SolverTables(*tables)


@kernel
def new_model_table(*fields):
    return ModelTable(*fields)


@kernel
def new_particle_table(*fields):
    return ParticleTable(*fields)


@kernel
def new_parameter_table(*fields):
    return ParameterTable(*fields)


@kernel
def new_team_table(*fields):
    return TeamTable(*fields)


@kernel
def new_collider_table(*fields):
    return ColliderTable(*fields)


@kernel
def new_time_table(*fields):
    return TimeTable(*fields)


@kernel
def new_hierarchy_table(*fields):
    return HierarchyTable(*fields)


_CONSTRUCTORS = (new_model_table, new_particle_table, new_parameter_table, new_team_table,
                 new_collider_table, new_time_table, new_hierarchy_table)


def kernel_tables(model, particles, parameters, teams, colliders, time, hierarchy):
    """The seven tables as the kernels take them: ``(solver_tables, stage_tables)``, the
    seven StructRefs (sharing the arrays; for stage kernels run alone: tests, benchmarks) and
    ``SolverTables`` holding them, the frame kernel's one table argument (numba types a
    StructRef argument in Python on every call, ~3 us each, measured). With the JIT off, the
    namedtuples themselves and a ``SolverTablesTuple`` of them."""
    tables = (model, particles, parameters, teams, colliders, time, hierarchy)
    if config.DISABLE_JIT:
        return SolverTablesTuple(*tables), tables
    _ensure_defined()
    structs = tuple(new(*table) for new, table in zip(_CONSTRUCTORS, tables))
    return new_solver_tables(*structs), structs
