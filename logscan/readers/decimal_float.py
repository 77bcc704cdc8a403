"""Correctly rounded decimal -> float64 for mantissas Clinger's fast path cannot take (the
Eisel-Lemire algorithm, as in Go's strconv and fast_float), in numba.

A token w * 10**e with w < 2**63 and |e| <= ``MAX_EXP10``: w is normalised to 64 bits and
multiplied by a 128-bit truncated mantissa of 10**e; when the product leaves no doubt about the
rounding the float64 is built from it, else (a near-halfway case, a subnormal or overflowing result)
the kernel says so and the caller uses a full parser. The result equals ``float(token)`` whenever
the kernel gives one: this is the 17-digit ``repr`` float that loggers writing Python's ``json``
produce, which Clinger's path (w <= 2**53) leaves alone.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

MAX_EXP10 = 340


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

_M32 = np.uint64(0xFFFFFFFF)
_S32 = np.uint64(32)


@njit(cache=True, inline="always")
def _mul64(a, b):  # pragma: no cover - numba kernel
    """(high, low) 64-bit halves of the 128-bit product of two uint64."""
    a0 = a & _M32
    a1 = a >> _S32
    b0 = b & _M32
    b1 = b >> _S32
    w0 = a0 * b0
    t = a1 * b0 + (w0 >> _S32)
    w1 = (t & _M32) + a0 * b1
    hi = a1 * b1 + (t >> _S32) + (w1 >> _S32)
    return hi, a * b


@njit(cache=True)
def eisel_lemire(w, e10, pow_hi, pow_lo):  # pragma: no cover - numba kernel
    """(w * 10**e10 as the correctly rounded float64, True), or (0.0, False) when undecided; w > 0."""
    if e10 < -MAX_EXP10 or e10 > MAX_EXP10:
        return 0.0, False
    man = np.uint64(w)
    clz = 0
    top = np.uint64(1) << np.uint64(63)
    while man & top == np.uint64(0):
        man = man << np.uint64(1)
        clz += 1
    exp2 = ((217706 * e10) >> 16) + 64 + 1023 - clz
    k = e10 + MAX_EXP10
    x_hi, x_lo = _mul64(man, pow_hi[k])
    mask9 = np.uint64(0x1FF)
    if x_hi & mask9 == mask9 and x_lo + man < man:  # the wider approximation
        y_hi, y_lo = _mul64(man, pow_lo[k])
        m_hi = x_hi
        m_lo = x_lo + y_hi
        if m_lo < x_lo:
            m_hi += np.uint64(1)
        if m_hi & mask9 == mask9 and m_lo + np.uint64(1) == np.uint64(0) and y_lo + man < man:
            return 0.0, False
        x_hi = m_hi
        x_lo = m_lo
    msb = x_hi >> np.uint64(63)
    mantissa = x_hi >> (msb + np.uint64(9))
    exp2 -= 1 - int(msb)
    if x_lo == np.uint64(0) and x_hi & mask9 == np.uint64(0) and mantissa & np.uint64(3) == np.uint64(1):
        return 0.0, False  # halfway between two floats: undecided here
    mantissa += mantissa & np.uint64(1)
    mantissa = mantissa >> np.uint64(1)
    if mantissa >> np.uint64(53) > np.uint64(0):
        mantissa = mantissa >> np.uint64(1)
        exp2 += 1
    if exp2 <= 0 or exp2 >= 0x7FF:  # subnormal, or beyond float64
        return 0.0, False
    return math.ldexp(np.float64(mantissa), exp2 - 1075), True
