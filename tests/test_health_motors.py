"""The `health` detector's motor checks (docs/algorithms.md section 3c, detectors/motor_outputs.py)
on real PX4 logs edited by the test (pyulog reads the log, the test rewrites parameters and
topics, pyulog writes it back): DShot outputs, an unused output group, unused output channels, a
motor stopped on purpose, and a motor really stopping in flight; always through the real CLI."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest
import pyulog
from conftest import REPO, need_testdata

EVENTS = "px4-ulog/sample_px4_events.ulg"  # SITL quad, PX4 v1.14: PWM_MAIN_FUNC1..4 = Motor1..4, actuator_motors
ROBOLOGS = "px4-ulog-extra/robologs_fmu_v5_test.ulg"  # real FMU v5 quad, legacy mixer (no FUNC params)
NEVER_ARMED = "px4-ulog/sample_logging_tagged_and_default_params.ulg"  # SITL quad, armed never set
# the example profile of the log's PX4 generation; None: the built-in px4 profile
PROFILES = {EVENTS: "px4-ins-v1.14.profile.toml", ROBOLOGS: None, NEVER_ARMED: "px4-ins.profile.toml"}
DSHOT_MIN = 0.055  # PX4's default DSHOT_MIN
STOP_FOR_S = 4.0
# how late an alarm may start after its event: min_duration_s (1 s) at the outputs' 10 Hz, plus a
# sample period and a grid step (as tests/test_health.py)
LATE_S = 1.5


def edit_log(source: str, out: Path, edit) -> Path:
    """A real log read by pyulog, changed by ``edit(ulog)``, written back by pyulog."""
    ulog = pyulog.ULog(str(need_testdata(source)))
    edit(ulog)
    ulog.write_ulog(str(out))
    return out


def analyze(cli, source: str, log: Path, tmp_path: Path) -> dict:
    """The health detector's JSON entry of ``logscan analyze log --detector health``, with the
    log's time zero (``clock_offset_s``: a log time in s minus it is a time in the JSON)."""
    profile = ["--profile", str(REPO / "docs" / "examples" / PROFILES[source])] if PROFILES[source] else []
    result = cli("analyze", str(log), *profile, "--json", "-", "-o", str(tmp_path / "r.html"), "-d", "health")
    assert result.exit_code in (0, 1, 2), result.stderr
    entry = json.loads(result.stdout)["logs"][0]
    health = next(d for d in entry["detectors"] if d["detector"] == "health")
    return {**health, "clock_offset_s": entry["clock"]["offset_s"]}


def motor_alarms(health: dict) -> list[dict]:
    return [a for a in health["alarms"] if a["signal"].startswith("health.motor")]


def flight_window(ulog) -> tuple[int, int]:
    """(first, last) timestamp in us of the longest stretch with ``landed`` 0."""
    land = ulog.get_dataset("vehicle_land_detected").data
    t, flying = land["timestamp"].astype(np.int64), land["landed"] == 0
    edges = np.flatnonzero(np.diff(np.concatenate(([0], flying.astype(int), [0]))))
    starts, ends = edges[::2], edges[1::2] - 1
    longest = int(np.argmax(t[ends] - t[starts]))
    return int(t[starts[longest]]), int(t[ends[longest]])


def stop_window(ulog) -> tuple[int, int]:
    """A 4 s stretch in the middle of the flight, in us."""
    first, last = flight_window(ulog)
    middle = (first + last) // 2
    return middle - int(STOP_FOR_S * 5e5), middle + int(STOP_FOR_S * 5e5)


def to_dshot(ulog, *, stop_motor: int | None = None) -> None:
    """Rewrite the log as a DShot600 vehicle: every MAIN timer -3, the PWM disarmed values still
    at PX4's PWM default 1000 (as on real DShot vehicles), outputs on the DShot scale: 0
    disarmed, DSHOT_MIN * 1999 at PWM_MIN (1000) up to 1999 at 2000; unused outputs 0."""
    for timer in range(4):
        ulog.initial_parameters[f"PWM_MAIN_TIM{timer}"] = -3
    for k in range(1, 17):
        ulog.initial_parameters[f"PWM_MAIN_DIS{k}"] = 1000
    ulog.initial_parameters["DSHOT_MIN"] = DSHOT_MIN
    data = ulog.get_dataset("actuator_outputs").data
    low = DSHOT_MIN * 1999.0
    for k in range(16):
        pwm = data[f"output[{k}]"].astype(np.float64)
        dshot = np.where(pwm <= 900.0, 0.0, np.round(low + (pwm - 1000.0) / 1000.0 * (1999.0 - low)))
        data[f"output[{k}]"] = (dshot if k < 4 else np.zeros_like(dshot)).astype(np.float32)
    if stop_motor is not None:
        stop(ulog, stop_motor, 0.0)


