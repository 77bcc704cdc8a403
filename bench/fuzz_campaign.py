"""Fuzzing campaign: mutated MCAP, CSV, ULog and profile inputs through `python -m logscan`.

The mutators, seeds, subprocess runner and oracle live here; `tests/test_fuzz.py` drives the
same ones with hypothesis for CI (a few hundred cases), and this script runs a long campaign:

    python bench/fuzz_campaign.py --cases 10000 --jobs 2 --seed 1 --keep /tmp/fuzz-failures

Each mutated file is analysed (`analyze --no-report --json -`; many files per process, each log's
exit code is in the JSON) in a subprocess with a timeout and an address-space cap; a batch that
hangs, dies, prints a traceback or loses a log is re-run one file per process to name the culprit.
A case passes when its exit code is 0, 1 or 2 (never 3, "a bug in logscan"), nothing hangs or hits
the memory cap, stderr holds no traceback, Python warning or raw control character, and 0/1 (no
alarm / alarms) is only given for a log that was fully read and fully checked: never for one the
JSON calls partial or unchecked, never for a mutation the reader must notice (an MCAP cut short
or a flip under its CRCs, a ULog cut inside a message).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import random
import re
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import time
import tomllib
from collections import Counter, defaultdict
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SAMPLES = REPO / "sample_logs"
TESTDATA = REPO.parent / "shared" / "testdata"
ULOG_DIR = TESTDATA / "px4-ulog"

CASE_TIMEOUT_S = 60.0  # one log, one process
MEMORY_CAP_BYTES = 2 << 30  # RLIMIT_AS of every logscan process; a normal run peaks near 0.55 GiB
BATCH_SIZE = 40
# OpenBLAS reserves a buffer per core when scipy loads it, so the address space a run needs would
# grow with the machine; one thread keeps the cap meaningful anywhere (the EKF runs in numba).
CHILD_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}

MCAP_MAGIC = b"\x89MCAP0\r\n"
OP_FOOTER, OP_CHUNK, OP_METADATA, OP_DATA_END = 0x02, 0x06, 0x0C, 0x0F

PX4_PROFILE = """\
name = "px4 fuzz seed"

[vehicle]
model = "linear"
rate_hz = 100

[vehicle.params]
A = [[0.0]]
B = [[0.0]]
C = { accel = [[1.0]] }
R = { accel = [1.0] }
inputs = ["thrust"]
states = ["az"]

[inputs]
thrust = "/actuator_controls_0_0/control[3]"
stale_s = 0.5

[measurements.accel]
channels = ["/sensor_combined_0/accelerometer_m_s2[2]"]
rate_hz = 100
"""

# ----------------------------------------------------------------------------------------------
# Seeds
# ----------------------------------------------------------------------------------------------

# the short seeds (CI); build_seeds(full=True) adds the shipped 60-180 s logs for the campaign
SMALL_SEEDS = {
    "mcap": ("quad_zstd", "quad_plain", "quad_datacrc", "sbw_ros2", "jackal_lz4"),
    "csv": ("csv_ns", "csv_s_semicolon"),
    "ulog": ("ulog_tagged", "ulog_appended"),
}


@dataclass
class Seed:
    """One intact input the mutators start from.

    ``args``: extra `analyze` arguments (a profile for logs that embed none); ``sidecars``: files
    written beside each case (suffix -> bytes, e.g. ``.profile.toml`` for a CSV); ``profile``: the
    TOML the log is analysed with (the "profile" mutations start from it); ``messages``: an MCAP's
    parsed content, for the mutations that write a new, intact file.
    """

    name: str
    fmt: str  # mcap | csv | ulog
    data: bytes
    ext: str
    args: tuple[str, ...] = ()
    sidecars: dict[str, bytes] = field(default_factory=dict)
    profile: str | None = None
    messages: McapContent | None = None
    data_crc: bool = False  # MCAP: a data-section CRC covers every record before DataEnd
    exit_code: int | None = None  # the intact seed's exit code (filled by the warm-up)


@dataclass
class McapContent:
    """An MCAP's records as the mcap library reads them (for rewriting)."""

    profile: str
    library: str
    schemas: dict[int, tuple[str, str, bytes]]  # id -> (name, encoding, data)
    channels: dict[int, tuple[str, str, int, dict]]  # id -> (topic, encoding, schema id, metadata)
    messages: list[tuple[int, int, int, int, bytes]]  # (channel id, log_time, publish_time, sequence, data)
    metadata: list[tuple[str, dict]]


def read_mcap_content(data: bytes, window_ns: tuple[int, int] | None = None) -> McapContent:
    import io

    from mcap.reader import make_reader

    reader = make_reader(io.BytesIO(data))
    header = reader.get_header()
    schemas, channels, messages = {}, {}, []
    for schema, channel, message in reader.iter_messages(log_time_order=False):
        if window_ns and not window_ns[0] <= message.log_time < window_ns[1]:
            continue
        if schema is not None:
            schemas[schema.id] = (schema.name, schema.encoding, bytes(schema.data))
        channels[channel.id] = (channel.topic, channel.message_encoding, channel.schema_id, dict(channel.metadata))
        messages.append((channel.id, message.log_time, message.publish_time, message.sequence, bytes(message.data)))
    metadata = [(m.name, dict(m.metadata)) for m in make_reader(io.BytesIO(data)).iter_metadata()]
    return McapContent(header.profile, header.library, schemas, channels, messages, metadata)


def write_mcap_content(
    content: McapContent,
    *,
    chunk_size: int = 64 * 1024,
    compression: str = "lz4",
    crcs: bool = True,
    data_crc: bool = False,
    chunking: bool = True,
    metadata: list[tuple[str, dict]] | None = None,
) -> bytes:
    """``content`` written as a new, valid MCAP file (the mcap library's writer)."""
    import io

    from mcap.writer import CompressionType, Writer

    out = io.BytesIO()
    kind = {"lz4": CompressionType.LZ4, "zstd": CompressionType.ZSTD, "": CompressionType.NONE}[compression]
    writer = Writer(
        out,
        chunk_size=chunk_size,
        compression=kind,
        use_chunking=chunking,
        enable_crcs=crcs,
        enable_data_crcs=data_crc,
    )
    writer.start(content.profile, content.library)
    for name, values in content.metadata if metadata is None else metadata:
        writer.add_metadata(name, values)
    schema_ids = {sid: writer.register_schema(*spec) for sid, spec in content.schemas.items()}
    channel_ids = {
        cid: writer.register_channel(topic, enc, schema_ids.get(sid, 0), meta)
        for cid, (topic, enc, sid, meta) in content.channels.items()
    }
    for cid, log_time, publish_time, sequence, data in content.messages:
        writer.add_message(channel_ids[cid], log_time, data, publish_time, sequence)
    writer.finish()
    return out.getvalue()


def _metadata_value(content: McapContent, name: str, key: str) -> str | None:
    for meta_name, values in content.metadata:
        if meta_name == name:
            return values.get(key)
    return None


def _with_profile(content: McapContent, profile: str) -> list[tuple[str, dict]]:
    """The metadata records of ``content`` with the embedded profile replaced by ``profile``."""
    return [(name, {"toml": profile} if name == "logscan.profile" else values) for name, values in content.metadata]


def _json_to_ros2(content: McapContent, window: tuple[int, int]) -> bytes:
    """The JSON topics of ``content`` (numeric leaves) as a ROS 2 CDR MCAP (logscan's writer)."""
    import numpy as np

    from logscan.readers.mcap.writer import TopicData, mcap_bytes

    per_topic: dict[str, tuple[list[int], list[dict]]] = {}
    for cid, log_time, _pub, _seq, data in content.messages:
        if not window[0] <= log_time < window[1]:
            continue
        flat = _flatten(json.loads(data))
        if flat:
            times, rows = per_topic.setdefault(content.channels[cid][0], ([], []))
            times.append(log_time)
            rows.append(flat)
    topics = {}
    for topic, (times, rows) in per_topic.items():
        names = [n for n in rows[0] if all(n in r for r in rows)]
        if names:
            fields = {n: np.array([r[n] for r in rows], dtype=np.float64) for n in names}
            type_name = "".join(p.title() for p in re.split(r"[^A-Za-z0-9]+", topic) if p) or "Msg"
            topics[topic] = TopicData(f"fuzz_msgs/msg/{type_name}", np.array(times, dtype=np.int64), fields)
    return mcap_bytes(topics, encoding="ros2", metadata=dict(content.metadata))


