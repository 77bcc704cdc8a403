"""The built-in px4 profile's measurement noise (logscan.profiles.px4_noise, docs/algorithms.md
section 6.7a): from the scatter of PX4's own innovations, never from the receiver's reported
accuracy; the "blind" warning where the filter's test stays far looser than the data; a sudden
rise of the reported accuracy as a finding (health, detectors/accuracy_jump.py); and a
spoofing-like GNSS ramp, its receiver reporting worse accuracy as it starts, injected into a real
log and caught within 2 s by both."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import need_testdata
from scipy.stats import chi2
from ulog_edit import edit_ulog

from logscan.pipeline import NIS_BLIND, builtin_profile_for
from logscan.profiles import parse_profile
from logscan.profiles.px4_noise import FLOOR, MIN_SAMPLES, innovation_std, paired

REAL_LOGS = [
    "px4-ulog/sample_log_small.ulg",
    "px4-ulog/sample_logging_tagged_and_default_params.ulg",
    "px4-ulog/sample_px4_events.ulg",
    "px4-ulog/sample_appended_multiple.ulg",
    "px4-ulog-extra/robologs_fmu_v5_test.ulg",
    "px4-ulog-extra/mcap_ulog2mcap_test_ulog.ulg",
]
EVENTS = "px4-ulog/sample_px4_events.ulg"  # SITL quadcopter, judged in flight from 21.7 s to 25.1 s
GPS = "vehicle_gps_position"


# --- the estimate --------------------------------------------------------------------------------


def test_innovation_std_is_the_rms_of_the_accepted_innovations_at_its_upper_bound():
    rng = np.random.default_rng(3)
    y = rng.normal(0.0, 0.2, 400)
    S = np.full(y.size, 1.0)  # PX4's own (loose) innovation variance: every sample within its gate
    sigma, n = innovation_std(y, S, gate=5.0)
    rms = np.sqrt(np.mean(y**2))
    assert n == 400 and sigma == pytest.approx(rms * np.sqrt(400 / chi2.ppf(0.05, 400)))
    assert 0.2 < sigma < 0.23
    # a glitch PX4 rejected (outside its gate) and samples it did not fuse (0) do not count
    y_bad = np.concatenate([y, [50.0] * 100, [0.0] * 50])
    S_bad = np.concatenate([S, np.ones(150)])
    assert innovation_std(y_bad, S_bad, gate=5.0) == (sigma, n)
    # a short log errs to loose: the bound is wider with fewer samples
    short, k = innovation_std(y[:12], S[:12], gate=5.0)
    assert k == 12 and short / np.sqrt(np.mean(y[:12] ** 2)) > 1.25
    assert innovation_std(y[: MIN_SAMPLES - 1], S[: MIN_SAMPLES - 1], gate=5.0) is None


def test_an_innovation_takes_the_variance_published_nearest_to_it():
    t_y = np.array([0, 100, 200, 300]) * 1_000_000  # ns
    t_s = t_y + 3_000_000  # the variance topic stamped 3 ms later
    y, s = paired(t_y, np.array([1.0, 2.0, 3.0, 4.0]), np.r_[t_s[:2], t_s[3]], np.array([10.0, 20.0, 40.0]))
    assert y.tolist() == [1.0, 2.0, 4.0] and s.tolist() == [10.0, 20.0, 40.0]  # 200 ms: none within 20 ms


def test_a_v1_14_log_gives_its_noise_through_estimator_aid_src_and_only_fused_samples_count():
    from logscan.log import Channel
    from logscan.profiles.px4_noise import px4_noise

    rng = np.random.default_rng(5)
    n = 200
    t = np.arange(n, dtype=np.int64) * 200_000_000
    fused = (np.arange(n) % 4 != 0).astype(float)  # a quarter not fused: their innovations are wild
    y = np.where(fused != 0, rng.normal(0.0, 0.05, n), 30.0)

    def topic(name, values):
        return {f"/estimator_aid_src_{name}_0/{f}": Channel(f, t, v) for f, v in values.items()}

    channels = {
        **topic("gnss_vel", {"innovation[0]": y, "innovation_variance[0]": np.full(n, 1e4), "fused": fused}),
        **topic("baro_hgt", {"innovation": 10 * y, "innovation_variance": np.full(n, 1e4), "fused": fused}),
    }
    configured = {"gnss_velocity": ((0.3, 0.3, 0.45), "EKF2_GPS_V_NOISE"), "baro": ((3.5,), "EKF2_BARO_NOISE")}
    noise = px4_noise(channels, lambda name, default: default, configured)
    rms = np.sqrt(np.mean(y[fused != 0] ** 2))
    bound = np.sqrt(150 / chi2.ppf(0.05, 150))
    assert noise["gnss_velocity"].std[0] == pytest.approx(rms * bound)
    assert noise["gnss_velocity"].std[1:] == (0.3, 0.45)  # not logged: PX4's configured noise
    assert noise["gnss_velocity"].samples == (150, None, None)
    assert noise["baro"].std[0] == pytest.approx(10 * rms * bound)


# --- the built-in profile on the real logs -------------------------------------------------------


@pytest.mark.testdata("px4-ulog")
def test_the_noise_comes_from_px4s_innovations_within_its_configured_noise():
    built = builtin_profile_for(need_testdata(EVENTS))
    profile = parse_profile(built.text)
    groups = profile.measurements
    configured = {"gnss_position": [0.5, 0.5, 0.75], "gnss_velocity": [0.3, 0.3, 0.45], "baro": [3.5]}
    for name, ceiling in configured.items():
        std = groups[name].noise_std
        assert all(FLOOR <= s <= c for s, c in zip(std, ceiling)), (name, std)
        assert any(s < c / 2 for s, c in zip(std, ceiling)), (name, std)  # the data, not the parameter
        assert groups[name].noise_channels is None  # the receiver's reported accuracy is not the noise
    line = next(x for x in built.text.splitlines() if x.startswith("noise_std") and "innovations" in x)
    assert "PX4's own innovations" in line and "95 %" in line


@pytest.mark.testdata("px4-ulog")
@pytest.mark.testdata("px4-ulog-extra")
@pytest.mark.parametrize("name", REAL_LOGS)
def test_no_builtin_px4_profile_takes_the_receivers_accuracy_as_its_noise(name):
    profile = parse_profile(builtin_profile_for(need_testdata(name)).text)
    assert all(group.noise_channels is None for group in profile.measurements.values())


@pytest.mark.testdata("px4-ulog")
@pytest.mark.testdata("px4-ulog-extra")
@pytest.mark.parametrize("name", REAL_LOGS)
def test_each_group_is_within_the_healthy_nis_band_or_said_to_be_blind(name, cli, tmp_path):
    """Mean NIS per output on the real logs: never above 3 (too tight: false alarms), and a group
    below 0.3 is named blind in the verdict's warnings."""
    out = tmp_path / "summary.json"
    result = cli("analyze", str(need_testdata(name)), "--no-report", "--json", str(out))
    assert "Traceback" not in result.stderr
    log = json.loads(out.read_text())["logs"][0]
    sizes = {"gnss_position": 3, "gnss_velocity": 3, "baro": 1, "attitude": 3}
    for group, total in log["filter"]["mean_nis"].items():
        level = total / sizes[group]
        assert level <= 1.0 / NIS_BLIND, (group, level)
        blind = [w for w in log["warnings"] if w.startswith(f"group '{group}' is blind")]
        if level < NIS_BLIND:
            assert blind, (group, level, log["warnings"])
    assert not [a for d in log["detectors"] if d["detector"] == "nis" for a in d["alarms"]]