def stop(ulog, output: int, value: float, *, on_purpose: bool = False) -> tuple[int, int]:
    """Output ``output`` at ``value`` for 4 s mid-flight (with ``on_purpose`` PX4's own motor
    command is NaN meanwhile, a stop the allocator asked for); the window in us."""
    first, last = stop_window(ulog)
    data = ulog.get_dataset("actuator_outputs").data
    inside = (data["timestamp"] >= first) & (data["timestamp"] <= last)
    data[f"output[{output}]"][inside] = value
    if on_purpose:
        motors = ulog.get_dataset("actuator_motors").data
        motors[f"control[{output}]"][(motors["timestamp"] >= first) & (motors["timestamp"] <= last)] = np.nan
    return first, last


def unused_aux_group(ulog) -> None:
    """An all-zero ``actuator_outputs`` instance 1 whose AUX outputs are configured as motors."""
    main = ulog.get_dataset("actuator_outputs")
    aux = copy.deepcopy(main)
    aux.multi_id = 1
    aux.msg_id = max(d.msg_id for d in ulog.data_list) + 1  # its own subscription
    aux.data = {f: (v if f in ("timestamp", "noutputs") else np.zeros_like(v)) for f, v in main.data.items()}
    ulog.data_list.append(aux)
    for k in range(1, 5):
        ulog.initial_parameters[f"PWM_AUX_FUNC{k}"] = 100 + k
        ulog.initial_parameters[f"PWM_AUX_DIS{k}"] = 1000


# --- no alarm: the motors run, or PX4 itself stopped them ------------------------------------------


@pytest.mark.testdata(EVENTS)
def test_dshot_outputs_are_judged_on_the_dshot_scale(tmp_path, cli):
    log = edit_log(EVENTS, tmp_path / "dshot.ulg", to_dshot)
    health = analyze(cli, EVENTS, log, tmp_path)
    assert motor_alarms(health) == []
    zero = health["info"]["checks"]["health.motor_zero"]["limit"]
    assert "PWM_MAIN_TIM0 = -3 (DShot600)" in zero["protocol"]
    assert zero["outputs"] == ["1", "2", "3", "4"] and zero["stopped_at"] == [0.0] * 4
    assert zero["max"] == [1999.0] * 4
    assert "health.motor_max.5" not in health["info"]["checks"]  # Motor functions only


@pytest.mark.testdata(EVENTS)
def test_an_unused_output_group_is_no_motor(tmp_path, cli):
    log = edit_log(EVENTS, tmp_path / "aux.ulg", unused_aux_group)
    assert pyulog.ULog(str(log)).get_dataset("actuator_outputs", 1).data["output[0]"].max() == 0.0
    health = analyze(cli, EVENTS, log, tmp_path)
    assert motor_alarms(health) == []
    assert "no motor output was active while armed" in health["info"]["skipped"]["health.motor_saturated.aux"]
    assert "health.motor_zero" in health["info"]["checks"]  # the MAIN motors are still judged


@pytest.mark.testdata(ROBOLOGS)
def test_unused_output_channels_of_a_legacy_log_are_no_motors(tmp_path, cli):
    def eight_outputs(ulog):  # 8 outputs, 5 to 8 held at the disarmed value (PWM_MAIN_DISARM 900)
        data = ulog.get_dataset("actuator_outputs").data
        data["noutputs"][:] = 8
        for k in range(4, 8):
            data[f"output[{k}]"][:] = 900.0

    log = edit_log(ROBOLOGS, tmp_path / "eight.ulg", eight_outputs)
    health = analyze(cli, ROBOLOGS, log, tmp_path)
    assert motor_alarms(health) == []
    zero = health["info"]["checks"]["health.motor_zero"]["limit"]
    assert zero["outputs"] == ["1", "2", "3", "4"] and zero["not_motors"] == ["5", "6", "7", "8"]
    assert zero["stopped_at"] == [900.0] * 4 and zero["stopped_from"] == ["PWM_MAIN_DISARM"] * 4


@pytest.mark.testdata(EVENTS)
def test_a_motor_px4_stops_on_purpose_is_no_alarm(tmp_path, cli):
    log = edit_log(EVENTS, tmp_path / "purpose.ulg", lambda u: stop(u, 1, 900.0, on_purpose=True))
    health = analyze(cli, EVENTS, log, tmp_path)
    assert motor_alarms(health) == []
    assert health["info"]["checks"]["health.motor_zero"]["outputs_stopped"] == []


# --- alarm: a motor PX4 commands to run sits at its stopped value in flight -------------------------


