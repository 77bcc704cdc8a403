"""Calibration of the measurement noise by `logscan train` (logscan.training.calibration).

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

from logscan.pipeline import load_profile_for
from logscan.profiles import parse_profile
from logscan.training.calibration import apply_calibration, calibrate


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


def test_train_on_a_window_of_each_log_records_it_and_reads_only_it(ins_logs, cli, tmp_path):
    (train_a, _, _), wrong = ins_logs
    counts = {}
    for name, window in (("full", ()), ("window", ("--start", "20", "--end", "50"))):
        tables = tmp_path / f"{name}.json"
        result = cli("train", train_a, "--profile", wrong, "-o", str(tables), "--no-report", "--calibrate", *window)
        assert result.exit_code == 0, result.stderr
        document = json.loads(tables.read_text())
        counts[name] = document["calibration"]["groups"]["gnss_position"]["updates"]
        if window:
            assert document["training_window"] == {"start_s": 20.0, "end_s": 50.0}
            assert "trained on 1 log(s) (20 s to 50 s of each)" in result.stdout
        else:
            assert document["training_window"] is None
    # 10 Hz GNSS: 30 s of a 60 s log hold half its fixes
    assert counts["window"] == pytest.approx(counts["full"] / 2, rel=0.05)
    bad = cli(
        "train",
        train_a,
        "--profile",
        wrong,
        "-o",
        str(tmp_path / "bad.json"),
        "--calibrate",
        "--start",
        "9",
        "--end",
        "3",
    )
    assert bad.exit_code == 2 and "--end 3 must be after --start 9" in bad.stderr


def test_calibration_reads_only_the_judged_steps(ins_logs):
    """Steps the [alarms] policy does not judge (here the filter's first 30 s) are not calibrated
    on: the NIS counts are those of the judged steps alone, and judged_steps follows the policy."""
    from logscan.align import align
    from logscan.models import get_model
    from logscan.readers import read_log
    from logscan.training.calibration import judged_steps
    from logscan.training.process_noise import evaluate

    (path, _, _), wrong = ins_logs
    text = open(wrong).read() + "\n[alarms]\nignore_start_s = 30.0\n"
    profile = parse_profile(text)
    run = align(read_log(path), profile)
    judged = judged_steps(profile, run)
    assert judged is not None and judged.dtype == bool
    np.testing.assert_array_equal(judged, run.t >= run.t[0] + 30.0)
    assert judged_steps(parse_profile(open(wrong).read()), run) is None  # no policy: every step
    model = get_model("ins")
    noise = {name: np.asarray(m.noise_std, dtype=float) for name, m in profile.measurements.items()}
    everything = evaluate(model, [run], noise, np.ones(model.n_states))
    second_half = evaluate(model, [run], noise, np.ones(model.n_states), [judged])
    for name, (_, count) in everything.nis.items():
        assert 0.4 * count <= second_half.nis[name][1] <= 0.6 * count, name
    assert second_half.samples < everything.samples


def test_a_group_whose_noise_is_at_the_floor_is_costed_at_its_own_level():
    """The concentrated cost takes each group's level of S out; at the R floor the level is Q's to
    set, so that group's cost is the plain -2 log L (log S + y^2 / S summed)."""
    from logscan.training.process_noise import _concentrated_cost

    terms = {"a": np.array([10.0, 0.5, 100.0]), "b": np.array([-3.0, 400.0, 50.0])}
    concentrated = _concentrated_cost(terms)
    plain_b = _concentrated_cost(terms, frozenset({"b"}))
    assert plain_b - concentrated == pytest.approx((-3.0 + 400.0) - (-3.0 + 50 * np.log(400.0 / 50) + 50))
    # a group whose innovations are as wide as S predicts (y^2 / S averaging 1) costs the same either way
    fitted = {"c": np.array([7.0, 80.0, 80.0])}
    assert _concentrated_cost(fitted) == pytest.approx(_concentrated_cost(fitted, frozenset({"c"})))


def test_a_group_with_logged_noise_is_calibrated_through_a_factor_on_it(ins_logs):
    """A group whose std is logged per sample (noise_channels: the filter takes those in place of
    noise_std) is calibrated by a factor on the logged std: 5x too large comes back to about 1/5."""
    from dataclasses import replace

    from logscan.align import align
    from logscan.models import get_model
    from logscan.readers import read_log
    from logscan.training.calibration import calibrated_runs, calibration_lines, mean_nis_per_output

    (path, _, _), wrong = ins_logs
    profile = parse_profile(open(wrong).read())
    run = align(read_log(path), profile)
    group = run.groups["gnss_position"]
    logged = np.broadcast_to(np.asarray(group.noise_std), (run.n_steps, 3)).copy()  # 5x the truth
    run = replace(run, groups={**run.groups, "gnss_position": replace(group, noise_std_series=logged)})
    model = get_model("ins")
    calibration = calibrate(model, [run], process_noise=False)
    entry = calibration["groups"]["gnss_position"]
    assert entry["noise_factor"] == pytest.approx(0.2, rel=0.1)
    assert entry["logged_noise"] and not calibration["groups"]["attitude"]["logged_noise"]
    assert "logged per-sample std x 0.2" in "\n".join(calibration_lines(calibration))
    assert entry["mean_nis_per_output_after"] == pytest.approx(1.0, abs=0.2)
    (again,) = calibrated_runs([run], calibration)
    np.testing.assert_allclose(again.groups["gnss_position"].noise_std_series, logged * entry["noise_factor"])
    np.testing.assert_array_equal(run.groups["gnss_position"].noise_std_series, logged)  # the input kept
    noise = {name: np.asarray(e["noise_std"]) for name, e in calibration["groups"].items()}
    assert mean_nis_per_output(model, [again], noise)["gnss_position"][0] == pytest.approx(1.0, abs=0.2)


def test_noise_channels_scale_is_read_written_and_refused_without_noise_channels(ins_logs):
    _, wrong = ins_logs
    text = open(wrong).read()
    head, rest = text.split("[measurements.gnss_position]", 1)
    logged = 'noise_channels = ["/gnss/position.north", "/gnss/position.north", "/gnss/position.down"]\n'
    with_scale = head + "[measurements.gnss_position]\n" + logged + "noise_channels_scale = 0.25\n" + rest
    profile = parse_profile(with_scale)
    assert profile.measurements["gnss_position"].noise_channels_scale == 0.25
    assert "noise_channels_scale = 0.25" in profile.to_toml()
    with pytest.raises(Exception, match="noise_channels_scale"):
        parse_profile(head + "[measurements.gnss_position]\nnoise_channels_scale = 0.25\n" + rest)
    with pytest.raises(Exception, match="noise_channels_scale"):
        parse_profile(head + "[measurements.gnss_position]\n" + logged + "noise_channels_scale = -1\n" + rest)


def test_a_group_no_noise_std_can_calibrate_keeps_the_profiles(ins_logs, monkeypatch):
    """A group whose mean NIS per output is still under the band with its noise at the floor (here
    a floor of half the profile's variance, for a profile 5x too wide) keeps the profile's noise
    and says why: its R at the floor would alarm on every small deviation of a real log."""
    import logscan.training.calibration as calibration_module
    from logscan.align import align
    from logscan.models import get_model
    from logscan.readers import read_log
    from logscan.training.calibration import calibration_lines

    (path, _, _), wrong = ins_logs
    monkeypatch.setattr(calibration_module, "CAL_FLOOR", 0.5)
    run = align(read_log(path), parse_profile(open(wrong).read()))
    calibration = calibrate(get_model("ins"), [run], process_noise=False)
    for name, entry in calibration["groups"].items():
        assert not entry["calibrated"] and entry["noise_std"] == entry["profile_noise_std"], name
        assert entry["nis_at_floor"] < 0.8 and entry["mean_nis_per_output_after"] < entry["nis_at_floor"], name
    text = "\n".join(calibration_lines(calibration))
    assert "gnss_position: not calibrated: at the floor" in text and "the profile's noise_std kept" in text
    profile = parse_profile(open(wrong).read())
    assert apply_calibration(profile, calibration) == []  # nothing applied


def test_a_real_px4_flight_calibrates_what_it_can_and_says_what_it_cannot(cli, tmp_path):
    """The one flight of ../shared/testdata that flies (PX4 SITL, 3.4 s judged): GNSS position,
    GNSS velocity and baro come to NIS about 1 from the built-in profile's noise (PX4's own
    innovations; none logged per fix: the receiver's accuracy is not the noise); PX4's own attitude
    estimate cannot be calibrated (still under the band at the floor) and keeps the profile's
    noise, and analyze says it is blind."""
    from conftest import need_testdata

    path = str(need_testdata("px4-ulog/sample_px4_events.ulg"))
    tables = tmp_path / "px4.json"
    result = cli("train", path, "--calibrate", "-o", str(tables), "--no-report")
    assert result.exit_code == 0, result.stderr
    groups = json.loads(tables.read_text())["calibration"]["groups"]
    for name in ("gnss_position", "gnss_velocity", "baro"):
        assert groups[name]["calibrated"] and 0.5 <= groups[name]["mean_nis_per_output_after"] <= 2.0, name
        assert not groups[name]["logged_noise"], name
    assert not groups["attitude"]["calibrated"] and groups["attitude"]["nis_at_floor"] < 0.8
    assert groups["attitude"]["noise_std"] == groups["attitude"]["profile_noise_std"]
    summary = tmp_path / "s.json"
    analysed = cli("analyze", path, "--tables", str(tables), "--no-report", "--json", str(summary))
    log = json.loads(summary.read_text())["logs"][0]
    assert analysed.exit_code in (0, 2) and log["n_alarms"] == 0, analysed.stdout  # healthy: no alarms
    (attitude,) = [w for w in log["warnings"] if w.startswith("group 'attitude' is blind")]
    assert "the tables' calibration found no noise_std that brings it to 1" in attitude
