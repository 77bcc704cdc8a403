"""The bulk JSON path: messages laid out like their topic's first message, matched and parsed in one pass.

The first message is split into literal segments and value tokens (numbers, true, false, NaN,
Infinity; never inside strings; ``null`` is literal). One numba kernel walks every message: it
checks the literal segments byte for byte (eight at a time) and parses each value token where it
stands (`decimal_float.decimal_number`: correctly rounded, as json.loads) into a column-major
(fields x messages) array, so each field's column is contiguous and no copy of the numbers is
made on the way. Tokens the kernel declines (NaN, Infinity, more than 19 digits, an undecided
rounding) are copied, space separated, for numpy's correctly rounded parser, in one call. A
message that differs anywhere else (another string value, a missing key, other whitespace) is
left to json.loads and the generic walk (`json_decoder.json_columns`).

The kernel's first compile costs as much CPU as json.loads and the generic walk spend on about
40-60 MB of JSON messages (measured on the quadcopter sample's messages: the compile 3.2-4.6 s, the
generic path 0.22-0.33 s for its 3.7 MB), so a log's messages take the generic path, which gives the
same columns, while the kernel is neither compiled in this process nor in the disk cache and until
those parsed so, on this machine's reads together, reach `TIER_BYTES` (`JsonTier`): the ski-rental
rule. A small log's first run does not pay the compile; a large log, or enough small ones, pay at
most that much parsing the slow way before it is made once.
"""

from __future__ import annotations

import json
import os
import re
import warnings
from pathlib import Path

import numpy as np
from numba import njit

from logscan.artifacts import write_atomic
from logscan.errors import LogscanError
from logscan.numba_cache import follow_dependencies, kernel_cached
from logscan.readers.bits import load_u64, uncounted
from logscan.readers.decimal_float import decimal_number
from logscan.readers.flatten import MessageBytes, layout_of

# JSON message bytes a log parses the generic way before the kernel is compiled (module docstring):
# below the 40-60 MB the compile costs, so that a large log pays less than twice the compile
TIER_BYTES = 32 << 20
TALLY_NAME = "logscan-json-generic-bytes"  # `JsonTier`'s count across reads, beside numba's cache

_TOKEN_CHARS = frozenset(b"0123456789+-.eEabcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ")
IS_TOKEN = np.zeros(256, dtype=np.bool_)
IS_TOKEN[list(_TOKEN_CHARS)] = True


def value_tokens(data: bytes) -> list[tuple[int, int]]:
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


@njit(cache=True, inline="always")
def _same_bytes(buf, p, literal, start, length):  # pragma: no cover - numba kernel
    """buf[p:p + length] == literal[start:start + length] (both in range), eight bytes at a time."""
    i = 0
    while i + 8 <= length:
        if load_u64(buf, p + i) != load_u64(literal, start + i):
            return False
        i += 8
    while i < length:
        if buf[p + i] != literal[start + i]:
            return False
        i += 1
    return True


@njit(cache=True, inline="always")
def _boolean(buf, p, end):  # pragma: no cover - numba kernel
    """1 for the token ``true`` at buf[p], 0 for ``false``, -1 for anything else."""
    if p + 4 <= end and buf[p] == 116 and buf[p + 1] == 114 and buf[p + 2] == 117 and buf[p + 3] == 101:
        if p + 4 == end or not IS_TOKEN[buf[p + 4]]:
            return 1
    if p + 5 <= end and buf[p] == 102 and buf[p + 1] == 97 and buf[p + 2] == 108 and buf[p + 3] == 115:
        if buf[p + 4] == 101 and (p + 5 == end or not IS_TOKEN[buf[p + 5]]):
            return 0
    return -1


