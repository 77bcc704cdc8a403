"""A-TFM end to end (detectors/atfm.py, logscan/training/train.py, `logscan train`): training on healthy
Jackal-like logs gives a lookup table the detector uses; an attack on one speed sensor alarms on
its pairs and names it; tables trained for another profile or on faulty logs are refused."""

from __future__ import annotations

import inspect
import json

import numpy as np
import pytest

from logscan.detectors.atfm import AtfmDetector, mode_segments
from logscan.errors import NotTrainedError, ProfileError
from logscan.pipeline import create_detectors, load_profile_for, needs_of, prepare
from logscan.training.tables import apply_tables, profile_fingerprint, read_tables
from logscan.training.train import train_logs


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """Two healthy multi-speed logs with glitches and one with a GPS speed bias of 0.3 m/s (60-90 s)."""
    from logscan.cli.main import main

    root = tmp_path_factory.mktemp("atfm")

    def simulate(name: str, *args: str) -> str:
        path = str(root / name)
        try:
            main(["simulate", "dc_motor", "--duration", "120", "-q", "-o", path, *args])
        except SystemExit as exc:
            assert exc.code in (0, None)
        return path

    return {
        "healthy": [simulate("h1.mcap", "--seed", "21", "--glitches", "2"), simulate("h2.mcap", "--seed", "22")],
        "bias": simulate("bias.mcap", "--seed", "23", "--fault", "bias:/gps/speed:60:90:0.3"),
        "root": root,
    }


@pytest.fixture(scope="module")
def tables(logs):
    document = train_logs(logs["healthy"], None)
    path = logs["root"] / "tables.json"
    path.write_text(json.dumps(document), encoding="utf-8")
    return path, document


def test_segments_drop_the_settle_time_and_never_span_a_mode_change():
    mode = np.array([0.4] * 10 + [1.0] * 4 + [np.nan] * 3 + [1.0] * 8)
    assert mode_segments(mode, 3) == [(0.4, 3, 10), (1.0, 3 + 10, 14), (1.0, 20, 25)]


def test_the_table_covers_every_mode_and_sensor_with_sound_rows(tables):
    _, document = tables
    (state,) = [s for s in document["detectors"] if s["detector"] == "atfm"]
    detector = AtfmDetector.from_state(state)
    table = detector.tables_["speed"]
    assert table["sensors"] == ["left", "right", "gps"]
    np.testing.assert_allclose(table["modes"], [0.4, 0.7, 1.0, 1.3, 1.6, 1.9])
    eps, e = table["eps"], table["e"]
    assert np.all(np.diff(eps, axis=0) >= 0)  # the monotone envelope
    assert np.all(eps >= table["eps_knee"]) and np.all(eps > 0)
    assert np.all(e < 0.5 * table["w"])  # Lemma 4: e/w < 0.5
    # each knee lies on its own curve at the detection window
    for r, row in enumerate(table["curves"]):
        for i, curve in enumerate(row):
            w_index = table["windows"].index(table["w"])
            k = int(np.argmin(np.abs(curve["eps"] - table["eps_knee"][r, i])))
            assert curve["counts"][k, w_index] == e[r, i]
    assert [log["name"] for log in document["training_logs"]] == ["h1.mcap", "h2.mcap"]
    assert all(len(log["sha256"]) == 64 for log in document["training_logs"])


def test_a_gps_bias_alarms_on_the_gps_pairs_and_names_the_gps(logs, tables):
    path, _ = tables
    loaded = load_profile_for(logs["bias"], None)
    (detector,) = apply_tables(create_detectors(loaded, ["atfm"]), path, loaded.profile)
    prepared = prepare(logs["bias"], loaded, needs_of([detector]))
    result = detector.run(prepared.run, None)
    signals = {a.signal for a in result.alarms}
    assert {"atfm.speed.left~gps", "atfm.speed.right~gps"} <= signals
    assert "atfm.speed.left~right" not in signals and "atfm.gps_speed.gps" in signals
    first = min(a.start for a in result.alarms)
    assert 60.0 <= first <= 63.0  # within 3 s of the attack's start
    assert "gps: in SI with every other sensor" in result.info["attribution.speed"]
    # the named sensor is an alarm of its own, under its measurement group: the incident names it
    named = [a for a in result.alarms if a.signal == "atfm.gps_speed.gps"]
    assert named and named[0].peak_ratio > 1
    assert not any(a.signal in ("atfm.encoder.left", "atfm.encoder.right") for a in result.alarms)
    assert {"speed median.fused", "speed hybrid.fused", "speed row in use.mode"} <= set(result.extras)
    assert "fusion RMSE vs fault-free.speed" not in result.info  # no truth given: nothing to compare


