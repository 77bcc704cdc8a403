"""The CLI's messages for bad arguments (issue 30): one line naming the argument or file, what is
wrong and what to do, exit 2; misspelt names get the closest ones (did you mean), and every
argument is checked before a log is read or a kernel compiled."""

from __future__ import annotations

from pathlib import Path

import pytest

SAMPLES = Path(__file__).resolve().parents[1] / "sample_logs"
README = Path(__file__).resolve().parents[1] / "README.md"
PROFILE = SAMPLES / "quad_healthy.profile.toml"
DETECTORS = "encoded_ekf, nis, cusum, frozen, atfm, atfm_residual, chi2, kgn, px4_estimator, health"
PROFILES_DOC = "https://github.com/logscan/logscan/blob/main/docs/profiles.md"
FAULTS = (
    "bias, drift, random, bitflip, stuck, actuator-offset, lost-actuator, cov-corruption, state-corruption, "
    "control-fault, control-stuck, "
    "imu-bias, imu-drift, imu-random, imu-bitflip, imu-stuck, motor-offset, lost-motor, roll-bias, rotor-loss"
)


def assert_message(result, line: str) -> None:
    assert result.exit_code == 2, (result.exit_code, result.stderr)
    assert result.stderr == f"logscan: error: {line}\n"


def test_an_unknown_model_is_named_with_the_closest_before_anything_else(cli, tmp_path, monkeypatch):
    import logscan.cli.simulate_cmd as simulate_cmd

    def compiles(*args, **kwargs):
        raise AssertionError("the simulator's kernel was looked at before the model was checked")

    monkeypatch.setattr(simulate_cmd, "_simulator_cold", compiles)
    result = cli("simulate", "quadcoptr", "-o", tmp_path / "q.mcap")
    assert_message(
        result,
        "cannot simulate model 'quadcoptr' (did you mean 'quadcopter'? simulated models: quadcopter, "
        "steer_by_wire, dc_motor, hover_uav, ins, ground_robot)",
    )
    assert not (tmp_path / "q.mcap").exists()


@pytest.mark.parametrize(
    ("args", "line"),
    [
        (["--duration", "-1"], "--duration -1 s is out of range (use 0 < duration <= 86400 s)"),
        (["--rate", "0.5"], "--rate 0.5 Hz is out of range (use 1 .. 10000 Hz)"),
        (["--scenario", "random"], "--scenario is for ground_robot (drop --scenario)"),
    ],
)
def test_simulate_checks_every_option_before_the_compile_note(cli, tmp_path, monkeypatch, args, line):
    import logscan.cli.simulate_cmd as simulate_cmd

    def compiles(*args, **kwargs):
        raise AssertionError("the simulator's kernel was looked at before the options were checked")

    monkeypatch.setattr(simulate_cmd, "_simulator_cold", compiles)
    assert_message(cli("simulate", "quadcopter", *args, "-o", tmp_path / "q.mcap"), line)
    assert not (tmp_path / "q.mcap").exists()


def test_an_unknown_fault_kind_is_named_with_the_closest_before_the_output_is_checked(cli):
    result = cli("simulate", "quadcopter", "--fault", "imu-bais")  # no -o: the fault is the first problem
    assert_message(
        result, f"unknown fault kind 'imu-bais' (did you mean 'imu-bias' or 'imu-bitflip'? choose one of {FAULTS})"
    )


@pytest.mark.parametrize("command", ["analyze", "evaluate"])
def test_an_unknown_detector_on_the_command_line_gets_the_closest_name(cli, command):
    result = cli(command, SAMPLES / "quad_healthy.mcap", "-d", "nsi", "--json", "-")
    assert_message(
        result, f"unknown detector 'nsi' (did you mean 'nis'? available: {DETECTORS} (see `logscan detectors`))"
    )
    assert result.stdout == ""


def test_a_window_after_the_log_says_which_option_not_none(cli):
    log = SAMPLES / "quad_healthy.mcap"
    result = cli("analyze", log, "--start", "100", "--no-report")
    assert_message(
        result,
        f"{log}: the window --start 100 holds no two grid steps of the log's channels (0.000 .. 60.000 s) "
        "(give --start/--end in seconds since the log's start, within its span)",
    )


