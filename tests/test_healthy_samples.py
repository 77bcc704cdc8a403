"""Every healthy sample log passes `logscan analyze` with its own profile (exit 0), the Jackal one
with its healthy glitches included, and every faulty sample still alarms on its fault."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from logscan.readers import read_log

HEALTHY = [
    "quad_healthy.mcap",
    "quad_healthy.csv",
    "sbw_healthy.mcap",
    "jackal_healthy.mcap",
    "jackal_train_1.mcap",
    "jackal_train_2.mcap",
    "hover_healthy.mcap",
    "ros2_ins.mcap",  # no embedded profile: the built-in ros2 one (tests/test_ros2_builtin.py)
]
FAULTY = [
    "quad_imu_bias.mcap",
    "quad_imu_bitflip.mcap",
    "quad_motor_offset.mcap",
    "quad_cov_corruption.mcap",
    "sbw_yaw_rate_bitflip.mcap",
    "jackal_gps_bias.mcap",
    "hover_rotor_offset.mcap",
    "ins_imu_bias.mcap",
]
# the hierarchical ground robot's logs (several loops; tests/test_ground_robot_sim.py reads them)
HIERARCHICAL = ["ground_robot_attack.mcap", "ground_robot_healthy.mcap"]


@pytest.mark.parametrize("name", HEALTHY)
def test_every_healthy_sample_exits_zero_with_its_own_profile(name, cli, sample, tmp_path):
    out = tmp_path / "summary.json"
    result = cli("analyze", sample(name), "--no-report", "--json", out)
    assert result.exit_code == 0, result.stdout + result.stderr
    summary = json.loads(out.read_text())["logs"][0]
    assert summary["n_alarms"] == 0
    # multi-rate columns (the CSV's empty cells) and healthy logs give nothing to warn about
    assert summary["warnings"] == []


def test_the_jackal_sample_has_glitches_that_alarm_without_its_floors(cli, sample, tmp_path):
    """The pass above is the profile's doing: the log does carry healthy transients, and the same
    profile without its [alarms] and [detectors.*] tables raises alarms on them."""
    path = sample("jackal_healthy.mcap")
    log = read_log(path)
    assert len(log.truth["transients"]) >= 5 and log.truth["events"] == []
    text = log.profile_text
    assert "[alarms]" in text and "[detectors.nis]" in text
    bare = tmp_path / "bare.toml"
    bare.write_text(text[: text.index("[alarms]")])
    result = cli("analyze", path, "--no-report", "--profile", bare)
    assert result.exit_code == 1, result.stdout
    assert "nis.gps_speed" in result.stdout


@pytest.mark.parametrize("name", FAULTY)
def test_every_faulty_sample_still_alarms_on_its_fault(name, cli, sample, tmp_path):
    out = tmp_path / "summary.json"
    result = cli("analyze", sample(name), "--no-report", "--json", out)
    assert result.exit_code == 1, result.stdout + result.stderr
    summary = json.loads(out.read_text())["logs"][0]
    assert len(summary["truth_events"]) == 1
    assert any(score["tp"] >= 1 for score in summary["scores"].values()), summary["scores"]


def test_the_samples_listed_here_are_every_sample_log():
    folder = Path(__file__).resolve().parents[1] / "sample_logs"
    shipped = sorted(p.name for p in folder.iterdir() if p.suffix in (".mcap", ".csv"))
    if not shipped:
        pytest.skip("sample logs missing (run sample_logs/make_samples.py)")
    assert shipped == sorted(HEALTHY + FAULTY + HIERARCHICAL)
