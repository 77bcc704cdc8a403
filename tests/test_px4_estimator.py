"""The `px4_estimator` detector (docs/algorithms.md section 3b): PX4's own EKF2 test ratios per
aiding source, read from crafted ULog files with known events and from the real PX4 logs of
../shared/testdata/px4-ulog, always through the real CLI (`logscan analyze ... --detector px4_estimator`)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import pyulog
from conftest import REPO, need_testdata, one_state_profile
from ulog_writer import write_ulog

from logscan.detectors.px4_estimator import NO_RATIOS, Px4EstimatorDetector

THRUST = "/vehicle_thrust_setpoint_0/xyz[2]"
ACCEL = "/sensor_combined_0/accelerometer_m_s2[2]"
DURATION_S = 60.0


def base_topics() -> dict:
    """The two simple channels the one-state profile reads: 100 Hz IMU and thrust set-point."""
    t_us = np.arange(1, int(DURATION_S * 100) + 1) * 10_000
    n = t_us.size
    rng = np.random.default_rng(7)
    accel = np.column_stack([np.zeros(n), np.zeros(n), -9.81 + rng.normal(0.0, 0.05, n)])
    return {
        "sensor_combined": (t_us, {"accelerometer_m_s2": accel}),
        "vehicle_thrust_setpoint": (t_us, {"xyz": np.column_stack([np.zeros(n), np.zeros(n), np.full(n, -0.5)])}),
    }


def ratios_10hz() -> np.ndarray:
    return np.arange(1, int(DURATION_S * 10) + 1) * 100_000  # 10 Hz, microseconds


def new_style_log(path: Path) -> Path:
    """v1.12+ topics: gps_hpos = 3 over [20, 30) s and a 0.5 s baro_vpos spike of 5 at 40 s; the
    rest 0.3. estimator_status' pos_test_ratio follows gps_hpos."""
    t_us = ratios_10hz()
    t = t_us / 1e6
    n = t.size
    gps = np.where((t >= 20.0) & (t < 30.0), 3.0, 0.3)
    baro = np.where((t >= 40.0) & (t < 40.5), 5.0, 0.3)
    topics = base_topics()
    topics["estimator_innovation_test_ratios"] = (
        t_us,
        {"gps_hpos": np.column_stack([gps, np.full(n, 0.3)]), "baro_vpos": baro, "heading": np.full(n, 0.3)},
    )
    topics["estimator_status"] = (t_us, {"pos_test_ratio": gps, "hgt_test_ratio": np.full(n, 0.3)})
    return write_ulog(path, topics, parameters={"EKF2_GPS_P_GATE": 5.0})


POS_GATE = 3.0  # EKF2_GPS_P_GATE of the legacy log (PX4's default: 5)
POS_VAR = 0.04  # position innovation variance, m^2


def legacy_log(path: Path) -> Path:
    """v1.6-1.8 topics: ekf2_innovations with a 1 m north position innovation over [10, 20) s
    (ratio 1 / (3^2 * 0.04) = 2.78 with the log's gate 3; exactly 1 with PX4's default gate 5)."""
    t_us = ratios_10hz()
    t = t_us / 1e6
    n = t.size
    innov = np.full((n, 6), 0.05)
    innov[(t >= 10.0) & (t < 20.0), 3] = 1.0
    var = np.column_stack([np.full((n, 3), 0.01), np.full((n, 3), POS_VAR)])
    topics = base_topics()
    topics["ekf2_innovations"] = (
        t_us,
        {
            "vel_pos_innov": innov,
            "vel_pos_innov_var": var,
            "mag_innov": np.zeros((n, 3)),  # not fused (0 / 0): no statistic
            "mag_innov_var": np.zeros((n, 3)),
            "heading_innov": np.full(n, 0.1),
            "heading_innov_var": np.full(n, 0.01),
        },
    )
    topics["estimator_status"] = (t_us, {"pos_test_ratio": np.full(n, 0.2)})
    return write_ulog(path, topics, parameters={"EKF2_GPS_P_GATE": POS_GATE, "EKF2_HGT_MODE": 0})


def no_ratio_log(path: Path) -> Path:
    return write_ulog(path, base_topics())


@pytest.fixture
def profile(tmp_path) -> Path:
    path = tmp_path / "one.profile.toml"
    path.write_text(one_state_profile(THRUST, ACCEL), encoding="utf-8")
    return path