@pytest.mark.parametrize("command", ["analyze", "evaluate"])
def test_tables_that_are_not_json_are_one_line_before_any_log(cli, command):
    result = cli(command, SAMPLES / "quad_healthy.mcap", "--tables", README, "--json", "-")
    assert_message(
        result,
        f"{README}: not a tables file: not JSON (line 1, column 1) (give the tables JSON `logscan train -o` wrote)",
    )
    assert result.stdout == ""


def test_a_csv_without_time_column_says_so_before_no_profile(cli, tmp_path):
    log = tmp_path / "flight.csv"
    log.write_text("a,b\n1,2\n3,4\n")
    result = cli("analyze", log, "--no-report")
    assert_message(
        result,
        f"{log}: no time column among 'a', 'b' "
        "(name it time, timestamp, t or stamp, optionally with a unit: time_s, timestamp_us)",
    )


def test_a_csv_with_a_time_column_and_no_profile_still_says_no_profile(cli, tmp_path):
    log = tmp_path / "flight.csv"
    log.write_text("time_s,a\n0,2\n0.1,4\n")
    result = cli("analyze", log, "--no-report")
    assert_message(
        result,
        f"{log}: no profile: the log embeds none (`logscan init-profile {log} -o profile.toml` writes a starter one "
        f"to edit; then pass --profile profile.toml (see {PROFILES_DOC}))",
    )


def profile_with(tmp_path, old: str, new: str) -> Path:
    text = PROFILE.read_text()
    assert old in text
    path = tmp_path / "bad.toml"
    path.write_text(text.replace(old, new, 1))
    return path


def test_every_profile_problem_is_listed_not_counted(cli, tmp_path):
    profile = tmp_path / "bad.toml"
    profile.write_text(
        PROFILE.read_text().replace("stale_s = 0.025", "stale_s = -1").replace("rate_hz = 10.0", "rate_hz = 0")
    )
    result = cli("analyze", SAMPLES / "quad_healthy.mcap", "--profile", profile, "--no-report")
    assert_message(
        result,
        f"{profile}: invalid profile: 3 problems: [measurements.accel] stale_s: must be > 0, got -1; "
        "[measurements.gyro] stale_s: must be > 0, got -1; [measurements.position] rate_hz: must be > 0, got 0 "
        f"(see {PROFILES_DOC})",
    )


def test_a_misspelt_detector_parameter_gets_the_closest(cli, tmp_path):
    profile = profile_with(tmp_path, "[mode]", "[detectors.nis]\nwindw = 3\n\n[mode]")
    result = cli("analyze", SAMPLES / "quad_healthy.mcap", "--profile", profile, "--no-report")
    assert_message(
        result,
        f"{profile}: detector 'nis': unknown parameter(s) windw (did you mean 'window'? known: alpha, "
        "budget_per_hour, n_persist, overall, proof_hours, window)",
    )


def test_a_misspelt_detector_in_a_profile_gets_the_closest(cli, tmp_path):
    profile = profile_with(tmp_path, "[mode]", "[detectors.nsi]\n\n[mode]")
    result = cli("analyze", SAMPLES / "quad_healthy.mcap", "--profile", profile, "--no-report")
    assert_message(
        result,
        f"{profile}: unknown detector 'nsi' (did you mean 'nis'? available: {DETECTORS} (see `logscan detectors`))",
    )


def test_a_misspelt_model_parameter_gets_the_closest(cli, tmp_path):
    profile = profile_with(tmp_path, 'model = "quadcopter"', 'model = "quadcopter"\nparams = { masss = 1.2 }')
    result = cli("analyze", SAMPLES / "quad_healthy.mcap", "--profile", profile, "--no-report")
    assert_message(
        result,
        f"{profile}: invalid profile: [vehicle] params: model 'quadcopter' cannot be built: model 'quadcopter': "
        f"unknown parameter masss (did you mean 'mass'?) (see {PROFILES_DOC})",
    )