def test_fusion_rmse_against_the_fault_free_fusion_when_truth_exists(logs, tables):
    from logscan.readers import read_log

    path, _ = tables
    loaded = load_profile_for(logs["bias"], None)
    (detector,) = apply_tables(create_detectors(loaded, ["atfm"]), path, loaded.profile)
    prepared = prepare(logs["bias"], loaded, needs_of([detector]))
    result = detector.run(prepared.run, None, truth=read_log(logs["bias"]).truth)
    text = result.info["fusion RMSE vs fault-free.speed"]
    rmse = {method: float(value) for method, value in (part.split() for part in text.split(", "))}
    assert set(rmse) == {"average", "moving_average", "median", "iterative", "marzullo", "hybrid"}
    # a 0.3 m/s GPS bias for 30 s of 120: the average moves by 0.1 while it lasts, the median barely
    assert 0.03 < rmse["average"] < 0.07 and rmse["median"] < 0.5 * rmse["average"]


def test_no_alarm_on_a_healthy_log_with_glitches(logs, tables):
    path, _ = tables
    healthy = logs["healthy"][0]
    loaded = load_profile_for(healthy, None)
    (detector,) = apply_tables(create_detectors(loaded, ["atfm"]), path, loaded.profile)
    prepared = prepare(healthy, loaded, needs_of([detector]))
    assert detector.run(prepared.run, None).alarms == []


def test_a_fixed_row_uses_that_row_throughout(logs, tables):
    path, _ = tables
    loaded = load_profile_for(logs["bias"], None)
    (detector,) = apply_tables(create_detectors(loaded, ["atfm"]), path, loaded.profile)
    detector.params["row"] = 1.9
    prepared = prepare(logs["bias"], loaded, needs_of([detector]))
    result = detector.run(prepared.run, None)
    rows = result.extras["speed row in use.mode"]
    assert np.nanmin(rows) == np.nanmax(rows) == pytest.approx(1.9)
    detector.params["row"] = 0.5
    with pytest.raises(ProfileError, match="not a trained mode value"):
        detector.run(prepared.run, None)


def test_untrained_atfm_says_which_command_to_run(logs):
    loaded = load_profile_for(logs["bias"], None)
    (detector,) = create_detectors(loaded, ["atfm"])
    prepared = prepare(logs["bias"], loaded, needs_of([detector]))
    with pytest.raises(NotTrainedError, match="no lookup table") as info:
        detector.run(prepared.run, None)
    assert "logscan train" in info.value.one_line()


def test_tables_of_another_profile_are_refused(logs, tables, tmp_path):
    """Another vehicle (its id) is another profile; a rate is not the profile's identity, but the
    tables' windows count its samples: one more than 10 % off is refused too."""
    path, _ = tables
    loaded = load_profile_for(logs["bias"], None)
    for change, refusal in (
        (lambda text: text.replace("[vehicle]", '[vehicle]\nid = "another jackal"', 1), "trained for another profile"),
        (lambda text: text.replace("rate_hz = 10.0", "rate_hz = 5.0", 1), "trained at other rates"),
    ):
        profile = tmp_path / "other.toml"
        profile.write_text(change(loaded.profile.to_toml()), encoding="utf-8")
        other_loaded = load_profile_for(logs["bias"], profile)
        same = profile_fingerprint(other_loaded.profile) == profile_fingerprint(loaded.profile)
        assert same == (refusal == "trained at other rates")
        with pytest.raises(ProfileError, match=refusal) as info:
            apply_tables(create_detectors(other_loaded, ["atfm"]), path, other_loaded.profile)
        assert f"--profile {profile}" in info.value.one_line()  # a profile file: the command passes it


