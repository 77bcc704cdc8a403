"""The hand-written `ins` example profiles in docs/examples on the real PX4 logs of
../shared/testdata/px4-ulog: each log is analysed end to end through the CLI, the filter updates
every group it names, and the NIS of every group is reported (finite, in the JSON summary)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO, need_testdata

from logscan.models import get_model
from logscan.profiles import load_profile

EXAMPLES = REPO / "docs" / "examples"
# log -> the example profile written for its PX4 generation
LOGS = {
    "sample_log_small.ulg": "px4-ins.profile.toml",
    "sample_logging_tagged_and_default_params.ulg": "px4-ins.profile.toml",
    "sample_px4_events.ulg": "px4-ins-v1.14.profile.toml",
    "sample_appended_multiple.ulg": "px4-ins-legacy.profile.toml",
}


@pytest.mark.parametrize("profile", sorted({*LOGS.values()}))
def test_example_profile_is_valid_for_the_ins_model(profile):
    loaded = load_profile(EXAMPLES / profile)
    assert loaded.vehicle.model == "ins"
    model = get_model("ins", loaded.vehicle.params)
    assert set(loaded.measurements) <= set(model.groups)
    assert loaded.inputs.names == list(model.input_names)


@pytest.mark.parametrize(("log", "profile"), sorted(LOGS.items()))
def test_ins_profile_analyses_the_real_px4_log(log, profile, cli, tmp_path):
    path = need_testdata(Path("px4-ulog") / log)
    summary = tmp_path / "summary.json"
    report = tmp_path / "report.html"
    result = cli("analyze", str(path), "--profile", str(EXAMPLES / profile), "-o", str(report), "--json", str(summary))
    assert result.exit_code in (0, 1), result.stderr  # analysed (alarms or not), nothing unchecked
    entry = json.loads(summary.read_text())["logs"][0]
    groups = set(load_profile(EXAMPLES / profile).measurements)
    filt = entry["filter"]
    assert set(filt["updates"]) == groups and min(filt["updates"].values()) >= 20
    assert filt["divergence_episodes"] == 0
    nis = filt["mean_nis"]
    assert set(nis) == groups and all(np.isfinite(v) and v >= 0 for v in nis.values())
    assert entry["model"] == "ins"
    nis_series = next(d for d in entry["detectors"] if d["detector"] == "nis")["series"]
    assert {f"nis.{g}" for g in groups} <= set(nis_series)  # per-group NIS statistics, drawn in the report
    html = report.read_text(encoding="utf-8")
    read = len({ch.split("/")[1] for g in load_profile(EXAMPLES / profile).measurements.values() for ch in g.channels})
    found = re.search(r"(\d+) read of \d+ in the log", html)
    assert found and int(found.group(1)) >= read  # ULog topics (no leading "/") found read