def analyze(cli, log: Path, profile: Path, *detectors: str, report: Path) -> tuple[int, dict]:
    """`logscan analyze` with ``detectors`` (px4_estimator by default): exit code and the log's JSON
    entry; the HTML report goes to ``report`` (its figures draw every statistic)."""
    args = ["analyze", str(log), "--profile", str(profile), "--json", "-", "-o", str(report)]
    for name in detectors or ("px4_estimator",):
        args += ["--detector", name]
    result = cli(*args)
    assert result.exit_code in (0, 1, 2), result.stderr
    return result.exit_code, json.loads(result.stdout)["logs"][0]


def detector_entry(entry: dict, name: str = "px4_estimator") -> dict:
    return next(d for d in entry["detectors"] if d["detector"] == name)


# --- the crafted logs ----------------------------------------------------------------------------


def test_the_crafted_ulog_is_read_by_pyulog_and_logscan(tmp_path, cli):
    path = new_style_log(tmp_path / "new.ulg")
    ulog = pyulog.ULog(str(path))
    names = {d.name for d in ulog.data_list}
    assert {"estimator_innovation_test_ratios", "estimator_status", "sensor_combined"} <= names
    ratios = ulog.get_dataset("estimator_innovation_test_ratios")
    assert ratios.data["gps_hpos[0]"].size == 600
    assert ulog.msg_info_dict["sys_name"] == "PX4"
    assert ulog.initial_parameters["EKF2_GPS_P_GATE"] == pytest.approx(5.0)
    result = cli("inspect", str(path), "--full")
    assert result.exit_code == 0, result.stderr
    assert "estimator_innovation_test_ratios_0" in result.stdout and "gps_hpos[0..1]" in result.stdout


def test_gps_hpos_over_its_gate_for_10_s_is_one_alarm_and_a_short_baro_spike_none(tmp_path, cli, profile):
    code, entry = analyze(cli, new_style_log(tmp_path / "new.ulg"), profile, report=tmp_path / "report.html")
    assert code == 1
    result = detector_entry(entry)
    assert {"px4.gps_hpos", "px4.baro_vpos", "px4.heading", "px4.pos_test_ratio", "px4.hgt_test_ratio"} <= set(
        result["series"]
    )
    assert result["info"]["sources"]["px4.gps_hpos"] == "estimator_innovation_test_ratios_0"
    assert result["info"]["sources"]["px4.pos_test_ratio"] == "estimator_status_0"
    gps = [a for a in result["alarms"] if a["signal"] == "px4.gps_hpos"]
    assert len(gps) == 1
    assert 20.0 <= gps[0]["start"] <= 22.1 and gps[0]["end"] <= 31.0
    assert gps[0]["first_exceed"] == pytest.approx(20.0, abs=0.05)
    assert gps[0]["peak_value"] == pytest.approx(3.0)
    assert not [a for a in result["alarms"] if a["signal"] == "px4.baro_vpos"]  # 0.5 s < 2 s
    assert result["series"]["px4.baro_vpos"]["max"] == pytest.approx(5.0)  # the spike was read
    assert {a["signal"] for a in result["alarms"]} == {"px4.gps_hpos", "px4.pos_test_ratio"}
    assert result["warnings"] == [] and entry["unchecked"] == []
    assert "px4.gps_hpos" in (tmp_path / "report.html").read_text(encoding="utf-8")  # drawn in the report


def test_a_ratio_while_the_source_is_not_fused_is_no_evidence(tmp_path, cli, profile):
    """estimator_status_flags: GNSS fused only from 25 s; gps_hpos over its gate at 20-30 s then
    alarms from its 25 s on (2 s later at the earliest), never before."""
    t_us = ratios_10hz()
    t = t_us / 1e6
    gps = np.where((t >= 20.0) & (t < 30.0), 3.0, 0.3)
    topics = base_topics()
    topics["estimator_innovation_test_ratios"] = (t_us, {"gps_hpos": np.column_stack([gps, gps])})
    fused = (t >= 25.0).astype(np.float64)
    topics["estimator_status_flags"] = (t_us, {"cs_gps": fused, "cs_baro_hgt": np.ones(t.size)})
    log = write_ulog(tmp_path / "flags.ulg", topics, parameters={"EKF2_GPS_P_GATE": 5.0})
    code, entry = analyze(cli, log, profile, report=tmp_path / "report.html")
    (alarm,) = [a for a in detector_entry(entry)["alarms"] if a["signal"] == "px4.gps_hpos"]
    assert alarm["first_exceed"] == pytest.approx(25.0, abs=0.05) and alarm["start"] >= 26.9


