"""Lane streams: loads and stores of the block stages tagged with scoped alias metadata.

A block stage's lane loop (``for i in range(width)``) reads and writes rows ``k0 + i`` of
several (components, rows) arrays, at row offsets LLVM cannot relate (the child's and the
parent's rows of one array, say). Left alone, its vectoriser emits a runtime overlap check
for every pair of a written and another accessed stream (hundreds of compares for the angle
entry) at *every* entry of the loop, which runs only ``width`` (~50) lanes: the checks cost
about as much as the maths.

What is true of one execution of such a loop is stated instead:
- ``READ``-scope accesses (arrays the loop does not write, and written arrays at rows it
  does not write) never touch a written stream;
- each written stream (one array component at one row offset, scopes 1..STREAMS) is
  disjoint from every other stream in every lane (rows of distinct particles differ by
  multiples of the width, components by the array's row count).
``open_streams()`` at the start of each execution opens new instances of the scopes
(llvm.experimental.noalias.scope.decl), so nothing is claimed across executions, whose roles
differ (a child's row is its own child's parent row). Only the memory model changes, never
the arithmetic: results keep their bits.

The caller owns the claim: every written stream of a loop gets its own scope (a literal
int; a 3-vector takes ``scope .. scope + 2``, a quaternion ``scope .. scope + 3``), every
load of a written stream uses that stream's scope, and any other load uses ``READ``.
"""
from __future__ import annotations

from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

READ = 0
STREAMS = 40
_DOMAIN = "magica_py.lane_streams"


def _scope_node(module, i):
    domain = module.add_metadata([ir.MetaDataString(module, _DOMAIN)])
    return module.add_metadata([ir.MetaDataString(module, f"{_DOMAIN}.{i}"), domain])


def _tag(module, instruction, scope):
    if not 0 <= scope <= STREAMS:
        raise ValueError(f"lane stream scope {scope} outside 0..{STREAMS}")
    instruction.set_metadata("alias.scope", module.add_metadata([_scope_node(module, scope)]))
    others = [_scope_node(module, i) for i in range(STREAMS + 1) if i != scope]
    instruction.set_metadata("noalias", module.add_metadata(others))


def _pointer(context, builder, array_type, array, indices):
    ary = context.make_array(array_type)(context, builder, array)
    shape = cgutils.unpack_tuple(builder, ary.shape, array_type.ndim)
    strides = cgutils.unpack_tuple(builder, ary.strides, array_type.ndim)
    return cgutils.get_item_pointer2(context, builder, ary.data, shape, strides, array_type.layout, indices)


def _row_index(context, builder, index_type, index):
    return context.cast(builder, index, index_type, types.intp)


def _component_scope(scope, c):
    return scope if scope == READ else scope + c


def _literal_scope(scope):
    return isinstance(scope, types.IntegerLiteral)


@intrinsic
def sload(typingctx, array, row, scope):
    """``array[row]`` (1-D) in stream ``scope``."""
    if not (isinstance(array, types.Array) and array.ndim == 1 and _literal_scope(scope)):
        return None
    tag = scope.literal_value

    def codegen(context, builder, sig, args):
        pointer = _pointer(context, builder, sig.args[0], args[0], [_row_index(context, builder, sig.args[1], args[1])])
        value = builder.load(pointer)
        _tag(builder.module, value, tag)
        return value

    return array.dtype(array, row, scope), codegen


@intrinsic
def sstore(typingctx, array, row, value, scope):
    """``array[row] = value`` (1-D) in stream ``scope``."""
    if not (isinstance(array, types.Array) and array.ndim == 1 and _literal_scope(scope)):
        return None
    tag = scope.literal_value

    def codegen(context, builder, sig, args):
        pointer = _pointer(context, builder, sig.args[0], args[0], [_row_index(context, builder, sig.args[1], args[1])])
        _tag(builder.module, builder.store(context.cast(builder, args[2], sig.args[2], sig.args[0].dtype), pointer), tag)
        return context.get_dummy_value()

    return types.none(array, row, value, scope), codegen


def _load_n(n):
    def typer(typingctx, array, row, scope):
        if not (isinstance(array, types.Array) and array.ndim == 2 and _literal_scope(scope)):
            return None
        tag = scope.literal_value
        row_type = types.UniTuple(array.dtype, n)

        def codegen(context, builder, sig, args):
            k = _row_index(context, builder, sig.args[1], args[1])
            values = []
            for c in range(n):
                pointer = _pointer(context, builder, sig.args[0], args[0], [context.get_constant(types.intp, c), k])
                value = builder.load(pointer)
                _tag(builder.module, value, _component_scope(tag, c))
                values.append(value)
            return context.make_tuple(builder, row_type, values)

        return row_type(array, row, scope), codegen

    typer.__name__ = f"sload{n}"
    typer.__doc__ = (f"``(array[0, row], .., array[{n - 1}, row])`` (a (components, rows) block array) in streams "
                     f"``scope + c`` (all ``READ`` when ``scope`` is READ).")
    return intrinsic(typer)


def _store_n(n):
    def typer(typingctx, array, row, value, scope):
        if not (isinstance(array, types.Array) and array.ndim == 2 and isinstance(value, types.BaseTuple)
                and len(value) == n and _literal_scope(scope)):
            return None
        tag = scope.literal_value
        if tag == READ:
            raise ValueError("a store cannot be in the READ stream")

        def codegen(context, builder, sig, args):
            k = _row_index(context, builder, sig.args[1], args[1])
            for c in range(n):
                pointer = _pointer(context, builder, sig.args[0], args[0], [context.get_constant(types.intp, c), k])
                v = context.cast(builder, builder.extract_value(args[2], c), sig.args[2][c], sig.args[0].dtype)
                _tag(builder.module, builder.store(v, pointer), tag + c)
            return context.get_dummy_value()

        return types.none(array, row, value, scope), codegen

    typer.__name__ = f"sstore{n}"
    typer.__doc__ = f"``array[:{n}, row] = value`` in streams ``scope + c``."
    return intrinsic(typer)


sload3 = _load_n(3)
sload4 = _load_n(4)
sstore3 = _store_n(3)
sstore4 = _store_n(4)


@intrinsic
def open_streams(typingctx):
    """New instances of every stream scope: the claims of one loop execution start here."""
    def codegen(context, builder, sig, args):
        module = builder.module
        fn = cgutils.get_or_insert_function(module, ir.FunctionType(ir.VoidType(), [ir.MetaDataType()]),
                                            "llvm.experimental.noalias.scope.decl")
        for i in range(STREAMS + 1):
            builder.call(fn, [module.add_metadata([_scope_node(module, i)])])
        return context.get_dummy_value()

    return types.none(), codegen
