"""Row access for loops that LLVM should vectorise over a team's particles (the per-frame
stages): ``flat`` 1-D views, unsigned row loads and stores, and loads/stores tagged with
scoped alias metadata for loops that read through an index array.

Values and arithmetic are unchanged (bits identical); only how memory is described to LLVM.
(The block stages' per-pair scopes of ``solver/constraints/bending.py`` are a different use:
in-place accumulators.)
"""
from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

from magica_py.jit import kernel


# ----------------------------------------------------------------------------- vectorised loops
# The per-frame stages loop over a team's particles with no dependency between them; LLVM
# vectorises such a loop only if it can prove (or check at run time) that its stores do not
# overwrite what it reads. An affine row access (``flat[3 p + c]``) can be checked; a gather
# through an index array (``local_to_world[transform_index[p]]``) cannot ("cannot identify
# array bounds"), and one such access makes every access of its alias set unanalysable. A loop
# whose loads all go through ``load_input(a, i, scope)`` and whose stores all go through
# ``store_output3/4(a, i, row, scope)`` tells LLVM (scoped alias metadata) that, for that scope,
# no store ever writes memory that a load reads. Use it only when that is true for *every*
# execution of the scope in a compiled function: a loop that reads back what it writes
# (in-place update) must not use these. Values and arithmetic are unchanged (bits identical).
def _scope_list(module, name):
    domain = module.add_metadata([ir.MetaDataString(module, "magica_py.frame_stage")])
    scope = module.add_metadata([ir.MetaDataString(module, "magica_py.frame_stage." + name), domain])
    return module.add_metadata([scope])


def _flat_pointer(context, builder, array_type, array, index_type, index):
    data = context.make_array(array_type)(context, builder, array).data
    i = context.cast(builder, index, index_type, types.uint64)
    return builder.gep(data, [i], inbounds=True)


@intrinsic
def load_input(typingctx, array, index, scope):
    """``array[index]`` (1-D C array, unsigned index) read as an input of loop ``scope``."""
    if not (isinstance(array, types.Array) and array.ndim == 1 and isinstance(index, types.Integer)
            and isinstance(scope, types.StringLiteral)):
        return None
    name = scope.literal_value

    def codegen(context, builder, sig, args):
        value = builder.load(_flat_pointer(context, builder, sig.args[0], args[0], sig.args[1], args[1]))
        value.set_metadata("alias.scope", _scope_list(builder.module, name))
        return value

    return array.dtype(array, index, scope), codegen


def _row_intrinsic(n):
    def typer(typingctx, array, index, scope):
        if not (isinstance(array, types.Array) and array.ndim == 1 and isinstance(index, types.Integer)
                and isinstance(scope, types.StringLiteral)):
            return None
        name = scope.literal_value
        row_type = types.UniTuple(array.dtype, n)

        def codegen(context, builder, sig, args):
            data = context.make_array(sig.args[0])(context, builder, args[0]).data
            base = context.cast(builder, args[1], sig.args[1], types.uint64)
            row = builder.gep(data, [base], inbounds=True)
            values = []
            for c in range(n):   # constant offsets from one row pointer: provably distinct
                value = builder.load(builder.gep(row, [ir.Constant(base.type, c)], inbounds=True))
                value.set_metadata("alias.scope", _scope_list(builder.module, name))
                values.append(value)
            return context.make_tuple(builder, row_type, values)

        return row_type(array, index, scope), codegen

    typer.__name__ = f"load_input{n}"
    typer.__doc__ = f"``array[index : index + {n}]`` as a tuple, read as inputs of loop ``scope``."
    return intrinsic(typer)


load_input3 = _row_intrinsic(3)
load_input4 = _row_intrinsic(4)


def _row_store_intrinsic(n):
    def typer(typingctx, array, index, row, scope):
        if not (isinstance(array, types.Array) and array.ndim == 1 and isinstance(index, types.Integer)
                and isinstance(row, types.BaseTuple) and len(row) == n and isinstance(scope, types.StringLiteral)):
            return None
        name = scope.literal_value

        def codegen(context, builder, sig, args):
            data = context.make_array(sig.args[0])(context, builder, args[0]).data
            base = context.cast(builder, args[1], sig.args[1], types.uint64)
            row = builder.gep(data, [base], inbounds=True)
            for c in range(n):
                value = context.cast(builder, builder.extract_value(args[2], c), sig.args[2][c], sig.args[0].dtype)
                store = builder.store(value, builder.gep(row, [ir.Constant(base.type, c)], inbounds=True))
                store.set_metadata("noalias", _scope_list(builder.module, name))
            return context.get_dummy_value()

        return types.none(array, index, row, scope), codegen

    typer.__name__ = f"store_output{n}"
    typer.__doc__ = f"``array[index : index + {n}] = row`` as outputs of loop ``scope``."
    return intrinsic(typer)


store_output3 = _row_store_intrinsic(3)
store_output4 = _row_store_intrinsic(4)


@intrinsic
def flat(typingctx, a):
    """A C-contiguous array as a 1-D view: row p of an (n, k) array is ``[k p, k p + k)``
    with k a compile-time constant, so LLVM sees a loop's rows as strided accesses. (numba's
    ``reshape`` calls a C helper, ~20 ns per array per stage call.)"""
    if not (isinstance(a, types.Array) and a.layout == "C"):
        return None
    flat_type = types.Array(a.dtype, 1, "C")

    def codegen(context, builder, sig, args):
        src = context.make_array(sig.args[0])(context, builder, args[0])
        size = context.get_constant(types.intp, 1)
        for dim in cgutils.unpack_tuple(builder, src.shape, sig.args[0].ndim):
            size = builder.mul(size, dim)
        out = context.make_array(flat_type)(context, builder)
        itemsize = context.get_constant(types.intp, context.get_abi_sizeof(context.get_data_type(a.dtype)))
        context.populate_array(out, data=src.data, shape=cgutils.pack_array(builder, [size]),
                               strides=cgutils.pack_array(builder, [itemsize]), itemsize=src.itemsize,
                               meminfo=src.meminfo, parent=src.parent)
        result = out._getvalue()
        if context.enable_nrt:
            context.nrt.incref(builder, flat_type, result)
        return result

    return flat_type(a), codegen


@kernel
def row3(a, i):
    """``a[i : i + 3]`` of a flat view as a tuple (unsigned i: no wraparound select)."""
    return (a[i], a[i + np.uint64(1)], a[i + np.uint64(2)])


@kernel
def row4(a, i):
    return (a[i], a[i + np.uint64(1)], a[i + np.uint64(2)], a[i + np.uint64(3)])


@kernel
def set_row3(a, i, v):
    a[i] = v[0]
    a[i + np.uint64(1)] = v[1]
    a[i + np.uint64(2)] = v[2]


@kernel
def set_row4(a, i, q):
    a[i] = q[0]
    a[i + np.uint64(1)] = q[1]
    a[i + np.uint64(2)] = q[2]
    a[i + np.uint64(3)] = q[3]


# branch-free twins of math3d helpers (both sides computed, then selected: same bits)
