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

The 64x64 -> 128-bit product, the zero counts, the bit cast and the unaligned load are single LLVM
instructions (`bits`): emulated with 32-bit halves the product was half of Eisel-Lemire's time.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from logscan.numba_cache import follow_dependencies
from logscan.readers.bits import byte_at, float_of_bits, leading_zeros, load_u64, mul_128, trailing_zeros

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


_M9 = np.uint64(0x1FF)
_ZERO = np.uint64(0)
_ONE = np.uint64(1)
_THREE = np.uint64(3)
_TEN = np.uint64(10)
_HUNDRED_MILLION = np.uint64(100000000)
_S8, _S9, _S16, _S32, _S52, _S63 = (np.uint64(k) for k in (8, 9, 16, 32, 52, 63))  # shift counts
_MANTISSA_BITS = np.uint64((1 << 52) - 1)
_ZEROS8 = np.uint64(0x3030303030303030)  # eight ASCII '0'
_BYTES_0_4 = np.uint64(0x000000FF000000FF)
_MUL_100_1E6 = np.uint64(100 + (1000000 << 32))
_MUL_1_1E4 = np.uint64(1 + (10000 << 32))
_PLUS118 = np.uint64(0x7676767676767676)  # 0x76 + 10 = 0x80: the top bit of a byte over 9
_BYTE_TOPS = np.uint64(0x8080808080808080)
_POW10_INT = np.array([10**k for k in range(20)], dtype=np.uint64)
# n < 8 digits in the low bytes of a load: shifted to the top by _DIGITS_UP[n] bits, '0's below them
_DIGITS_UP = np.array([64 - 8 * n for n in range(8)], dtype=np.uint64)
_ZEROS_BELOW = np.array([0x3030303030303030 >> (8 * n) if n else 0 for n in range(8)], dtype=np.uint64)
IS_DIGIT = np.zeros(256, dtype=np.bool_)
IS_DIGIT[48:58] = True
_E, _PLUS, _MINUS, _POINT, _ZERO_CHAR = (ord(c) for c in "e+-.0")  # b | 32 == _E: "e" or "E"


@njit(cache=True, inline="always")
def _value_of_eight(v):  # pragma: no cover - numba kernel
    """The number the 8 ASCII digits of ``v`` spell (first byte most significant)."""
    v = v - _ZEROS8
    v = v * _TEN + (v >> _S8)
    low = (v & _BYTES_0_4) * _MUL_100_1E6
    high = ((v >> _S16) & _BYTES_0_4) * _MUL_1_1E4
    return (low + high) >> _S32


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
        if m_hi & _M9 == _M9 and m_lo + _ONE == _ZERO and y_lo + man < man:
            return 0.0, False
        x_hi = m_hi
        x_lo = m_lo
    msb = x_hi >> _S63
    mantissa = x_hi >> (msb + _S9)
    exp2 -= 1 - int(msb)
    if x_lo == _ZERO and x_hi & _M9 == _ZERO and mantissa & _THREE == _ONE:
        return 0.0, False  # halfway between two floats: undecided here
    mantissa += mantissa & _ONE
    mantissa = mantissa >> _ONE
    if mantissa >> np.uint64(53) > _ZERO:
        mantissa = mantissa >> _ONE
        exp2 += 1
    if exp2 <= 0 or exp2 >= 0x7FF:  # subnormal, or beyond float64
        return 0.0, False
    # exp2 is the biased exponent; the mantissa's bit 52 is the implicit one
    return float_of_bits((mantissa & _MANTISSA_BITS) | (np.uint64(exp2) << _S52)), True


@njit(cache=True, inline="always")
def _digits(buf, i, end, w):  # pragma: no cover - numba kernel
    """Accumulate the decimal digits from buf[i] into w: (w, where the digits stop). Eight bytes
    are loaded at a time: all digits are combined at once, and so are the n < 8 digits before the
    first non-digit (shifted to the top, '0's below them). Byte-wise in the last 7 bytes of buf."""
    while i + 8 <= end:
        v = load_u64(buf, i)
        x = v ^ _ZEROS8  # a digit byte becomes 0..9
        non_digits = ((x + _PLUS118) | x) & _BYTE_TOPS  # top bit of each byte > 9 (exact up to the first)
        if non_digits == _ZERO:
            w = w * _HUNDRED_MILLION + _value_of_eight(v)
            i += 8
            continue
        n = trailing_zeros(non_digits) >> 3  # digits before the first non-digit
        if n:
            w = w * _POW10_INT[n] + _value_of_eight((v << _DIGITS_UP[n]) | _ZEROS_BELOW[n])
            i += n
        return w, i
    while i < end and IS_DIGIT[byte_at(buf, i)]:
        w = w * _TEN + np.uint64(byte_at(buf, i) - _ZERO_CHAR)
        i += 1
    return w, i


