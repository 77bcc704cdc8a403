"""Decoder factory for MCAP channels with the ``json`` message encoding (the mcap library has none)."""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from typing import Any

from mcap.decoder import DecoderFactory as McapDecoderFactory
from mcap.records import Schema


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
