"""docs/ci.md's GitHub Actions workflow: valid YAML, the artifact uploaded even when the analysis
fails, the kernel cache where logscan keeps it, and its logscan command run as written on a
`logs/` folder of sample logs (exit 0 on healthy logs, 1 with a faulty one, reports written)."""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
DOC = (ROOT / "docs" / "ci.md").read_text(encoding="utf-8")


def workflows() -> list[dict]:
    return [yaml.safe_load(body) for body in re.findall(r"^```yaml\n(.*?)^```", DOC, re.S | re.M)]


def steps() -> list[dict]:
    (workflow,) = workflows()
    (job,) = workflow["jobs"].values()
    return job["steps"]


def logscan_commands() -> list[list[str]]:
    return [shlex.split(step["run"], comments=True) for step in steps() if step.get("run", "").startswith("logscan ")]


def test_the_page_has_one_workflow_with_a_job():
    (workflow,) = workflows()
    assert workflow["jobs"] and (True in workflow or "on" in workflow)  # YAML 1.1 reads `on` as True


def test_python_is_set_up_and_logscan_installed_before_it_runs():
    uses = [step.get("uses", "") for step in steps()]
    runs = [step.get("run", "") for step in steps()]
    setup = next(i for i, u in enumerate(uses) if u.startswith("actions/setup-python@"))
    install = next(i for i, r in enumerate(runs) if r.startswith("pip install"))
    analyze = next(i for i, r in enumerate(runs) if r.startswith("logscan analyze"))
    assert setup < install < analyze


def test_the_reports_are_uploaded_even_when_the_analysis_fails():
    upload = next(step for step in steps() if step.get("uses", "").startswith("actions/upload-artifact@"))
    assert upload.get("if") == "always()"
    (command,) = logscan_commands()
    output = command[command.index("-o") + 1]
    assert upload["with"]["path"].rstrip("/") == output.rstrip("/")


def test_the_cached_path_is_logscans_cache_on_linux(monkeypatch):
    import logscan

    cache = next(step for step in steps() if step.get("uses", "").startswith("actions/cache@"))
    monkeypatch.delenv("LOGSCAN_CACHE_DIR", raising=False)
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    monkeypatch.setattr(sys, "platform", "linux")
    assert Path(cache["with"]["path"]).expanduser() == logscan.cache_dir()


@pytest.mark.parametrize(
    "logs, code", [(("quad_healthy.mcap", "sbw_healthy.mcap"), 0), (("quad_healthy.mcap", "quad_imu_bias.mcap"), 1)]
)
def test_the_workflows_command_runs_as_written(tmp_path, logs, code):
    (command,) = logscan_commands()
    assert command[:2] == ["logscan", "analyze"]
    (tmp_path / "logs").mkdir()
    for name in logs:
        shutil.copy2(ROOT / "sample_logs" / name, tmp_path / "logs" / name)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(
        [sys.executable, "-m", "logscan", *command[1:]], cwd=tmp_path, env=env, capture_output=True, text=True
    )
    assert done.returncode == code, done.stderr
    reports = tmp_path / "reports"
    assert sorted(p.name for p in reports.glob("*.report.html")) == sorted(
        n.replace(".mcap", ".report.html") for n in logs
    )
    assert (reports / "plotly.min.js").is_file()
    summary = json.loads((reports / "summary.json").read_text(encoding="utf-8"))
    assert summary["exit_code"] == code and len(summary["logs"]) == len(logs)
