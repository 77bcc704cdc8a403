"""JSON message decoding for MCAP: the decoder factory (the mcap library has none) and the columns of
a topic's messages, by the bulk template path (`json_template`) where the messages fit it."""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from mcap.decoder import DecoderFactory as McapDecoderFactory
from mcap.records import Schema

from logscan.readers.flatten import FlatColumns, MessageBytes, add_to_groups, columns_from_groups
from logscan.readers.json_template import JsonTier, fast_json


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


def json_columns(datas: MessageBytes | Sequence[bytes], tier: JsonTier | None = None) -> tuple[FlatColumns, list[int]]:
    """Numeric columns of JSON messages (see ``flatten``) and the indices that are not JSON.

    ``datas``: packed message bytes, or a list of per-message bytes. Only the messages the template
    path does not take become ``bytes`` objects. ``tier``: the log's choice of that path (none:
    always tried).
    """
    packed = datas if isinstance(datas, MessageBytes) else MessageBytes.from_list(datas)
    groups: dict = {}
    entries = []
    n = len(packed)
    remaining: list[int] = list(range(n))
    if n > 1 and (tier is None or tier.use_kernel(packed.total_bytes())):
        fast = fast_json(packed)
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