def test_train_cli_writes_tables_and_analyze_uses_them(logs, cli, tmp_path):
    out = tmp_path / "t.json"
    result = cli("train", *logs["healthy"], "-o", out, "--no-report")
    assert result.exit_code == 0, result.stderr
    assert "atfm speed: w = 100" in result.stdout and "left" in result.stdout
    assert set(read_tables(out)) == {"atfm"}
    analysed = cli("analyze", logs["bias"], "--tables", out, "-d", "atfm", "--no-report")
    assert analysed.exit_code == 1 and "atfm.speed.left~gps" in analysed.stdout
    untrained = cli("analyze", logs["bias"], "-d", "atfm", "--no-report")
    assert untrained.exit_code == 2 and "logscan train" in untrained.stdout + untrained.stderr


def test_train_refuses_a_faulty_log_unless_allowed(logs, cli, tmp_path):
    out = tmp_path / "t.json"
    refused = cli("train", logs["bias"], "-o", out, "--no-report")
    assert refused.exit_code == 2 and "fault" in refused.stderr and not out.exists()
    allowed = cli("train", logs["bias"], "-o", out, "--no-report", "--allow-faulty", "-q")
    assert allowed.exit_code == 0 and out.exists()


def test_a_bad_tables_file_stops_analyze_before_any_log_is_read(logs, cli, tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "something else"}', encoding="utf-8")
    result = cli("analyze", logs["bias"], "--tables", bad, "--no-report")
    assert result.exit_code == 2 and "not a logscan tables file" in result.stderr


# --- the residual flavour (hybrid KF + A-TFM) ---------------------------------------------------


def test_segment_counts_never_reach_back_across_a_mode_change():
    from logscan.detectors.atfm_residual import segment_counts

    rng = np.random.default_rng(4)
    exceed = rng.random(300) < 0.3
    mode = np.repeat([0.4, 1.0, np.nan, 1.0], [100, 80, 20, 100])
    counts = segment_counts(exceed, mode, 25)
    expected = []
    for k in range(exceed.size):  # brute force: back to w steps or the run's first step
        first = k
        while (
            first > 0
            and k - first + 1 < 25
            and (mode[first - 1] == mode[k] or (np.isnan(mode[first - 1]) and np.isnan(mode[k])))
        ):
            first -= 1
        expected.append(int(exceed[first : k + 1].sum()))
    np.testing.assert_array_equal(counts, expected)


@pytest.fixture(scope="module")
def residual_setup(logs, tmp_path_factory):
    """A profile enabling atfm_residual, and tables trained on the healthy logs with it.

    The tests using it have "residual" in their names: .ci/run's lowest-versions step leaves them
    out with -k (the training compiles that detector's kernels, about 50 s of CPU from cold)."""
    root = tmp_path_factory.mktemp("residual")
    loaded = load_profile_for(logs["healthy"][0], None)
    profile = root / "p.toml"
    profile.write_text(loaded.profile.to_toml() + "\n[detectors.atfm_residual]\n", encoding="utf-8")
    document = train_logs(logs["healthy"], str(profile))
    tables_file = root / "t.json"
    tables_file.write_text(json.dumps(document), encoding="utf-8")
    return profile, tables_file, document


def residual_result(path, profile, tables_file):
    loaded = load_profile_for(path, profile)
    (detector,) = apply_tables(create_detectors(loaded, ["atfm_residual"]), tables_file, loaded.profile)
    prepared = prepare(path, loaded, needs_of([detector]))
    return detector.run(prepared.run, prepared.trace)


