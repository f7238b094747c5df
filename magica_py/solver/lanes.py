"""The lane layout: the solver's tables packed so that the teams of a block sit side by side.

Teams of identical structure (topology, collider shapes, parameters) are grouped into
*blocks* of up to ``LANES`` teams, one team per *lane* (``solver/blocks.py``). Every table of
the solver is a float64 array of shape ``(items, rows * LANES)``: value ``r`` of item ``i``
(a particle slot, a team's block, a collider slot, ...) for lane ``l`` sits at
``[i, r * LANES + l]``. So

* a stage's loop over the lanes of a block reads and writes consecutive memory, and every
  row of an item lies at a *constant* distance from the others (``LANES`` is a module
  constant): LLVM proves the row accesses of one item independent and vectorises the lane
  loop across teams with at most a few run-time overlap checks, with documented numba only
  (no alias annotations; docs/architecture.md, *Lane form*);
* the lane index is the loop variable itself (no negative-index wraparound in the address);
* a team that matches no other is a block of width one: the same code runs with one lane.

A table's rows are declared once in a ``RowTable`` (name, number of rows, units and the stage
that writes it); ``RowTable.add`` returns the field's first column (``row * LANES``), bound to a
module constant that the kernels use (``NEXT_POS``), so that numba compiles it as a constant.
``get3(a, i, NEXT_POS, l)`` / ``put3`` move a 3-vector of lane ``l`` of item ``i`` in and out
of a table (``get1``/``get4`` likewise).

Rules the stages keep so that their lane loops vectorise (measured, docs/BENCHMARKS.md):
the lane loop is the innermost loop; it reads a partner item's rows (another particle of the
team) in a loop of its own that copies them next to the item being solved (a *gather* into
scratch rows), so that the solving loop touches one item of each table; a value chosen by a
condition is loaded unconditionally and then selected (a conditional load stops the
vectoriser). A branch inside the lane loop is computed on both sides for every lane and one
result selected, also where its condition is the same for the whole block: a costly path that
depends on a block's parameter goes into the function holding the loop as an ``np.bool_``
constant, one call site per value (``step.predict_move_lanes``' ``mix``), so that the loop
without it is compiled without it.
"""
from __future__ import annotations

import numpy as np

from magica_py.jit import kernel

LANES = 16   # lanes of a block

FLOAT = "float"       # a real value
QUATERNION = "quat"   # 4 rows (x, y, z, w), identity when fresh
INTEGER = "int"       # a small integer (a count, a flag, a code) stored exactly as float64


