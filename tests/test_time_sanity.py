"""Time sanity: one outlying timestamp never sizes the analysis grid, a grid too large is bad
input with its figures (before anything is allocated), --start/--end analyse a window, and a CSV
time column whose name contradicts its numbers is refused (docs/algorithms.md section 8.1)."""

from __future__ import annotations

import json
import shutil
import struct
import tracemalloc
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import need_testdata, one_state_profile

from logscan.align import MAX_GRID_STEPS, align, outlying_runs
from logscan.errors import InputError
from logscan.log import Channel, Log, SourceInfo
from logscan.profiles import parse_profile

DAY_NS = 86_400_000_000_000
LATE_NS = int(11.6 * DAY_NS)
GPS = ["/gps/position.x", "/gps/position.y", "/gps/position.z"]
ULOG_DIR = Path(__file__).resolve().parents[2] / "shared" / "testdata" / "px4-ulog"


def rewrite_mcap(source: Path, target: Path, edit) -> Path:
    """``source`` written again (JSON messages, same metadata) after ``edit(topics)`` changed the
    int64 log times of some of its topics (name -> logscan.readers.mcap.TopicData)."""
    from logscan.readers import read_log
    from logscan.readers.mcap import TopicData, write_mcap

    log = read_log(source)
    topics: dict[str, dict] = {}
    for name, channel in log.channels.items():
        topic, _, field = name.rpartition("/")
        topics.setdefault(topic, {"t": channel.t, "fields": {}})["fields"][field] = channel.values
    data = {topic: TopicData("x/msg/Y", np.array(e["t"]), e["fields"]) for topic, e in topics.items()}
    edit(data)
    metadata = {"logscan.profile": {"toml": log.profile_text}, "logscan.truth": {"json": json.dumps(log.truth)}}
    write_mcap(target, data, encoding="json", metadata=metadata)
    return target


def shift_gps(index: int | slice, shift_ns: int):
    def edit(topics):
        t = topics["/gps"].t_ns.copy()
        t[index] += shift_ns
        topics["/gps"].t_ns = t

    return edit


def analyze_json(cli, path, tmp_path, *args):
    out = tmp_path / f"{Path(path).stem}.json"
    result = cli("analyze", path, "--no-report", "--json", out, *args)
    assert out.exists(), result.stderr
    return result, json.loads(out.read_text())["logs"][0]


# --- isolated outlying timestamps ------------------------------------------------------------------


@pytest.mark.parametrize("name, code", [("quad_healthy.mcap", 0), ("quad_imu_bias.mcap", 1)])
def test_a_gps_message_stamped_days_late_is_dropped_with_a_warning_and_the_verdict_kept(
    cli, sample, tmp_path, name, code
):
    jumped = rewrite_mcap(sample(name), tmp_path / f"late_{name}", shift_gps(301, LATE_NS))
    result, log = analyze_json(cli, jumped, tmp_path)
    assert result.exit_code == code, result.stdout + result.stderr
    assert log["filter"]["steps"] == 6001  # the 60 s of the log at 100 Hz, not 11.6 days
    dropped = [w for w in log["warnings"] if "outlying" in w]
    assert len(dropped) == 1
    assert all(repr(ch) in dropped[0] for ch in GPS), dropped
    assert "1 outlying sample dropped at t=1002270.100 s (+11.6 days)" in dropped[0]
    assert "outlying sample" in result.stdout  # the printed summary lists it too
    # the dropped sample was the only reason the log spanned days: no "wrong time unit" warning
    assert not any("the log spans" in w for w in log["warnings"]), log["warnings"]


def test_a_log_time_of_2_63_minus_1_is_an_outlier_too(cli, sample, tmp_path):
    def edit(topics):
        t = topics["/imu"].t_ns.copy()
        t[-1] = 2**63 - 1
        topics["/imu"].t_ns = t

    jumped = rewrite_mcap(sample("quad_healthy.mcap"), tmp_path / "max.mcap", edit)
    result, log = analyze_json(cli, jumped, tmp_path)
    assert result.exit_code == 0, result.stdout + result.stderr
    assert log["filter"]["steps"] == 6001  # the inputs still end at 60 s
    assert any("'/imu/accel.x'" in w and "1 outlying sample" in w for w in log["warnings"])
    # block mode plans from the summary's span, which the outlier stretches to 292 years: millions
    # of blocks (20 GB before a test's worker was stopped). A span holding fewer messages than grid
    # steps is no long log: analysed at once, where the outlier is dropped, also when blocks are asked
    result, log = analyze_json(cli, jumped, tmp_path, "--block-s", "20")
    assert result.exit_code == 0 and log["filter"]["steps"] == 6001, result.stdout + result.stderr
    assert any(w.startswith("--block-s: the file's span") for w in log["warnings"]), log["warnings"]