def test_a_shorter_duration_lets_the_spike_through(tmp_path, cli, profile):
    text = profile.read_text(encoding="utf-8") + "\n[detectors.px4_estimator]\nmin_duration_s = 0.3\n"
    profile.write_text(text, encoding="utf-8")
    _, entry = analyze(cli, new_style_log(tmp_path / "new.ulg"), profile, report=tmp_path / "report.html")
    baro = [a for a in detector_entry(entry)["alarms"] if a["signal"] == "px4.baro_vpos"]
    assert len(baro) == 1 and 40.0 <= baro[0]["start"] <= 40.5


def test_ekf2_innovations_ratios_use_the_logs_gates(tmp_path, cli, profile):
    code, entry = analyze(cli, legacy_log(tmp_path / "legacy.ulg"), profile, report=tmp_path / "report.html")
    assert code == 1
    result = detector_entry(entry)
    assert result["info"]["sources"]["px4.gps_hpos"] == "ekf2_innovations_0"
    gates = result["info"]["gates"]
    assert gates["gps_hpos"] == pytest.approx(POS_GATE)  # EKF2_GPS_P_GATE of the log
    assert gates["heading"] == pytest.approx(2.6) and gates["baro_vpos"] == 5.0  # PX4's defaults
    series = result["series"]
    assert series["px4.gps_hpos"]["max"] == pytest.approx(1.0 / (POS_GATE**2 * POS_VAR), rel=1e-4)
    assert series["px4.gps_hpos"]["min"] == pytest.approx(0.05**2 / (POS_GATE**2 * POS_VAR), rel=1e-4)
    assert series["px4.heading"]["max"] == pytest.approx(0.1**2 / (2.6**2 * 0.01), rel=1e-4)
    assert series["px4.gps_hvel"]["max"] == pytest.approx(0.05**2 / (5.0**2 * 0.01), rel=1e-4)
    assert "px4.mag_field" not in series and "px4.mag_field" in result["info"]["unused"]  # 0 / 0
    (alarm,) = result["alarms"]
    assert alarm["signal"] == "px4.gps_hpos" and 10.0 <= alarm["start"] <= 12.1 and alarm["end"] <= 21.0


def test_no_estimator_topics_is_a_warning_and_not_checked(tmp_path, cli, profile):
    code, entry = analyze(cli, no_ratio_log(tmp_path / "plain.ulg"), profile, report=tmp_path / "report.html")
    result = detector_entry(entry)
    assert result["n_alarms"] == 0
    assert result["warnings"] == [NO_RATIOS]
    assert any(line.startswith("px4_estimator:") for line in entry["unchecked"])
    assert code == 2  # a verdict on a part that could not be checked is not "no alarms"


def test_without_raw_channels_the_detector_says_so_on_any_run():
    from test_detector_contract import synthetic_run

    run = synthetic_run()
    result = Px4EstimatorDetector().run(run)  # no raw= context at all
    assert result.alarms == [] and result.warnings == [NO_RATIOS]
    assert all(values.shape == (run.n_steps,) for values in result.series.values())
    assert not np.isfinite(next(iter(result.series.values()))).any()


def test_parameters_are_checked():
    from logscan.detectors.registry import default_registry
    from logscan.errors import ProfileError

    with pytest.raises(ProfileError, match="ratio"):
        default_registry().create("px4_estimator", {"ratio": 0.0})
    with pytest.raises(ProfileError, match="min_duration_s"):
        default_registry().create("px4_estimator", {"min_duration_s": -1.0})


# --- the real PX4 logs ---------------------------------------------------------------------------

EXAMPLES = REPO / "docs" / "examples"
# log -> the example profile of its PX4 generation (as tests/test_px4_ins_profiles.py) and the
# topic family the detector must have read on it
REAL_LOGS = {
    "sample_log_small.ulg": ("px4-ins.profile.toml", "estimator_innovation_test_ratios_0"),
    "sample_logging_tagged_and_default_params.ulg": ("px4-ins.profile.toml", "estimator_innovation_test_ratios_1"),
    "sample_px4_events.ulg": ("px4-ins-v1.14.profile.toml", "estimator_innovation_test_ratios_0"),
    "sample_appended_multiple.ulg": ("px4-ins-legacy.profile.toml", "ekf2_innovations_0"),
}


