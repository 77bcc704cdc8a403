"""JSON message decoding for MCAP: the decoder factory (the mcap library has none) and a bulk path."""

from __future__ import annotations

import json
import re
import warnings
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from mcap.decoder import DecoderFactory as McapDecoderFactory
from mcap.records import Schema
from numba import njit

from logscan.numba_cache import follow_dependencies
from logscan.readers.decimal_float import POW10_HI, POW10_LO, eisel_lemire
from logscan.readers.flatten import FlatColumns, MessageBytes, add_to_groups, columns_from_groups, layout_of


class JsonDecoder:
    """Callable decoding one JSON message; ``decode_many`` parses a batch in one ``json.loads``.

    ``decode_many`` returns the decoded messages and the indices of those that failed to parse
    (their slots hold None).
    """

    def __call__(self, data: bytes) -> Any:
        return json.loads(data)

    def decode_many(self, datas: Sequence[bytes]) -> tuple[list[Any], list[int]]:
        if not datas:
            return [], []
        try:
            # One parser call for the whole batch: "[m0,m1,...]".
            decoded = json.loads(b"[" + b",".join(datas) + b"]")
            if len(decoded) == len(datas):
                return decoded, []
        except (ValueError, UnicodeDecodeError, RecursionError):
            pass
        # Some message is not JSON on its own (or joined messages re-split differently):
        # decode one by one and report the failures.
        out: list[Any] = []
        failed: list[int] = []
        for index, data in enumerate(datas):
            try:
                out.append(json.loads(data))
            except (ValueError, UnicodeDecodeError, RecursionError):
                out.append(None)
                failed.append(index)
        return out, failed


class JsonDecoderFactory(McapDecoderFactory):
    """Decodes channels whose message encoding is ``json``, whatever their schema (or none).

    Returns None for every other encoding, so it can sit in a list with the ROS and protobuf
    factories.
    """

    def decoder_for(self, message_encoding: str, schema: Schema | None) -> Callable[[bytes], Any] | None:
        if message_encoding != "json":
            return None
        return JsonDecoder()


# ---------------------------------------------------------------------------------------------
# Fast path: messages that are the first message with other numbers in it.
#
# The first message is split into literal segments and value tokens (numbers, true, false, NaN,
# Infinity; never inside strings). A numba kernel checks every message against those literal
# segments byte for byte and copies its tokens, space separated, into one buffer. A second kernel
# parses the tokens that Clinger's exact fast path covers (at most 2**53 as digits, |exponent| <= 22:
# what loggers write); numpy parses the rest in one call. Both are correctly rounded, like
# json.loads. Messages that differ anywhere else (another string value, a missing key, other
# whitespace) go through json.loads and the generic walk.

_TOKEN_CHARS = frozenset(b"0123456789+-.eEabcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ")
_IS_TOKEN = np.zeros(256, dtype=np.bool_)
_IS_TOKEN[list(_TOKEN_CHARS)] = True


def _value_tokens(data: bytes) -> list[tuple[int, int]]:
    """(start, end) of each value token of one JSON text, outside strings; ``null`` is literal."""
    spans = []
    i, n = 0, len(data)
    while i < n:
        c = data[i]
        if c == 0x22:  # a string: skip it, honouring backslash escapes
            i += 1
            while i < n and data[i] != 0x22:
                i += 2 if data[i] == 0x5C else 1
            i += 1
        elif c in _TOKEN_CHARS:
            j = i
            while j < n and data[j] in _TOKEN_CHARS:
                j += 1
            if data[i:j] != b"null":
                spans.append((i, j))
            i = j
        else:
            i += 1
    return spans


@njit(cache=True)
def _match_template(buf, starts, ends, literal, lit_start, lit_len, is_token, ok, out):  # pragma: no cover
    """Check each message against the literal segments; copy its tokens to ``out``. Returns length."""
    k = lit_start.size - 1  # tokens per message
    w = 0
    for m in range(starts.size):
        p = starts[m]
        end = ends[m]
        w_message = w
        good = True
        for j in range(k + 1):
            length = lit_len[j]
            if p + length > end:
                good = False
                break
            for i in range(length):
                if buf[p + i] != literal[lit_start[j] + i]:
                    good = False
                    break
            if not good:
                break
            p += length
            if j == k:
                break
            q = p
            while q < end and is_token[buf[q]]:
                q += 1
            if q == p:
                good = False
                break
            if q - p == 4 and buf[p] == 116 and buf[p + 1] == 114 and buf[p + 2] == 117 and buf[p + 3] == 101:
                out[w] = 49  # true -> 1
                w += 1
            elif q - p == 5 and buf[p] == 102 and buf[p + 1] == 97 and buf[p + 2] == 108:
                out[w] = 48  # false -> 0
                w += 1
            else:
                for i in range(p, q):
                    out[w] = buf[i]
                    w += 1
            out[w] = 32
            w += 1
            p = q
        if good and p != end:
            good = False
        ok[m] = good
        if not good:
            w = w_message
    return w


