"""Damage the readers must count (issue 31): mutators and a campaign through `python -m logscan`.

Classes (each case is a healthy seed with one kind of damage, or a valid oddity):

  mcap_inner      an edit inside a chunk whose CRC is recomputed (and the data-section CRC, when the
                  seed has one): a message's channel id made undefined, a Channel record's id made
                  another channel's, a message's log_time beyond int64 ns. Damaged.
  mcap_lz4_lie    an lz4 chunk whose header declares another uncompressed size (1 GiB, 500 MiB, 2x,
                  +1, -1, half, 0), or whose payload really inflates to 128 or 448 MiB of zeros (not
                  records); the data-section CRC recomputed. Damaged.
  mcap_zero_chunk the seed rewritten with one more topic holding a single message of 1-16 MiB of zeros
                  (lz4 or zstd): valid, extremely compressible; must read as the seed does (same exit).
  ulog_subscription  a ULog 'A' record's type byte made undefined, an 'A' record reusing another's
                  msg_id, data messages' type bytes made undefined, a data message's msg_id made one
                  no 'A' record subscribes. Damaged.
  csv_short_row   the CSV cut inside its last row, before its last separator (fewer fields than the
                  header, no line break). Damaged.

A case passes when its exit code is 0, 1 or 2 (never 3), no traceback, hang or memory cap (2 GiB
address space), 0/1 only for a fully read and checked log and never for a damaged case, and a valid
case gets its seed's exit code. The runner, seeds and oracle are `fuzz_campaign.py`'s.

    python bench/fuzz_damage.py --cases 300 --jobs 2 --seed 1 --json /tmp/damage.json
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import random
import struct
import sys
import tempfile
import time
import zlib
from collections import Counter, defaultdict
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path

BENCH = Path(__file__).resolve().parent


def _campaign_module():
    if "fuzz_campaign" in sys.modules:
        return sys.modules["fuzz_campaign"]
    spec = importlib.util.spec_from_file_location("fuzz_campaign", BENCH / "fuzz_campaign.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["fuzz_campaign"] = module  # dataclasses look their module up while it loads
    spec.loader.exec_module(module)
    return module


fc = _campaign_module()

CLASSES = ("mcap_inner", "mcap_lz4_lie", "mcap_zero_chunk", "ulog_subscription", "csv_short_row")
CLASS_FORMAT = {
    "mcap_inner": "mcap",
    "mcap_lz4_lie": "mcap",
    "mcap_zero_chunk": "mcap",
    "ulog_subscription": "ulog",
    "csv_short_row": "csv",
}
SEED_NAMES = {
    "mcap": ("jackal_lz4", "jackal_zstd"),
    "ulog": ("ulog_tagged", "ulog_small"),  # healthy (ulog_appended alarms), ulog_small only in full seeds
    "csv": ("csv_ns", "csv_s_semicolon"),
}
_ULOG_TYPES = frozenset(b"BFIMPQARDLCSO")
OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK, OP_DATA_END = 0x03, 0x04, 0x05, 0x06, 0x0F


def damage_seeds(seeds: dict) -> dict:
    """The healthy seeds of the damage classes (jackal_zstd is jackal_lz4 written with zstd)."""
    out = {name: seeds[name] for names in SEED_NAMES.values() for name in names if name in seeds}
    lz4 = out.get("jackal_lz4")
    if lz4 is not None and "jackal_zstd" not in out:
        data = fc.write_mcap_content(lz4.messages, compression="zstd", data_crc=True)
        out["jackal_zstd"] = replace(lz4, name="jackal_zstd", data=data, exit_code=None)
    return out


# -- MCAP: chunks edited with valid CRCs ------------------------------------------------------------


def _chunks(data: bytes) -> list[tuple[int, int]]:
    return [(start, end) for op, start, end in fc.mcap_records(data) if op == OP_CHUNK]


def _parse_chunk(data: bytes, start: int) -> dict:
    t0, t1, size, crc = struct.unpack_from("<QQQI", data, start + 9)
    pos = start + 9 + 28
    (n,) = struct.unpack_from("<I", data, pos)
    compression = data[pos + 4 : pos + 4 + n].decode()
    pos += 4 + n
    (stored,) = struct.unpack_from("<Q", data, pos)
    payload = data[pos + 8 : pos + 8 + stored]
    return {"t0": t0, "t1": t1, "size": size, "crc": crc, "compression": compression, "payload": payload}


def _decompress(chunk: dict) -> bytes:
    if chunk["compression"] == "lz4":
        import lz4.frame

        return lz4.frame.decompress(chunk["payload"])
    if chunk["compression"] == "zstd":
        import zstandard

        return zstandard.ZstdDecompressor().decompress(chunk["payload"], max_output_size=chunk["size"])
    return chunk["payload"]


def _compress(compression: str, inner: bytes) -> bytes:
    if compression == "lz4":
        import lz4.frame

        return lz4.frame.compress(inner)
    if compression == "zstd":
        import zstandard

        return zstandard.ZstdCompressor().compress(inner)
    return inner


def _chunk_record(chunk: dict, inner: bytes, *, declared: int | None = None, payload: bytes | None = None) -> bytes:
    payload = _compress(chunk["compression"], inner) if payload is None else payload
    crc = zlib.crc32(inner) if chunk["crc"] else 0
    name = chunk["compression"].encode()
    size = len(inner) if declared is None else declared
    body = struct.pack("<QQQI", chunk["t0"], chunk["t1"], size, crc) + struct.pack("<I", len(name)) + name
    body += struct.pack("<Q", len(payload)) + payload
    return bytes([OP_CHUNK]) + struct.pack("<Q", len(body)) + body


def _with_data_crc(data: bytes) -> bytes:
    """``data`` with its DataEnd CRC recomputed (left 0 when the seed has none)."""
    for op, start, _end in fc.mcap_records(data):
        if op == OP_DATA_END:
            (old,) = struct.unpack_from("<I", data, start + 9)
            if old == 0:
                return data
            out = bytearray(data)
            struct.pack_into("<I", out, start + 9, zlib.crc32(data[:start]))
            return bytes(out)
    return data


def _inner_records(inner: bytes) -> list[tuple[int, int, int]]:
    out, pos = [], 0
    while pos + 9 <= len(inner):
        op = inner[pos]
        (length,) = struct.unpack_from("<Q", inner, pos + 1)
        out.append((op, pos + 9, pos + 9 + length))
        pos += 9 + length
    return out


def mcap_inner(seed, rng: random.Random):
    data = seed.data
    start, end = rng.choice(_chunks(data))
    chunk = _parse_chunk(data, start)
    inner = bytearray(_decompress(chunk))
    records = _inner_records(bytes(inner))
    messages = [r for r in records if r[0] == OP_MESSAGE]
    channel_recs = [r for r in records if r[0] == OP_CHANNEL]
    defined = sorted(seed.messages.channels)
    kinds = ["undefined_channel", "log_time"] + (["channel_id"] if channel_recs and len(defined) > 1 else [])
    kind = rng.choice(kinds)
    if kind == "undefined_channel":
        picked = rng.sample(messages, rng.choice((1, 1, 3, 10)) if len(messages) >= 10 else 1)
        new_id = max(defined) + 1 + rng.randrange(1000)
        for _op, body, _end in picked:
            struct.pack_into("<H", inner, body, new_id)
        detail = f"{len(picked)} message(s) of the chunk at {start} on undefined channel {new_id}"
    elif kind == "log_time":
        _op, body, _end = rng.choice(messages)
        value = rng.choice((2**63, 2**64 - 1, 2**63 + rng.randrange(2**40)))
        struct.pack_into("<Q", inner, body + 6, value)
        detail = f"a message's log_time {value} in the chunk at {start}"
    else:
        _op, body, _end = rng.choice(channel_recs)
        (old,) = struct.unpack_from("<H", inner, body)
        new_id = rng.choice([c for c in defined if c != old])
        struct.pack_into("<H", inner, body, new_id)
        detail = f"Channel record {old} -> id {new_id} in the chunk at {start}"
    out = _with_data_crc(data[:start] + _chunk_record(chunk, bytes(inner)) + data[end:])
    return fc.Case(seed.name, "mcap", "mcap_inner", detail, out, ".mcap", damaged=True)


def mcap_lz4_lie(seed, rng: random.Random):
    data = seed.data
    start, end = rng.choice(_chunks(data))
    chunk = _parse_chunk(data, start)
    actual = chunk["size"]
    if rng.random() < 0.15:  # a payload that really inflates (zeros) to what it declares, up to the cap
        import lz4.frame

        zeros = rng.choice((128, 448)) << 20
        record = _chunk_record(chunk, b"", declared=zeros, payload=lz4.frame.compress(bytes(zeros)))
        out = _with_data_crc(data[:start] + record + data[end:])
        detail = f"lz4 chunk at {start} replaced by {zeros >> 20} MiB of zeros (declared so; no records)"
        return fc.Case(seed.name, "mcap", "mcap_lz4_lie", detail, out, ".mcap", damaged=True)
    lie = rng.choice((1 << 30, 500 << 20, 2 * actual, actual + 1, actual - 1, actual // 2, 0))
    inner = _decompress(chunk)
    record = _chunk_record(chunk, inner, declared=lie, payload=chunk["payload"])
    out = _with_data_crc(data[:start] + record + data[end:])
    detail = f"{chunk['compression']} chunk at {start} declares {lie} bytes, holds {actual}"
    return fc.Case(seed.name, "mcap", "mcap_lz4_lie", detail, out, ".mcap", damaged=True)


def mcap_zero_chunk(seed, rng: random.Random):
    content = seed.messages
    zeros = rng.choice((1, 4, 4, 16)) << 20
    compression = rng.choice(("lz4", "zstd"))
    cid = max(content.channels) + 1
    times = [m[1] for m in content.messages]
    t = times[len(times) // 2]
    extra = replace(
        content,
        channels={**content.channels, cid: ("/zeros", "raw", 0, {})},
        messages=sorted([*content.messages, (cid, t, t, 0, bytes(zeros))], key=lambda m: m[1]),
    )
    out = fc.write_mcap_content(extra, compression=compression, data_crc=seed.data_crc)
    detail = f"one {zeros >> 20} MiB all-zero message on /zeros, {compression} chunks"
    return fc.Case(seed.name, "mcap", "mcap_zero_chunk", detail, out, ".mcap", damaged=False)


# -- ULog: subscriptions and message types ------------------------------------------------------------


def _undefined_type(rng: random.Random) -> int:
    return rng.choice([t for t in range(1, 256) if t not in _ULOG_TYPES])


def ulog_subscription(seed, rng: random.Random):
    data = bytearray(seed.data)
    messages = fc.ulog_messages(bytes(data))
    subs = [m for m in messages if m[2] == "A"]
    datas = [m for m in messages if m[2] == "D"]
    ids = {struct.unpack_from("<H", data, s + 4)[0] for s, _e, _k in subs}
    kind = rng.choice(("A_type", "A_reuses_id", "D_type", "D_unsubscribed"))
    if kind == "A_type":
        start, _end, _k = rng.choice(subs)
        data[start + 2] = _undefined_type(rng)
        detail = f"'A' record at {start}: type byte 0x{data[start + 2]:02x}"
    elif kind == "A_reuses_id":
        one, other = rng.sample(subs, 2)
        (msg_id,) = struct.unpack_from("<H", data, one[0] + 4)
        struct.pack_into("<H", data, other[0] + 4, msg_id)
        detail = f"'A' record at {other[0]} reuses msg_id {msg_id}"
    elif kind == "D_type":
        picked = rng.sample(datas, rng.choice((1, 2, 5)))
        for start, _end, _k in picked:
            data[start + 2] = _undefined_type(rng)
        detail = f"{len(picked)} data message(s): type byte undefined"
    else:
        start, _end, _k = rng.choice(datas)
        new_id = max(ids) + 1 + rng.randrange(100)
        struct.pack_into("<H", data, start + 3, new_id)
        detail = f"data message at {start}: msg_id {new_id}, no 'A' record subscribes it"
    return fc.Case(seed.name, "ulog", "ulog_subscription", detail, bytes(data), ".ulg", damaged=True)


# -- CSV: a last row cut short ---------------------------------------------------------------------


def csv_short_row(seed, rng: random.Random):
    data = seed.data.rstrip(b"\r\n")
    last_start = data.rfind(b"\n") + 1
    sep = b";" if b";" in data[last_start:] else b","
    last_sep = data.rfind(sep)
    cut = rng.randrange(last_start + 1, last_sep + 1)  # before the last separator: a field short
    detail = f"cut at byte {cut} inside the last row ({last_sep + 1 - last_start} bytes before its last field)"
    return fc.Case(seed.name, "csv", "csv_short_row", detail, data[:cut], ".csv", damaged=True, sidecars=seed.sidecars)


MUTATORS = {
    "mcap_inner": mcap_inner,
    "mcap_lz4_lie": mcap_lz4_lie,
    "mcap_zero_chunk": mcap_zero_chunk,
    "ulog_subscription": ulog_subscription,
    "csv_short_row": csv_short_row,
}


def draw(seeds: dict, damage_class: str, n: int, rng: random.Random) -> list:
    """``n`` cases of ``damage_class`` on its seeds (the lz4 lie on lz4 seeds only)."""
    names = [name for name in SEED_NAMES[CLASS_FORMAT[damage_class]] if name in seeds]
    if damage_class == "mcap_lz4_lie":
        names = [name for name in names if name.endswith("lz4")]
    cases = []
    for _ in range(n):
        seed = seeds[rng.choice(names)]
        case = MUTATORS[damage_class](seed, random.Random(rng.randrange(2**32)))
        case.args = seed.args
        cases.append(case)
    return cases


def judge(seeds: dict, outcomes: list) -> list:
    """The runner's oracle, plus: a valid case gets its seed's exit code."""
    for outcome in outcomes:
        case = outcome.case
        expected = seeds[case.seed].exit_code
        if not case.damaged and expected is not None and outcome.exit_code != expected:
            outcome.problems.append(f"exit {outcome.exit_code} on a valid log whose seed exits {expected}")
    return outcomes


def exit0_on_damage(outcome) -> bool:
    return outcome.case.damaged and outcome.exit_code in (0, 1)


def summary(outcomes: list) -> dict:
    """Per class: cases, exit codes, exit 0/1 on damaged input, failures, peak RSS max."""
    by_class: dict[str, list] = defaultdict(list)
    for outcome in outcomes:
        by_class[outcome.case.kind].append(outcome)
    return {
        name: {
            "cases": len(group),
            "exit_codes": dict(sorted(Counter(str(o.exit_code) for o in group).items())),
            "exit_0_or_1_on_damaged": sum(exit0_on_damage(o) for o in group),
            "failed": sum(bool(o.problems) for o in group),
            "peak_rss_mb_max": round(max(o.max_rss_mb for o in group), 1),
            "first_problems": [f"{o.case.label[:120]}: {'; '.join(o.problems)[:200]}" for o in group if o.problems][:5],
        }
        for name, group in sorted(by_class.items())
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=300, help="cases per class")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--classes", default=",".join(CLASSES))
    parser.add_argument("--json", type=Path, help="write the summary here")
    parser.add_argument("--keep", type=Path, help="copy failing cases here")
    args = parser.parse_args(argv)
    rng = random.Random(args.seed)
    import logscan

    with tempfile.TemporaryDirectory(prefix="fuzz-damage-") as tmp:
        root = Path(tmp)
        seeds = damage_seeds(fc.build_seeds(root / "seeds", full=True))
        env = fc.child_env(logscan.cache_dir())
        warm = fc.Runner(root / "warm", env)
        warm.workdir.mkdir()
        problems = fc.warm_up(warm, seeds)
        print("seeds:", {s.name: s.exit_code for s in seeds.values()}, problems or "", flush=True)
        batches = []
        for damage_class in args.classes.split(","):
            cases = draw(seeds, damage_class, args.cases, rng)
            batches += [cases[i : i + fc.BATCH_SIZE] for i in range(0, len(cases), fc.BATCH_SIZE)]
        started = time.monotonic()

        def run(index_batch):
            index, batch = index_batch
            work = root / f"w{index}"
            work.mkdir()
            return judge(seeds, fc.Runner(work, env, keep=args.keep).analyze(batch))

        outcomes = []
        with ThreadPoolExecutor(args.jobs) as pool:
            for done in pool.map(run, enumerate(batches)):
                outcomes += done
                print(f"{len(outcomes)} cases, {time.monotonic() - started:.0f} s", file=sys.stderr, flush=True)
    report = {"seeds": {s.name: s.exit_code for s in seeds.values()}, "classes": summary(outcomes)}
    text = json.dumps(report, indent=2)
    print(text)
    if args.json:
        args.json.write_text(text + "\n", encoding="utf-8")
    return 1 if any(o.problems for o in outcomes) else 0


if __name__ == "__main__":
    sys.exit(main())
