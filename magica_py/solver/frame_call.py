"""How the system calls the frame kernel: the frame's arrays in one StructRef.

The frame reads the solver's tables, the team clocks and the hierarchy: 49 arrays, whose
fields are declared by three namedtuples (``frame.Tables``, ``TimeArrays``,
``HierarchyArrays``). numba's dispatcher types namedtuple arguments field by field in Python
(~7 us a call for the three, measured) and 49 separate array arguments in ~2.7 us; a
StructRef (``numba.experimental.structref``, the documented API: ``register``,
``define_proxy``) holding the 49 arrays is typed in about a microsecond (its type is found
through Python: a call taking it cost 1.35-1.75 us against 0.49 us for one array, session
25). On the single tail (a frame of ~40 us) that is worth having. ``frame_arrays`` builds the StructRef once per
change of tables (``ClothSystem._frame_arrays``); it shares the numpy arrays, so the kernel
sees every write made to them. The frame kernels (``frame.simulate_frame``, and a parallel
frame's ``begin_parallel_frame``, ``simulate_worker``, ``end_parallel_frame``) take it and
pass it down the frame recipe (``frame.py``'s module docstring), each recipe function binding
the arrays it uses to locals: a namedtuple of the arrays copied into each function instead
costs numba one reference count per array and copy (docs/architecture.md).

With ``NUMBA_DISABLE_JIT=1`` the StructRef is a plain namedtuple with the same field names
(``FrameArraysTuple``), so the frame runs as Python.
"""
from __future__ import annotations

from collections import namedtuple

from numba import config, types
from numba.experimental import structref

from magica_py.jit import kernel
from magica_py.solver.frame import HierarchyArrays, Tables, TimeArrays

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