# 10**0 .. 10**22: every one is exact in float64 (5**22 < 2**53)
_POW10 = np.array([10.0**k for k in range(23)], dtype=np.float64)
_MANTISSA_MAX = 2**53
_W_MAX = (2**63 - 1 - 9) // 10  # digits beyond this would overflow the int64 mantissa


@njit(cache=True)
def _json_number(text, start, stop, pow10, pow_hi, pow_lo):  # pragma: no cover - compiled
    """(value, True) for a JSON number token text[start:stop] that the exact kernels give.

    Decimal token = w * 10**e with integer w <= 2**53 and |e| <= 22: w and 10**|e| are exact
    doubles, so the one IEEE product / quotient x = w * 10**e or x = w / 10**-e is the correctly
    rounded value, as json.loads / strtod give it (Clinger's fast path). Up to 18 digits otherwise
    (17-digit ``repr`` floats): Eisel-Lemire (`decimal_float`), correctly rounded where it decides.
    Anything else (more digits, an undecided rounding, NaN, Infinity, not JSON number syntax) ->
    (nan, False).
    """
    i = start
    negative = False
    if i < stop and text[i] == 45:  # '-'
        negative = True
        i += 1
    if i >= stop or text[i] < 48 or text[i] > 57:
        return np.nan, False
    w = np.int64(0)
    e = 0
    if text[i] == 48:  # a leading 0 stands alone
        i += 1
        if i < stop and 48 <= text[i] <= 57:
            return np.nan, False
    else:
        while i < stop and 48 <= text[i] <= 57:
            if w > _W_MAX:
                return np.nan, False
            w = w * 10 + (text[i] - 48)
            i += 1
    if i < stop and text[i] == 46:  # '.' then at least one digit
        i += 1
        if i >= stop or text[i] < 48 or text[i] > 57:
            return np.nan, False
        while i < stop and 48 <= text[i] <= 57:
            if w > _W_MAX:
                return np.nan, False
            w = w * 10 + (text[i] - 48)
            e -= 1
            i += 1
    if i < stop and (text[i] == 101 or text[i] == 69):  # 'e' / 'E', optional sign, digits
        i += 1
        exp_negative = False
        if i < stop and (text[i] == 43 or text[i] == 45):
            exp_negative = text[i] == 45
            i += 1
        if i >= stop or text[i] < 48 or text[i] > 57:
            return np.nan, False
        exponent = 0
        while i < stop and 48 <= text[i] <= 57:
            if exponent < 10000:
                exponent = exponent * 10 + (text[i] - 48)
            i += 1
        e += -exponent if exp_negative else exponent
    if i != stop:
        return np.nan, False
    if w == 0:
        value = 0.0
    elif w <= _MANTISSA_MAX and 0 <= e <= 22:
        value = np.float64(w) * pow10[e]  # x = w * 10**e, one rounding
    elif w <= _MANTISSA_MAX and -22 <= e < 0:
        value = np.float64(w) / pow10[-e]  # x = w / 10**-e, one rounding
    else:
        value, exact = eisel_lemire(w, e, pow_hi, pow_lo)
        if not exact:
            return np.nan, False
    return (-value if negative else value), True


@njit(cache=True)
def _parse_numbers(text, used, pow10, pow_hi, pow_lo, values, rest):  # pragma: no cover - compiled
    """Parse the space-terminated tokens of text[:used] into ``values``.

    Tokens ``_json_number`` does not take are left NaN in ``values`` and copied, space-terminated,
    to ``rest`` for numpy. Returns (tokens, tokens left, bytes used in rest).
    """
    count = 0
    n_rest = 0
    r = 0
    p = np.int64(0)  # not a literal 0: that would compile _json_number a second time
    while p < used:
        q = p
        while text[q] != 32:
            q += 1
        if count >= values.size:
            return count + 1, n_rest, r
        value, exact = _json_number(text, p, q, pow10, pow_hi, pow_lo)
        values[count] = value
        if not exact:
            for i in range(p, q + 1):
                rest[r] = text[i]
                r += 1
            n_rest += 1
        count += 1
        p = q + 1
    return count, n_rest, r