def _flatten(node, prefix: str = "") -> dict[str, float]:
    out: dict[str, float] = {}
    if isinstance(node, dict):
        for key, value in node.items():
            out.update(_flatten(value, f"{prefix}.{key}" if prefix else key))
    elif isinstance(node, (int, float)) and not isinstance(node, bool) and prefix:
        out[prefix] = float(node)
    return out


def cut_ulog(data: bytes, budget: int) -> bytes:
    """The first whole messages of a ULog up to about ``budget`` bytes (a valid, shorter log)."""
    ends = [end for _off, end, _type in ulog_messages(data) if end <= budget]
    return data[: ends[-1]] if ends else data


def build_seeds(workdir: Path, *, full: bool = False) -> dict[str, Seed]:
    """The seeds, written under ``workdir`` (kept small: 5-10 s windows of the sample logs).

    ``full`` adds the shipped sample logs themselves (60-180 s, multi-chunk) for the campaign.
    """
    workdir.mkdir(parents=True, exist_ok=True)
    seeds: dict[str, Seed] = {}

    def add(seed: Seed) -> None:
        seeds[seed.name] = seed

    bias = (SAMPLES / "quad_imu_bias.mcap").read_bytes()
    quad = read_mcap_content(bias, (27 * 10**9, 34 * 10**9))  # the accelerometer bias starts at 30 s
    quad_profile = _metadata_value(quad, "logscan.profile", "toml")
    add(Seed("quad_zstd", "mcap", write_mcap_content(quad, compression="zstd"), ".mcap", profile=quad_profile))
    add(
        Seed(
            "quad_plain",  # no chunks, no CRC: flipped bytes reach the JSON decoder
            "mcap",
            write_mcap_content(quad, chunking=False, crcs=False),
            ".mcap",
            profile=quad_profile,
            messages=quad,
        )
    )
    profile_path = workdir / "quad.profile.toml"
    profile_path.write_text(quad_profile, encoding="utf-8")
    add(
        Seed(
            "quad_datacrc",  # no metadata (profile given), chunk and data-section CRCs
            "mcap",
            write_mcap_content(quad, data_crc=True, metadata=[]),
            ".mcap",
            args=("--profile", str(profile_path)),
            profile=quad_profile,
            data_crc=True,
        )
    )
    sbw_full = read_mcap_content((SAMPLES / "sbw_healthy.mcap").read_bytes(), (0, 6 * 10**9))
    sbw_bytes = _json_to_ros2(sbw_full, (0, 6 * 10**9))
    sbw = read_mcap_content(sbw_bytes)
    add(
        Seed(
            "sbw_ros2",  # ROS 2 CDR in uncompressed chunks without CRCs: flips reach the CDR decoder
            "mcap",
            write_mcap_content(sbw, compression="", crcs=False, chunk_size=16 * 1024),
            ".mcap",
            profile=_metadata_value(sbw, "logscan.profile", "toml"),
            messages=sbw,
        )
    )
    jackal = read_mcap_content((SAMPLES / "jackal_healthy.mcap").read_bytes(), (0, 25 * 10**9))
    add(
        Seed(
            "jackal_lz4",
            "mcap",
            write_mcap_content(jackal, compression="lz4", data_crc=True),
            ".mcap",
            profile=_metadata_value(jackal, "logscan.profile", "toml"),
            data_crc=True,
            messages=jackal,
        )
    )

    csv_lines = (SAMPLES / "quad_healthy.csv").read_bytes().splitlines(keepends=True)
    sidecars = {
        ".profile.toml": (SAMPLES / "quad_healthy.profile.toml").read_bytes(),
        ".truth.json": (SAMPLES / "quad_healthy.truth.json").read_bytes(),
    }
    csv_profile = sidecars[".profile.toml"].decode()
    add(Seed("csv_ns", "csv", b"".join(csv_lines[:801]), ".csv", sidecars=sidecars, profile=csv_profile))
    seconds = [b"time" + csv_lines[0][len(b"time_ns") :].replace(b",", b";")]
    for line in csv_lines[1:801]:
        stamp, rest = line.split(b",", 1)
        seconds.append(f"{int(stamp) / 1e9:.3f};".encode() + rest.replace(b",", b";"))
    add(Seed("csv_s_semicolon", "csv", b"".join(seconds), ".csv", sidecars=sidecars, profile=csv_profile))

    if ULOG_DIR.is_dir():
        px4 = workdir / "px4.profile.toml"
        px4.write_text(PX4_PROFILE, encoding="utf-8")
        args = ("--profile", str(px4))
        tagged = (ULOG_DIR / "sample_logging_tagged_and_default_params.ulg").read_bytes()
        add(Seed("ulog_tagged", "ulog", cut_ulog(tagged, 800_000), ".ulg", args=args, profile=PX4_PROFILE))
        appended = (ULOG_DIR / "sample_appended_multiple.ulg").read_bytes()
        add(Seed("ulog_appended", "ulog", appended, ".ulg", args=args, profile=PX4_PROFILE))

    if full:
        for name in ("quad_imu_bias", "sbw_healthy"):
            data = (SAMPLES / f"{name}.mcap").read_bytes()
            content = read_mcap_content(data)
            profile = _metadata_value(content, "logscan.profile", "toml")
            add(Seed(name, "mcap", data, ".mcap", profile=profile, data_crc=True, messages=content))
        add(
            Seed(
                "quad_healthy_csv",
                "csv",
                b"".join(csv_lines),
                ".csv",
                sidecars=sidecars,
                profile=csv_profile,
            )
        )
        if ULOG_DIR.is_dir():
            small = (ULOG_DIR / "sample_log_small.ulg").read_bytes()
            add(Seed("ulog_small", "ulog", small, ".ulg", args=args, profile=PX4_PROFILE))
    for seed in seeds.values():
        if seed.fmt == "mcap" and seed.messages is None:
            seed.messages = read_mcap_content(seed.data)
    return seeds


# ----------------------------------------------------------------------------------------------
# Format walkers
# ----------------------------------------------------------------------------------------------


def mcap_records(data: bytes) -> list[tuple[int, int, int]]:
    """Top-level records of an intact MCAP: (opcode, record start, record end)."""
    records, pos = [], len(MCAP_MAGIC)
    while pos + 9 <= len(data) - len(MCAP_MAGIC):
        op = data[pos]
        (length,) = struct.unpack_from("<Q", data, pos + 1)
        end = pos + 9 + length
        records.append((op, pos, end))
        if op == OP_FOOTER or end > len(data):
            break
        pos = end
    return records


def mcap_data_end(data: bytes) -> int:
    """Offset just past the DataEnd record (its CRC field included); the file size when absent."""
    for op, _start, end in mcap_records(data):
        if op == OP_DATA_END:
            return end
    return len(data)


def ulog_messages(data: bytes) -> list[tuple[int, int, str]]:
    """The messages of an intact ULog after its 16-byte header: (start, end, type letter)."""
    out, pos = [], 16
    while pos + 3 <= len(data):
        size, kind = struct.unpack_from("<HB", data, pos)
        end = pos + 3 + size
        if end > len(data):
            break
        out.append((pos, end, chr(kind)))
        pos = end
    return out


_ULOG_SIZES = {
    "int8_t": 1,
    "uint8_t": 1,
    "bool": 1,
    "char": 1,
    "int16_t": 2,
    "uint16_t": 2,
    "int32_t": 4,
    "uint32_t": 4,
    "float": 4,
    "int64_t": 8,
    "uint64_t": 8,
    "double": 8,
}


@dataclass
class UlogLayout:
    """Where the numbers of a ULog are: every data message, and the float fields of each topic."""

    messages: list[tuple[int, int, str]]
    data_messages: list[tuple[int, int, int]]  # (start, end, msg_id)
    floats: dict[int, list[tuple[int, str]]]  # msg_id -> [(offset in the payload after msg_id, type)]
    first_data: int  # start of the first data message


