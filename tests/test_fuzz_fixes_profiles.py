"""Profile bugs the fuzzing campaign found (tests/fuzz_regressions/README.md), fixed: tiny rates,
huge staleness limits and integers beyond float range that overflowed once past the profile checks
are refused when the profile is parsed, naming the file, the key and the allowed range (exit 2, never 3);
with several logs, each log's error names it by its path (not a Python tuple)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from logscan.errors import InputError, ProfileError
from logscan.fleet import LogFailure, run_many
from logscan.profiles import parse_profile
from logscan.profiles.schema import MAX_STALE_S, MIN_RATE_HZ

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
        "must be >= 0.01 Hz (a 100 s period), got 1e-300 (see https://github.com/logscan/logscan/blob/main/docs/profiles.md)"
    )


@pytest.mark.parametrize(
    "old, new, where",
    [
        ("rate_hz = 100.0", "rate_hz = 5e-324", "[vehicle] rate_hz"),  # NaN grid steps
        ("rate_hz = 100.0", "rate_hz = 0.001", "[vehicle] rate_hz"),
        ("rate_hz = 10.0", "rate_hz = 1e-300", "[measurements.position] rate_hz"),
        ("[mode]", '[redundant.x]\nsensors = { a = "/imu/accel.x", b = "/imu/accel.y" }\nrate_hz = 1e-9\n\n[mode]', ""),
    ],
)
def test_every_rate_below_the_minimum_is_refused(old, new, where):
    line = _refused(_edited(old, new))
    where = where or "[redundant.x] rate_hz"
    assert line.startswith(f"p.toml: invalid profile: {where}: must be >= 0.01 Hz (a 100 s period), got "), line


@pytest.mark.parametrize("rate", [MIN_RATE_HZ, 1e9, 1e300])
def test_the_minimum_rate_and_high_rates_are_accepted(rate):
    """A rate too high for the log is refused by alignment, with the span and the grid's steps
    (tests/test_time_sanity.py)."""
    profile = parse_profile(_edited("rate_hz = 100.0", f"rate_hz = {rate!r}"))
    assert profile.vehicle.rate_hz == rate


def test_zero_and_negative_rates_keep_their_message():
    assert "[vehicle] rate_hz: must be > 0, got 0 " in _refused(_edited("rate_hz = 100.0", "rate_hz = 0"))


# -- profile-stale-overflow -------------------------------------------------------------------------


def test_a_huge_stale_s_is_refused_at_parse_time_naming_the_profile_key_and_range(tmp_path, cli):
    log = _reproducer(tmp_path, "profile_stale_huge")
    result = cli("analyze", log, "--no-report", "--json", "-")
    assert result.exit_code == 2, result.stderr
    assert result.stderr.strip() == (
        f"logscan: error: {log} (embedded profile): invalid profile: [measurements.accel] stale_s: "
        "must be at most 1000000 s (or inf: never stale), got 1e+308 (see https://github.com/logscan/logscan/blob/main/docs/profiles.md)"
    )


BIG_INTEGER = "1" + "0" * 400  # TOML integers have no size limit in tomllib


@pytest.mark.parametrize("value", ["1e308", str(2**63 - 1), str(2**64), "1e7"])
@pytest.mark.parametrize(
    "old, new, where",
    [
        ("stale_s = 0.025", "stale_s = {}", "[measurements.accel]"),
        ("[inputs]", "[inputs]\nstale_s = {}", "[inputs]"),
        ("[mode]\n", "[mode]\nstale_s = {}\n", "[mode]"),
        ("[onboard]\n", "[onboard]\nstale_s = {}\n", "[onboard]"),
        (
            "[mode]",
            '[redundant.x]\nsensors = {{ a = "/imu/accel.x", b = "/imu/accel.y" }}\nstale_s = {}\n\n[mode]',
            "[redundant.x]",
        ),
    ],
)
def test_every_staleness_limit_beyond_the_maximum_is_refused(old, new, where, value):
    line = _refused(_edited(old, new.format(value)))
    expected = f"p.toml: invalid profile: {where} stale_s: must be at most 1000000 s (or inf: never stale), got "
    assert line.startswith(expected), line


@pytest.mark.parametrize("value", ["inf", repr(MAX_STALE_S)])
def test_inf_and_the_maximum_staleness_are_accepted(value):
    profile = parse_profile(_edited("stale_s = 0.025", f"stale_s = {value}"))
    assert profile.measurements["accel"].stale_s == float(value)


@pytest.mark.parametrize(
    "old, new, message",
    [
        ("stale_s = 0.025", f"stale_s = {BIG_INTEGER}", "[measurements.accel] stale_s: must be a finite number"),
        ("rate_hz = 100.0", f"rate_hz = {BIG_INTEGER}", "[vehicle] rate_hz: must be a finite number, got an integer"),
        ("[0.1, 0.1, 0.1]", f"[{BIG_INTEGER}, 0.1, 0.1]", "[measurements.accel] noise_std: must be finite, got an"),
        ("stale_s = 0.025", "stale_s = 1" + "0" * 5000, "invalid TOML: an integer has more than 4300 digits"),
    ],
)
def test_an_integer_beyond_float_range_is_a_profile_error_not_an_overflow(old, new, message):
    assert message in _refused(_edited(old, new))


# -- error-tuple-name -------------------------------------------------------------------------------


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_with_several_logs_each_error_names_its_log_as_a_plain_path(tmp_path, cli, jobs):
    logs = [_reproducer(tmp_path, "unknown_detector", name) for name in ("first", "second")]
    result = cli("analyze", *logs, "--no-report", "--json", "-", "--jobs", jobs)
    assert result.exit_code == 2, result.stderr
    errors = json.loads(result.stdout)["errors"]
    assert [e["file"] for e in errors] == [str(log) for log in logs]
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 2
    for log, line, error in zip(logs, lines, errors):
        assert line.startswith(f"logscan: error: {log}") and error["error"].startswith(str(log)), line
        assert "unknown detector 'no_such_detector'" in line and "('" not in line


def test_run_many_names_a_failed_log_by_the_first_item_of_its_tuple():
    outcomes = run_many([("a", "a.html"), ("bad", "bad.html")], _pair_task)
    assert outcomes[0] == "A"
    assert outcomes[1] == LogFailure("bad", "bad: cannot read", 2)


def _pair_task(item: tuple[str, str]) -> str:
    log, _report = item
    if log == "bad":
        raise InputError("cannot read")
    return log.upper()


# -- unknown-detector-unnamed -----------------------------------------------------------------------

UNKNOWN = "unknown detector 'no_such_detector' (available: "


def test_an_unknown_detector_in_a_sidecar_profile_names_the_profile_and_its_log(tmp_path, cli):
    log = _reproducer(tmp_path, "unknown_detector")
    result = cli("analyze", log, "--no-report", "--json", "-")
    assert result.exit_code == 2 and result.stdout == "", result.stderr
    assert result.stderr.startswith(f"logscan: error: {log} (embedded profile): {UNKNOWN}"), result.stderr


def test_an_unknown_detector_in_a_profile_file_names_that_file(tmp_path, cli):
    log = _reproducer(tmp_path, "unknown_detector")
    profile = tmp_path / "unknown.toml"
    shutil.copyfile(REGRESSIONS / "unknown_detector.profile.toml", profile)
    result = cli("analyze", log, "--profile", profile, "--no-report")
    assert result.exit_code == 2
    assert result.stderr.startswith(f"logscan: error: {profile}: {UNKNOWN}"), result.stderr


def test_a_bad_detector_setting_in_a_sidecar_profile_names_its_log_not_just_embedded(tmp_path, cli):
    log = _reproducer(tmp_path, "unknown_detector")
    sidecar = log.with_suffix(".profile.toml")
    sidecar.write_text(sidecar.read_text().replace("[detectors.no_such_detector]", "[detectors.nis]\nwindow = 0"))
    result = cli("analyze", log, "--no-report")
    assert result.exit_code == 2
    assert result.stderr.strip() == (
        f"logscan: error: {log} (embedded profile): detector 'nis': window must be an integer in [1, inf), got 0"
    )


def test_an_unknown_detector_given_on_the_command_line_is_not_blamed_on_the_profile(tmp_path, cli):
    log = _reproducer(tmp_path, "unknown_detector")  # --detector replaces the profile's choice
    result = cli("analyze", log, "--detector", "nope", "--no-report")
    assert result.exit_code == 2
    assert result.stderr.startswith("logscan: error: unknown detector 'nope' (available: "), result.stderr


@pytest.mark.parametrize(
    ("setting", "expected"),
    [
        ("window = 1" + "0" * 400, "window must be an integer in [1, inf), got 10000000000000000000...00000000"),
        ("budget_per_hour = 1" + "0" * 400, "budget_per_hour must be a number in [1e-12, inf)"),
        ("window = 9223372036854775808", "window must be an integer in [1, inf), got 9223372036854775808"),
    ],
)
def test_detector_settings_beyond_int64_or_float_range_are_profile_errors(cli, sample, tmp_path, setting, expected):
    """10**400 as a window used to pass the checks and fail in numpy (exit 3)."""
    log = tmp_path / "quad.csv"
    shutil.copy(sample("quad_healthy.csv"), log)
    base = Path(sample("quad_healthy.profile.toml")).read_text(encoding="utf-8")
    (tmp_path / "quad.profile.toml").write_text(base + f"\n[detectors.nis]\n{setting}\n", encoding="utf-8")
    result = cli("analyze", log, "--no-report", "-q")
    assert result.exit_code == 2, result.stderr
    assert expected in result.stderr and len(result.stderr) < 500  # the 401 digits are not quoted


@pytest.mark.parametrize(
    ("param", "expected"),
    [
        ("La = 1e-300", "parameters give numbers beyond float range"),
        ("N = 1e200", "parameters give numbers beyond float range"),
        ("Km = 1e308", "discretised at dt = 0.05 s are not finite"),
    ],
)
def test_model_parameters_beyond_float_range_are_profile_errors(cli, sample, tmp_path, param, expected):
    """dc_motor with La = 1e-300 or Km = 1e308 raised OverflowError in Python float arithmetic or
    in the discretisation (exit 3)."""
    from logscan.readers import read_embedded_profile

    log = sample("jackal_healthy.mcap")
    text = read_embedded_profile(log)
    profile = tmp_path / "jackal.toml"
    profile.write_text(text.replace("[inputs]", f"[vehicle.params]\n{param}\n\n[inputs]", 1), encoding="utf-8")
    result = cli("analyze", log, "--profile", profile, "--no-report", "-q")
    assert result.exit_code == 2, result.stderr
    assert "invalid profile" in result.stderr and expected in result.stderr
