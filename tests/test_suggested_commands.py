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