def ulog_layout(data: bytes) -> UlogLayout:
    messages = ulog_messages(data)
    formats: dict[str, list[tuple[str, int]]] = {}
    subscribed: dict[int, str] = {}
    data_messages = []
    for start, end, kind in messages:
        body = data[start + 3 : end]
        if kind == "F":
            name, _, fields = body.decode("ascii", "replace").partition(":")
            parsed = []
            for spec in filter(None, fields.split(";")):
                type_spec = spec.split(" ")[0]
                base, _, count = type_spec.partition("[")
                parsed.append((base, int(count[:-1]) if count else 1))
            formats[name] = parsed
        elif kind == "A" and len(body) >= 3:
            (msg_id,) = struct.unpack_from("<H", body, 1)
            subscribed[msg_id] = body[3:].decode("ascii", "replace")
        elif kind == "D" and len(body) >= 2:
            data_messages.append((start, end, struct.unpack_from("<H", body, 0)[0]))

    def float_offsets(name: str, base: int, depth: int = 0) -> tuple[list[tuple[int, str]], int]:
        offsets, pos = [], base
        for type_name, count in formats.get(name, []):
            for _ in range(count):
                if type_name in _ULOG_SIZES:
                    if type_name in ("float", "double"):
                        offsets.append((pos, type_name))
                    pos += _ULOG_SIZES[type_name]
                elif depth < 4:
                    inner, pos = float_offsets(type_name, pos, depth + 1)
                    offsets.extend(inner)
        return offsets, pos

    floats = {msg_id: float_offsets(name, 0)[0] for msg_id, name in subscribed.items()}
    first = data_messages[0][0] if data_messages else len(data)
    return UlogLayout(messages, data_messages, floats, first)


# ----------------------------------------------------------------------------------------------
# Mutations
# ----------------------------------------------------------------------------------------------


@dataclass
class Case:
    """One mutated input: the bytes of the log (and of its sidecars), what was done, what to expect.

    ``damaged``: the mutation broke something the reader must notice (exit 0/1 would be a lie).
    ``args``: extra `analyze` arguments (a mutated ``--profile``: one process per case).
    """

    seed: str
    fmt: str
    kind: str
    detail: str
    data: bytes
    ext: str
    damaged: bool = False
    args: tuple[str, ...] = ()
    sidecars: dict[str, bytes] = field(default_factory=dict)
    profile_arg: str | None = None  # a mutated profile to pass as --profile (written beside the case)

    @property
    def label(self) -> str:
        return f"{self.seed}/{self.kind}: {self.detail}"

    def __repr__(self) -> str:  # tracebacks show it: not the bytes
        return f"Case({self.label[:120]!r}, {len(self.data)} bytes, damaged={self.damaged})"


INT_EDGES = (0, 1, 2**31, 2**32, 2**62, 2**63 - 1, 2**63, 2**64 - 1)
TIME_OUTLIERS_NS = (
    ("+11.6 days", 10**15),
    ("+300 years", 10**19 - 1),
    ("2**63-1", None),
    ("-1 ns", -1),
    ("-2**63", -(2**63)),
    ("zero", 0),
)


def _flip(data: bytes, rng: random.Random, lo: int = 0, hi: int | None = None) -> tuple[bytes, list[int]]:
    out = bytearray(data)
    hi = len(data) if hi is None else hi
    positions = sorted({rng.randrange(lo, hi) for _ in range(rng.choice((1, 1, 2, 3, 8)))})
    for pos in positions:
        out[pos] ^= rng.randrange(1, 256)
    return bytes(out), positions


def _cut_point(size: int, boundaries: list[int], rng: random.Random) -> int:
    """A cut strictly inside the file: near a record boundary half of the time."""
    if boundaries and rng.random() < 0.5:
        return max(0, min(size - 1, rng.choice(boundaries) + rng.choice((-1, 0, 0, 1, 9))))
    return rng.randrange(0, size)


def _time_value(seed_ns: int, rng: random.Random) -> tuple[str, int]:
    name, value = rng.choice(TIME_OUTLIERS_NS)
    if value is None:
        value = 2**63 - 1
    elif name.startswith("+"):
        value = seed_ns + value
    return name, value


# --- MCAP ---


def mcap_flip(seed: Seed, rng: random.Random) -> Case:
    records = mcap_records(seed.data)
    if rng.random() < 0.6:  # a record's body rather than anywhere
        op, start, end = rng.choice(records)
        data, where = _flip(seed.data, rng, start, end)
    else:
        data, where = _flip(seed.data, rng)
    return Case(seed.name, "mcap", "flip", f"bytes {where}", data, seed.ext, damaged=mcap_flip_noticed(seed, where))


def mcap_flip_noticed(seed: Seed, positions: list[int]) -> bool:
    """Whether flipped bytes at ``positions`` must make the reader stop (the spec and README):
    the magic, a record's length (framing), a chunk's sizes, CRC, compression or, under its CRC,
    its records; and anything in the data section when its CRC covers records no other CRC
    does (metadata). A flipped opcode makes a record unknown, which readers skip: only a
    data-section CRC can tell, and only for a chunk. Message indexes and a chunk's time range are
    not needed to read the messages (flips there may pass with a warning)."""
    records = mcap_records(seed.data)
    data_end = mcap_data_end(seed.data)
    has_metadata = any(op == OP_METADATA for op, _s, _e in records)
    for pos in positions:
        if pos < len(MCAP_MAGIC) or (seed.data_crc and has_metadata and pos < data_end):
            return True
        for op, start, end in records:
            if not start <= pos < end or start >= data_end:
                continue
            if start + 1 <= pos < start + 9:  # the record's length
                return True
            if op == OP_CHUNK:
                body = start + 9
                (name_len,) = struct.unpack_from("<I", seed.data, body + 28)
                records_at = body + 32 + name_len + 8
                (crc,) = struct.unpack_from("<I", seed.data, body + 24)
                if pos == start and seed.data_crc:
                    return True
                if body + 16 <= pos < (end if crc else records_at):
                    return True
    return False


def mcap_truncate(seed: Seed, rng: random.Random) -> Case:
    cut = _cut_point(len(seed.data), [s for _op, s, _e in mcap_records(seed.data)], rng)
    return Case(seed.name, "mcap", "truncate", f"cut at {cut} of {len(seed.data)}", seed.data[:cut], seed.ext, True)