@pytest.mark.testdata(EVENTS)
@pytest.mark.parametrize("protocol", ["pwm", "dshot"])
def test_a_motor_stopping_in_flight_is_one_alarm_at_its_time(tmp_path, cli, protocol):
    window = {}

    def edit(ulog):
        if protocol == "dshot":
            to_dshot(ulog)
        window["us"] = stop(ulog, 1, 900.0 if protocol == "pwm" else 0.0)

    log = edit_log(EVENTS, tmp_path / f"{protocol}.ulg", edit)
    health = analyze(cli, EVENTS, log, tmp_path)
    (alarm,) = motor_alarms(health)
    assert alarm["signal"] == "health.motor_zero"
    assert health["info"]["checks"]["health.motor_zero"]["outputs_stopped"] == ["2"]
    onset, end = (np.asarray(window["us"]) / 1e6 - health["clock_offset_s"]).tolist()
    assert alarm["first_exceed"] == pytest.approx(onset, abs=0.15)
    assert onset <= alarm["start"] <= onset + LATE_S
    assert alarm["end"] == pytest.approx(end, abs=0.15)


@pytest.mark.testdata(EVENTS)
@pytest.mark.parametrize("commanded", [0.0, None])
def test_where_stopped_and_idle_are_one_value_the_command_tells_them_apart(tmp_path, cli, commanded):
    """PX4 v1.13+'s PWM defaults: PWM_MAIN_DISn = PWM_MAIN_MINn = 1000, so an output at 1000 is
    stopped or idling. Output 2 at 1000 for 4 s mid-flight: PX4 commanding it 0 (idle) is no
    alarm; PX4 commanding it as logged (about half thrust) is a stopped motor."""

    def edit(ulog):
        for k in range(1, 17):
            ulog.initial_parameters[f"PWM_MAIN_DIS{k}"] = 1000
            ulog.initial_parameters[f"PWM_MAIN_MIN{k}"] = 1000
        first, last = stop(ulog, 1, 1000.0)
        if commanded is not None:
            motors = ulog.get_dataset("actuator_motors").data
            motors["control[1]"][(motors["timestamp"] >= first) & (motors["timestamp"] <= last)] = commanded

    health = analyze(cli, EVENTS, edit_log(EVENTS, tmp_path / "idle.ulg", edit), tmp_path)
    zero = health["info"]["checks"]["health.motor_zero"]
    assert zero["limit"]["stopped_at"] == [1000.0] * 4
    assert zero["limit"]["stopped_from"] == ["PWM_MAIN_DIS1, = its idle minimum"] + [
        f"PWM_MAIN_DIS{k}, = its idle minimum" for k in (2, 3, 4)
    ]
    if commanded is None:
        (alarm,) = motor_alarms(health)
        assert alarm["signal"] == "health.motor_zero" and zero["outputs_stopped"] == ["2"]
    else:
        assert motor_alarms(health) == [] and zero["outputs_stopped"] == []


@pytest.mark.testdata(NEVER_ARMED)
def test_a_log_never_armed_says_so(tmp_path, cli):
    health = analyze(cli, NEVER_ARMED, need_testdata(NEVER_ARMED), tmp_path)
    assert health["info"]["skipped"]["health.motor_saturated"] == "actuator_outputs_0: never armed while it was logged"


@pytest.mark.testdata("px4-ulog-extra/mcap_ulog2mcap_test_ulog.ulg")
def test_a_motor_px4_never_commands_in_flight_is_named_as_the_reason_nothing_was_judged(tmp_path, cli):
    """The real FMU-v6C plane (MAV_TYPE 1) has its motor 1 on AUX4 (PWM_AUX_FUNC4 101), at 1000 us
    all its 2 s in the air and 1152-1223 us after; actuator_motors control[0] is NaN at every sample
    armed and flying (PX4 stopped it on purpose). "No sample to judge on the analysis grid" hid that."""
    out = tmp_path / "s.json"
    path = need_testdata("px4-ulog-extra/mcap_ulog2mcap_test_ulog.ulg")
    result = cli("analyze", str(path), "-d", "health", "--no-report", "--json", str(out))
    (log,) = json.loads(out.read_text())["logs"]
    (health,) = log["detectors"]
    why = health["info"]["skipped"]["health.motor_zero.aux"]
    assert why.startswith("actuator_outputs_1: actuator_motors_0.control[0] (aux4) NaN at all ")
    assert "samples armed and flying: PX4 commanded no motor to run in flight" in why
    assert f"health: motor_zero.aux: {why}" in log["skipped_checks"] and result.exit_code == 0
    assert health["info"]["checks"]["health.motor_saturated.aux"]["limit"]["commands"] == [
        "actuator_motors_0.control[0]"
    ]