def test_a_misspelt_model_in_a_profile_gets_the_closest(cli, tmp_path):
    profile = profile_with(tmp_path, 'model = "quadcopter"', 'model = "quadcoptr"')
    result = cli("analyze", SAMPLES / "quad_healthy.mcap", "--profile", profile, "--no-report")
    assert_message(
        result,
        f"{profile}: invalid profile: [vehicle] model: unknown model 'quadcoptr' (did you mean 'quadcopter'?) "
        "(known models: dc_motor, hover_uav, ins, linear, quadcopter, steer_by_wire, unicycle, wheeled) "
        f"(see {PROFILES_DOC})",
    )


# --- help and tables ---------------------------------------------------------------------------------


def test_analyze_help_groups_its_options(cli):
    result = cli("analyze", "--help")
    assert result.exit_code == 0
    titles = [line for line in result.stdout.splitlines() if line and not line.startswith(" ") and line.endswith(":")]
    assert titles == ["Input:", "Detectors:", "Outputs:", "CI:", "Parallel:", "Other options:"]
    section = result.stdout.split("\nParallel:\n", 1)[1].split("\n\n", 1)[0]
    assert "--jobs" in section and "--scheduler" in section and "--junit" not in section


@pytest.mark.parametrize(
    "command, titles",
    [
        ("evaluate", ["Input:", "Detectors:", "Scoring:", "Outputs:", "Parallel:", "Other options:"]),
        ("train", ["Input:", "Training:", "Outputs:", "Parallel:", "Other options:"]),
    ],
)
def test_evaluate_and_train_help_group_their_options_like_analyze(cli, command, titles):
    result = cli(command, "--help")
    assert result.exit_code == 0
    shown = [line for line in result.stdout.splitlines() if line and not line.startswith(" ") and line.endswith(":")]
    assert shown == titles
    section = result.stdout.split("\nParallel:\n", 1)[1].split("\n\n", 1)[0]
    assert "--jobs" in section and "--scheduler" in section and "--quiet" not in section


@pytest.mark.parametrize("command", ["analyze", "evaluate", "train"])
def test_every_option_of_a_grouped_command_is_in_a_group(command):
    import click

    from logscan.cli.main import cli as group

    params = group.commands[command].params
    untagged = [p.name for p in params if isinstance(p, click.Option) and not hasattr(p, "help_group")]
    assert untagged == ["help"] or untagged == [], untagged


def test_the_command_list_is_not_cut(cli):
    result = cli("--help")
    listing = result.stdout.split("\nCommands:\n", 1)[1]
    assert "..." not in listing
    assert "Run the model-based detectors on each LOG and report the incidents and alarms." in " ".join(listing.split())


def test_alarm_rows_align_whatever_the_names():
    from types import SimpleNamespace

    from logscan.alarms import AlarmInterval
    from logscan.cli.render import _incident_lines

    def alarm(detector, signal, start):
        return AlarmInterval(start, start + 1, start, start, 2.0, 1.0, 2.0, "upper", 3, signal, detector)

    clock = SimpleNamespace(utc=False, short=lambda t, digits=3: f"{t:.{digits}f}")
    incidents = [
        SimpleNamespace(alarms=[alarm("nis", "nis.accel", 1.0)], headline_in=lambda c: "first"),
        SimpleNamespace(
            alarms=[alarm("a_long_detector_name", "a_very_long_statistic.name_x", 5.0)], headline_in=lambda c: "2nd"
        ),
    ]
    lines, shown = _incident_lines(incidents, clock, max_rows=12)
    rows = [line for line in lines if not line.lstrip().startswith("incident")]
    assert shown == 2 and len(rows) == 2
    assert rows[0].index("1.00") == rows[1].index("5.00")  # the start column, after the longest names
    end = rows[0].index("2.00") + len("2.00")
    assert rows[1].index("6.00") + len("6.00") == end
    assert rows[0][end : end + 10] == rows[1][end : end + 10] == "         2"  # peak/threshold