def mcap_length(seed: Seed, rng: random.Random) -> Case:
    """A record length (u64 after the opcode) or a chunk's size field set to an edge value."""
    records = mcap_records(seed.data)
    chunks = [r for r in records if r[0] == OP_CHUNK]
    out = bytearray(seed.data)
    if chunks and rng.random() < 0.5:
        _op, start, _end = rng.choice(chunks)
        body = start + 9
        (clen,) = struct.unpack_from("<I", seed.data, body + 28)
        size_at = {"uncompressed_size": body + 16, "records_size": body + 32 + clen}
        name = rng.choice(sorted(size_at))
        (old,) = struct.unpack_from("<Q", seed.data, size_at[name])
        new = rng.choice((*INT_EDGES, old - 1, old + 1, old * 2, old // 2, 1 << 30, (1 << 30) + 1, 33_000 * 1000))
        struct.pack_into("<Q", out, size_at[name], new % 2**64)
        detail = f"chunk at {start}: {name} {old} -> {new}"
    else:
        op, start, end = rng.choice(records)
        old = end - start - 9
        new = rng.choice((*INT_EDGES, old - 1, old + 1, old * 2, rng.randrange(2**64)))
        struct.pack_into("<Q", out, start + 1, new % 2**64)
        detail = f"record op 0x{op:02x} at {start}: length {old} -> {new}"
    changed = bytes(out) != seed.data
    return Case(seed.name, "mcap", "length", detail, bytes(out), seed.ext, damaged=changed)


def _rewrite(seed: Seed, messages=None, channels=None, metadata=None) -> bytes:
    content = seed.messages
    assert content is not None
    edited = McapContent(
        content.profile,
        content.library,
        content.schemas,
        content.channels if channels is None else channels,
        content.messages if messages is None else messages,
        content.metadata,
    )
    return write_mcap_content(edited, data_crc=seed.data_crc, metadata=metadata)


def _wanted_indices(seed: Seed) -> list[int]:
    """Messages of the topics the profile reads (the others are never decoded)."""
    profile = seed.profile or ""
    content = seed.messages
    assert content is not None
    topics = {cid for cid, (topic, *_rest) in content.channels.items() if f'"{topic}/' in profile}
    return [i for i, m in enumerate(content.messages) if m[0] in topics] or list(range(len(content.messages)))


def mcap_time(seed: Seed, rng: random.Random) -> Case:
    """One message stamped far from the others (an intact file: the writer's CRCs are right)."""
    messages = list(seed.messages.messages)
    index = rng.choice(_wanted_indices(seed))
    cid, log_time, pub, seq, data = messages[index]
    name, value = _time_value(log_time, rng)
    messages[index] = (cid, value % 2**64, pub, seq, data)
    topic = seed.messages.channels[cid][0]
    detail = f"message {index} on {topic}: log_time {log_time} -> {name} ({value})"
    return Case(seed.name, "mcap", "time", detail, _rewrite(seed, messages=messages), seed.ext)


# values put in place of a number: JSON texts, CSV cells, TOML values
JSON_SPECIALS = (
    *'NaN Infinity -Infinity 1e999 -1e999 1e308 5e-324 -0.0 "" "1.5" null true [] {} "\\u0000"'.split(),
    *("18446744073709551616", "9" * 5000, "1" + "0" * 400),
)
FLOAT_SPECIALS = (math.nan, math.inf, -math.inf, 1e308, -1e308, 5e-324, -0.0, 3.4e38)


def _json_special(data: bytes, rng: random.Random) -> tuple[bytes, str]:
    """One numeric literal of a JSON message replaced by an edge-case text."""
    text = data.decode("utf-8", "replace")
    numbers = list(re.finditer(r"-?\d+(\.\d+)?([eE][-+]?\d+)?", text))
    if not numbers:
        return data, "no number"
    match = rng.choice(numbers)
    value = rng.choice(JSON_SPECIALS)
    shown = value if len(value) < 20 else f"{value[:8]}...({len(value)} chars)"
    return (text[: match.start()] + value + text[match.end() :]).encode(), f"{match.group(0)} -> {shown}"


def mcap_special(seed: Seed, rng: random.Random) -> Case:
    """NaN, inf, huge or non-numbers in the values of a few messages (JSON text or CDR float64)."""
    messages = list(seed.messages.messages)
    wanted = _wanted_indices(seed)
    details = []
    for index in sorted({rng.choice(wanted) for _ in range(rng.choice((1, 3, 20)))}):
        cid, log_time, pub, seq, data = messages[index]
        if seed.messages.channels[cid][1] == "json":
            data, what = _json_special(data, rng)
        else:  # CDR: a 4-byte header, then float64 fields (logscan's writer)
            slots = (len(data) - 4) // 8
            if slots <= 0:
                continue
            slot = rng.randrange(slots)
            value = rng.choice(FLOAT_SPECIALS)
            data = data[: 4 + 8 * slot] + struct.pack("<d", value) + data[4 + 8 * slot + 8 :]
            what = f"float64 {slot} -> {value!r}"
        messages[index] = (cid, log_time, pub, seq, data)
        details.append(f"#{index} {what}")
    return Case(seed.name, "mcap", "special", "; ".join(details[:4]), _rewrite(seed, messages=messages), seed.ext)


NAME_GARBAGE = ("\x1b[31m", "\r", "\x00", "\x07", "\x9b2J", "\u202e", "\n", "\x7f", "", " ", "/", "é" * 3)


def mcap_names(seed: Seed, rng: random.Random) -> Case:
    """Control characters (or nothing) in a topic name or in a JSON field name."""
    channels = dict(seed.messages.channels)
    cid = rng.choice(sorted(channels))
    topic, enc, sid, meta = channels[cid]
    garbage = rng.choice(NAME_GARBAGE)
    messages = None
    if enc == "json" and rng.random() < 0.5:
        messages = list(seed.messages.messages)
        for i, (mcid, t, pub, seq, data) in enumerate(messages):
            if mcid == cid:
                messages[i] = (
                    mcid,
                    t,
                    pub,
                    seq,
                    re.sub(rb'"(\w+)":', lambda m: b'"' + m.group(1) + garbage.encode() + b'":', data, count=1),
                )
        detail = f"first field name of {topic} + {garbage!r}"
    else:
        new = rng.choice((topic + garbage, garbage + topic, garbage, topic[:2] + garbage + topic[2:]))
        channels[cid] = (new, enc, sid, meta)
        detail = f"topic {topic!r} -> {new!r}"
    return Case(seed.name, "mcap", "names", detail, _rewrite(seed, messages=messages, channels=channels), seed.ext)


def mcap_profile(seed: Seed, rng: random.Random) -> Case:
    """The embedded profile mutated (or, for a log analysed with --profile, that profile)."""
    text, detail = mutate_toml(seed.profile or "", rng)
    if seed.args:  # the profile comes from --profile: one process per case
        return Case(seed.name, "mcap", "profile", detail, seed.data, seed.ext, profile_arg=text)
    metadata = _with_profile(seed.messages, text)
    return Case(seed.name, "mcap", "profile", detail, _rewrite(seed, metadata=metadata), seed.ext)


# --- CSV ---

CSV_SPECIALS = (
    *"nan NaN inf -inf +inf Infinity 1e308 -1e308 1e400 -1e400 5e-324 1e-400 -0 NA abc 0x10 1e --1".split(),
    *("", '"1,5"', "9" * 400, "\u0661\u0662", " 1 ", "18446744073709551616"),
)
CSV_TIME_SPECIALS = ("", "nan", "inf", "-1", "1e400", "abc", "99999999999999999999999", "2024-03-18 14:49:10")


def _csv_rows(seed: Seed) -> tuple[bytes, list[list[bytes]]]:
    sep = b";" if b";" in seed.data.split(b"\n", 1)[0] else b","
    return sep, [line.split(sep) for line in seed.data.splitlines()]


def _csv_join(sep: bytes, rows: list[list[bytes]]) -> bytes:
    return b"\n".join(sep.join(row) for row in rows) + b"\n"


def csv_flip(seed: Seed, rng: random.Random) -> Case:
    data, where = _flip(seed.data, rng)
    return Case(seed.name, "csv", "flip", f"bytes {where}", data, seed.ext, sidecars=seed.sidecars)


def csv_truncate(seed: Seed, rng: random.Random) -> Case:
    boundaries = [m.end() for m in re.finditer(rb"\n", seed.data)]
    cut = _cut_point(len(seed.data), boundaries, rng)
    return Case(seed.name, "csv", "truncate", f"cut at {cut}", seed.data[:cut], seed.ext, sidecars=seed.sidecars)


def csv_time(seed: Seed, rng: random.Random) -> Case:
    sep, rows = _csv_rows(seed)
    row = rng.randrange(1, len(rows))
    old = rows[row][0]
    seconds = not rows[0][0].endswith(b"_ns")
    if rng.random() < 0.7:
        name, value = _time_value(int(float(old) * (1e9 if seconds else 1)), rng)
        text = repr(value / 1e9) if seconds else str(value)
    else:
        name = text = rng.choice(CSV_TIME_SPECIALS)
    rows[row][0] = text.encode()
    detail = f"row {row}: time {old.decode()} -> {name} ({text})"
    return Case(seed.name, "csv", "time", detail, _csv_join(sep, rows), seed.ext, sidecars=seed.sidecars)


def csv_special(seed: Seed, rng: random.Random) -> Case:
    sep, rows = _csv_rows(seed)
    width = len(rows[0])
    details = []
    if rng.random() < 0.2:  # a whole column
        col = rng.randrange(1, width)
        value = rng.choice(("nan", "", "inf", "1e308"))
        for row in rows[1:]:
            if col < len(row) and row[col]:
                row[col] = value.encode()
        details.append(f"column {rows[0][col].decode()} all {value!r}")
    else:
        for _ in range(rng.choice((1, 3, 30))):
            row, col = rng.randrange(1, len(rows)), rng.randrange(1, width)
            value = rng.choice(CSV_SPECIALS)
            if col < len(rows[row]):
                rows[row][col] = value.encode()
                details.append(f"({row},{col}) {value[:12]!r}")
    return Case(
        seed.name, "csv", "special", " ".join(details[:6]), _csv_join(sep, rows), seed.ext, sidecars=seed.sidecars
    )


def csv_names(seed: Seed, rng: random.Random) -> Case:
    sep, rows = _csv_rows(seed)
    col = rng.randrange(len(rows[0]))
    old = rows[0][col].decode()
    new = rng.choice(
        (
            old + rng.choice(NAME_GARBAGE),
            rng.choice(NAME_GARBAGE),
            rows[0][(col + 1) % len(rows[0])].decode(),  # a duplicate name
            "x" * 10_000,
            "time",
            '"a' + sep.decode() + 'b"',
        )
    )
    rows[0][col] = new.encode("utf-8")
    shown = new if len(new) < 30 else f"{new[:10]}...({len(new)} chars)"
    detail = f"column {col} {old!r} -> {shown!r}"
    return Case(seed.name, "csv", "names", detail, _csv_join(sep, rows), seed.ext, sidecars=seed.sidecars)


def csv_structure(seed: Seed, rng: random.Random) -> Case:
    """Rows duplicated, dropped, shuffled or ragged; blank lines, CRLF, a BOM, NUL bytes."""
    sep, rows = _csv_rows(seed)
    what = rng.choice(("duplicate", "drop", "swap", "ragged", "blank", "crlf", "bom", "nul", "header-only", "reverse"))
    body = rows[1:]
    if what == "duplicate":
        i = rng.randrange(len(body))
        body[i:i] = [body[i]] * rng.choice((1, 50))
    elif what == "drop":
        i = rng.randrange(len(body))
        del body[i : i + rng.choice((1, 100, len(body)))]
    elif what == "swap":
        i, j = rng.randrange(len(body)), rng.randrange(len(body))
        body[i], body[j] = body[j], body[i]
    elif what == "ragged":
        i = rng.randrange(len(body))
        body[i] = body[i][: rng.randrange(len(body[i]))] if rng.random() < 0.5 else body[i] + [b"1"] * 5
    elif what == "blank":
        body.insert(rng.randrange(len(body)), [b""])
    elif what == "reverse":
        body.reverse()
    elif what == "header-only":
        body = []
    data = _csv_join(sep, [rows[0], *body])
    if what == "crlf":
        data = data.replace(b"\n", b"\r\n")
    elif what == "bom":
        data = b"\xef\xbb\xbf" + data
    elif what == "nul":
        pos = rng.randrange(len(data))
        data = data[:pos] + b"\x00" + data[pos:]
    return Case(seed.name, "csv", "structure", what, data, seed.ext, sidecars=seed.sidecars)


def csv_profile(seed: Seed, rng: random.Random) -> Case:
    text, detail = mutate_toml(seed.profile or "", rng)
    sidecars = {**seed.sidecars, ".profile.toml": text.encode("utf-8", "surrogateescape")}
    return Case(seed.name, "csv", "profile", detail, seed.data, seed.ext, sidecars=sidecars)


# --- ULog ---


def ulog_flip(seed: Seed, rng: random.Random) -> Case:
    data, where = _flip(seed.data, rng)
    return Case(seed.name, "ulog", "flip", f"bytes {where}", data, seed.ext, args=seed.args)


def ulog_truncate(seed: Seed, rng: random.Random) -> Case:
    layout = ulog_layout(seed.data)
    boundaries = [end for _s, end, _k in layout.messages]
    cut = _cut_point(len(seed.data), boundaries, rng)
    damaged = cut < 16 or cut not in set(boundaries)  # between two messages: a valid, shorter log
    detail = f"cut at {cut} of {len(seed.data)}" + ("" if damaged else " (between two messages)")
    return Case(seed.name, "ulog", "truncate", detail, seed.data[:cut], seed.ext, damaged=damaged, args=seed.args)


def ulog_length(seed: Seed, rng: random.Random) -> Case:
    """A message's uint16 size set to an edge value."""
    layout = ulog_layout(seed.data)
    start, end, kind = rng.choice(layout.messages)
    old = end - start - 3
    new = rng.choice((0, 1, 2, old - 1, old + 1, old + 3, 0xFFFF, rng.randrange(0x10000))) % 0x10000
    out = bytearray(seed.data)
    struct.pack_into("<H", out, start, new)
    detail = f"'{kind}' message at {start}: size {old} -> {new}"
    return Case(seed.name, "ulog", "length", detail, bytes(out), seed.ext, args=seed.args)


def _data_message(layout: UlogLayout, rng: random.Random, with_floats: bool = False) -> tuple[int, int, int]:
    pool = [m for m in layout.data_messages if not with_floats or layout.floats.get(m[2])]
    return rng.choice(pool or layout.data_messages)


def ulog_time(seed: Seed, rng: random.Random) -> Case:
    layout = ulog_layout(seed.data)
    start, _end, msg_id = _data_message(layout, rng)
    at = start + 5  # size, type, msg_id, then the topic's uint64 timestamp (us)
    (old,) = struct.unpack_from("<Q", seed.data, at)
    name, value_ns = _time_value(old * 1000, rng)
    value = value_ns // 1000 if name.startswith("+") else value_ns
    out = bytearray(seed.data)
    struct.pack_into("<Q", out, at, value % 2**64)
    detail = f"data message at {start} (msg_id {msg_id}): timestamp {old} us -> {name} ({value})"
    return Case(seed.name, "ulog", "time", detail, bytes(out), seed.ext, args=seed.args)


def ulog_special(seed: Seed, rng: random.Random) -> Case:
    layout = ulog_layout(seed.data)
    out = bytearray(seed.data)
    details = []
    for _ in range(rng.choice((1, 3, 40))):
        start, _end, msg_id = _data_message(layout, rng, with_floats=True)
        fields = layout.floats.get(msg_id)
        if not fields:
            continue
        offset, type_name = rng.choice(fields)
        value = rng.choice(FLOAT_SPECIALS)
        at = start + 5 + offset
        if at + 8 > len(out):
            continue
        if type_name == "float" and math.isfinite(value) and abs(value) > 3.4e38:
            value = math.copysign(math.inf, value)  # beyond float32: its overflow
        struct.pack_into("<f" if type_name == "float" else "<d", out, at, value)
        details.append(f"msg {msg_id}@{start}+{offset} {value!r}")
    return Case(seed.name, "ulog", "special", " ".join(details[:5]), bytes(out), seed.ext, args=seed.args)


def ulog_names(seed: Seed, rng: random.Random) -> Case:
    """Control characters in an info value (sys_name...), a message format's name or field name."""
    layout = ulog_layout(seed.data)
    candidates = [m for m in layout.messages if m[2] in "IF"]
    start, end, kind = rng.choice(candidates)
    body = seed.data[start + 3 : end]
    garbage = rng.choice(NAME_GARBAGE).encode("utf-8")
    if kind == "I":
        key_len = body[0]
        new_body = body[: 1 + key_len] + garbage + body[1 + key_len :] + garbage
        detail = f"info {body[1 : 1 + key_len].decode('ascii', 'replace')!r} value + {garbage!r}"
    else:
        colon = body.find(b":")
        at = rng.choice((colon, body.find(b" ", colon) + 1 or colon))
        new_body = body[:at] + garbage + body[at:]
        detail = f"format {body[:colon].decode('ascii', 'replace')!r}: {garbage!r} at {at}"
    data = seed.data[:start] + struct.pack("<HB", len(new_body), ord(kind)) + new_body + seed.data[end:]
    return Case(seed.name, "ulog", "names", detail, data, seed.ext, args=seed.args)


def ulog_profile(seed: Seed, rng: random.Random) -> Case:
    text, detail = mutate_toml(seed.profile or "", rng)
    return Case(seed.name, "ulog", "profile", detail, seed.data, seed.ext, profile_arg=text)


# --- profile TOML ---

TOML_SPECIALS = (
    *(math.nan, math.inf, -math.inf, 0, 0.0, -1, -1.0, 1e308, -1e308, 5e-324, 1e-300, 2**63 - 1, -(2**63), 2**64),
    *("", "\x1b[31mred", "a\rb", "x" * 5000, "/imu/accel.x", [], {}, [math.nan], [1e308, -1e308], True, [[]]),
)
TOML_LINES = (
    "[vehicle]",
    "rate_hz = 1e9",
    "[measurements.extra]\nchannels = []",
    '[measurements.extra]\nchannels = ["/imu/accel.x"]\nrate_hz = 0',
    "[detectors.nis]\nwindow = 0",
    "[detectors.encoded_ekf]\nrho = -1",
    "[detectors.no_such_detector]",
    "[alarms]\nmerge_gap_s = 1e308",
    '[redundant.speed]\nsensors = { a = "/imu/accel.x" }',
    'x = """',
    "\x00",
)


def _leaf_paths(node, path=()) -> list[tuple]:
    out = [path] if path else []
    if isinstance(node, dict):
        for key, value in node.items():
            out.extend(_leaf_paths(value, (*path, key)))
    elif isinstance(node, list):
        for index, value in enumerate(node):
            out.extend(_leaf_paths(value, (*path, index)))
    return out


def _set_path(node, path: tuple, value, delete: bool = False) -> None:
    for key in path[:-1]:
        node = node[key]
    if delete:
        del node[path[-1]]
    else:
        node[path[-1]] = value


def mutate_toml(text: str, rng: random.Random) -> tuple[str, str]:
    """A mutated profile: a value replaced by an edge case, a key dropped, a line added, or
    bytes flipped or cut (latin-1 keeps any byte as one character)."""
    how = rng.choice(("value", "value", "value", "drop", "line", "flip", "truncate"))
    if how in ("value", "drop"):
        doc = tomllib.loads(text)
        paths = _leaf_paths(doc)
        path = rng.choice(paths)
        if how == "drop":
            _set_path(doc, path, None, delete=True)
            return dump_toml(doc), f"dropped {'.'.join(map(str, path))}"
        value = rng.choice(TOML_SPECIALS)
        _set_path(doc, path, value)
        shown = repr(value) if len(repr(value)) < 24 else f"{repr(value)[:12]}...({len(repr(value))} chars)"
        return dump_toml(doc), f"{'.'.join(map(str, path))} = {shown}"
    if how == "line":
        line = rng.choice(TOML_LINES)
        lines = text.splitlines()
        at = rng.randrange(len(lines) + 1)
        return "\n".join([*lines[:at], line, *lines[at:]]) + "\n", f"line {at}: {line[:30]!r}"
    raw = text.encode("utf-8")
    if how == "flip":
        data, where = _flip(raw, rng)
        return data.decode("latin-1"), f"bytes {where} flipped"
    cut = rng.randrange(len(raw))
    return raw[:cut].decode("latin-1"), f"cut at {cut}"


_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def _toml_key(key: str) -> str:
    return key if _BARE_KEY.match(key) else _toml_string(key)


def _toml_string(text: str) -> str:
    out = []
    for ch in text:
        if ch in '"\\':
            out.append("\\" + ch)
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04x}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return _toml_string(value)
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items()) + " }"
    return _toml_string(str(value))  # dates and times