# Arguments: buf uint8 (any size), starts / ends int64 (m,): the part's messages buf[starts[i]:ends[i]];
# literal uint8 (L,), lit_start / lit_len int64 (k + 1,): the literal segments around the k tokens;
# row0: the part's first message number; ok bool (m,) out; values float64 (k * n,) out: token j of
# message row0 + i at [j * n + row0 + i]; rest uint8, rest_at int64 (k * n,) out: the declined
# tokens' text (each followed by a space) and their slots in values; counts int64 (2,) in/out:
# bytes used in rest, tokens in rest.
@njit(cache=True)
def match_and_parse(
    buf, starts, ends, literal, lit_start, lit_len, row0, ok, values, rest, rest_at, counts
):  # pragma: no cover
    """Check each message against the literal segments and parse its tokens into ``values``."""
    buf = uncounted(buf)  # else each token's call to the number scan counts a reference up and down
    k = lit_start.size - 1  # tokens per message
    n = values.size // k if k else 0
    used = counts[0]
    n_rest = counts[1]
    for m in range(starts.size):
        p = starts[m]
        end = ends[m]
        used_before, n_rest_before = used, n_rest
        good = True
        for j in range(k + 1):
            length = lit_len[j]
            if p + length > end or not _same_bytes(buf, p, literal, lit_start[j], length):
                good = False
                break
            p += length
            if j == k:
                break
            slot = j * n + row0 + m
            flag = _boolean(buf, p, end)
            if flag >= 0:
                values[slot] = flag
                p += 4 + (1 - flag)
                continue
            value, exact, q = decimal_number(buf, p, end)
            if exact and (q == end or not IS_TOKEN[buf[q]]):
                values[slot] = value
                p = q
                continue
            q = p  # the whole token, for numpy
            while q < end and IS_TOKEN[buf[q]]:
                q += 1
            if q == p:
                good = False
                break
            values[slot] = np.nan
            for i in range(p, q):
                rest[used] = buf[i]
                used += 1
            rest[used] = 32
            used += 1
            rest_at[n_rest] = slot
            n_rest += 1
            p = q
        if good and p != end:
            good = False
        ok[m] = good
        if not good:
            used, n_rest = used_before, n_rest_before
    counts[0] = used
    counts[1] = n_rest


class Template:
    """The literal segments around the value tokens of one JSON text, as the kernel reads them."""

    def __init__(self, first: bytes, spans: list[tuple[int, int]]):
        parts, cursor = [], 0
        for start, end in spans:
            parts.append(first[cursor:start])
            cursor = end
        parts.append(first[cursor:])
        self.tokens = len(spans)
        self.lit_len = np.array([len(part) for part in parts], dtype=np.int64)
        self.lit_start = np.concatenate([[0], np.cumsum(self.lit_len)[:-1]]).astype(np.int64)
        self.literal = np.frombuffer(b"".join(parts) + b"\0", dtype=np.uint8)


def fast_json(packed: MessageBytes):
    """(signature, message numbers, (n, k) values with contiguous columns) for the messages laid
    out like the first, or None when the first is not JSON or has no numbers."""
    first = packed.message(0)
    try:
        signature, first_values = layout_of(json.loads(first))
    except (ValueError, UnicodeDecodeError, RecursionError):
        return None
    spans = value_tokens(first)
    keys = signature[0]
    if not keys or len(spans) != len(keys):
        return None
    template = Template(first, spans)
    n, k = len(packed), len(keys)
    ok = np.zeros(n, dtype=np.bool_)
    values = np.empty(k * n, dtype=np.float64)
    # a declined token and its space fit in its bytes and the literal byte after it (the last one
    # of a message: one byte more); the pages are touched only if used
    rest = np.empty(packed.total_bytes() + n + 1, dtype=np.uint8)
    rest_at = np.empty(k * n, dtype=np.int64)
    counts = np.zeros(2, dtype=np.int64)
    for (buf, starts, ends), row in zip(packed.parts, packed.first.tolist()):
        literal = (template.literal, template.lit_start, template.lit_len)
        match_and_parse(buf, starts, ends, *literal, row, ok[row : row + starts.size], values, rest, rest_at, counts)
    indices = np.flatnonzero(ok)
    if indices.size == 0 or indices[0] != 0:
        return None
    used, n_rest = int(counts[0]), int(counts[1])
    if n_rest and not _parse_rest(rest[:used].tobytes(), rest_at[:n_rest], values):
        return None
    by_field = values.reshape(k, n)
    if indices.size != n:
        by_field = by_field[:, indices]
    matrix = by_field.T  # (messages, fields), each field's column contiguous
    if not np.array_equal(matrix[0], np.asarray(first_values, dtype=np.float64), equal_nan=True):
        return None
    return signature, indices, matrix