# --- colour and progress -----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("env", "expected"),
    [
        ({}, False),
        ({"FORCE_COLOR": "1"}, True),
        ({"NO_COLOR": "1", "FORCE_COLOR": "1"}, False),
        ({"FORCE_COLOR": ""}, False),
    ],
)
def test_colour_follows_no_color_and_force_color_off_a_terminal(monkeypatch, env, expected):
    from logscan.cli.progress import use_colour

    for name in ("NO_COLOR", "FORCE_COLOR"):
        monkeypatch.delenv(name, raising=False)
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    assert use_colour() is expected and use_colour(err=True) is expected


def test_the_verdict_is_coloured_by_the_exit_code_with_force_color(cli, monkeypatch):
    monkeypatch.delenv("NO_COLOR", raising=False)
    monkeypatch.setenv("FORCE_COLOR", "1")
    result = cli("analyze", SAMPLES / "quad_imu_bias.mcap", "--no-report", "-q")
    assert result.exit_code == 1
    first = result.stdout.splitlines()[0]
    assert first.startswith(f"{SAMPLES / 'quad_imu_bias.mcap'}: \x1b[31m\x1b[1m14 alarms in 1 incident\x1b[0m  (")
    monkeypatch.setenv("NO_COLOR", "1")
    plain = cli("analyze", SAMPLES / "quad_imu_bias.mcap", "--no-report", "-q")
    assert plain.exit_code == 1 and "\x1b" not in plain.stdout
    assert plain.stdout == result.stdout.replace("\x1b[31m\x1b[1m", "").replace("\x1b[0m", "")


def test_no_progress_under_ci_even_on_a_terminal(monkeypatch):
    import sys
    from types import SimpleNamespace

    from logscan.cli.options import show_progress

    monkeypatch.setattr(sys, "stderr", SimpleNamespace(isatty=lambda: True))
    monkeypatch.delenv("CI", raising=False)
    assert show_progress(False) and not show_progress(True)
    monkeypatch.setenv("CI", "true")
    assert not show_progress(False)


def test_a_step_line_ticks_and_ends_with_the_time_each_step_took(monkeypatch):
    import io
    import sys
    import time

    from logscan.cli.progress_bar import BarLine

    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    err = Terminal()
    monkeypatch.setattr(sys, "stderr", err)
    line = BarLine(interval=0.01)
    line.step("logscan: f.mcap: filtering", name="filtering")  # nothing says yet how fast: no bar, the time
    time.sleep(0.1)
    line.step("logscan: f.mcap: detecting", name="detector nis")
    line.close()
    text = err.getvalue()
    assert text.count("\r\x1b[Klogscan: f.mcap: filtering... 0 s") >= 2  # drawn, then redrawn by the ticker
    ended = [part for part in text.split("\r\x1b[K") if part.endswith("\n")]
    assert [part.split(" (")[0] for part in ended] == ["logscan: f.mcap: filtering", "logscan: f.mcap: detecting"]
    assert ended[0].endswith(" s)\n") and float(ended[0].split(" (")[1].split(" s)")[0]) >= 0.1


# --- shell completion ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("args", "incomplete", "expected"),
    [
        (["simulate"], "quad", ["quadcopter"]),
        (["simulate"], "g", ["ground_robot"]),
        (["simulate", "quadcopter", "--fault"], "imu-b", ["imu-bias", "imu-bitflip"]),
        (["analyze", "flight.mcap", "-d"], "n", ["nis"]),
        (["evaluate", "logs/", "--detector"], "atfm", ["atfm", "atfm_residual"]),
    ],
)
def test_the_shell_completes_models_fault_kinds_and_detectors(args, incomplete, expected):
    from click.shell_completion import BashComplete

    from logscan.cli.main import cli

    completions = BashComplete(cli, {}, "logscan", "_LOGSCAN_COMPLETE").get_completions(args, incomplete)
    assert [item.value for item in completions] == expected