def json_columns(datas: MessageBytes | Sequence[bytes]) -> tuple[FlatColumns, list[int]]:
    """Numeric columns of JSON messages (see ``flatten``) and the indices that are not JSON.

    ``datas``: packed message bytes, or a list of per-message bytes. Only the messages the template
    path does not take become ``bytes`` objects.
    """
    packed = datas if isinstance(datas, MessageBytes) else MessageBytes.from_list(datas)
    groups: dict = {}
    entries = []
    n = len(packed)
    remaining: list[int] = list(range(n))
    if n > 1:
        fast = _fast_json(packed)
        if fast is not None:
            signature, indices, matrix = fast
            entries.append((signature, indices, matrix))
            left = np.ones(n, dtype=bool)
            left[indices] = False
            remaining = np.flatnonzero(left).tolist()
    decoded, failed_local = JsonDecoder().decode_many(packed.to_list(remaining))
    failed = [remaining[i] for i in failed_local]
    bad = set(failed_local)
    add_to_groups(
        groups,
        [m for i, m in enumerate(decoded) if i not in bad],
        [remaining[i] for i in range(len(remaining)) if i not in bad],
    )
    entries.extend((signature, indices, rows) for signature, (indices, rows) in groups.items())
    return columns_from_groups(entries), failed


_INTEGER_TOKEN = re.compile(rb"-?[0-9]+")


def _has_huge_integer(tokens: bytes, parsed: np.ndarray) -> bool:
    """True when a space-separated token that parsed to +-inf is an integer (beyond float range)."""
    words = tokens.split()
    return any(_INTEGER_TOKEN.fullmatch(words[i]) for i in np.flatnonzero(np.isinf(parsed)).tolist())


def _fast_json(packed: MessageBytes):
    """(signature, message numbers, (n, k) values) for the messages laid out like the first."""
    first = packed.message(0)
    try:
        signature, first_values = layout_of(json.loads(first))
    except (ValueError, UnicodeDecodeError, RecursionError):
        return None
    spans = _value_tokens(first)
    keys = signature[0]
    if not keys or len(spans) != len(keys):
        return None
    literal_parts, cursor = [], 0
    for start, end in spans:
        literal_parts.append(first[cursor:start])
        cursor = end
    literal_parts.append(first[cursor:])
    lit_len = np.array([len(part) for part in literal_parts], dtype=np.int64)
    lit_start = np.concatenate([[0], np.cumsum(lit_len)[:-1]]).astype(np.int64)
    literal = np.frombuffer(b"".join(literal_parts) + b"\0", dtype=np.uint8)
    n = len(packed)
    ok = np.zeros(n, dtype=np.bool_)
    out = np.empty(packed.total_bytes() + 2 * n * len(keys) + 1, dtype=np.uint8)
    used = 0
    for (buf, starts, ends), row in zip(packed.parts, packed.first.tolist()):
        used += _match_template(
            buf, starts, ends, literal, lit_start, lit_len, _IS_TOKEN, ok[row : row + starts.size], out[used:]
        )
    indices = np.flatnonzero(ok)
    if indices.size == 0:
        return None
    if indices[0] != 0:
        return None
    values = np.empty(indices.size * len(keys), dtype=np.float64)
    rest = np.empty(used + 1, dtype=np.uint8)
    count, n_rest, rest_used = _parse_numbers(out, used, _POW10, POW10_HI, POW10_LO, values, rest)
    if count != values.size:
        return None
    if n_rest:  # tokens the exact kernel leaves alone: numpy's correctly rounded parser
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a token that is no number: handled by the size check
            try:
                parsed = np.fromstring(rest[:rest_used].tobytes().decode("ascii"), sep=" ")
            except ValueError:
                return None
        if parsed.size != n_rest:
            return None  # some token was not a number: let json.loads judge every message
        if np.isinf(parsed).any() and _has_huge_integer(rest[:rest_used].tobytes(), parsed):
            return None  # numpy gives it +-inf; the generic path makes it NaN and counts it (flatten)
        values[np.isnan(values)] = parsed  # the kernel marks exactly those tokens NaN, in order
    matrix = values.reshape(indices.size, len(keys))
    if not np.array_equal(matrix[0], np.asarray(first_values, dtype=np.float64), equal_nan=True):
        return None
    return signature, indices, matrix


follow_dependencies(__name__)  # the cached kernels are stamped with decimal_float's parsing too
