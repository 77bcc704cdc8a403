"""Single machine instructions numba does not spell, as LLVM intrinsics for the readers' kernels:
the 64x64 -> 128-bit product, leading / trailing zero and set-bit counts, a bit cast, the
unaligned 8-byte load that lets a kernel look at eight text bytes at once, a byte read without
numba's negative-index test, and an array view without a reference count."""

from __future__ import annotations

from llvmlite import ir  # type: ignore[import-untyped]
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic


@intrinsic
def mul_128(typingctx, a, b):  # pragma: no cover - compiled
    """(high, low) 64-bit halves of the 128-bit product of two uint64."""
    signature = types.UniTuple(types.uint64, 2)(types.uint64, types.uint64)

    def codegen(context, builder, sig, args):
        wide = ir.IntType(128)
        product = builder.mul(builder.zext(args[0], wide), builder.zext(args[1], wide))
        high = builder.trunc(builder.lshr(product, ir.Constant(wide, 64)), ir.IntType(64))
        low = builder.trunc(product, ir.IntType(64))
        return context.make_tuple(builder, sig.return_type, (high, low))

    return signature, codegen


@intrinsic
def leading_zeros(typingctx, a):  # pragma: no cover - compiled
    """Leading zero bits of a uint64 (64 for 0)."""
    signature = types.int64(types.uint64)

    def codegen(context, builder, sig, args):
        return builder.ctlz(args[0], ir.Constant(ir.IntType(1), 0))

    return signature, codegen


@intrinsic
def trailing_zeros(typingctx, a):  # pragma: no cover - compiled
    """Trailing zero bits of a uint64 (64 for 0)."""
    signature = types.int64(types.uint64)

    def codegen(context, builder, sig, args):
        return builder.cttz(args[0], ir.Constant(ir.IntType(1), 0))

    return signature, codegen


@intrinsic
def float_of_bits(typingctx, a):  # pragma: no cover - compiled
    """The float whose IEEE bits are ``a``: a float32 for a uint32, else a float64 (``a`` as a uint64)."""
    single = isinstance(a, types.Integer) and a.bitwidth == 32 and not a.signed
    signature = types.float32(types.uint32) if single else types.float64(types.uint64)

    def codegen(context, builder, sig, args):
        return builder.bitcast(args[0], ir.FloatType() if single else ir.DoubleType())

    return signature, codegen


@intrinsic
def load_u64(typingctx, buf, index):  # pragma: no cover - compiled
    """The 8 bytes buf[index:index + 8] of a uint8 array as one little-endian uint64 (any alignment;
    the caller checks that they are inside the array)."""
    signature = types.uint64(buf, types.int64)

    def codegen(context, builder, sig, args):
        array = context.make_array(sig.args[0])(context, builder, args[0])
        pointer = builder.bitcast(builder.gep(array.data, [args[1]]), ir.IntType(64).as_pointer())
        return builder.load(pointer, align=1)

    return signature, codegen


@intrinsic
def set_bits(typingctx, a):  # pragma: no cover - compiled
    """Set bits of a uint64."""
    signature = types.int64(types.uint64)

    def codegen(context, builder, sig, args):
        return builder.ctpop(args[0])

    return signature, codegen


@intrinsic
def byte_at(typingctx, buf, index):  # pragma: no cover - compiled
    """buf[index] of a uint8 array, 0 <= index < buf.size (the caller checks): numba's indexing with
    a signed index adds a test for a negative one at every byte, 8 % of a CSV parse."""
    signature = types.uint8(buf, types.int64)

    def codegen(context, builder, sig, args):
        array = context.make_array(sig.args[0])(context, builder, args[0])
        return builder.load(builder.gep(array.data, [args[1]]))

    return signature, codegen


@intrinsic
def uncounted(typingctx, array):  # pragma: no cover - compiled
    """The array without its reference count (no meminfo, no parent), for a kernel that holds the
    array itself for the whole call: numba increfs and decrefs an array at each inlined helper it
    is passed to (`scan_number` per cell), atomic operations that were a third of the parse; on
    this view they are no-ops LLVM removes."""

    def codegen(context, builder, sig, args):
        view = context.make_array(sig.args[0])(context, builder, value=args[0])
        view.meminfo = cgutils.get_null_value(view.meminfo.type)
        view.parent = cgutils.get_null_value(view.parent.type)
        return view._getvalue()

    return array(array), codegen