def dump_toml(doc: dict, prefix: tuple = ()) -> str:
    """TOML text of ``doc`` (tables as [a.b] sections, dicts inside arrays inline)."""
    lines = [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in doc.items() if not isinstance(v, dict) or not v]
    out = "\n".join(lines) + ("\n" if lines else "")
    for key, value in doc.items():
        if isinstance(value, dict) and value:
            path = (*prefix, key)
            out += f"\n[{'.'.join(_toml_key(p) for p in path)}]\n" + dump_toml(value, path)
    return out


MUTATORS = {
    "mcap": {
        "flip": mcap_flip,
        "truncate": mcap_truncate,
        "length": mcap_length,
        "time": mcap_time,
        "special": mcap_special,
        "names": mcap_names,
        "profile": mcap_profile,
    },
    "csv": {
        "flip": csv_flip,
        "truncate": csv_truncate,
        "time": csv_time,
        "special": csv_special,
        "names": csv_names,
        "structure": csv_structure,
        "profile": csv_profile,
    },
    "ulog": {
        "flip": ulog_flip,
        "truncate": ulog_truncate,
        "length": ulog_length,
        "time": ulog_time,
        "special": ulog_special,
        "names": ulog_names,
        "profile": ulog_profile,
    },
}


def draw_cases(seeds: dict[str, Seed], fmt: str, kinds, n: int, rng: random.Random) -> list[Case]:
    """``n`` cases of format ``fmt``: a seed among its short seeds and a kind of ``kinds`` each."""
    names = [name for name in SMALL_SEEDS[fmt] if name in seeds]
    return [
        mutate(seeds[rng.choice(names)], rng.choice(sorted(kinds)), random.Random(rng.randrange(2**32)))
        for _ in range(n)
    ]


