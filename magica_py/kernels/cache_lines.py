"""Reading memory ahead of the work that needs it (docs/tech-notes.md, LAYOUT).

Work that touches rows scattered over a large array (the hierarchy propagation's levels, a
solver block's stages) waits for memory at each first touch; reading the same rows once in
address order lets the hardware prefetcher stream them into the cache first. ``read_lines``
is that read: one load per 64-byte line of a flat span, summed, so that the caller can store
the sum and keep the loads (an unused load is removed by the compiler).
"""
from __future__ import annotations

from magica_py.jit import kernel


@kernel(inline="always")
def read_lines(rows, lo, hi):
    """One read per cache line of ``rows[lo:hi]`` (a flat float64 view), summed, and the last
    value. A plain sum: without fastmath LLVM keeps it a chain of scalar loads (an integer fold
    would be vectorised into gathers, which fetch the lines half as fast here)."""
    acc = 0.0
    for k in range(lo, hi, 8):
        acc += rows[k]
    if hi > lo:
        acc += rows[hi - 1]
    return acc
