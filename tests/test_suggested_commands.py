"""The commands an error's hint suggests are commands that run: the log's own path where it is
known, no placeholder where a real value exists (the tables' commands: tests/test_tables_transfer.py)."""

from __future__ import annotations

import shlex

from conftest import one_state_profile


def _suggested(stderr: str) -> list[str]:
    words = shlex.split(stderr.split("`")[1])
    assert words[0] == "logscan"
    return words[1:]


def test_a_log_without_a_finite_sample_names_the_inspect_command_for_it(cli, tmp_path):
    log = tmp_path / "all nan.csv"  # a space in the path: the command quotes it
    log.write_text("time_s,thrust,accel\n" + "".join(f"{i / 100:.2f},nan,nan\n" for i in range(50)))
    profile = tmp_path / "one.toml"
    profile.write_text(one_state_profile("/thrust", "/accel"))
    refused = cli("analyze", log, "--profile", profile, "--no-report")
    assert refused.exit_code == 2 and "none of the profile's input and measurement channels" in refused.stderr
    args = _suggested(refused.stderr)
    assert args == ["inspect", str(log), "--channels"]
    inspected = cli(*args)
    assert inspected.exit_code == 0 and "/thrust" in inspected.stdout


def test_an_untrained_atfm_names_a_train_command_that_runs_on_logs_embedding_their_profile(cli, sample, tmp_path):
    faulty = sample("jackal_gps_bias.mcap")
    untrained = cli("analyze", faulty, "-d", "atfm", "--no-report")
    assert untrained.exit_code == 2
    message = untrained.stdout + untrained.stderr
    args = _suggested(message[message.index("train one with") :])
    assert args[:2] == ["train", "HEALTHY_LOG..."] and "--profile" not in args  # the samples embed theirs
    tables = tmp_path / "tables.json"
    healthy = [str(sample(f"jackal_train_{i}.mcap")) for i in (1, 2)]
    args = ["train", *healthy, *args[2:]]
    args[args.index("-o") + 1] = str(tables)
    assert cli(*args, "--no-report", "-q").exit_code == 0
    assert cli("analyze", faulty, "-d", "atfm", "--tables", tables, "--no-report").exit_code == 1  # the GPS bias