def test_an_early_outlier_keeps_the_alarm_times_of_the_log(cli, sample, tmp_path):
    """The outlier is the log's first timestamp: times count from the grid's start, so the
    injected fault still shows at 30 s."""

    def edit(topics):  # every message 12 days later but one GPS message (MCAP log times are unsigned)
        for topic in topics.values():
            topic.t_ns = topic.t_ns + 12 * DAY_NS
        topics["/gps"].t_ns[301] -= 12 * DAY_NS

    jumped = rewrite_mcap(sample("quad_imu_bias.mcap"), tmp_path / "early.mcap", edit)
    result, log = analyze_json(cli, jumped, tmp_path)
    assert result.exit_code == 1, result.stdout + result.stderr
    assert log["filter"]["steps"] == 6001
    assert log["incidents"][0]["start"] == 30.0
    assert log["scores"]["nis"]["tp"] == 1
    assert any("t=-1036769.900 s (-12.0 days)" in w for w in log["warnings"]), log["warnings"]


def test_a_wide_csv_row_stamped_days_late_is_one_warning_naming_its_channels(cli, sample, tmp_path):
    source = sample("quad_healthy.csv")
    frame = pd.read_csv(source)
    frame.loc[3000, "time_ns"] += LATE_NS
    path = tmp_path / "late.csv"
    frame.to_csv(path, index=False)
    for suffix in (".truth.json", ".profile.toml"):
        shutil.copy(source.with_name(f"quad_healthy{suffix}"), tmp_path / f"late{suffix}")
    result, log = analyze_json(cli, path, tmp_path)
    assert result.exit_code == 0, result.stdout + result.stderr
    assert log["filter"]["steps"] == 6001
    dropped = [w for w in log["warnings"] if "outlying" in w]
    assert len(dropped) == 1, dropped  # one line for every channel of the row
    assert "'/cmd/thrust'" in dropped[0] and "more: 1 outlying sample dropped at t=1002270.000 s" in dropped[0]


def _ulog_messages(data: bytes):
    pos = 16  # after the file header
    while pos + 3 <= len(data):
        size, kind = struct.unpack_from("<HB", data, pos)
        yield pos, size, chr(kind)
        pos += 3 + size


