"""MCAP writer: both encodings read back to the same channels, deterministic bytes, metadata."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest
from mcap.reader import NonSeekingReader, make_reader

from logscan.errors import UsageError
from logscan.readers.mcap import read_mcap
from logscan.readers.mcap.writer import TopicData, mcap_bytes, write_mcap


def _topics() -> dict[str, TopicData]:
    rng = np.random.default_rng(3)
    t_imu = np.arange(500, dtype=np.int64) * 5_000_000
    t_gps = np.arange(50, dtype=np.int64) * 50_000_000 + 1  # interleaves with the IMU
    return {
        "/imu": TopicData(
            "sensor_msgs/msg/Imu",
            t_imu,
            {
                "linear_acceleration.x": rng.normal(size=500),
                "linear_acceleration.y": rng.normal(size=500),
                "angular_velocity.z": rng.normal(size=500),
                "orientation.q.w": np.ones(500),
            },
        ),
        "/gps": TopicData("logscan/Gps", t_gps, {"position.x": rng.normal(size=50), "speed": rng.normal(size=50)}),
    }


@pytest.mark.parametrize("encoding", ["json", "ros2"])
def test_round_trip_gives_nested_channel_names_and_exact_values(tmp_path, encoding):
    topics = _topics()
    path = tmp_path / f"{encoding}.mcap"
    write_mcap(path, topics, encoding=encoding)
    log = read_mcap(path, None)
    expected = {f"{topic}/{name}" for topic, data in topics.items() for name in data.fields}
    assert set(log.channels) == expected
    for topic, data in topics.items():
        for name, values in data.fields.items():
            channel = log.channels[f"{topic}/{name}"]
            np.testing.assert_array_equal(channel.t, data.t_ns)
            np.testing.assert_array_equal(channel.values, values)  # bit exact, both encodings
    assert log.source.skipped == [] and not log.source.partial
    assert log.source.topics["/imu"].schema == "sensor_msgs/msg/Imu"
    assert log.source.topics["/imu"].encoding == ("cdr" if encoding == "ros2" else "json")


@pytest.mark.parametrize("encoding", ["json", "ros2"])
def test_file_is_in_log_time_order_with_summary_and_crcs(tmp_path, encoding):
    path = tmp_path / "o.mcap"
    write_mcap(path, _topics(), encoding=encoding)
    with open(path, "rb") as fh:
        reader = make_reader(fh, validate_crcs=True)
        summary = reader.get_summary()
        times = [m.log_time for _, _, m in reader.iter_messages(log_time_order=False)]
    assert times == sorted(times) and len(times) == 550
    assert summary.statistics.message_count == 550 and summary.chunk_indexes
    assert all(ci.compression in ("lz4", "") for ci in summary.chunk_indexes)
    with open(path, "rb") as fh:  # the streaming reader also checks the data-section CRC
        streamed = list(NonSeekingReader(fh, validate_crcs=True).iter_messages(log_time_order=False))
    assert [m.log_time for _, _, m in streamed] == times
    assert [m.sequence for _, c, m in streamed if c.topic == "/gps"] == list(range(50))
    data = path.read_bytes()
    summary_start, _, summary_crc = struct.unpack_from("<QQI", data, len(data) - 8 - 20)
    assert zlib.crc32(data[summary_start : len(data) - 8 - 4]) == summary_crc


@pytest.mark.parametrize("encoding", ["json", "ros2"])
def test_same_inputs_give_the_same_bytes(encoding):
    meta = {"logscan.profile": {"toml": "[vehicle]\nmodel = 'quadcopter'\n"}}
    first = mcap_bytes(_topics(), encoding=encoding, metadata=meta)
    second = mcap_bytes(_topics(), encoding=encoding, metadata=meta)
    assert first == second
    assert b"logscan" in first[:64]  # fixed library string in the header


def test_metadata_round_trips_into_truth_and_profile(tmp_path):
    truth = '{"events": [{"start": 3.0, "end": 5.0, "kind": "imu-bias", "target": "/imu"}]}'
    profile = '[vehicle]\nmodel = "quadcopter"\nrate_hz = 100\n'
    path = tmp_path / "m.mcap"
    write_mcap(
        path,
        _topics(),
        metadata={
            "logscan.truth": {"json": truth},
            "logscan.profile": {"toml": profile},
            "other": {"k": "v"},
        },
    )
    log = read_mcap(path, None)
    assert log.truth == {"events": [{"start": 3.0, "end": 5.0, "kind": "imu-bias", "target": "/imu"}]}
    assert log.profile_text == profile
    assert log.source.metadata["other"] == {"k": "v"}


def test_non_finite_values_survive_json(tmp_path):
    t = np.arange(3, dtype=np.int64)
    path = tmp_path / "nan.mcap"
    write_mcap(path, {"/a": TopicData("A", t, {"v": np.array([np.nan, np.inf, -1.5])})})
    values = read_mcap(path, None).channels["/a/v"].values
    assert np.isnan(values[0]) and values[1] == np.inf and values[2] == -1.5


def test_write_is_atomic_and_leaves_no_temporary_file(tmp_path):
    path = tmp_path / "a.mcap"
    write_mcap(path, _topics())
    assert [p.name for p in tmp_path.iterdir()] == ["a.mcap"]


def test_bad_inputs_are_usage_errors(tmp_path):
    t = np.arange(3, dtype=np.int64)
    with pytest.raises(UsageError, match="ROS 2 field name"):
        mcap_bytes({"/a": TopicData("p/A", t, {"Bad.x": np.zeros(3)})}, encoding="ros2")
    with pytest.raises(UsageError, match="shape"):
        mcap_bytes({"/a": TopicData("p/A", t, {"x": np.zeros(4)})})
    with pytest.raises(UsageError, match="both a value and a message"):
        mcap_bytes({"/a": TopicData("p/A", t, {"x": np.zeros(3), "x.y": np.zeros(3)})})
    with pytest.raises(UsageError, match="encoding"):
        mcap_bytes({"/a": TopicData("p/A", t, {"x": np.zeros(3)})}, encoding="cbor")
