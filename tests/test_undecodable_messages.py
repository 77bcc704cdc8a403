"""Messages whose bytes do not decode are data the log lost, as a damaged chunk's are: the log is
read only in part and the verdict says what was dropped (docs/inputs.md, MCAP input)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import need_testdata

ROS2_MCAP = "ros-robots/robot_localization_test1_husky_ros2/robot_localization_test1_husky_ros2.mcap"
LENGTH_BYTE = 15  # CDR: 4 bytes encapsulation, header.stamp sec and nanosec, then frame_id's length


def _damage(src: Path, dst: Path, every: int) -> dict[str, int]:
    """Copy the MCAP with the high byte of frame_id's length flipped in every ``every``-th message
    of each topic (a string of gigabytes: the message cannot decode); topic -> messages damaged."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    damaged: dict[str, int] = {}
    seen: dict[str, int] = {}
    with open(src, "rb") as fh, open(dst, "wb") as out:
        reader = make_reader(fh)
        summary = reader.get_summary()
        writer = Writer(out)
        writer.start(profile=reader.get_header().profile, library="test")
        for schema in summary.schemas.values():
            writer.register_schema(schema.name, schema.encoding, schema.data)
        for channel in summary.channels.values():
            writer.register_channel(channel.topic, channel.message_encoding, channel.schema_id, channel.metadata)
        for _, channel, message in reader.iter_messages(log_time_order=False):
            data = bytearray(message.data)
            seen[channel.topic] = seen.get(channel.topic, 0) + 1
            if seen[channel.topic] % every == 0:
                data[LENGTH_BYTE] ^= 0xFF
                damaged[channel.topic] = damaged.get(channel.topic, 0) + 1
            writer.add_message(channel.id, message.log_time, bytes(data), message.publish_time, message.sequence)
        writer.finish()
    return damaged


@pytest.mark.testdata(ROS2_MCAP)
def test_a_real_ros2_mcap_with_undecodable_messages_is_read_only_in_part(cli, tmp_path):
    """The real Husky drive with 1 message in 200 of each topic damaged: analyze said "no alarms" (exit 0) with no
    word of the 82 messages it dropped, while inspect listed them."""
    path = tmp_path / "husky_damaged.mcap"
    damaged = _damage(need_testdata(ROS2_MCAP), path, every=200)
    assert set(damaged) == {"/imu/data", "/husky_velocity_controller/odom", "/fix"}, damaged
    out = tmp_path / "s.json"
    result = cli("analyze", str(path), "--no-report", "--json", str(out))
    (log,) = json.loads(out.read_text())["logs"]
    assert result.exit_code == 2 and "not fully checked" in log["verdict"], result.stdout
    (line,) = [u for u in log["unchecked"] if u.startswith("the log was read only in part")]
    assert f"{sum(damaged.values())} message(s) whose bytes do not decode dropped" in line
    for topic, count in damaged.items():
        assert f"{topic} x{count}" in line
    assert f"not checked: {line}" in result.stdout
    assert cli("analyze", str(path), "--no-report", "--allow-partial").exit_code == 0
    shown = cli("inspect", str(path))
    assert "PARTIAL:   only part of the file was read: " in shown.stdout, shown.stdout