def jump_ulog(source: Path, target: Path, topic: str, shift_us: int) -> None:
    """``source`` with the timestamp of the middle data message of ``topic`` moved by ``shift_us``."""
    data = bytearray(source.read_bytes())
    ids = set()
    for pos, size, kind in _ulog_messages(data):
        if kind == "A":  # add logged message: multi_id u8, msg_id u16, name
            multi, msg_id = struct.unpack_from("<BH", data, pos + 3)
            if f"{bytes(data[pos + 6 : pos + 3 + size]).decode()}_{multi}" == topic:
                ids.add(msg_id)
    hits = [p for p, _, kind in _ulog_messages(data) if kind == "D" and struct.unpack_from("<H", data, p + 3)[0] in ids]
    offset = hits[len(hits) // 2] + 5  # after the header and msg_id: the topic's uint64 timestamp
    struct.pack_into("<Q", data, offset, struct.unpack_from("<Q", data, offset)[0] + shift_us)
    target.write_bytes(bytes(data))


ULOG_PROFILE = one_state_profile("/actuator_controls_0_0/control[3]", "/sensor_combined_0/accelerometer_m_s2[2]")


def test_a_ulog_message_stamped_days_late_is_dropped_like_any_other(cli, tmp_path):
    source = ULOG_DIR / "sample_logging_tagged_and_default_params.ulg"
    need_testdata(source)
    profile = tmp_path / "px4.toml"
    profile.write_text(ULOG_PROFILE)
    jumped = tmp_path / "jumped.ulg"
    jump_ulog(source, jumped, "sensor_combined_0", LATE_NS // 1000)
    original, before = analyze_json(cli, source, tmp_path, "-p", profile)
    result, after = analyze_json(cli, jumped, tmp_path, "-p", profile)
    assert result.exit_code == original.exit_code, result.stdout + result.stderr
    assert after["filter"]["steps"] == before["filter"]["steps"] < 2000
    assert any(
        "'/sensor_combined_0/accelerometer_m_s2[2]'" in w and "1 outlying sample" in w and "+11.6 days" in w
        for w in after["warnings"]
    ), after["warnings"]


# --- the rule on its own ---------------------------------------------------------------------------


def test_outlying_runs_are_tiny_runs_behind_a_gap_of_many_spacings():
    t = np.arange(1000, dtype=np.int64) * 10_000_000  # 100 Hz, 10 s
    main, lo, hi, gap = outlying_runs(np.append(t, [LATE_NS, LATE_NS + 10_000_000]))
    assert main == (0, 1000) and list(zip(lo, hi)) == [(1000, 1002)] and gap == 10_000_000_000
    # a gap of 5 s at 100 Hz (500 spacings) is no break; nor is anything in a short channel
    assert outlying_runs(np.append(t, t[-1] + 5_000_000_000))[1].size == 0
    assert outlying_runs(np.append(t[:40], LATE_NS))[1].size == 0
    # differences over the whole int64 range are exact (no wrap to negative steps)
    _, lo, _, _ = outlying_runs(np.concatenate(([-(2**63)], t, [2**63 - 1])))
    assert list(lo) == [0, 1001]


class _Model:
    input_names = ("force",)
    state_names = ("pos", "vel")
    groups: dict = {}


PROFILE = """
[vehicle]
model = "fake"
rate_hz = 100

[inputs]
force = "/force"

[measurements.speed]
channels = ["/speed"]
rate_hz = 10
stale_s = 0.3
"""


def _aligned(channels: dict[str, np.ndarray], toml: str = PROFILE, **window):
    from logscan.models.base import GroupSpec

    model = _Model()
    model.groups = {"speed": GroupSpec("speed", 0, ("v",), (0.1,), (-10.0,), (10.0,))}
    log = Log({n: Channel(n, t, np.zeros(t.size)) for n, t in channels.items()}, SourceInfo("x.mcap", "mcap"))
    return align(log, parse_profile(toml, model=model), **window)


def test_a_sensor_back_after_an_outage_inside_the_log_is_a_gap_not_an_outlier():
    force = np.arange(0, 600_001, 10) * 1_000_000  # 100 Hz for 600 s
    speed = np.concatenate((np.arange(0, 100_001, 100), [500_000, 500_100])) * 1_000_000  # back for 0.1 s
    run = _aligned({"/force": force, "/speed": speed})
    assert not any("outlying" in w for w in run.warnings)
    assert run.channel_stats["/speed"].get("outliers", 0) == 0 and run.n_steps == 60_001


def test_a_channel_on_another_clock_is_refused_with_the_figures_not_allocated():
    """A whole channel 11.6 days late is not an outlier (it is all of its channel): the grid
    would be 1.0e8 steps, refused before anything the size of the grid exists."""
    t = np.arange(0, 60_001, 10) * 1_000_000
    tracemalloc.start()
    try:
        with pytest.raises(InputError) as caught:
            _aligned({"/force": t, "/speed": t[::10] + LATE_NS})
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    line = caught.value.one_line()
    assert "span 11.6 days at 100 Hz = 1.0e8 steps" in line and "check the time unit or pass --start/--end" in line
    assert "\n" not in line and peak < 20_000_000


@pytest.mark.parametrize("rate", ["1e9", "1e300"])
def test_a_profile_rate_of_a_gigahertz_is_exit_2_with_the_figures(cli, sample, tmp_path, rate):
    from logscan.readers import read_embedded_profile

    profile = tmp_path / "fast.toml"
    profile.write_text(
        read_embedded_profile(sample("quad_healthy.mcap")).replace("rate_hz = 100.0\n", f"rate_hz = {rate}\n", 1)
    )
    result = cli("analyze", sample("quad_healthy.mcap"), "-p", profile, "--no-report")
    assert result.exit_code == 2 and not result.stdout
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "span 60 s at" in lines[0] and "steps, over the analysis grid's limit" in lines[0]
    assert ("= 6.0e10 steps" in lines[0]) == (rate == "1e9")


def test_the_grid_limit_passes_a_day_at_100_hz_and_refuses_1e8_steps():
    assert 86_400 * 100 < MAX_GRID_STEPS < 1e8


# --- CSV time units --------------------------------------------------------------------------------


def _csv(tmp_path: Path, column: str, times) -> Path:
    path = tmp_path / "units.csv"
    pd.DataFrame({column: times, "x": np.zeros(len(times))}).to_csv(path, index=False)
    return path


def test_time_s_holding_epoch_nanoseconds_is_exit_2_saying_what_to_rename_it_to(cli, tmp_path):
    times = 1_710_000_000_000_000_000 + np.arange(600, dtype=np.int64) * 10_000_000
    result = cli("inspect", _csv(tmp_path, "time_s", times))
    assert result.exit_code == 2
    line = result.stderr.strip()
    assert "\n" not in line and "time column 'time_s' states seconds but a median of 1.71e+18 s" in line
    assert "read as nanoseconds they are epoch time, ~100 Hz" in line and "rename it to 'time_ns'" in line


@pytest.mark.parametrize(
    "column, times, problem",
    [
        ("time_us", np.arange(600) * 1e-4, "a median step of 0.0001 us is 1e+10 Hz"),  # seconds as us
        ("timestamp_ms", np.arange(600) * 1e8, "600 samples 1e+08 ms apart span 1.9 years"),
        ("time [s]", np.arange(600) * 1e12, "a median of 3e+14 s is 9.49e+06 years"),
    ],
)
def test_a_stated_unit_its_numbers_contradict_is_refused(tmp_path, column, times, problem):
    from logscan.readers import read_log

    with pytest.raises(InputError) as caught:
        read_log(_csv(tmp_path, column, times))
    assert f"time column {column!r} states" in caught.value.message and problem in caught.value.message


def test_a_stated_unit_that_fits_is_read_even_with_an_outlying_row(tmp_path):
    from logscan.readers import read_log

    log = read_log(_csv(tmp_path, "time_s", np.append(np.arange(599) * 0.01, 1e6)))
    assert log.source.time_unit == "s" and len(log.channels["/x"]) == 600


# --- --start / --end -------------------------------------------------------------------------------


def test_a_window_before_the_fault_has_no_alarm_and_scores_no_event(cli, sample, tmp_path):
    result, log = analyze_json(cli, sample("quad_imu_bias.mcap"), tmp_path, "--start", "0", "--end", "20")
    assert result.exit_code == 0, result.stdout + result.stderr
    assert log["n_alarms"] == 0 and log["filter"]["steps"] == 2001
    assert log["scores"]["nis"]["fn"] == 0  # the fault at 30-40 s is not in the window


def test_a_window_around_the_fault_gives_the_incident_at_the_log_time(cli, sample, tmp_path):
    result, log = analyze_json(cli, sample("quad_imu_bias.mcap"), tmp_path, "--start", "25", "--end", "45")
    assert result.exit_code == 1, result.stdout + result.stderr
    assert log["filter"]["steps"] == 2001
    assert log["incidents"][0]["source"] == "accel" and log["incidents"][0]["start"] == 30.0
    assert all(25.0 <= a["start"] <= a["end"] <= 45.0 for d in log["detectors"] for a in d["alarms"])
    assert log["scores"]["nis"]["tp"] == 1
    text = cli("analyze", sample("quad_imu_bias.mcap"), "--no-report", "--start", "25", "--end", "45").stdout
    # the summary names the window, and where its filter started
    assert "(25.0-45.0 s of 60.0 s, filtered from 0.0 s, model quadcopter" in text.splitlines()[0]


def test_window_grid_points_are_the_full_grids_points(sample):
    from logscan.profiles import parse_profile as parse
    from logscan.readers import read_log

    log = read_log(sample("quad_healthy.mcap"))
    profile = parse(log.profile_text)
    full = align(log, profile)
    part = align(log, profile, start_s=12.345, end_s=20.0)
    assert part.window == (12.345, 20.0) and part.t[0] == full.t[1235] and part.t[-1] == full.t[2000]
    np.testing.assert_array_equal(part.t, full.t[1235:2001])
    np.testing.assert_array_equal(part.u, full.u[1235:2001])


@pytest.mark.parametrize(
    "args, message",
    [
        (("--start", "25", "--end", "20"), "--end 20 must be after --start 25"),
        (("--start", "5", "--end", "5"), "--end 5 must be after --start 5"),
        (("--start", "nan"), "--start nan is not a finite number"),
        (("--start", "100", "--end", "200"), "holds no two grid steps of the log's channels (0.000 .. 60.000 s)"),
        (("--end", "-3"), "holds no two grid steps"),
    ],
)
def test_a_bad_window_is_exit_2_with_one_line(cli, sample, args, message):
    result = cli("analyze", sample("quad_imu_bias.mcap"), "--no-report", *args)
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], result.stderr


def test_evaluate_scores_the_window(cli, sample, tmp_path):
    out = tmp_path / "eval.json"
    result = cli("evaluate", sample("quad_imu_bias.mcap"), "--start", "25", "--end", "45", "--json", out)
    assert result.exit_code == 0, result.stderr
    scores = json.loads(out.read_text())["scores"]["nis"]
    assert scores["tp"] == 1 and scores["fn"] == 0
    result = cli("evaluate", sample("quad_imu_bias.mcap"), "--end", "20", "--json", out)
    assert json.loads(out.read_text())["scores"]["nis"]["tp"] == 0 == json.loads(out.read_text())["scores"]["nis"]["fn"]
    assert cli("evaluate", sample("quad_imu_bias.mcap"), "--start", "3", "--end", "1").exit_code == 2
