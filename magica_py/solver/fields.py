"""Field tables as data: one declaration per structure-of-arrays, allocation generated from it.

Each SoA (the solver's global model, particle state, team state, collider state) is a
``collections.namedtuple`` of numpy arrays so that one numba call receives all of them
(numba types a namedtuple of arrays as a heterogeneous tuple; attribute access compiles to a
field load). A field is ``(name, per, trailing_shape, dtype, doc)`` where ``per`` names the
leading dimension (``"particle"``, ``"team"``, ...) and ``doc`` gives units and the phase
that writes it.
"""
from __future__ import annotations

import sys
from collections import namedtuple

import numpy as np

F64 = np.float64
I32 = np.int32
U8 = np.uint8


def make_soa(type_name: str, fields: list[tuple]):
    """The namedtuple class of a field table, with the table attached as ``FIELDS``.

    The class is attributed to the calling module (where it must be bound under
    ``type_name``) so that numba's on-disk cache can pickle kernel signatures by reference.
    """
    module = sys._getframe(1).f_globals["__name__"]
    cls = namedtuple(type_name, [f[0] for f in fields], module=module)
    cls.FIELDS = tuple(fields)
    cls.__doc__ = type_name + ":\n" + "\n".join(
        f"  {name:28s} ({per}{', ' + ','.join(map(str, shape)) if shape else ''}) {np.dtype(dt).name}: {doc}"
        for name, per, shape, dt, doc in fields)
    return cls


def allocate(cls, sizes: dict[str, int], fill: dict | None = None):
    """Zero-filled arrays for every field of ``cls``; quaternion fields start as identity."""
    arrays = {}
    for name, per, shape, dtype, _doc in cls.FIELDS:
        a = np.zeros((sizes[per],) + tuple(shape), dtype=dtype)
        if shape == (4,) and dtype == F64 and ("rot" in name or "quat" in name):
            a[..., 3] = 1.0
        arrays[name] = a
    for name, value in (fill or {}).items():
        arrays[name][...] = value
    return cls(**arrays)


def grow(cls, soa, sizes: dict[str, int], fill: dict | None = None):
    """A copy of ``soa`` with leading dimensions enlarged to ``sizes`` (old rows kept bit for
    bit; new rows as ``allocate`` makes them, with ``fill``)."""
    fresh = allocate(cls, sizes, fill)
    for name, per, _shape, _dtype, _doc in cls.FIELDS:
        old = getattr(soa, name)
        n = min(old.shape[0], sizes[per])
        getattr(fresh, name)[:n] = old[:n]
    return fresh