# --- a sensor does not vouch for itself ----------------------------------------------------------


@pytest.mark.testdata("px4-ulog")
def test_a_gnss_ramp_whose_receiver_reports_worse_accuracy_is_caught_within_2_s(cli, tmp_path):
    """A spoofer walks the position north at 3 m/s from 22 s; as it starts the receiver reports 4
    times worse eph, epv and speed accuracy (what a real attack showed). The noise does not widen
    with them, so the GNSS position test alarms within 2 s of the onset."""
    from pyulog import ULog

    source = need_testdata(EVENTS)
    start_us = ULog(str(source), [GPS]).start_timestamp
    onset_s, speed = 22.0, 3.0

    def spoof(data) -> None:
        t = (data["timestamp"].astype(np.int64) - start_us) / 1e6
        data["latitude_deg"][:] += speed * np.clip(t - onset_s, 0.0, None) / 111_320.0  # m north -> deg
        for field in ("eph", "epv", "s_variance_m_s"):
            data[field][t >= onset_s] *= 4.0

    path = edit_ulog(source, tmp_path / "spoofed.ulg", {GPS: spoof})
    out = tmp_path / "summary.json"
    cli("analyze", str(path), "--no-report", "--json", str(out))
    log = json.loads(out.read_text())["logs"][0]
    # this log's clock counts from its start timestamp (UTC microseconds): the onset is at onset_s
    assert log["clock"]["offset_s"] == pytest.approx(start_us / 1e6)
    onset = onset_s
    nis = next(d for d in log["detectors"] if d["detector"] == "nis")
    (alarm,) = [a for a in nis["alarms"] if a["signal"] == "nis.gnss_position"]
    # EKF2_GPS_DELAY (110 ms) puts a fix that much earlier on the grid: the onset too
    assert onset - 0.2 <= alarm["first_exceed"] and alarm["start"] <= onset + 2.0, (alarm, onset)
    # the receiver's sudden loss of accuracy is a finding of its own (health), 1 s after it
    health = next(d for d in log["detectors"] if d["detector"] == "health")
    jumps = [a for a in health["alarms"] if a["signal"].startswith("health.gnss_accuracy_jump.")]
    assert {a["signal"].rsplit(".", 1)[1] for a in jumps} == {"eph", "epv", "s_variance_m_s"}
    assert all(onset - 0.2 <= a["first_exceed"] and a["start"] <= onset + 2.0 for a in jumps), jumps
    assert log["n_alarms"] >= 1 and log["exit_code"] in (1, 2)


def test_an_accuracy_jump_is_a_rise_over_the_recent_median_and_a_slow_drift_is_none():
    from logscan.detectors.accuracy_jump import accuracy_jump

    t = (np.arange(600) * 0.2e9).astype(np.int64)  # 5 Hz for 120 s
    slow = np.linspace(1.0, 2.5, t.size)  # geometry: 2.5 times worse over 2 minutes
    assert np.nanmax(accuracy_jump(t, slow, 10.0)) < 1.2
    step = np.where(t >= 60e9, 3.0, 1.0)
    step[100] = np.nan  # a sample not judged (no 3D fix) stays NaN and out of the median
    ratio = accuracy_jump(t, step, 10.0)
    assert np.isnan(ratio[0]) and np.isnan(ratio[100]) and ratio[99] == 1.0
    assert ratio[300] == pytest.approx(3.0) and ratio[324] == pytest.approx(3.0)  # the 25 before: 1
    assert ratio[326] == pytest.approx(1.0)  # after half the window the median has moved up
