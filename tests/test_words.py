"""Plain words for every statistic (`Detector.signal_label`): every statistic each registered detector
produces on sample logs (simulated, crafted ULogs, and the real PX4 logs when present) has a
non-empty label, and the report, the JSON and the summary show it beside the statistic's name."""

from __future__ import annotations

import json

import pytest
from conftest import SAMPLES, TESTDATA, one_state_profile
from test_detector_contract import pipeline_case, pipeline_detector
from test_health import crafted_log
from test_px4_estimator import new_style_log
from test_report import figures

from logscan.detectors.registry import default_registry
from logscan.detectors.words import group_words
from logscan.verdict.incidents import signal_label

REGISTRY = default_registry()
SIMULATED = [name for name in REGISTRY.names() if not REGISTRY.get(name).raw_topics]
AUTOPILOT = [name for name in REGISTRY.names() if REGISTRY.get(name).raw_topics]


def produced_on_fixtures(name: str) -> set[str]:
    """The statistics detector ``name`` produces on its healthy and faulty simulated fixtures (the
    contract test's sample logs through `logscan.pipeline.preparation`, trained on the healthy one)."""
    found: set[str] = set()
    for kind in ("healthy", "faulty"):
        run, trace, model, _, traces = pipeline_case(kind, name)
        result = pipeline_detector(name).run(run, trace, model=model, traces=traces)
        found |= set(result.series) | {a.signal for a in result.alarms}
    return found


@pytest.mark.parametrize("name", SIMULATED)
def test_every_statistic_of_a_model_based_detector_has_plain_words(name):
    produced = produced_on_fixtures(name)
    assert produced, f"{name} produced no statistic on its fixtures"
    unlabelled = sorted(s for s in produced if not signal_label(s, name))
    assert unlabelled == [], f"{name}: no plain words for {unlabelled}"
    for signal in produced:  # words, not the technical name again
        assert signal_label(signal, name) != signal and len(signal_label(signal, name)) > 15


def _autopilot_logs(tmp_path) -> list:
    """Crafted ULogs with every PX4 topic the autopilot detectors read, and the real PX4 logs."""
    logs = [new_style_log(tmp_path / "ratios.ulg"), crafted_log(tmp_path / "health.ulg")]
    real = TESTDATA / "px4-ulog"
    return logs + (sorted(real.glob("*.ulg")) if real.is_dir() else [])


def test_every_statistic_of_an_autopilot_detector_has_plain_words(tmp_path, cli):
    profile = tmp_path / "one.profile.toml"
    profile.write_text(
        one_state_profile("/vehicle_thrust_setpoint_0/xyz[2]", "/sensor_combined_0/accelerometer_m_s2[2]")
    )
    produced: dict[str, set[str]] = {name: set() for name in AUTOPILOT}
    for log in _autopilot_logs(tmp_path):
        crafted = log.parent == tmp_path
        args = ["analyze", log, "--no-report", "--json", tmp_path / "out.json"]
        args += ["--profile", profile] if crafted else []
        for name in AUTOPILOT:
            args += ["--detector", name]
        result = cli(*args)
        assert result.exit_code in (0, 1, 2), result.stderr
        for entry in json.loads((tmp_path / "out.json").read_text())["logs"][0]["detectors"]:
            produced[entry["detector"]] |= set(entry["series"])
            assert all(entry["labels"][s] for s in entry["series"]), entry["labels"]  # and in the JSON
    for name, signals in produced.items():
        assert len(signals) >= 3, f"{name} produced {sorted(signals)}"
        assert sorted(s for s in signals if not signal_label(s, name)) == [], name


def test_labels_name_the_sensor_in_words():
    nis = next(n for n in SIMULATED if REGISTRY.get(n).signal_label("nis.accel"))
    assert "accelerometer" in signal_label("nis.accel", nis)
    assert group_words("encoder[1]") == "wheel encoders (channel 1)" and group_words("wheel_odo") == "wheel odo"
    assert signal_label("nis.accel", "no_such_detector") == ""  # an unknown detector: no words, no error


def test_the_report_json_and_summary_show_the_words_beside_the_name(tmp_path, cli):
    log = SAMPLES / "quad_imu_bias.mcap"
    if not log.is_file():
        pytest.skip("sample log missing")
    report, out = tmp_path / "r.html", tmp_path / "r.json"
    result = cli("analyze", log, "-o", report, "--json", out)
    assert result.exit_code == 1, result.stderr
    entry = json.loads(out.read_text())["logs"][0]
    alarm = next(a for d in entry["detectors"] for a in d["alarms"] if a["signal"].startswith("nis."))
    words = alarm["label"]
    assert words and words == signal_label(alarm["signal"], alarm["detector"])
    assert any(alarm["signal"] in line and words in line for line in result.stdout.splitlines())  # stdout
    html = report.read_text(encoding="utf-8")
    # the alarm table: one line per alarm, its words the signal cell's tooltip
    assert f'<td title="{words}">{alarm["signal"]}</td>' in html.replace("&#39;", "'")
    # a statistic's own figure carries its words under the title (the technical name stays in it)
    e_x = signal_label("e_x", "encoded_ekf")
    # a section's rows are one figure: each row's title is an annotation, "<b>name</b> words"
    titles = [a["text"] for f in figures(html) for a in f["figure"]["layout"].get("annotations", [])]
    assert any(t.startswith("<b>encoded_ekf: e_x</b>") and e_x in t for t in titles), titles
    assert "what its" in html  # the section's list of its statistics in words