def mutate(seed: Seed, kind: str, rng: random.Random) -> Case:
    case = MUTATORS[seed.fmt][kind](seed, rng)
    if not case.args and seed.args and case.profile_arg is None:
        case.args = seed.args
    return case


# ----------------------------------------------------------------------------------------------
# Running logscan
# ----------------------------------------------------------------------------------------------

# Caps its own address space, then runs `python -m logscan ARGS` as its child (inheriting the cap)
# and passes on its exit status; the child's peak RSS goes to a file. (The peak RSS of a process
# forked from a large parent starts at the parent's size, so the test process cannot measure its
# children directly; no preexec_fn either, so it is safe with threads.)
_LAUNCH = """\
import os, resource, signal, sys
cap, report = int(sys.argv[1]), sys.argv[2]
resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
pid = os.fork()
if pid == 0:
    os.execv(sys.executable, [sys.executable, "-m", "logscan", *sys.argv[3:]])
_pid, status, usage = os.wait4(pid, 0)
with open(report, "w") as out:
    out.write(str(usage.ru_maxrss))
if os.WIFSIGNALED(status):
    signal.signal(os.WTERMSIG(status), signal.SIG_DFL)
    os.kill(os.getpid(), os.WTERMSIG(status))
os._exit(os.waitstatus_to_exitcode(status))
"""


@dataclass
class Proc:
    """One finished logscan process."""

    returncode: int | None  # None: killed at the timeout
    stdout: str
    stderr: str
    seconds: float
    max_rss_mb: float


def child_env(cache_dir: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "LOGSCAN_REQUIRE_TESTDATA")}
    env.update(CHILD_ENV, LOGSCAN_CACHE_DIR=str(cache_dir), PYTHONDONTWRITEBYTECODE="1")
    return env


def run_logscan(
    args: list[str], *, cwd: Path, env: dict, timeout: float = CASE_TIMEOUT_S, memory: int = MEMORY_CAP_BYTES
) -> Proc:
    """`python -m logscan ARGS` with an address-space cap and a timeout (its process group killed)."""
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err, tempfile.TemporaryDirectory() as tmp:
        report = Path(tmp) / "maxrss"
        started = time.monotonic()
        proc = subprocess.Popen(
            [sys.executable, "-S", "-c", _LAUNCH, str(memory), str(report), *args],
            cwd=cwd,
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=out,
            stderr=err,
            start_new_session=True,
        )
        try:
            proc.wait(timeout)
            timed_out = False
        except subprocess.TimeoutExpired:
            timed_out = True
        _kill_group(proc.pid)  # at the timeout, or helpers it left behind
        proc.wait()
        out.seek(0)
        err.seek(0)
        rss_kb = int(report.read_text() or 0) if report.exists() else 0
        return Proc(
            None if timed_out else proc.returncode,
            out.read().decode("utf-8", "replace"),
            err.read().decode("utf-8", "replace"),
            time.monotonic() - started,
            rss_kb / 1024,
        )