class RowTable:
    """The rows of one packed table: ``add(name, size, doc)`` declares a field of ``size`` rows
    and returns its first column; ``allocate(items)`` makes a fresh table.

    ``item`` names what the leading dimension counts (``"particle slot"``, ``"block"``, ...);
    ``doc`` of a field gives units and the stage that writes it."""

    def __init__(self, name: str, item: str):
        self.name = name
        self.item = item
        self.fields: dict[str, tuple[int, int, str, str]] = {}   # name -> (first row, rows, kind, doc)
        self.rows = 0
        self.fill: dict[str, float] = {}
        self.shared: dict[str, tuple[int, int, str, str]] = {}   # name -> (first row, rows, field, doc)
        self._fresh = None   # fresh_row's result, made on first use

    def add(self, name: str, size: int, doc: str, kind: str = FLOAT, fill: float | None = None) -> int:
        if name in self.fields:
            raise ValueError(f"{self.name}: field {name!r} declared twice")
        if kind == QUATERNION and size != 4:
            raise ValueError(f"{self.name}: quaternion field {name!r} must have 4 rows")
        self.fields[name] = (self.rows, size, kind, doc)
        self._fresh = None
        if fill is not None:
            self.fill[name] = float(fill)
        self.rows += size
        return self.fields[name][0] * LANES

    def share(self, name: str, size: int, over: str, doc: str, offset: int = 0) -> int:
        """A scratch field in rows ``offset .. offset + size`` of the scratch field ``over``,
        for a stage that never runs while ``over``'s stage keeps values there (both use their
        rows only within one call); returns its first column. It adds no rows: it is not a
        field of its own (no fresh value, no view), only a second name for those rows."""
        if name in self.fields or name in self.shared:
            raise ValueError(f"{self.name}: field {name!r} declared twice")
        first, rows, _kind, _doc = self.fields[over]
        if offset < 0 or offset + size > rows:
            raise ValueError(f"{self.name}: {name!r} does not fit in the {rows} rows of {over!r}")
        self.shared[name] = (first + offset, size, over, doc)
        return (first + offset) * LANES

    @property
    def width(self) -> int:
        """Columns of the table: rows x LANES."""
        return self.rows * LANES

    def column(self, name: str) -> int:
        return self.fields[name][0] * LANES

    def size(self, name: str) -> int:
        return self.fields[name][1]

    def fresh_row(self) -> np.ndarray:
        """One item's fresh values, every lane: zeros, identity quaternions, declared fills
        (read-only; made once)."""
        if self._fresh is not None:
            return self._fresh
        row = np.zeros(self.width)
        for name, (first, size, kind, _doc) in self.fields.items():
            fill = self.fill.get(name, 0.0)
            for r in range(size):
                row[(first + r) * LANES:(first + r + 1) * LANES] = 1.0 if (kind == QUATERNION and r == 3) else fill
        row.flags.writeable = False
        self._fresh = row
        return row

    def allocate(self, items: int) -> np.ndarray:
        """A fresh table of ``items`` items: zeros, identity quaternions, declared fills."""
        table = np.empty((items, self.width))
        table[:] = self.fresh_row()
        return table

    def reset_lanes(self, table: np.ndarray, items, lanes) -> None:
        """Every field of ``items`` (an index, slice or array) for ``lanes`` (an index, slice or
        list) back to its fresh value."""
        lanes = np.atleast_1d(np.arange(LANES)[lanes])
        cols = (np.arange(self.rows)[:, None] * LANES + lanes[None, :]).ravel()
        rows = np.atleast_1d(np.arange(table.shape[0])[items])
        table[np.ix_(rows, cols)] = self.fresh_row()[cols]

    def view(self, table: np.ndarray, name: str, items, lane: int) -> np.ndarray:
        """Field ``name`` of ``items`` for one lane as an (n,) or (n, size) float64 array (a copy)."""
        first, size, _kind, _doc = self.fields[name]
        cols = [(first + r) * LANES + lane for r in range(size)]
        rows = np.atleast_1d(np.arange(table.shape[0])[items])
        block = table[rows][:, cols]
        return block[:, 0].copy() if size == 1 else block.copy()

    def write(self, table: np.ndarray, name: str, items, lane: int, values) -> None:
        """The inverse of ``view``: ``values`` ((n,) or (n, size)) into field ``name`` of one lane."""
        first, size, _kind, _doc = self.fields[name]
        values = np.asarray(values, dtype=np.float64).reshape(-1, size)
        rows = np.atleast_1d(np.arange(table.shape[0])[items])
        for r in range(size):
            table[rows, (first + r) * LANES + lane] = values[:, r]

    def describe(self) -> str:
        lines = [f"{self.name}: one item per {self.item}, {self.rows} rows x {LANES} lanes"]
        for name, (first, size, kind, doc) in self.fields.items():
            lines.append(f"  {name:28s} rows {first:3d}-{first + size - 1:3d} ({kind}): {doc}")
        return "\n".join(lines)


# ----------------------------------------------------------------------------- lane access
@kernel
def get1(a, i, col, l):
    """Value of lane ``l`` of item ``i`` in the field starting at column ``col``."""
    return a[i, col + l]


@kernel
def put1(a, i, col, l, x):
    a[i, col + l] = x


@kernel
def get3(a, i, col, l):
    """3-vector of lane ``l`` of item ``i`` (rows col/LANES .. +2)."""
    return (a[i, col + l], a[i, col + LANES + l], a[i, col + 2 * LANES + l])


@kernel
def put3(a, i, col, l, v):
    a[i, col + l] = v[0]
    a[i, col + LANES + l] = v[1]
    a[i, col + 2 * LANES + l] = v[2]


@kernel
def get4(a, i, col, l):
    """Quaternion (x, y, z, w) of lane ``l`` of item ``i``."""
    return (a[i, col + l], a[i, col + LANES + l], a[i, col + 2 * LANES + l], a[i, col + 3 * LANES + l])


@kernel
def put4(a, i, col, l, q):
    a[i, col + l] = q[0]
    a[i, col + LANES + l] = q[1]
    a[i, col + 2 * LANES + l] = q[2]
    a[i, col + 3 * LANES + l] = q[3]
