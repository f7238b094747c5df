"""How the system calls the frame kernel: the frame's arrays in one StructRef.

The frame kernel (``frame.simulate_frame``) takes the solver's tables, the team clocks and the
hierarchy as three namedtuples of arrays (``frame.Tables``, ``TimeArrays``,
``HierarchyArrays``: 49 arrays). numba's dispatcher types a namedtuple argument field by field
in Python (~7 us a call for the three, measured) and 49 separate array arguments in ~2.7 us;
a StructRef (``numba.experimental.structref``, the documented API: ``register``,
``define_proxy``) holding the 49 arrays is typed in well under a microsecond. On the single
tail (a frame of ~32 us) that is worth having. ``frame_arrays`` builds the StructRef once per
change of tables (``ClothSystem._frame_arrays``); it shares the numpy arrays, so the kernel
sees every write made to them. ``frame_entry`` rebuilds the namedtuples from its fields and
runs the frame.

With ``NUMBA_DISABLE_JIT=1`` the StructRef is a plain namedtuple with the same field names
(``FrameArraysTuple``), so the frame runs as Python.
"""
from __future__ import annotations

from collections import namedtuple

from numba import config, types
from numba.experimental import structref

from magica_py.jit import kernel
from magica_py.solver.frame import (
    HierarchyArrays, Tables, TimeArrays, WorkerTable, simulate_frame, simulate_frame_parallel,
)

# the StructRef's fields: Tables' fields, then TimeArrays' (prefixed tt_), then
# HierarchyArrays' (prefixed h_), in the namedtuples' order
FRAME_ARRAY_FIELDS = (tuple(Tables._fields) + tuple("tt_" + f for f in TimeArrays._fields)
                      + tuple("h_" + f for f in HierarchyArrays._fields))


@structref.register
class FrameArraysType(types.StructRef):
    """numba's type of ``FrameArrays`` (fields: ``FRAME_ARRAY_FIELDS``, array types)."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class FrameArrays(structref.StructRefProxy):
    """The frame kernel's 49 arrays in one object (fields ``FRAME_ARRAY_FIELDS``)."""


structref.define_proxy(FrameArrays, FrameArraysType, list(FRAME_ARRAY_FIELDS))
# the JIT-off stand-in (attribute access is the same)
FrameArraysTuple = namedtuple("FrameArraysTuple", FRAME_ARRAY_FIELDS)


@kernel
def new_frame_arrays(*fields):
    return FrameArrays(*fields)


def frame_arrays(T, tt, h):
    """``FrameArrays`` sharing the arrays of ``T`` (``Tables``), ``tt`` (``TimeArrays``) and
    ``h`` (``HierarchyArrays``)."""
    fields = (*T, *tt, *h)
    if config.DISABLE_JIT:
        return FrameArraysTuple(*fields)
    return new_frame_arrays(*fields)


@kernel
def frame_tuples(F):
    """The three namedtuples of ``F``'s arrays (``frame_entry``'s and the parallel entry's)."""
    T = Tables(F.PS, F.TS, F.CS, F.TRS, F.EDS, F.PM, F.PP, F.TM, F.LM, F.TRM, F.BM, F.VM, F.P, F.BI, F.topology,
               F.PT, F.TI, F.CT, F.blocks)
    tt = TimeArrays(F.tt_active, F.tt_suspended, F.tt_update_mode, F.tt_team_time_scale, F.tt_time, F.tt_old_time,
                    F.tt_now_update_time, F.tt_old_update_time, F.tt_frame_update_time, F.tt_frame_old_time,
                    F.tt_update_count, F.tt_skip_count, F.tt_frame_delta_time, F.tt_now_time_scale,
                    F.tt_frame_add, F.tt_frame_interpolation, F.tt_running, F.tt_step_running)
    h = HierarchyArrays(F.h_parent, F.h_local_position, F.h_local_rotation, F.h_world_position, F.h_world_rotation,
                        F.h_lossy_scale, F.h_local_to_world, F.h_build_world_position, F.h_build_world_rotation,
                        F.h_build_lossy_scale, F.h_build_local_to_world, F.h_build_pose_pending)
    return T, tt, h


@kernel(forceinline=False)
def frame_entry(F, frame_values, area, wind_zones, angle, bending, point_collision, edge_collision, motion, quality,
                lines, triangles, wind):
    """``frame.simulate_frame`` on the arrays of ``F`` (``frame_arrays``); the other arguments
    are ``simulate_frame``'s. Returns ``frame.frame_counts``."""
    T, tt, h = frame_tuples(F)
    return simulate_frame(T, tt, h, frame_values, area, wind_zones, angle, bending, point_collision, edge_collision,
                          motion, quality, lines, triangles, wind)


@kernel(forceinline=False)
def frame_entry_parallel(F, frame_values, area, wind_zones, block_worker, worker_load, angle, bending,
                         point_collision, edge_collision, motion, quality, lines, triangles, wind):
    """``frame.simulate_frame_parallel`` on the arrays of ``F``; ``block_worker`` and
    ``worker_load`` are its ``WorkerTable``."""
    T, tt, h = frame_tuples(F)
    return simulate_frame_parallel(T, tt, h, frame_values, area, wind_zones, WorkerTable(block_worker, worker_load),
                                   angle, bending, point_collision, edge_collision, motion, quality, lines, triangles,
                                   wind)