def _kill_group(pgid: int) -> None:
    try:
        os.killpg(pgid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


# ----------------------------------------------------------------------------------------------
# The oracle
# ----------------------------------------------------------------------------------------------

TRACEBACK = "Traceback (most recent call last)"
PY_WARNING = re.compile(r"^\S+\.py:\d+: \w*Warning: ", re.M)
MEMORY_TEXT = re.compile(
    r"MemoryError|Cannot allocate memory|out of memory|bad_alloc|failed to map segment|OpenBLAS error: Memory"
)
# C0 controls except tab and newline, DEL and C1 controls: they reach a terminal raw
RAW_CONTROL = re.compile(r"[\x00-\x08\x0b-\x1f\x7f\x80-\x9f]")


@dataclass
class Outcome:
    """What one case gave: its exit code, problems (empty: passed) and the first line to show."""

    case: Case
    exit_code: int | None
    problems: list[str]
    line: str = ""
    seconds: float = 0.0
    max_rss_mb: float = 0.0
    partial: bool = False
    known: str = ""  # the KNOWN_BUGS ids of the problems waived


def _first_line(text: str) -> str:
    for line in text.splitlines():
        if line.strip():
            return line.strip()[:200]
    return ""


def stream_problems(proc: Proc) -> list[str]:
    """Problems visible in one process as a whole: hang, signal, memory, traceback, raw text."""
    problems = []
    if proc.returncode is None:
        problems.append(f"timeout: still running after {proc.seconds:.0f} s (killed)")
    elif proc.returncode < 0:
        problems.append(f"killed by signal {-proc.returncode} ({signal.Signals(-proc.returncode).name})")
    text = proc.stderr
    memory = MEMORY_TEXT.search(text)
    if memory:
        problems.append(f"memory cap hit: {memory.group(0)}")
    if TRACEBACK in text:
        problems.append("Python traceback on stderr")
    warning = PY_WARNING.search(text)
    if warning:
        problems.append(f"Python warning on stderr: {_first_line(text[warning.start() :])}")
    raw = RAW_CONTROL.search(text)
    if raw:
        problems.append(f"raw control character {raw.group(0)!r} on stderr")
    return problems


def judge_entry(case: Case, entry: dict, is_error: bool) -> tuple[int | None, list[str], str, bool]:
    """(exit code, problems, line, partial) of one log's entry in the JSON summary."""
    code = entry.get("exit_code")
    problems = []
    if is_error:
        line = str(entry.get("error", ""))
        partial = False
        if line.startswith("('"):
            problems.append(f"error names the log as a Python tuple: {line[:80]}")
        if code in (0, 1):
            problems.append(f"exit {code} with an error: {line}")
    else:
        failed = entry.get("failed_detectors") or []
        line = str(failed[0]) if failed else str(entry.get("verdict", ""))
        partial = bool(entry.get("log", {}).get("partial"))
        unchecked = entry.get("unchecked") or []
        if code in (0, 1) and (partial or unchecked):
            problems.append(f"exit {code} on a log not fully checked (partial={partial}, unchecked={unchecked[:1]})")
        if code in (0, 1) and case.damaged:
            problems.append(f"exit {code} ({line}) although the mutation damaged the file")
    if code not in (0, 1, 2):
        problems.append(f"exit {code}: {line}")
    if MEMORY_TEXT.search(line):
        problems.append(f"memory cap hit: {line}")
    return code, problems, line, partial


# Bugs the campaign found that are not fixed yet: id -> does this problem show it. Each has a
# reproducer in tests/fuzz_regressions (xfail(strict) while open); a problem that shows one is
# counted as "known" instead of failing its case. None is open: mcap-chunk-skipped,
# json-huge-integer, profile-rate-tiny, profile-stale-overflow, runtime-warning-leak,
# ulog-missing-timestamp, unknown-detector-unnamed, error-tuple-name and
# output-replaces-special-file are fixed, their reproducers kept as regression tests.
KNOWN_BUGS: dict = {}


def waive_known(case: Case, entry: dict | None, problems: list[str]) -> tuple[list[str], str]:
    """(the problems no known bug explains, the ids of those that explain the others)."""
    left, known = [], []
    for problem in problems:
        ids = [bug for bug, shows in KNOWN_BUGS.items() if shows(case, entry or {}, problem)]
        if ids:
            known.extend(i for i in ids if i not in known)
        else:
            left.append(problem)
    return left, ",".join(known)


# ----------------------------------------------------------------------------------------------
# Batches
# ----------------------------------------------------------------------------------------------


@dataclass
class Runner:
    """Writes cases under ``workdir`` and runs them; ``env`` carries the shared numba cache."""

    workdir: Path
    env: dict
    timeout: float = CASE_TIMEOUT_S
    memory: int = MEMORY_CAP_BYTES
    counter: int = 0
    keep: Path | None = None  # failing cases copied here
    forget: bool = False

    def write(self, case: Case) -> tuple[Path, list[str]]:
        self.counter += 1
        stem = f"c{self.counter:06d}_{case.seed}_{case.kind}"
        path = self.workdir / f"{stem}{case.ext}"
        path.write_bytes(case.data)
        for suffix, data in case.sidecars.items():
            (self.workdir / f"{stem}{suffix}").write_bytes(data)
        args = list(case.args)
        if case.profile_arg is not None:
            profile = self.workdir / f"{stem}_profile.toml"
            profile.write_bytes(case.profile_arg.encode("utf-8", "surrogateescape"))
            args = ["--profile", profile.name]
        return path, args

    def analyze(self, cases: list[Case]) -> list[Outcome]:
        """Every case analysed: one process per group of cases sharing arguments; a batch that went
        wrong as a whole (hang, signal, traceback, warning, a log missing from the JSON) is split in
        halves until the cases that did it are alone."""
        written = [(case, *self.write(case)) for case in cases]
        groups: dict[tuple, list] = defaultdict(list)
        for case, path, args in written:
            groups[tuple(args)].append((case, path))
        outcomes: dict[int, Outcome] = {}
        for args, members in groups.items():
            for (case, _path), outcome in zip(members, self._batch(list(args), members), strict=True):
                outcomes[id(case)] = outcome
        for case, path, _args in written:
            self._cleanup(path, outcomes[id(case)])
        return [outcomes[id(case)] for case in cases]

    def _batch(self, args: list[str], members: list[tuple[Case, Path]]) -> list[Outcome]:
        names = [path.name for _case, path in members]
        timeout = self.timeout if len(members) == 1 else self.timeout + 5.0 * len(members)
        proc = run_logscan(
            ["analyze", *names, *args, "--no-report", "--json", "-", "-q"],
            cwd=self.workdir,
            env=self.env,
            timeout=timeout,
            memory=self.memory,
        )
        whole = stream_problems(proc)
        document = _json_document(proc.stdout)
        entries = _entries(document, names) if document else {}
        if document is not None and document.get("exit_code") != proc.returncode:
            whole.append(f"JSON exit_code {document.get('exit_code')} but the process exited {proc.returncode}")
        missing = [name for name in names if name not in entries]
        if len(members) > 1 and (whole or missing):  # bisect to the culprits
            half = len(members) // 2
            outcomes = self._batch(args, members[:half]) + self._batch(args, members[half:])
            if not any(o.problems or o.known for o in outcomes):  # each half is fine: the batch is not
                for outcome in outcomes:
                    outcome.problems.append(
                        f"in a batch of {len(members)}: {'; '.join(whole or ['missing from the JSON'])}"
                    )
            return outcomes
        if document is None:  # one log, no JSON: must be a one-line error naming it (exit 2)
            case, path = members[0]
            problems = list(whole)
            lines = [x for x in proc.stderr.splitlines() if x.startswith("logscan:")]  # warnings aside
            line = lines[0][:200] if lines else _first_line(proc.stderr)
            if proc.returncode != 2 or not line.startswith("logscan: error:") or path.stem not in line:
                problems.append(f"exit {proc.returncode} without a JSON summary: {line}")
            problems, known = waive_known(case, None, problems)
            return [Outcome(case, proc.returncode, problems, line, proc.seconds, proc.max_rss_mb, known=known)]
        outcomes = []
        for case, path in members:
            entry, is_error = entries[path.name]
            code, problems, line, partial = judge_entry(case, entry, is_error)
            problems, known = waive_known(case, entry, whole + problems)
            outcomes.append(Outcome(case, code, problems, line, proc.seconds, proc.max_rss_mb, partial, known))
        return outcomes

    def inspect(self, case: Case) -> Outcome:
        """`logscan inspect` on one case (text view): exit 0 or 2, PARTIAL when it is damaged."""
        path, _args = self.write(case)
        proc = run_logscan(
            ["inspect", path.name], cwd=self.workdir, env=self.env, timeout=self.timeout, memory=self.memory
        )
        problems = stream_problems(proc)
        raw = RAW_CONTROL.search(proc.stdout)
        if raw:
            problems.append(f"raw control character {raw.group(0)!r} on stdout")
        if proc.returncode not in (0, 2, None):
            problems.append(f"inspect exit {proc.returncode}: {_first_line(proc.stderr)}")
        if proc.returncode == 0 and case.damaged and "PARTIAL" not in proc.stdout:
            problems.append("inspect exit 0 without PARTIAL although the mutation damaged the file")
        problems, known = waive_known(case, None, problems)
        outcome = Outcome(case, proc.returncode, problems, _first_line(proc.stderr), proc.seconds, proc.max_rss_mb)
        outcome.known = known
        self._cleanup(path, outcome)
        return outcome

    def _cleanup(self, path: Path, outcome: Outcome) -> None:
        stem = path.name[: -len(outcome.case.ext)]
        files = [p for p in self.workdir.iterdir() if p.name.startswith(stem)]
        if outcome.problems and self.keep is not None:
            self.keep.mkdir(parents=True, exist_ok=True)
            for file in files:
                shutil.copy2(file, self.keep / file.name)
            (self.keep / f"{stem}.txt").write_text(
                f"{outcome.case.label}\nexit {outcome.exit_code}\n" + "\n".join(outcome.problems) + "\n",
                encoding="utf-8",
            )
        for file in files:
            file.unlink()
        if self.forget:  # a long campaign keeps the labels of its cases, not their bytes
            outcome.case.data, outcome.case.sidecars, outcome.case.profile_arg = b"", {}, None


def _json_document(stdout: str) -> dict | None:
    try:
        document = json.loads(stdout)
    except ValueError:
        return None
    return document if isinstance(document, dict) else None


def _entries(document: dict, names: list[str]) -> dict[str, tuple[dict, bool]]:
    """Each log's entry, by the file name it was given as: (entry, is an error entry)."""
    out: dict[str, tuple[dict, bool]] = {}
    for entry in document.get("logs", []):
        out[Path(str(entry.get("file"))).name] = (entry, False)
    for entry in document.get("errors", []):
        where = entry.get("file")
        name = where[0] if isinstance(where, list) else where
        out[Path(str(name)).name] = (entry, True)
    return {name: out[name] for name in names if name in out}


def warm_up(runner: Runner, seeds: dict[str, Seed]) -> list[str]:
    """Analyse every intact seed once (compiles the numba kernels into the shared cache) and record
    its exit code; the problems of seeds that are not clean 0/1 runs."""
    cases = [Case(s.name, s.fmt, "intact", "", s.data, s.ext, args=s.args, sidecars=s.sidecars) for s in seeds.values()]
    runner.timeout = max(runner.timeout, 300.0)  # the first run compiles
    try:
        outcomes = runner.analyze(cases)
    finally:
        runner.timeout = CASE_TIMEOUT_S
    problems = []
    for outcome in outcomes:
        seeds[outcome.case.seed].exit_code = outcome.exit_code
        if outcome.problems or outcome.exit_code not in (0, 1):
            problems.append(f"seed {outcome.case.seed}: exit {outcome.exit_code} {outcome.line} {outcome.problems}")
    return problems


# ----------------------------------------------------------------------------------------------
# The campaign
# ----------------------------------------------------------------------------------------------


def plan(seeds: dict[str, Seed], n: int, rng: random.Random) -> list[tuple[str, str, int]]:
    """``n`` (seed, kind, case seed) triples, the formats and their kinds in turn."""
    by_format: dict[str, list[str]] = defaultdict(list)
    for seed in seeds.values():
        by_format[seed.fmt].append(seed.name)
    slots = [(fmt, kind) for fmt in sorted(by_format) for kind in MUTATORS[fmt]]
    out = []
    for i in range(n):
        fmt, kind = slots[i % len(slots)]
        out.append((rng.choice(by_format[fmt]), kind, rng.randrange(2**32)))
    return out


def run_campaign(seeds: dict[str, Seed], runner_for, n: int, jobs: int, rng: random.Random, inspect_every: int = 20):
    """Yield outcomes of ``n`` cases (+ an `inspect` run every ``inspect_every`` cases)."""
    work = plan(seeds, n, rng)
    batches: dict[tuple, list] = defaultdict(list)
    for seed_name, kind, case_seed in work:
        batches[(seeds[seed_name].fmt, kind)].append((seed_name, kind, case_seed))
    chunks = []
    for items in batches.values():
        for i in range(0, len(items), BATCH_SIZE):
            chunks.append(items[i : i + BATCH_SIZE])

    def run_chunk(chunk):
        runner = runner_for()
        cases = [mutate(seeds[s], k, random.Random(c)) for s, k, c in chunk]
        inspected = [runner.inspect(dataclasses.replace(c)) for c in cases[::inspect_every]]  # a copy to forget
        single = [c for c in cases if c.profile_arg is not None]
        batched = [c for c in cases if c.profile_arg is None]
        outcomes = runner.analyze(batched) if batched else []
        outcomes += [runner.analyze([c])[0] for c in single]
        return outcomes, inspected

    with ThreadPoolExecutor(max_workers=jobs) as pool:
        yield from pool.map(run_chunk, chunks)


def print_table(results: list[Outcome], inspected: list[Outcome], seconds: float, seeds: dict[str, Seed]) -> None:
    """Outcomes per format and mutation kind (Markdown); "verdict changed": exit 0 <-> 1 against
    the intact seed's, exit 3 cases and failed cases with their first line."""
    rows: dict[tuple, dict] = defaultdict(lambda: Counter())
    rss: dict[tuple, float] = defaultdict(float)
    for outcome in results:
        key = (outcome.case.fmt, outcome.case.kind)
        row = rows[key]
        row["cases"] += 1
        code = outcome.exit_code
        row[str(code) if code in (0, 1, 2, 3) else ("timeout" if code is None else "other")] += 1
        row["partial"] += outcome.partial
        row["changed"] += code in (0, 1) and code != seeds[outcome.case.seed].exit_code
        row["problems"] += bool(outcome.problems)
        row["known"] += bool(outcome.known) and not outcome.problems
        rss[key] = max(rss[key], outcome.max_rss_mb)
    print(f"\n{len(results)} analyze cases + {len(inspected)} inspect runs in {seconds / 60:.1f} min\n")
    columns = "cases,exit 0,exit 1,exit 2,exit 3,timeout,other,partial,verdict changed,failed,known bug,max RSS MB"
    columns = columns.split(",")
    print("| format | mutation | " + " | ".join(columns) + " |")
    print("|---|---|" + "---:|" * len(columns))
    keys = ("cases", "0", "1", "2", "3", "timeout", "other", "partial", "changed", "problems", "known")
    total = Counter()
    for key in sorted(rows):
        row = rows[key]
        total.update(row)
        cells = [row[c] for c in keys]
        print(f"| {key[0]} | {key[1]} | " + " | ".join(map(str, cells)) + f" | {rss[key]:.0f} |")
    cells = [total[c] for c in keys]
    print("| all | | " + " | ".join(map(str, cells)) + f" | {max(rss.values(), default=0):.0f} |")
    codes = Counter(o.exit_code for o in inspected)
    failed_inspect = [o for o in inspected if o.problems]
    print(f"\ninspect: {dict(sorted(codes.items(), key=str))}, failed {len(failed_inspect)}")
    failed = [o for o in results if o.problems] + failed_inspect
    exit3 = [o for o in results if o.exit_code == 3]
    if exit3:
        print(f"\nexit 3 ({len(exit3)}):")
        for o in exit3[:40]:
            print(f"  {o.case.label[:140]}\n    {o.line[:200]}")
    moved = [o for o in results if o.case.kind == "time" and o.exit_code in (0, 1)]
    moved = [o for o in moved if o.exit_code != seeds[o.case.seed].exit_code]
    if moved:
        print(f"\nverdict changed by one outlying timestamp ({len(moved)}):")
        for o in moved[:20]:
            print(f"  {o.case.label[:160]}: exit {seeds[o.case.seed].exit_code} -> {o.exit_code} ({o.line[:80]})")
    if failed:
        print(f"\nfailed cases ({len(failed)}), by problem:")
        by_problem = Counter(re.sub(r"\d+", "N", p)[:120] for o in failed for p in o.problems)
        for problem, count in by_problem.most_common(30):
            print(f"  {count:6d}  {problem}")
        for o in failed[:30]:
            print(f"  {o.case.label[:140]}\n    exit {o.exit_code}: {o.problems[0][:200]}")
    known = Counter(bug for o in results + inspected for bug in o.known.split(",") if bug)
    if known:
        print(f"\nknown bugs: {dict(known)}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=10_000, help="analyze cases (default 10000)")
    parser.add_argument("--jobs", type=int, default=2, help="processes at a time (default 2)")
    parser.add_argument("--seed", type=int, default=1, help="random seed of the campaign (default 1)")
    parser.add_argument("--keep", type=Path, help="copy failing cases (with a .txt of what failed) here")
    parser.add_argument("--small", action="store_true", help="only the short seeds (no 60 s sample logs)")
    opts = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="logscan-fuzz-") as tmp:
        root = Path(tmp)
        seeds = build_seeds(root / "seeds", full=not opts.small)
        env = child_env(root / "cache")
        counter = iter(range(10**9))

        def runner_for() -> Runner:
            workdir = root / f"w{next(counter)}"
            workdir.mkdir()
            return Runner(workdir, env, keep=opts.keep, forget=True)

        started = time.monotonic()
        problems = warm_up(runner_for(), seeds)
        print(f"seeds: {', '.join(f'{s.name} ({s.fmt}, exit {s.exit_code})' for s in seeds.values())}")
        print(f"warm-up (compiling into the shared cache): {time.monotonic() - started:.0f} s")
        for problem in problems:
            print(f"  SEED PROBLEM: {problem}")
        started = time.monotonic()
        results: list[Outcome] = []
        inspected: list[Outcome] = []
        for outcomes, inspects in run_campaign(seeds, runner_for, opts.cases, opts.jobs, random.Random(opts.seed)):
            results.extend(outcomes)
            inspected.extend(inspects)
            if len(results) % 500 < BATCH_SIZE:
                print(f"  {len(results)} cases, {time.monotonic() - started:.0f} s", file=sys.stderr, flush=True)
        print_table(results, inspected, time.monotonic() - started, seeds)
        failed = [o for o in results + inspected if o.problems]
        return 1 if failed or problems else 0


if __name__ == "__main__":
    sys.exit(main())
