"""Row access for the per-frame stages' loops over a team's particles: ``flat`` 1-D views of
C-contiguous ``(n, k)`` tables and tuple loads / stores of one row of such a view.

Row p of an ``(n, k)`` table is ``flat[k p : k p + k]`` with k a constant, so a loop's rows are
plain strided accesses. Plain indexing throughout: ``NUMBA_BOUNDSCHECK=1`` checks every access
and ``NUMBA_DISABLE_JIT=1`` runs these as Python.
"""
from __future__ import annotations

import numpy as np

from magica_py.jit import kernel


@kernel
def flat(a):
    """A C-contiguous array as a 1-D view of the same memory."""
    return a.reshape(a.size)


@kernel
def row3(a, i):
    """``a[i : i + 3]`` of a flat view as a tuple (unsigned i: no wraparound select)."""
    return (a[i], a[i + np.uint64(1)], a[i + np.uint64(2)])


@kernel
def row4(a, i):
    """``a[i : i + 4]`` of a flat view as a tuple."""
    return (a[i], a[i + np.uint64(1)], a[i + np.uint64(2)], a[i + np.uint64(3)])


@kernel
def set_row3(a, i, v):
    """``a[i : i + 3] = v``."""
    a[i] = v[0]
    a[i + np.uint64(1)] = v[1]
    a[i + np.uint64(2)] = v[2]


@kernel
def set_row4(a, i, q):
    """``a[i : i + 4] = q``."""
    a[i] = q[0]
    a[i + np.uint64(1)] = q[1]
    a[i + np.uint64(2)] = q[2]
    a[i + np.uint64(3)] = q[3]
