"""The starter profile of a CSV log (`logscan.profiles.starter`): which columns become states, the
fresh mode of forward-filled ones, noise read from the column, and a profile that always parses."""

from __future__ import annotations

import numpy as np
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from logscan.cli.main import cli
from logscan.log import Channel, Log, SourceInfo
from logscan.profiles import parse_profile
from logscan.profiles.starter import starter_profile

NS = 1_000_000_000


def wide_log(columns: dict[str, np.ndarray], rate_hz: float = 20.0) -> Log:
    n = len(next(iter(columns.values())))
    t = (np.arange(n) * NS / rate_hz).astype(np.int64)
    return Log({f"/{k}": Channel(f"/{k}", t, v) for k, v in columns.items()}, SourceInfo("flight.csv", "csv"))


def test_columns_are_kept_or_dropped_with_their_reason():
    rng = np.random.default_rng(1)
    n = 2000
    speed = 18 + np.cumsum(rng.normal(0, 0.02, n)) + rng.normal(0, 0.25, n)
    filled = np.repeat(rng.normal(0, 0.3, n // 8 + 1), 8)[:n]
    built = starter_profile(
        wide_log(
            {
                "speed": speed,
                "acc": filled,
                "copy": speed.copy(),
                "fix": np.full(n, 3.0),
                "mode": np.repeat([0.0, 1.0, 2.0, 1.0], n // 4),
                "counter": np.arange(n, dtype=float),
            }
        )
    )
    kept = {c.channel: c for c in built.kept}
    dropped = dict(built.dropped)
    assert set(kept) == {"/speed", "/acc"}
    assert kept["/speed"].fresh == "on_sample" and kept["/acc"].fresh == "on_change"
    assert kept["/acc"].rate_hz == 2.5  # fresh every 8th row of 20 Hz
    assert dropped["/copy"] == "an exact copy of /speed"
    assert dropped["/fix"].startswith("constant")
    assert "distinct values" in dropped["/mode"] and "undecided" in dropped["/mode"]
    assert "counter" in dropped["/counter"]
    # the noise is the column's own: white noise 0.25 read back within 10 %
    assert abs(kept["/speed"].noise_std - 0.25) < 0.025
    profile = parse_profile(built.text)
    assert profile.measurements["acc"].fresh == "on_change"
    assert "# columns not used:" in built.text and "#   /fix: constant (3)" in built.text


def test_init_profile_writes_a_starter_for_a_csv_that_analyze_accepts(tmp_path):
    rng = np.random.default_rng(2)
    t = np.arange(600) / 20
    lines = ["time_s,alt,acc,label"] + [
        f"{ti:.2f},{100 + 0.01 * i + rng.normal(0, 0.3):.3f},{np.sin(i // 8):.4f},x" for i, ti in enumerate(t)
    ]
    (tmp_path / "flight.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    runner = CliRunner()
    written = runner.invoke(cli, ["init-profile", str(tmp_path / "flight.csv"), "-o", str(tmp_path / "p.toml")])
    assert written.exit_code == 0, written.output
    text = (tmp_path / "p.toml").read_text(encoding="utf-8")
    assert "#   label: text, not numeric" in text and 'fresh = "on_change"' in text
    analysed = runner.invoke(
        cli, ["analyze", str(tmp_path / "flight.csv"), "--profile", str(tmp_path / "p.toml"), "--no-report", "-q"]
    )
    assert analysed.exit_code in (0, 1), analysed.output


def test_a_misspelt_column_of_a_csv_with_units_in_its_header_suggests_the_real_one(cli, tmp_path):
    """The read keeps only the columns the profile names, so a misspelt one ("/sped [m/s]") was
    matched against none of the others; and "/x" is too far from "/x [m]" by letters alone (the
    unit a CSV header carries is part of the channel's name)."""
    t = np.arange(400) / 20
    lines = ["time [s],x [m],y [m],speed [m/s]"] + [
        f"{ti:.2f},{10 * np.cos(ti / 10):.4f},{10 * np.sin(ti / 10):.4f},{1 + 0.01 * np.sin(ti):.4f}" for ti in t
    ]
    log = tmp_path / "drive.csv"
    log.write_text("\n".join(lines) + "\n", encoding="utf-8")
    starter = tmp_path / "p.toml"
    assert cli("init-profile", log, "-o", starter).exit_code == 0
    text = starter.read_text(encoding="utf-8")
    assert '"/x [m]"' in text and '"/speed [m/s]"' in text
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace('"/x [m]"', '"/x"').replace('"/speed [m/s]"', '"/sped [m/s]"'), encoding="utf-8")
    result = cli("analyze", log, "--profile", bad, "--no-report")
    assert result.exit_code == 2 and "Traceback" not in result.stderr
    assert "no channel '/x' in the log (did you mean '/x [m]'?)" in result.stderr
    assert "no channel '/sped [m/s]' in the log (did you mean '/speed [m/s]'?)" in result.stderr


finite = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False, width=32)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    data=arrays(np.float64, st.tuples(st.integers(40, 200), st.integers(2, 6)), elements=finite),
    fill=st.integers(1, 9),
)
def test_any_numeric_csv_with_two_varying_columns_gives_a_profile_that_parses(data, fill):
    n = data.shape[0]
    ramp = np.linspace(0.0, 1.0, n)
    # two columns that surely vary (one forward-filled when fill > 1), whatever hypothesis draws
    columns = {f"c{j}": data[:, j] for j in range(data.shape[1])}
    columns["ramp_noise"] = ramp + np.sin(np.arange(n) * 1.7)
    columns["filled"] = np.repeat(np.cos(np.arange(n) * 0.9), fill)[:n]
    built = starter_profile(wide_log(columns))
    assert built.kept
    profile = parse_profile(built.text)
    assert len(profile.measurements) == len(built.kept)
    assert all(np.isfinite(c.noise_std) and c.noise_std > 0 and c.q > 0 for c in built.kept)
