"""Profile bugs the fuzzing campaign found (tests/fuzz_regressions/README.md), fixed: rates and
staleness limits that overflowed once past the profile checks are refused when the profile is
parsed, naming the file, the key and the allowed range (exit 2, never 3)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from logscan.errors import ProfileError
from logscan.profiles import parse_profile
from logscan.profiles.schema import MAX_RATE_HZ, MIN_RATE_HZ

REGRESSIONS = Path(__file__).resolve().parent / "fuzz_regressions"
HEALTHY_PROFILE = (Path(__file__).resolve().parents[1] / "sample_logs" / "quad_healthy.profile.toml").read_text()


def _reproducer(tmp_path: Path, stem: str, name: str | None = None) -> Path:
    """The reproducer ``stem``.csv and its sidecar profile, copied into ``tmp_path`` (as ``name``)."""
    name = name or stem
    for suffix in (".csv", ".profile.toml"):
        shutil.copyfile(REGRESSIONS / f"{stem}{suffix}", tmp_path / f"{name}{suffix}")
    return tmp_path / f"{name}.csv"


def _edited(old: str, new: str) -> str:
    """The healthy sample profile with the first ``old`` replaced by ``new``."""
    assert old in HEALTHY_PROFILE
    return HEALTHY_PROFILE.replace(old, new, 1)


def _refused(text: str) -> str:
    with pytest.raises(ProfileError) as info:
        parse_profile(text, source="p.toml")
    return info.value.one_line()


# -- profile-rate-tiny ------------------------------------------------------------------------------


def test_a_tiny_vehicle_rate_is_refused_at_parse_time_naming_the_profile_key_and_range(tmp_path, cli):
    log = _reproducer(tmp_path, "profile_rate_tiny")
    result = cli("analyze", log, "--no-report", "--json", "-")
    assert result.exit_code == 2, result.stderr
    assert result.stderr.strip() == (
        f"logscan: error: {log} (embedded profile): invalid profile: [vehicle] rate_hz: "
        "must be between 0.01 and 100000 Hz, got 1e-300 (see docs/profiles.md)"
    )


@pytest.mark.parametrize(
    "old, new, where",
    [
        ("rate_hz = 100.0", "rate_hz = 5e-324", "[vehicle] rate_hz"),  # NaN grid steps
        ("rate_hz = 100.0", "rate_hz = 1e9", "[vehicle] rate_hz"),  # a grid step of 1 ns
        ("rate_hz = 100.0", "rate_hz = 0.001", "[vehicle] rate_hz"),
        ("rate_hz = 10.0", "rate_hz = 1e-300", "[measurements.position] rate_hz"),
        ("[mode]", '[redundant.x]\nsensors = { a = "/imu/accel.x", b = "/imu/accel.y" }\nrate_hz = 1e6\n\n[mode]', ""),
    ],
)
def test_every_rate_out_of_range_is_refused(old, new, where):
    line = _refused(_edited(old, new))
    where = where or "[redundant.x] rate_hz"
    assert line.startswith(f"p.toml: invalid profile: {where}: must be between 0.01 and 100000 Hz, got "), line


@pytest.mark.parametrize("rate", [MIN_RATE_HZ, MAX_RATE_HZ])
def test_the_rate_bounds_themselves_are_accepted(rate):
    profile = parse_profile(_edited("rate_hz = 100.0", f"rate_hz = {rate!r}"))
    assert profile.vehicle.rate_hz == rate


def test_zero_and_negative_rates_keep_their_message():
    assert "[vehicle] rate_hz: must be > 0, got 0 " in _refused(_edited("rate_hz = 100.0", "rate_hz = 0"))