@pytest.mark.parametrize(("log", "case"), sorted(REAL_LOGS.items()))
def test_real_px4_logs(log, case, cli, capsys, tmp_path):
    profile, topic = case
    path = need_testdata(Path("px4-ulog") / log)
    code, entry = analyze(cli, path, EXAMPLES / profile, "px4_estimator", "nis", report=tmp_path / "report.html")
    assert code in (0, 1)
    assert detector_entry(entry, "nis")["series"]
    result = detector_entry(entry)
    sources = result["info"]["sources"]
    assert topic in sources.values() and "estimator_status_0" in sources.values()
    assert not any(line.startswith("px4_estimator") for line in entry["unchecked"])
    with capsys.disabled():
        counts = {d["detector"]: d["n_alarms"] for d in entry["detectors"]}
        print(f"\n{log}: alarms {counts}, px4 sources read: {', '.join(sorted(sources))}")


# --- PX4's gate-only tests -----------------------------------------------------------------------


def gravity_log(path: Path) -> Path:
    """gravity (v1.13+ test ratios, and v1.14+ estimator_aid_src_gravity) at 3 over [10, 40) s, as
    while the vehicle accelerates; gps_hpos over its gate at [45, 55) s: a real fault."""
    t_us = ratios_10hz()
    over = {"gravity": (10.0, 40.0, 0.2), "gps_hpos": (45.0, 55.0, 0.3)}
    ratio = {k: np.where((t_us >= a * 1e6) & (t_us < b * 1e6), 3.0, low) for k, (a, b, low) in over.items()}
    gravity3 = np.column_stack([ratio["gravity"]] * 3)
    topics = base_topics()
    topics["estimator_innovation_test_ratios"] = (
        t_us,
        {"gravity": gravity3, "gps_hpos": np.column_stack([ratio["gps_hpos"]] * 2)},
    )
    fused = np.ones(t_us.size)
    topics["estimator_aid_src_gravity"] = (t_us, {"test_ratio": gravity3, "fused": fused})
    topics["estimator_aid_src_fake_pos"] = (t_us, {"test_ratio": gravity3[:, :2], "fused": fused})
    return write_ulog(path, topics, parameters={"EKF2_GPS_P_GATE": 5.0})


def test_gate_only_tests_are_read_but_never_an_alarm(tmp_path, cli, profile):
    """PX4 rejects the gravity observation by design while accelerating: 30 s over its gate is no
    alarm, and the summary against PX4 counts only the GNSS test's alarm."""
    code, entry = analyze(cli, gravity_log(tmp_path / "gravity.ulg"), profile, report=tmp_path / "report.html")
    result = detector_entry(entry)
    assert set(result["info"]["gate_only"]) == {"px4.gravity", "px4.aid_gravity", "px4.aid_fake_pos"}
    assert not [s for s in result["series"] if "gravity" in s or "fake" in s]
    assert {a["signal"] for a in result["alarms"]} == {"px4.gps_hpos"}
    (alarm,) = result["alarms"]
    assert 45.0 <= alarm["start"] <= 47.1
    assert entry["against_px4"]["px4_alarms"] == 1 and code == 1


def test_gate_only_matches_px4_sources_by_name():
    from logscan.detectors.px4_estimator import gate_only

    assert gate_only("gravity") and gate_only("aid_gravity") and gate_only("beta_test_ratio")
    assert gate_only("aid_fake_hgt") and gate_only("drag") and gate_only("aid_sideslip")
    assert not any(gate_only(s) for s in ("gps_hpos", "aid_gnss_vel", "baro_vpos", "heading", "mag_test_ratio"))


@pytest.mark.testdata("px4-ulog-extra/mcap_ulog2mcap_test_ulog.ulg")
def test_a_real_v1_14_log_reads_gravity_as_a_gate(cli, tmp_path):
    """A real PX4_FMU_V6C log logs gravity[0..2] among its test ratios: set aside, never a statistic."""
    path = need_testdata("px4-ulog-extra/mcap_ulog2mcap_test_ulog.ulg")
    result = cli("analyze", str(path), "--detector", "px4_estimator", "--json", "-", "-o", str(tmp_path / "r.html"))
    entry = json.loads(result.stdout)["logs"][0]
    px4 = detector_entry(entry)
    gravity = {f"px4.ekf{i}.gravity" for i in (0, 1)}  # two EKF2 instances
    assert gravity <= set(px4["info"]["gate_only"]) and not gravity & set(px4["series"])
    assert {"px4.ekf0.gps_hpos", "px4.ekf1.gps_hpos"} <= set(px4["series"])