def test_the_residual_tables_cover_each_speed_channel(residual_setup):
    _, _, document = residual_setup
    assert {s["detector"] for s in document["detectors"]} == {"atfm", "atfm_residual"}
    (state,) = [s for s in document["detectors"] if s["detector"] == "atfm_residual"]
    from logscan.detectors.atfm_residual import AtfmResidualDetector

    tables = AtfmResidualDetector.from_state(state).tables_
    assert set(tables) == {"encoder[0]", "encoder[1]", "gps_speed"}  # the speed sensors, not the current
    for table in tables.values():
        assert np.all(np.diff(table["eps"][:, 0]) >= 0) and np.all(table["e"] < 0.5 * table["w"])


def test_the_residual_flavour_is_quiet_on_its_training_logs_and_sees_the_gps_bias(logs, residual_setup):
    profile, tables_file, _ = residual_setup
    for healthy in logs["healthy"]:
        assert residual_result(healthy, profile, tables_file).alarms == []
    result = residual_result(logs["bias"], profile, tables_file)
    gps = [a for a in result.alarms if a.signal == "atfm_residual.gps_speed"]
    # the bias starts with a mode change (60 s), judged after its settle time (65 s); then the count
    # passes the budget's e (at most w = 100) once e + 1 GPS updates (10 Hz) have exceeded eps
    e = max(int(v.split(": ")[1]) for v in result.info["e.gps_speed"].split(", "))
    assert gps and any(65.0 <= a.start <= 65.0 + (e + 1) / 10.0 + 0.5 and a.end >= 89.0 for a in gps)


def test_the_residual_budget_threshold_is_never_below_the_knee(residual_setup):
    from logscan.detectors.atfm_residual import AtfmResidualDetector
    from logscan.detectors.budget import design_rate

    _, _, document = residual_setup
    (state,) = [s for s in document["detectors"] if s["detector"] == "atfm_residual"]
    detector = AtfmResidualDetector.from_state(state)
    for table in detector.tables_.values():
        knee = table["e"][:, 0]
        alpha = design_rate(0.1, 100.0) / (3600.0 * 50.0)  # 50 updates per second (the UGV's speed sensors)
        loose, tight = detector.thresholds(table, 1.0), detector.thresholds(table, alpha)
        assert np.array_equal(loose, knee)  # a budget that allows anything leaves the thesis's e
        assert np.all(tight >= knee) and np.all(tight > knee)  # minutes of training: the margin binds
        assert table["runs"].sum() > 0 and np.all(table["updates"] > 0)


def test_the_tests_of_the_residual_tables_say_residual_in_their_names():
    """.ci/run's lowest-versions step leaves the atfm_residual training out with -k "not residual": a
    test of residual_setup without the word would bring it back (about 50 s of CPU from cold)."""
    users = [
        name
        for name, test in globals().items()
        if name.startswith("test_") and "residual_setup" in inspect.signature(test).parameters
    ]
    assert users and all("residual" in name for name in users), users


def test_every_knee_of_the_sample_tables_equals_the_brute_force_rule(sample):
    """logscan train on the healthy multi-speed sample logs: eps grows with the speed (the thesis's
    Table I), and each stored knee is the brute-force knee (plain loops) of its own curve."""
    from test_tfm import brute_knee

    document = train_logs([str(sample("jackal_train_1.mcap")), str(sample("jackal_train_2.mcap"))], None)
    (state,) = [s for s in document["detectors"] if s["detector"] == "atfm"]
    table = AtfmDetector.from_state(state).tables_["speed"]
    eps = table["eps"]
    assert np.all(eps[-1] > 1.5 * eps[0])  # 1.9 m/s against 0.4 m/s, every sensor
    checked = 0
    for r, row in enumerate(table["curves"]):
        for i, curve in enumerate(row):
            for c, (w, eps_k, e_k) in enumerate(curve["knees"]):
                assert brute_knee(curve["eps"], curve["counts"][:, c], w) == (eps_k, e_k)
                checked += 1
            at = table["windows"].index(table["w"])
            assert (table["eps_knee"][r, i], table["e"][r, i]) == tuple(curve["knees"][at][1:])
    assert checked == len(table["modes"]) * len(table["sensors"]) * len(table["windows"])