@pytest.mark.parametrize("command", ["analyze", "evaluate"])
def test_a_bad_profile_for_several_logs_is_one_line_before_any_log(cli, tmp_path, command):
    profile = profile_with(tmp_path, "stale_s = 0.025", "stale_s = -1")
    logs = [SAMPLES / "quad_healthy.mcap", SAMPLES / "quad_imu_bias.mcap"]
    result = cli(command, *logs, "--profile", profile, "--json", "-")
    assert_message(
        result,
        f"{profile}: invalid profile: [measurements.accel] stale_s: must be > 0, got -1 (see {PROFILES_DOC})",
    )
    assert result.stdout == ""


def test_a_baseline_that_is_not_json_names_the_place_not_the_decoder(cli):
    result = cli("analyze", SAMPLES / "quad_healthy.mcap", "--no-report", "--baseline", README)
    assert_message(
        result,
        f"{README}: not a logscan analyze summary: not JSON (line 1, column 1) "
        "(pass a file written by `logscan analyze --json`)",
    )


def test_ground_truth_that_is_not_json_names_the_place_not_the_decoder(cli):
    result = cli("analyze", SAMPLES / "quad_healthy.mcap", "--no-report", "--truth", README)
    assert_message(
        result,
        f"{README}: ground truth is not valid JSON (line 1, column 1) "
        "(give a JSON object with a list of events (kind, target, start and end in seconds))",
    )


def test_evaluation_rows_align_whatever_the_check_names():
    from types import SimpleNamespace

    from logscan.cli.render import render_scores
    from logscan.verdict.evaluation import CHECK_SEPARATOR

    stats = SimpleNamespace(
        n_logs=2, n_events=6, tp=2, fn=4, fp=0, at_onset=0, recovery_alarms=0, transient_alarms=0, precision=1.0,
        recall=0.33, f1=0.5, mean_latency_s=0.09, max_latency_s=0.09, false_alarms_per_hour_healthy=0.0,
    )  # fmt: skip
    keys = ["cusum", f"cusum{CHECK_SEPARATOR}baro", f"cusum{CHECK_SEPARATOR}gnss_velocity.v_north_with_a_long_name"]
    evaluation = SimpleNamespace(keys=lambda: keys, aggregate=lambda key: stats, recovery_s=5.0)
    rows = render_scores(evaluation).splitlines()[2:5]
    assert len({len(row) for row in rows}) == 1, rows  # every column ends where the header's does
    assert len({row.index(" 0.33") for row in rows}) == 1


def test_the_summary_shows_the_first_warnings_and_counts_the_rest():
    """A log's screen shows MAX_WARNINGS warnings and says how many more the report and --json hold."""
    from logscan.cli.render import MAX_WARNINGS, render_summary
    from logscan.pipeline import analyze_log

    analysis = analyze_log(SAMPLES / "quad_healthy.mcap")
    for count in (MAX_WARNINGS, MAX_WARNINGS + 3):
        analysis.warnings = [f"warning number {k}" for k in range(count)]
        text = render_summary(analysis, None)
        assert [line for line in text.splitlines() if line.startswith("  warning: ")] == [
            f"  warning: warning number {k}" for k in range(MAX_WARNINGS)
        ]
        more = [line for line in text.splitlines() if "more warning(s)" in line]
        assert more == ([] if count == MAX_WARNINGS else ["  ... 3 more warning(s) (see the report / --json)"])


def test_the_summary_lists_the_first_incidents_and_counts_the_rest():
    """A day-long PX4 log's screen listed its 2,783 incidents one by one (its alarms were capped):
    the first max_rows are listed, then how many more the report and --json hold."""
    from logscan.cli.render import render_summary
    from logscan.pipeline import analyze_log

    analysis = analyze_log(SAMPLES / "quad_imu_bias.mcap")
    assert analysis.incidents
    for count, more in ((12, []), (15, ["  ... 3 more incident(s) (see the report / --json)"])):
        analysis.incidents = [analysis.incidents[0]] * count
        lines = render_summary(analysis, None, max_rows=12).splitlines()
        assert [line.split(":")[0] for line in lines if line.startswith("  incident ")] == [
            f"  incident {k}" for k in range(1, 13)
        ]
        assert [line for line in lines if "more incident(s)" in line] == more
