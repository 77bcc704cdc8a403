"""Hostile and odd inputs end in one line and exit 2, quickly and in bounded memory: decompression
bombs and absurd sizes in MCAP and ULog files, FIFOs and devices given as logs or found in
directories, files and directories the OS refuses to read, CSV numbers beyond every integer type,
and profiles nested 10,000 deep or 50 MB long."""

from __future__ import annotations

import errno
import os
import struct
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from logscan.errors import CorruptLogError, InputError, ProfileError
from logscan.fleet import expand_logs
from logscan.profiles import parse_profile
from logscan.readers import detect_format, read_log

MCAP_MAGIC = b"\x89MCAP0\r\n"
AS_ROOT = hasattr(os, "geteuid") and os.geteuid() == 0  # root reads files whatever their permissions


# -- hand-made MCAP and zstd bytes -----------------------------------------------------------------


def _record(op: int, body: bytes) -> bytes:
    return bytes([op]) + struct.pack("<Q", len(body)) + body


def _string(text: str) -> bytes:
    return struct.pack("<I", len(text)) + text.encode()


def _zstd_frame(prefix: bytes, zeros: int) -> bytes:
    """A zstd frame of ``prefix`` (one raw block) then ``zeros`` zero bytes as RLE blocks of 128 KiB:
    4 bytes per block, so 33 KB of frame decompress to 1 GB, and the frame states its content size."""
    # magic; descriptor: 8-byte content size, window descriptor present; window 2**17
    out = bytearray(struct.pack("<I", 0xFD2FB528)) + bytes([0xC0, 7 << 3]) + struct.pack("<Q", len(prefix) + zeros)
    if prefix:
        out += ((0 if zeros else 1) | (0 << 1) | (len(prefix) << 3)).to_bytes(3, "little") + prefix  # raw block
    left = zeros
    while left:
        size = min(1 << 17, left)
        left -= size
        out += ((1 if left == 0 else 0) | (1 << 1) | (size << 3)).to_bytes(3, "little") + b"\x00"  # RLE block
    return bytes(out)


def _chunk(compression: str, payload: bytes, declared: int) -> bytes:
    """A Chunk record (no CRC) holding ``payload`` that says it decompresses to ``declared`` bytes."""
    body = struct.pack("<QQQI", 0, 0, declared, 0) + _string(compression) + struct.pack("<Q", len(payload)) + payload
    return _record(0x06, body)


def _mcap(*chunks: bytes) -> bytes:
    data = _record(0x01, _string("") + _string("hostile")) + b"".join(chunks) + _record(0x0F, struct.pack("<I", 0))
    return MCAP_MAGIC + data + _record(0x02, struct.pack("<QQI", 0, 0, 0)) + MCAP_MAGIC


def _message_prefix(body_size: int) -> bytes:
    """Record and message header of one message of channel 1 whose data are ``body_size`` bytes."""
    return bytes([0x05]) + struct.pack("<Q", 22 + body_size) + struct.pack("<HIQQ", 1, 0, 1, 1)


def _zstd_bomb(path: Path, size: int = 1_200_000_000) -> Path:
    path.write_bytes(_mcap(_chunk("zstd", _zstd_frame(b"", size), size)))
    return path


# -- bounded decompression -------------------------------------------------------------------------


