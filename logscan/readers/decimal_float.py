"""Decimal text -> float64 in numba, correctly rounded or declined: Clinger's exact fast path, and
the Eisel-Lemire algorithm (as in Go's strconv and fast_float) for the mantissas it cannot take.

`decimal_number` reads one JSON number (``-?(0|[1-9][0-9]*)(\\.[0-9]+)?([eE][+-]?[0-9]+)?``) from
a byte buffer as the significant digits w (at most 19, so w < 2**64) and a power of ten e; eight
digits at a time where eight are there (one unaligned 64-bit load, checked and combined in
registers, as fast_float does). Then:

 - w <= 2**53 and |e| <= 22: w and 10**|e| are exact doubles, so the one IEEE product or quotient
   is the correctly rounded value (Clinger's fast path);
 - otherwise Eisel-Lemire: w normalised to 64 bits times a 128-bit truncated mantissa of 10**e;
   when the product leaves no doubt about the rounding the float64 is built from it, else (a
   near-halfway case, a subnormal or overflowing result) the kernel declines.

Where it gives a value it equals ``float(token)``: this covers the short decimals loggers write
and the 17-digit ``repr`` floats of Python's ``json``. Declined tokens (more than 19 significant
digits, an undecided rounding, NaN, Infinity, anything not JSON number syntax) are the caller's to
parse with a full parser.

The 64x64 -> 128-bit product, the leading-zero count, the bit cast and the unaligned load are LLVM
instructions (numba ``intrinsic``s): emulated with 32-bit halves they were half of the time.
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir  # type: ignore[import-untyped]
from numba import njit, types
from numba.extending import intrinsic

MAX_EXP10 = 340
MAX_DIGITS = 19  # 10**19 - 1 < 2**64: the mantissa of 19 digits never overflows
_CLINGER_W = np.uint64(2**53)


def _powers_of_ten() -> tuple[np.ndarray, np.ndarray]:
    """(high, low) 64-bit halves of 10**e scaled into [2**127, 2**128), truncated, e = -MAX..MAX."""
    hi, lo = [], []
    for e in range(-MAX_EXP10, MAX_EXP10 + 1):
        if e >= 0:
            v = 10**e
            bits = v.bit_length()
            m = v << (128 - bits) if bits <= 128 else v >> (bits - 128)
        else:
            d = 10**-e
            m = (1 << (127 + d.bit_length())) // d
        hi.append(m >> 64)
        lo.append(m & ((1 << 64) - 1))
    return np.array(hi, dtype=np.uint64), np.array(lo, dtype=np.uint64)


POW10_HI, POW10_LO = _powers_of_ten()
POW10 = np.array([10.0**k for k in range(23)], dtype=np.float64)  # 10**0 .. 10**22: all exact doubles


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
def float_of_bits(typingctx, a):  # pragma: no cover - compiled
    """The float64 whose IEEE bits are the uint64 ``a``."""
    signature = types.float64(types.uint64)

    def codegen(context, builder, sig, args):
        return builder.bitcast(args[0], ir.DoubleType())

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


_M9 = np.uint64(0x1FF)
_ONE = np.uint64(1)
_ZEROS8 = np.uint64(0x3030303030303030)  # eight ASCII '0'
_HIGH_NIBBLES = np.uint64(0xF0F0F0F0F0F0F0F0)
_PLUS6 = np.uint64(0x0606060606060606)
_THREES = np.uint64(0x3333333333333333)
_BYTES_0_4 = np.uint64(0x000000FF000000FF)
_MUL_100_1E6 = np.uint64(100 + (1000000 << 32))
_MUL_1_1E4 = np.uint64(1 + (10000 << 32))


@njit(cache=True, inline="always")
def _eight_digits(v):  # pragma: no cover - numba kernel
    """Whether the 8 bytes of ``v`` are all ASCII digits."""
    return ((v & _HIGH_NIBBLES) | (((v + _PLUS6) & _HIGH_NIBBLES) >> np.uint64(4))) == _THREES


@njit(cache=True, inline="always")
def _value_of_eight(v):  # pragma: no cover - numba kernel
    """The number the 8 ASCII digits of ``v`` spell (first byte most significant)."""
    v = v - _ZEROS8
    v = v * np.uint64(10) + (v >> np.uint64(8))
    low = (v & _BYTES_0_4) * _MUL_100_1E6
    high = ((v >> np.uint64(16)) & _BYTES_0_4) * _MUL_1_1E4
    return (low + high) >> np.uint64(32)


@njit(cache=True)
def eisel_lemire(w, e10):  # pragma: no cover - numba kernel
    """(w * 10**e10 as the correctly rounded float64, True), or (0.0, False) when undecided; w > 0."""
    if e10 < -MAX_EXP10 or e10 > MAX_EXP10:
        return 0.0, False
    man = np.uint64(w)
    clz = leading_zeros(man)
    man = man << np.uint64(clz)
    exp2 = ((217706 * e10) >> 16) + 64 + 1023 - clz
    k = e10 + MAX_EXP10
    x_hi, x_lo = mul_128(man, POW10_HI[k])
    if x_hi & _M9 == _M9 and x_lo + man < man:  # the wider approximation
        y_hi, y_lo = mul_128(man, POW10_LO[k])
        m_hi = x_hi
        m_lo = x_lo + y_hi
        if m_lo < x_lo:
            m_hi += _ONE
        if m_hi & _M9 == _M9 and m_lo + _ONE == np.uint64(0) and y_lo + man < man:
            return 0.0, False
        x_hi = m_hi
        x_lo = m_lo
    msb = x_hi >> np.uint64(63)
    mantissa = x_hi >> (msb + np.uint64(9))
    exp2 -= 1 - int(msb)
    if x_lo == np.uint64(0) and x_hi & _M9 == np.uint64(0) and mantissa & np.uint64(3) == _ONE:
        return 0.0, False  # halfway between two floats: undecided here
    mantissa += mantissa & _ONE
    mantissa = mantissa >> _ONE
    if mantissa >> np.uint64(53) > np.uint64(0):
        mantissa = mantissa >> _ONE
        exp2 += 1
    if exp2 <= 0 or exp2 >= 0x7FF:  # subnormal, or beyond float64
        return 0.0, False
    # exp2 is the biased exponent; the mantissa's bit 52 is the implicit one
    return float_of_bits((mantissa & np.uint64((1 << 52) - 1)) | (np.uint64(exp2) << np.uint64(52))), True


@njit(cache=True, inline="always")
def _digits(buf, i, end, w):  # pragma: no cover - numba kernel
    """Accumulate the decimal digits from buf[i] into w, eight at a time where eight are there:
    (w, where the digits stop)."""
    while i + 8 <= end:
        v = load_u64(buf, i)
        if not _eight_digits(v):
            break
        w = w * np.uint64(100000000) + _value_of_eight(v)
        i += 8
    while i < end and 48 <= buf[i] <= 57:
        w = w * np.uint64(10) + np.uint64(buf[i] - 48)
        i += 1
    return w, i


@njit(cache=True, inline="always")
def _exponent(buf, i, end):  # pragma: no cover - numba kernel
    """The exponent part at buf[i] ('e'/'E', optional sign, digits): (exponent, where it stops,
    False when the syntax is wrong). No 'e': (0, i, True). Huge exponents saturate at 10**4."""
    if i >= end or (buf[i] != 101 and buf[i] != 69):
        return 0, i, True
    i += 1
    negative = False
    if i < end and (buf[i] == 43 or buf[i] == 45):
        negative = buf[i] == 45
        i += 1
    if i >= end or buf[i] < 48 or buf[i] > 57:
        return 0, i, False
    exponent = 0
    while i < end and 48 <= buf[i] <= 57:
        if exponent < 10000:
            exponent = exponent * 10 + (buf[i] - 48)
        i += 1
    return (-exponent if negative else exponent), i, True


@njit(cache=True)
def decimal_number(buf, start, end):  # pragma: no cover - numba kernel
    """The JSON number at buf[start:...] (uint8 array, not past ``end``): (value, True, where it
    stops) when `decimal_number` rules give it exactly, else (nan, False, where reading stopped).
    The caller checks that the token ends where the number stops."""
    i = start
    negative = i < end and buf[i] == 45  # '-'
    if negative:
        i += 1
    if i >= end or buf[i] < 48 or buf[i] > 57:
        return np.nan, False, i
    w = np.uint64(0)
    digits = 0
    e = 0
    if buf[i] == 48:  # a leading 0 stands alone
        i += 1
        if i < end and 48 <= buf[i] <= 57:
            return np.nan, False, i
    else:
        first = i
        w, i = _digits(buf, i, end, w)
        digits = i - first
    if i < end and buf[i] == 46:  # '.' then at least one digit
        i += 1
        point = i
        if digits == 0:  # 0.000ddd: the zeros after the point are not significant
            while i < end and buf[i] == 48:
                i += 1
        first = i
        w, i = _digits(buf, i, end, w)
        if i == point:
            return np.nan, False, i
        digits += i - first
        e = point - i
    exponent, i, fine = _exponent(buf, i, end)
    if not fine or digits > MAX_DIGITS:
        return np.nan, False, i
    e += exponent
    if w == np.uint64(0):
        value = 0.0
    elif w <= _CLINGER_W and 0 <= e <= 22:
        value = np.float64(w) * POW10[e]  # x = w * 10**e, one rounding
    elif w <= _CLINGER_W and -22 <= e < 0:
        value = np.float64(w) / POW10[-e]  # x = w / 10**-e, one rounding
    else:
        value, exact = eisel_lemire(w, e)
        if not exact:
            return np.nan, False, i
    return (-value if negative else value), True, i
