"""Borrowed kernel tables: the solver's tables without reference counting inside a frame call.

The frame kernel receives each table (model, particles, parameters, ...) as a numba StructRef
(``frame.as_kernel_table``). numba reference-counts a StructRef and every array read from it:
each stage call increfs/decrefs its table arguments at entry and exit, and each field read
(``ps.next_pos``) increfs/decrefs the array. These are atomic (``lock``-prefixed)
read-modify-writes on a few shared counters: ~15 % of the serial crowd frame in ``perf``
(NRT_incref/NRT_decref on top), and with the parallel kernel both threads hammer the same
cache lines, which made ``parallel=True`` ~3x *slower* than serial.

``borrow(table)`` reinterprets a table as a ``BorrowedTableType``: the same payload (same
fields, same layout, same pointer) whose data model declares no reference-counted member,
so passing it to stage functions costs nothing, and whose field reads hand out arrays with a
null meminfo (as numba does for global constant arrays: ``NRT_incref(NULL)`` returns at once).
This is safe because the frame kernel's own arguments keep every table and array alive for
the whole call, and the kernels only index these arrays (never return or store them).
Nothing in the arithmetic changes: the results are bit-identical.
"""
from __future__ import annotations

from numba.core import cgutils, imputils, types
from numba.core.datamodel import default_manager, models
from numba.core.extending import intrinsic
from numba.core.imputils import lower_getattr_generic
from numba.core.typing.templates import AttributeTemplate, infer_getattr
from numba.experimental import structref


class BorrowedTableType(types.StructRef):
    """A solver table borrowed for the duration of a kernel call (see the module docstring)."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class _BorrowedTableModel(models.StructRefModel):
    """The StructRef layout (one meminfo pointer) with no member NRT needs to count."""

    def traverse(self, builder):
        return []

    def traverse_types(self):
        return [self._fe_type]

    def inner_models(self):
        return []


default_manager.register(BorrowedTableType, _BorrowedTableModel)


@infer_getattr
class _BorrowedTableAttribute(AttributeTemplate):
    key = BorrowedTableType

    def generic_resolve(self, typ, attr):
        if attr in typ.field_dict:
            return typ.field_dict[attr]


@lower_getattr_generic(BorrowedTableType)
def _borrowed_getattr(context, builder, typ, val, attr):
    dataval = structref._Utils(context, builder, typ).get_data_struct(val)
    value = getattr(dataval, attr)
    fieldtype = typ.field_dict[attr]
    if isinstance(fieldtype, types.Array):
        array = context.make_array(fieldtype)(context, builder, value=value)
        array.meminfo = cgutils.get_null_value(array.meminfo.type)
        value = array._getvalue()
    return imputils.impl_ret_borrowed(context, builder, fieldtype, value)


@intrinsic
def borrow(typingctx, table):
    """The ``BorrowedTableType`` view of a StructRef table (same pointer, no reference)."""
    if not isinstance(table, types.StructRef):
        return None
    borrowed = BorrowedTableType(list(table.field_dict.items()))

    def codegen(context, builder, signature, args):
        return args[0]

    return borrowed(table), codegen