def test_a_zstd_bomb_is_refused_before_it_is_decompressed(tmp_path, sample):
    bomb = _zstd_bomb(tmp_path / "bomb.mcap")
    assert bomb.stat().st_size < 40_000
    script = textwrap.dedent(
        """
        import resource, sys, time
        from logscan.errors import CorruptLogError
        from logscan.readers import read_log
        read_log(sys.argv[2])  # imports and compiled kernels first: they are not the bomb's
        base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        start = time.perf_counter()
        try:
            read_log(sys.argv[1])
            print("read")
        except CorruptLogError as exc:
            print(exc.one_line())
        print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - base, time.perf_counter() - start)
        """
    )
    proc = subprocess.run(
        [sys.executable, "-c", script, str(bomb), str(sample("quad_healthy.mcap"))],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    message, figures = proc.stdout.strip().splitlines()
    grew_kb = figures.split()[0]  # and the seconds taken: timed limits belong in bench/
    assert "decompression bomb" in message and str(bomb) in message
    assert int(grew_kb) < 200 * 1024, f"RSS grew {int(grew_kb) // 1024} MB"


def test_a_zstd_bomb_exits_2_with_one_line(cli_process, tmp_path):
    bomb = _zstd_bomb(tmp_path / "bomb.mcap")
    result = cli_process("inspect", bomb, timeout=120)
    assert result.exit_code == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and str(bomb) in lines[0] and "1200000000 bytes uncompressed" in lines[0]


def test_a_chunk_declaring_more_than_a_gib_is_refused_whatever_its_payload(tmp_path):
    import lz4.frame

    path = tmp_path / "huge.mcap"
    path.write_bytes(_mcap(_chunk("lz4", lz4.frame.compress(b"\x00" * 100), 1 << 40)))
    with pytest.raises(CorruptLogError, match="decompression bomb"):
        read_log(path)


def test_many_small_chunks_may_not_decompress_past_the_file_budget(tmp_path, monkeypatch):
    """Each chunk (1 MiB of one zero message) is under the per-chunk cap; 100 of them from a 15 KB
    file are 100 MiB: past a file budget of 64 MiB the chunks are skipped, the rest is kept."""
    from logscan.readers.mcap import scan

    monkeypatch.setattr(scan, "MIN_FILE_BUDGET_BYTES", 64 << 20)
    body = (1 << 20) - 31
    chunk = _chunk("zstd", _zstd_frame(_message_prefix(body), body), 31 + body)
    path = tmp_path / "many.mcap"
    path.write_bytes(_mcap(*[chunk] * 100))
    assert path.stat().st_size < 20_000
    log = read_log(path)
    assert log.source.partial
    assert "36 damaged chunk(s) skipped" in log.source.partial_reason
    assert "1000x the file size" in log.source.partial_reason
    assert "recovered 64 messages" in log.source.partial_reason


def test_a_zstd_frame_producing_more_than_its_chunk_declares_stops_there(tmp_path):
    path = tmp_path / "liar.mcap"
    path.write_bytes(_mcap(_chunk("zstd", _zstd_frame(b"", 5000), 1000)))
    with pytest.raises(CorruptLogError, match="chunk decompresses to more than the 1000 bytes its header declares"):
        read_log(path)


def test_lz4_output_stops_past_the_declared_size(tmp_path):
    import lz4.frame

    path = tmp_path / "long.mcap"
    path.write_bytes(_mcap(_chunk("lz4", lz4.frame.compress(b"\x00" * (1 << 20)), 1000)))
    with pytest.raises(CorruptLogError, match="chunk decompresses to more than the 1000 bytes its header declares"):
        read_log(path)


def test_cdr_layouts_of_huge_fixed_arrays_fall_back_to_the_decoder():
    from logscan.readers.mcap.cdr import cdr_layout
    from logscan.readers.mcap.scan_records import SchemaRec

    flat = SchemaRec(1, "pkg/msg/Big", "ros2msg", b"float64[1000000] x")
    nested = SchemaRec(
        2,
        "pkg/msg/Outer",
        "ros2msg",
        b"Mid[300] m\n================================================================================\n"
        b"MSG: pkg/Mid\nInner[300] i\n"
        b"================================================================================\n"
        b"MSG: pkg/Inner\nfloat64[300] v\n",
    )
    assert cdr_layout(flat) is None
    assert cdr_layout(nested) is None
    small = cdr_layout(SchemaRec(3, "pkg/msg/Small", "ros2msg", b"float64[9] covariance\nuint8[1000000] blob"))
    assert small is not None and len(small.paths) == 9 and small.skipped == ["blob"]


def test_embedded_truth_json_nested_too_deep_is_ignored_with_a_warning(tmp_path):
    from logscan.readers.mcap import TopicData, write_mcap

    path = tmp_path / "deep_truth.mcap"
    t = np.arange(10, dtype=np.int64) * 10_000_000
    topics = {"/x": TopicData("test/X", t, {"v": np.zeros(10)})}
    write_mcap(path, topics, metadata={"logscan.truth": {"json": "[" * 100_000}})
    log = read_log(path)
    assert log.truth is None
    assert any("logscan.truth" in w and "ignored" in w for w in log.source.warnings)


# -- ULog message formats ------------------------------------------------------------------------


def _ulog(formats: list[bytes]) -> bytes:
    def message(kind: str, body: bytes) -> bytes:
        return struct.pack("<HB", len(body), ord(kind)) + body

    out = b"ULog\x01\x12\x35\x01" + struct.pack("<Q", 0) + message("B", bytes(40))
    out += b"".join(message("F", f) for f in formats)
    out += message("A", b"\x00" + struct.pack("<H", 0) + b"A")
    return out + message("D", struct.pack("<H", 0) + struct.pack("<Q", 1) + bytes(16))


@pytest.mark.parametrize(
    "formats",
    [
        [b"A:uint64_t timestamp;A a;"],  # contains itself: pyulog recursed into a RecursionError (exit 3)
        [b"C:float[60000] x;", b"B:C[60000] c;", b"A:uint64_t timestamp;B[60000] b;"],  # 2e14 fields: hung
    ],
    ids=["self-containing", "multiplying"],
)
def test_ulog_formats_that_cannot_fit_a_message_are_refused_quickly(cli_process, tmp_path, formats):
    path = tmp_path / "formats.ulg"
    path.write_bytes(_ulog(formats))
    result = cli_process("inspect", path, timeout=60)
    assert result.exit_code == 0, result.stderr
    assert "PARTIAL" in result.stdout and "no data message was recovered" in result.stdout


def test_ulog_format_sizes_are_counted_once_per_format():
    from pyulog import ULog

    from logscan.readers.ulog_damage import format_bytes

    def fmt(text: bytes):
        return ULog.MessageFormat(text, None)

    formats = {f.name: f for f in (fmt(b"V:float[3] xyz;"), fmt(b"A:uint64_t timestamp;V[10] v;uint8_t[5] pad;"))}
    assert format_bytes("A", formats) == 8 + 10 * 12 + 5
    formats["B"] = fmt(b"B:A[1000] a;")
    with pytest.raises(ValueError, match="more than a ULog message can hold"):
        format_bytes("B", formats)


# -- special files -------------------------------------------------------------------------------


@pytest.fixture
def fifo(tmp_path):
    if not hasattr(os, "mkfifo"):
        pytest.skip("no FIFOs on this platform")
    path = tmp_path / "pipe.mcap"
    os.mkfifo(path)
    return path


@pytest.mark.parametrize("command", ["inspect", "analyze"])
def test_a_fifo_as_the_log_exits_2_at_once(cli_process, fifo, command):
    result = cli_process(command, fifo, timeout=60)  # a hang fails this test, not the suite
    assert result.exit_code == 2, result.stderr
    assert result.stderr.strip() == (
        f"logscan: error: {fifo}: is a FIFO (named pipe), not a regular file "
        "(logscan reads regular files only; save the data to a file first)"
    )


def test_a_fifo_in_a_directory_of_logs_fails_alone(cli_process, tmp_path, sample):
    logs = tmp_path / "logs"
    logs.mkdir()
    (logs / "flight.mcap").write_bytes(sample("sbw_healthy.mcap").read_bytes())
    os.mkfifo(logs / "stream.mcap")
    os.mkfifo(logs / "notes.txt")  # not named like a log: ignored like any other file
    assert expand_logs([str(logs)]) == [str(logs / "flight.mcap"), str(logs / "stream.mcap")]
    result = cli_process("analyze", logs, "-o", f"{tmp_path / 'reports'}/", timeout=300)
    assert result.exit_code == 2, result.stderr
    assert f"{logs / 'stream.mcap'}: is a FIFO (named pipe)" in result.stderr
    assert (tmp_path / "reports" / "flight.report.html").is_file()


def test_a_csv_directory_holding_a_fifo_is_refused(cli, tmp_path, sample):
    folder = tmp_path / "flight"
    folder.mkdir()
    (folder / "flight_sensor_0.csv").write_text("timestamp,x\n1,2\n2,3\n")
    os.mkfifo(folder / "flight_gps_0.csv")
    result = cli("inspect", folder)
    assert result.exit_code == 2
    assert f"{folder / 'flight_gps_0.csv'}: is a FIFO (named pipe), not a regular file" in result.stderr


def test_a_device_as_the_log_or_profile_exits_2(cli, sample):
    if not Path("/dev/null").exists():
        pytest.skip("no /dev/null")
    result = cli("inspect", "/dev/null")
    assert result.exit_code == 2 and "/dev/null: is a character device, not a regular file" in result.stderr
    result = cli("analyze", sample("sbw_healthy.mcap"), "--profile", "/dev/zero", "--no-report")
    assert result.exit_code == 2 and "/dev/zero: profile is a character device" in result.stderr


def test_a_fifo_as_the_profile_exits_2_at_once(cli_process, tmp_path, sample):
    profile = tmp_path / "profile.toml"
    os.mkfifo(profile)
    result = cli_process("analyze", sample("sbw_healthy.mcap"), "--profile", profile, "--no-report", timeout=60)
    assert result.exit_code == 2, result.stderr
    assert f"{profile}: profile is a FIFO (named pipe), not a regular file" in result.stderr


# -- what the OS refuses ---------------------------------------------------------------------------


@pytest.mark.skipif(AS_ROOT, reason="root reads files whatever their permissions")
@pytest.mark.parametrize("command", ["inspect", "analyze"])
def test_an_unreadable_file_exits_2(cli, tmp_path, sample, command):
    path = tmp_path / "locked.mcap"
    path.write_bytes(sample("sbw_healthy.mcap").read_bytes())
    path.chmod(0)
    try:
        result = cli(command, path, "--no-report") if command == "analyze" else cli(command, path)
    finally:
        path.chmod(0o600)
    assert result.exit_code == 2
    # inspect's argument is checked by click ("is not readable"), analyze's logs by the readers
    assert str(path) in result.stderr and ("permission denied" in result.stderr or "not readable" in result.stderr)


@pytest.mark.skipif(AS_ROOT, reason="root searches directories whatever their permissions")
@pytest.mark.parametrize("command", ["inspect", "analyze"])
def test_an_unsearchable_directory_exits_2(cli, tmp_path, command):
    folder = tmp_path / "flight"
    folder.mkdir()
    (folder / "flight_sensor_0.csv").write_text("timestamp,x\n1,2\n2,3\n")
    folder.chmod(0o600)  # listable, not searchable
    try:
        result = cli(command, folder, "--no-report") if command == "analyze" else cli(command, folder)
    finally:
        folder.chmod(0o700)
    assert result.exit_code == 2
    assert "permission denied (cannot list or search the directory)" in result.stderr


def _refuse(real, target: Path, error: OSError):
    """``real`` (open or os.scandir), raising ``error`` for ``target``: the OS refusing, even as root."""

    def fake(path, *args, **kwargs):
        if Path(os.fsdecode(path)) == target:
            raise error
        return real(path, *args, **kwargs)

    return fake


@pytest.mark.parametrize("command", ["inspect", "analyze"])
def test_a_directory_the_os_will_not_list_exits_2(cli, tmp_path, monkeypatch, command):
    folder = tmp_path / "flight"
    folder.mkdir()
    (folder / "flight_sensor_0.csv").write_text("timestamp,x\n1,2\n2,3\n")
    monkeypatch.setattr(os, "scandir", _refuse(os.scandir, folder, PermissionError(errno.EACCES, "Permission denied")))
    result = cli(command, folder, "--no-report") if command == "analyze" else cli(command, folder)
    assert result.exit_code == 2
    assert result.stderr.strip().endswith(
        f"{folder}: permission denied (cannot list or search the directory) "
        "(make it listable and searchable: chmod +rx)"
    )


def test_a_log_the_os_will_not_read_exits_2(cli, tmp_path, monkeypatch, sample):
    import builtins

    import logscan.readers

    path = tmp_path / "locked.mcap"
    path.write_bytes(sample("sbw_healthy.mcap").read_bytes())
    denied = _refuse(builtins.open, path, PermissionError(errno.EACCES, "Permission denied"))
    monkeypatch.setattr(logscan.readers, "open", denied, raising=False)
    result = cli("inspect", path)
    assert result.exit_code == 2 and f"{path}: permission denied" in result.stderr
    failing = _refuse(builtins.open, path, OSError(errno.EIO, "Input/output error"))
    monkeypatch.setattr(logscan.readers, "open", failing, raising=False)
    with pytest.raises(InputError, match="cannot read: Input/output error") as info:
        detect_format(path)
    assert "check the disk" in info.value.one_line()


def test_a_profile_the_os_will_not_read_exits_2(cli, tmp_path, monkeypatch, sample):
    import builtins

    import logscan.profiles.parse

    profile = tmp_path / "p.toml"
    profile.write_text(sample("quad_healthy.profile.toml").read_text())
    denied = _refuse(builtins.open, profile, PermissionError(errno.EACCES, "Permission denied"))
    monkeypatch.setattr(logscan.profiles.parse, "open", denied, raising=False)
    result = cli("analyze", sample("quad_healthy.mcap"), "--profile", profile, "--no-report")
    assert result.exit_code == 2
    assert f"{profile}: cannot read profile: permission denied" in result.stderr


# -- CSV numbers beyond every integer type ---------------------------------------------------------


def test_a_csv_integer_beyond_float_range_is_a_non_number(cli, tmp_path):
    path = tmp_path / "run.csv"
    path.write_text(f"time_s,x,y\n0,1,{2**64 + 1}\n1,{'9' * 400},5\n2,3,6\n")
    log = read_log(path)
    assert np.isnan(log.channels["/x"].values[1]) and log.channels["/x"].values[2] == 3
    assert log.channels["/y"].values[0] == float(2**64 + 1)  # a number, only beyond int64
    assert any(s.what == "cells of column 'x' of run.csv" and s.count == 1 for s in log.source.skipped)
    assert cli("inspect", path).exit_code == 0


@pytest.mark.parametrize("bad_time", [str(2**64 + 1), str(2**64 - 1), "9" * 400, "1e300"])
def test_a_csv_time_beyond_int64_ns_drops_its_row(tmp_path, bad_time):
    path = tmp_path / "run.csv"
    path.write_text(f"time_s,x\n0,1\n{bad_time},2\n2,3\n")
    log = read_log(path)
    assert log.channels["/x"].t.tolist() == [0, 2_000_000_000]
    assert any("out of range" in s.why and s.count == 1 for s in log.source.skipped)


def test_analyze_of_a_csv_with_a_time_above_2_64_is_no_internal_error(cli, tmp_path, sample):
    lines = sample("quad_healthy.csv").read_text().splitlines()
    cells = lines[5].split(",")
    cells[0] = str(2**64 + 1)
    lines[5] = ",".join(cells)
    path = tmp_path / "run.csv"
    path.write_text("\n".join(lines) + "\n")
    (tmp_path / "run.profile.toml").write_text(sample("quad_healthy.profile.toml").read_text())
    result = cli("analyze", path, "--no-report", "--exit-zero")
    assert result.exit_code == 0, result.stderr


# -- profiles nested 10,000 deep or 50 MB long -------------------------------------------------------


DEEP = 10_000


@pytest.mark.parametrize(
    "extra",
    [
        "x = " + "[" * DEEP + "]" * DEEP,
        "x = " + "{a = " * DEEP + "1" + "}" * DEEP,
        "a" + ".a" * DEEP + " = 1",
        "[a" + ".a" * DEEP + "]\nx = 1",
    ],
    ids=["arrays", "inline-tables", "dotted-key", "table-header"],
)
def test_a_profile_nested_10000_deep_exits_2(cli, tmp_path, sample, extra):
    profile = tmp_path / "deep.toml"
    profile.write_text(extra + "\n" + sample("quad_healthy.profile.toml").read_text())
    result = cli("analyze", sample("quad_healthy.mcap"), "--profile", profile, "--no-report")
    assert result.exit_code == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and str(profile) in lines[0] and "Traceback" not in result.stderr


def test_a_50_mb_profile_is_refused_before_parsing(cli, tmp_path, sample):
    profile = tmp_path / "huge.toml"
    with open(profile, "w") as fh:
        fh.write(sample("quad_healthy.profile.toml").read_text())
        fh.write(("# " + "x" * 97 + "\n") * 500_000)
    assert profile.stat().st_size > 50_000_000
    result = cli("analyze", sample("quad_healthy.mcap"), "--profile", profile, "--no-report")
    assert result.exit_code == 2
    assert f"{profile}: profile is {profile.stat().st_size} bytes, more than the 1048576" in result.stderr
    with pytest.raises(ProfileError, match="more than the 1048576"):  # an embedded profile too
        parse_profile("#" * 2_000_000, source="embedded")


def test_a_truth_sidecar_nested_too_deep_exits_2(cli, sample, tmp_path):
    """A `<log>.truth.json` nested 100,000 deep: one line, exit 2, never a RecursionError."""
    import shutil

    log = tmp_path / "run.csv"
    shutil.copy(sample("quad_healthy.csv"), log)
    shutil.copy(sample("quad_healthy.profile.toml"), tmp_path / "run.profile.toml")
    (tmp_path / "run.truth.json").write_text("[" * 100_000 + "]" * 100_000)
    result = cli("analyze", log, "--no-report")
    assert result.exit_code == 2, result.stderr
    assert "run.truth.json" in result.stderr and "nested too deeply" in result.stderr
