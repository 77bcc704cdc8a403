"""Chunk decompression bounded by the bytes produced: lz4 and zstd a piece at a time into a buffer
whose pages are touched only as they are written, stopping as soon as a frame produces more than
its chunk declares."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

INFLATE_STEP = 1 << 20  # bytes produced per decompression call


class InflateError(ValueError):
    """The payload does not decompress, or not to the size its chunk declares."""


def _fail(reason: str) -> None:
    raise InflateError(reason)


def inflate(compression: str, payload: bytes, size: int) -> np.ndarray:
    """The chunk's ``size`` bytes, decompressed a piece at a time into a buffer whose pages are
    touched only as they are written (RSS follows the bytes produced, not the size declared);
    stops as soon as the frame produces more than ``size``; fewer is a size mismatch (the caller's)."""
    out = np.empty(size, dtype=np.uint8)
    produced = 0
    for piece in _pieces(compression, payload):
        end = produced + len(piece)
        if end > size:
            _fail(f"chunk decompresses to more than the {size} bytes its header declares")
        out[produced:end] = np.frombuffer(piece, dtype=np.uint8)
        produced = end
    return out[:produced]


def _pieces(compression: str, payload: bytes) -> Iterator[bytes]:
    """The decompressed bytes of a chunk payload, ``INFLATE_STEP`` bytes at a time."""
    if compression == "lz4":
        yield from _lz4_pieces(payload)
    elif compression == "zstd":
        yield from _zstd_pieces(payload)
    else:
        _fail(f"unsupported chunk compression {compression[:40]!r}")


def _lz4_pieces(payload: bytes) -> Iterator[bytes]:
    import lz4.frame

    rest = payload
    try:
        while rest:  # one frame after the other, as lz4.frame.decompress reads them
            frame = lz4.frame.LZ4FrameDecompressor()
            piece = frame.decompress(rest, max_length=INFLATE_STEP)
            yield piece
            while not frame.eof and not frame.needs_input:
                yield frame.decompress(b"", max_length=INFLATE_STEP)
            if not frame.eof:
                _fail("lz4 chunk ends inside a frame (truncated or corrupt)")
            rest = frame.unused_data
    except RuntimeError as exc:  # lz4 raises RuntimeError on bad frames
        _fail(f"lz4 chunk does not decompress ({exc})")


def _zstd_pieces(payload: bytes) -> Iterator[bytes]:
    try:
        import zstandard
    except ImportError:
        _fail("zstd-compressed chunk and the zstandard package is not installed")
    if not payload:
        return
    try:
        with zstandard.ZstdDecompressor().stream_reader(payload, read_across_frames=True) as reader:
            while piece := reader.read(INFLATE_STEP):
                yield piece
    except zstandard.ZstdError as exc:
        _fail(f"zstd chunk does not decompress ({exc})")