_INTEGER_TOKEN = re.compile(rb"-?[0-9]+")


def _parse_rest(tokens: bytes, slots: np.ndarray, values: np.ndarray) -> bool:
    """Parse the space-terminated tokens the kernel declined into their ``slots`` of ``values``
    (numpy's correctly rounded parser, one call); False when one is not a number as json.loads
    reads it (then every message goes to json.loads, which judges)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a token that is no number: handled by the size check
        try:
            parsed = np.fromstring(tokens.decode("ascii"), sep=" ")
        except ValueError:
            return False
    if parsed.size != slots.size:
        return False  # some token was not a number
    if np.isinf(parsed).any() and _has_huge_integer(tokens, parsed):
        return False  # numpy gives it +-inf; the generic path makes it NaN and counts it (flatten)
    values[slots] = parsed
    return True


def _has_huge_integer(tokens: bytes, parsed: np.ndarray) -> bool:
    """True when a space-separated token that parsed to +-inf is an integer (beyond float range)."""
    words = tokens.split()
    return any(_INTEGER_TOKEN.fullmatch(words[i]) for i in np.flatnonzero(np.isinf(parsed)).tolist())


class JsonTier:
    """Whether one log's JSON messages go through the kernel (`fast_json`): yes once it is
    compiled here or cached on disk, or once the messages parsed the generic way reach `TIER_BYTES`,
    counted over this machine's earlier reads too (``tally``, a file beside numba's cache; none:
    this read's only), so that many small logs also come to the compile."""

    def __init__(self, tally: Path | None = None) -> None:
        self.tally = tally
        self.generic_bytes = _tallied(tally)
        self.counted = 0  # of them, this read's
        self.ready: bool | None = None  # the kernel compiled or cached (asked once per log)

    def use_kernel(self, message_bytes: int) -> bool:
        """Whether the next batch (of ``message_bytes``) takes the kernel; counts it when not."""
        if self.ready is None:
            self.ready = bool(match_and_parse.signatures) or kernel_cached(match_and_parse)
        if self.ready or self.generic_bytes >= TIER_BYTES:
            return True
        self.generic_bytes += message_bytes
        self.counted += message_bytes
        return False

    def save(self) -> None:
        """Add this read's generic bytes to the tally (best effort: a lost update, or a cache
        directory that cannot be written, only delays the compile)."""
        if self.tally is None or not self.counted:
            return
        try:
            write_atomic(self.tally, str(_tallied(self.tally) + self.counted))
        except LogscanError:  # an OutputError: the cache directory cannot be written
            return
        self.counted = 0


def tally_file() -> Path | None:
    """The tally of the generic path's bytes, in numba's cache directory (set by `logscan`)."""
    folder = os.environ.get("NUMBA_CACHE_DIR")
    return Path(folder) / TALLY_NAME if folder else None


def _tallied(tally: Path | None) -> int:
    """The bytes the tally holds (0: none, or not a count)."""
    if tally is None:
        return 0
    try:
        return max(0, int(tally.read_text(encoding="ascii")))
    except (OSError, ValueError):
        return 0


follow_dependencies(__name__)  # the cached kernel is stamped with decimal_float's parsing too
