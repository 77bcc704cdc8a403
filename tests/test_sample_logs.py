"""The shipped sample_logs/: present, small, carry truth and profile, and regenerate byte for byte."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

from logscan.pipeline import load_profile_for
from logscan.profiles import resolve_profile
from logscan.readers import read_log
from logscan.simulate import parse_fault
from logscan.simulate.faults import ALIASES

SAMPLES_DIR = Path(__file__).resolve().parents[1] / "sample_logs"
MAX_BYTES = 3_000_000


def _make_samples():
    spec = importlib.util.spec_from_file_location("make_samples", SAMPLES_DIR / "make_samples.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["make_samples"] = module  # dataclasses look their module up while building
    spec.loader.exec_module(module)
    return module


MAKE = _make_samples()
NAMES = [s.name for s in MAKE.SAMPLES]


def test_the_issue_asks_for_these_logs():
    models = [s.model for s in MAKE.SAMPLES]
    assert "quad_healthy.mcap" in NAMES
    assert {
        "quad_imu_bias.mcap",
        "quad_imu_bitflip.mcap",
        "quad_motor_offset.mcap",
        "quad_cov_corruption.mcap",
        "sbw_healthy.mcap",
        "jackal_healthy.mcap",
    } <= set(NAMES)
    assert models.count("steer_by_wire") >= 2
    assert any(s.fmt == "csv" for s in MAKE.SAMPLES)


@pytest.mark.parametrize("name", NAMES)
def test_sample_is_small_and_carries_its_truth_and_profile(name, sample):
    path = sample(name)
    spec = next(s for s in MAKE.SAMPLES if s.name == name)
    assert path.stat().st_size < MAX_BYTES
    log = read_log(path)
    if spec.fmt == "ros2-mcap":  # a ROS 2 recording embeds no profile: it gets the built-in ros2 one
        assert log.profile_text is None
        profile = load_profile_for(path, None).profile
    else:
        profile = resolve_profile(log)  # MCAP metadata record, or the CSV's .profile.toml sidecar
    profile.check_channels(log)
    assert profile.vehicle.model == spec.model
    assert log.duration_s == pytest.approx(spec.duration)
    if spec.fmt == "ros2-mcap":  # nor its truth: a recording has none
        assert log.truth is None and not spec.faults
        return
    expected = [parse_fault(f) for f in spec.faults]
    events = log.truth["events"]
    assert [(e["kind"], e["target"], e["start"], e["end"], e["magnitude"]) for e in events] == [
        (ALIASES.get(f.kind, (f.kind,))[0], f.target, f.start, f.end, f.magnitude) for f in expected
    ]
    assert log.truth["seed"] == spec.seed


@pytest.mark.slow
def test_regenerating_a_sample_gives_the_same_bytes(tmp_path, sample):
    name = "quad_imu_bias.mcap"
    shipped = sample(name)
    assert MAKE.main(["--out", str(tmp_path), name]) == 0
    assert (tmp_path / name).read_bytes() == shipped.read_bytes()


@pytest.mark.slow
def test_regenerating_the_csv_sample_gives_the_same_three_files(tmp_path, sample):
    name = "quad_healthy.csv"
    sample(name)
    assert MAKE.main(["--out", str(tmp_path), name]) == 0
    for suffix in (".csv", ".truth.json", ".profile.toml"):
        fresh = (tmp_path / name).with_suffix(suffix)
        assert fresh.read_bytes() == (SAMPLES_DIR / name).with_suffix(suffix).read_bytes()


def test_readme_table_lists_every_sample_and_its_faults():
    readme = (SAMPLES_DIR / "README.md").read_text()
    assert MAKE.readme_table() in readme


def test_make_samples_rejects_unknown_names(capsys):
    assert MAKE.main(["--out", "/nonexistent", "nosuch.mcap"]) == 2
    assert "unknown sample" in capsys.readouterr().err
