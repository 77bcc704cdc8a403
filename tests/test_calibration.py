"""Calibration of the measurement noise by `logscan train` (logscan.calibration).

A profile whose noise_std is five times the simulated noise leaves every group's mean NIS per
output near 1/25; `logscan train --calibrate` on healthy logs writes tables that carry a
calibrated noise_std that brings an unseen healthy log back to about 1 under
`logscan analyze --tables`.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from logscan.calibration import apply_calibration, calibrate
from logscan.pipeline import load_profile_for
from logscan.profiles import parse_profile


def _five_times_the_noise(text: str) -> str:
    def wider(match):
        return "noise_std = [" + ", ".join(f"{5 * float(v):g}" for v in match.group(1).split(",")) + "]"

    return re.sub(r"noise_std = \[([^\]]*)\]", wider, text)


@pytest.fixture(scope="module")
def ins_logs(tmp_path_factory):
    from logscan.simulate import simulate, write_simulation

    root = tmp_path_factory.mktemp("cal")
    paths = []
    for seed in (8101, 8102, 8103):
        path = root / f"healthy-{seed}.mcap"
        write_simulation(simulate("ins", [], duration=60.0, seed=seed), path)
        paths.append(str(path))
    wrong = root / "wrong.toml"
    wrong.write_text(_five_times_the_noise(load_profile_for(paths[0], None).text))
    return paths, str(wrong)


def test_train_calibrates_the_noise_and_an_unseen_log_comes_back_to_nis_one(ins_logs, cli, tmp_path):
    (train_a, train_b, unseen), wrong = ins_logs
    tables = tmp_path / "cal.json"
    result = cli("train", train_a, train_b, "--profile", wrong, "-o", str(tables), "--no-report", "--calibrate")
    assert result.exit_code == 0, result.stderr
    assert "mean NIS per output" in result.stdout
    document = json.loads(tables.read_text())
    for name, entry in document["calibration"]["groups"].items():
        assert entry["calibrated"], name
        assert entry["mean_nis_per_output_before"] < 0.1  # the profile's noise is 5x the data's
        assert entry["mean_nis_per_output_after"] == pytest.approx(1.0, abs=0.05)
        # back to the simulated noise (the model's default noise_std), within 10 %
        np.testing.assert_allclose(entry["noise_std"], np.asarray(entry["profile_noise_std"]) / 5, rtol=0.1)

    def mean_nis(*extra):
        summary = tmp_path / f"s{len(extra)}.json"
        cli("analyze", unseen, "--profile", wrong, "--no-report", "--json", str(summary), *extra)
        entry = json.loads(summary.read_text())["logs"][0]
        sizes = {"gnss_position": 3, "gnss_velocity": 3, "baro": 1, "heading": 1, "attitude": 3}
        return {g: v / sizes[g] for g, v in entry["filter"]["mean_nis"].items()}

    before, after = mean_nis(), mean_nis("--tables", str(tables))
    assert all(v < 0.1 for v in before.values()), before
    assert all(0.5 <= v <= 2.0 for v in after.values()), after


def test_a_group_with_too_few_updates_is_left_as_the_profile_has_it(ins_logs):
    from logscan.align import align
    from logscan.models import get_model
    from logscan.readers import read_log

    (path, _, _), wrong = ins_logs
    profile = parse_profile(open(wrong).read())
    run = align(read_log(path), profile, end_s=1.5)  # 15 GNSS fixes in 1.5 s: below CAL_MIN_UPDATES
    calibration = calibrate(get_model("ins"), [run])
    entry = calibration["groups"]["gnss_position"]
    assert not entry["calibrated"] and entry["noise_std"] == entry["profile_noise_std"]
    assert calibration["groups"]["attitude"]["calibrated"]  # 50 Hz: 75 updates
    before = list(profile.measurements["attitude"].noise_std)
    lines = apply_calibration(profile, calibration)
    assert profile.measurements["gnss_position"].noise_std == entry["profile_noise_std"]
    assert profile.measurements["attitude"].noise_std != before and any("attitude" in line for line in lines)