@njit(cache=True, inline="always")
def _exponent(buf, i, end):  # pragma: no cover - numba kernel
    """The exponent part at buf[i] ('e'/'E', optional sign, digits): (exponent, where it stops,
    False when the syntax is wrong). No 'e': (0, i, True). Huge exponents saturate at 10**4."""
    if i >= end or (byte_at(buf, i) | 32) != _E:
        return 0, i, True
    i += 1
    negative = False
    if i < end and (byte_at(buf, i) == _PLUS or byte_at(buf, i) == _MINUS):
        negative = byte_at(buf, i) == _MINUS
        i += 1
    if i >= end or not IS_DIGIT[byte_at(buf, i)]:
        return 0, i, False
    exponent = 0
    while i < end and IS_DIGIT[byte_at(buf, i)]:
        if exponent < 10000:
            exponent = exponent * 10 + (byte_at(buf, i) - _ZERO_CHAR)
        i += 1
    return (-exponent if negative else exponent), i, True


@njit(cache=True, inline="always")
def scan_number(buf, start, end):  # pragma: no cover - numba kernel
    """Read the JSON number at buf[start:...] (uint8 array, not past ``end``) as sign, significant
    digits w and power of ten e: (negative, w, e, digits, integer, where it stops, fine). ``integer``:
    no fraction and no exponent; ``digits``: significant digits (over `MAX_DIGITS`: w is wrong);
    ``fine`` False when the text is not JSON number syntax (then it stops where that showed)."""
    i = start
    negative = i < end and byte_at(buf, i) == _MINUS
    if negative:
        i += 1
    w = _ZERO
    if i >= end or not IS_DIGIT[byte_at(buf, i)]:
        return negative, w, 0, 0, False, i, False
    digits = 0
    e = 0
    if byte_at(buf, i) == _ZERO_CHAR:  # a leading 0 stands alone
        i += 1
        if i < end and IS_DIGIT[byte_at(buf, i)]:
            return negative, w, 0, 0, False, i, False
    else:
        first = i
        w, i = _digits(buf, i, end, w)
        digits = i - first
    integer = True
    if i < end and byte_at(buf, i) == _POINT:  # '.' then at least one digit
        integer = False
        i += 1
        point = i
        if digits == 0:  # 0.000ddd: the zeros after the point are not significant
            while i < end and byte_at(buf, i) == _ZERO_CHAR:
                i += 1
        first = i
        w, i = _digits(buf, i, end, w)
        if i == point:
            return negative, w, 0, 0, False, i, False
        digits += i - first
        e = point - i
    if i < end and (byte_at(buf, i) | 32) == _E:
        integer = False
        exponent, i, fine = _exponent(buf, i, end)
        if not fine:
            return negative, w, 0, 0, False, i, False
        e += exponent
    return negative, w, e, digits, integer, i, True


@njit(cache=True, inline="always")
def number_value(negative, w, e, digits):  # pragma: no cover - numba kernel
    """(the correctly rounded double of -+w * 10**e, True), or (nan, False) when declined (more
    than `MAX_DIGITS` digits, an undecided rounding, a subnormal or overflowing result)."""
    if digits > MAX_DIGITS:
        return np.nan, False
    if w == np.uint64(0):
        value = 0.0
    elif w <= _CLINGER_W and 0 <= e <= 22:
        value = np.float64(w) * POW10[e]  # x = w * 10**e, one rounding
    elif w <= _CLINGER_W and -22 <= e < 0:
        value = np.float64(w) / POW10[-e]  # x = w / 10**-e, one rounding
    else:
        value, exact = eisel_lemire(w, e)
        if not exact:
            return np.nan, False
    return (-value if negative else value), True


# `scan_number` compiled on its own and called, for the JSON kernel: inlined (into a compiled
# `decimal_number`) it was 1.2 s of that kernel's 2.1 s cold compile, as numba copies an inlined
# function's IR block by block and all its variables with each block; called with an `uncounted`
# buffer it parses as fast. The CSV kernel inlines `scan_number`: called per cell, its parse took
# a quarter longer.
scan_number_called = njit(cache=True)(scan_number.py_func)


@njit(cache=True, inline="always")
def decimal_number(buf, start, end):  # pragma: no cover - numba kernel
    """The JSON number at buf[start:...] (uint8 array, not past ``end``): (value, True, where it
    stops) when the module's rules give it exactly, else (nan, False, where reading stopped). The
    caller checks that the token ends where the number stops. Inlined; the scan is a call."""
    negative, w, e, digits, _integer, stop, fine = scan_number_called(buf, start, end)
    if not fine:
        return np.nan, False, stop
    value, exact = number_value(negative, w, e, digits)
    return value, exact, stop


follow_dependencies(__name__)  # the cached kernels are stamped with the intrinsics of `bits` too
