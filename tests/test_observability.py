"""The observability verdict (logscan.verdict.observability, docs/algorithms.md section 10): a steer-by-wire
actuator offset cannot be seen in straight driving and can in a lane change, a quadcopter sensor bias
is always seen, the analysis judges only around the ground truth's faults (and the same as the whole
run there), the batched kernel equals the recursion written out per signature, evaluate counts the
misses where a fault could not be seen apart, and the summary's observability validates against the
published schema."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from test_model_contract import CASES  # every model, with the contract's example parameters

from logscan.models import get_model
from logscan.results import FaultEvent
from logscan.verdict.observability import Direction, Observability, observability_of, spans_of
from logscan.verdict.scoring import label_observability, score_log

SCHEMA = Path(__file__).resolve().parents[1] / "docs" / "schema" / "analyze-summary.schema.json"


def _simulated(tmp_path_factory, model: str, seconds: float, seed: int, faults=()):
    from logscan.pipeline import analyze_log
    from logscan.simulate import parse_fault, simulate, write_simulation

    path = tmp_path_factory.mktemp(model) / f"{model}.mcap"
    sim = simulate(model, [parse_fault(f) for f in faults], duration=seconds, seed=seed)
    write_simulation(sim, str(path), "mcap-ros2")
    return path, analyze_log(path, detector_names=["nis"])


@pytest.fixture(scope="module")
def steer(tmp_path_factory):
    """25 s of steer-by-wire: a double lane change over 0-4 s and 20-24 s, straight driving between;
    a 10 % steering-motor offset over 6-16 s (straight)."""
    return _simulated(tmp_path_factory, "steer_by_wire", 25.0, 9101, ["actuator-offset::6:16:"])


def _index(obs: Observability, target: str) -> int:
    return next(i for i, d in enumerate(obs.directions) if d.target == target)


def _whole(analysis) -> Observability:
    """The verdict over every window start of the analysed log (the pipeline judges only around
    the ground truth's faults)."""
    prepared = analysis.prepared
    return observability_of(prepared.model, prepared.run, prepared.trace)


def test_steer_by_wire_actuator_offset_is_unobservable_straight_and_observable_in_a_lane_change(steer):
    _, analysis = steer
    obs = _whole(analysis)
    d = _index(obs, "steering_motor")
    seen = obs.observable(d, "actuator-offset")
    t = obs.t_start
    assert seen[(t >= 0.25) & (t <= 2.5)].all()  # the lane change: the offset moves the steering
    assert not seen[(t >= 5.0) & (t <= 18.5)].any()  # straight: nearly no torque, nearly no offset
    assert obs.observable(d, "lost-actuator")[(t >= 0.25) & (t <= 2.5)].all()
    spans = obs.unobservable_intervals(d, "actuator-offset")
    assert any(a <= 5.0 and b >= 18.5 for a, b in spans)
    # the truth's offset (6-16 s, all straight) is labelled unobservable; one reaching into the
    # next lane change is not
    event = analysis.events[0]
    assert (event.kind, event.target) == ("actuator-offset", "steering_motor")
    assert obs.event_verdict(event) is False
    later = FaultEvent(15.0, 22.0, "actuator-offset", "steering_motor", -0.1)
    assert obs.event_verdict(later) is True


def test_steer_by_wire_shading_words_and_report_figure(steer):
    from logscan.report.observability_figures import observability_figures

    _, analysis = steer
    blind = {(p["target"], p["kind"]): p for p in analysis.observability.blind_periods()}
    offset = blind[("steering_motor", "actuator-offset")]
    assert "could not be seen here" in offset["words"] and "barely commanded" in offset["words"]
    assert offset["unobservable_s"] > 10.0
    figures = observability_figures(analysis.observability)
    assert len(figures) == 1 and figures[0]["id"] == "ctx-observability"
    assert "could not be seen here" in figures[0]["json"]
    assert f"less than {analysis.observability.snr_min:.3g} standard deviations" in figures[0]["caption"]
    assert "Judged only from a second before each fault" in figures[0]["caption"]  # white elsewhere: no verdict
    assert not re.search(r"\d\.\d{4,} standard deviations", figures[0]["caption"])  # not 5.62716


def test_quadcopter_sensor_bias_is_always_observable(tmp_path_factory):
    _, analysis = _simulated(tmp_path_factory, "quadcopter", 15.0, 9102)
    assert analysis.observability is None  # no fault in its truth: no verdict needed
    obs = _whole(analysis)
    # the model's actuators (Model.actuators), named as the simulator's truth names them
    assert [d.target for d in obs.directions if d.what == "actuator"] == ["motor1", "motor2", "motor3", "motor4"]
    for target in ("accel.x", "accel.z", "gyro.y"):
        d = _index(obs, target)
        judged = np.isfinite(obs.evidence[:, d])
        assert judged.sum() > 40
        assert obs.observable(d, "bias")[judged].all(), target
        assert obs.unobservable_intervals(d, "bias") == []
    assert obs.event_verdict(FaultEvent(5.0, 8.0, "bias", "accel.x", 1.0)) is True
    assert obs.event_verdict(FaultEvent(5.0, 8.0, "stuck", "accel.x", 0.0)) is None  # no verdict


@pytest.mark.parametrize(("name", "params"), CASES)
def test_every_model_s_actuators_drive_its_inputs_each_its_own_way(name, params):
    model = get_model(name, params)
    actuators = model.actuators()
    A = len(actuators.names)
    assert actuators.M.shape == (model.n_inputs, A) and actuators.trim.shape == (A,)
    if model.inputs_are_sensors:
        assert A == 0  # the IMU of ins is a sensor: its faults are sensor faults
    else:  # one actuator per input at least (none for a model without inputs), each its own direction
        assert A >= model.n_inputs and np.linalg.matrix_rank(actuators.M) == model.n_inputs
        assert len(set(actuators.names)) == A


def test_the_mixer_follows_what_the_quadcopter_s_inputs_are():
    wrench, motors = get_model("quadcopter").actuators(), get_model("quadcopter", {"inputs": "motors"}).actuators()
    assert wrench.names == motors.names == ("motor1", "motor2", "motor3", "motor4")
    assert np.allclose(wrench.M, get_model("quadcopter").mixer_matrix())  # thrust and torques from motor thrusts
    assert np.array_equal(motors.M, np.eye(4))  # the inputs are the motors' own speeds
    hover = get_model("hover_uav")
    assert np.allclose(hover.actuators().trim, hover.hover_thrust())  # F1..F4 deviate from hover


def test_the_analysis_judges_around_the_truth_s_faults_as_the_whole_run_does(steer):
    _, analysis = steer
    obs, whole = analysis.observability, _whole(analysis)
    assert "judged around the ground truth's faults" in obs.notes[0]
    judged = np.isfinite(obs.evidence).all(axis=1)
    t = obs.t_start
    # the offset over 6-16 s: its window starts from a window before it to its end, no others
    assert judged[(t >= 5.0) & (t <= 16.0)].all() and not judged[(t < 5.0) | (t > 16.0)].any()
    assert np.array_equal(obs.evidence[judged], whole.evidence[judged])  # its kernel started at the log's start
    assert obs.event_verdict(analysis.events[0]) is whole.event_verdict(analysis.events[0]) is False


def test_a_span_judged_alone_settles_to_the_whole_run_s_evidence(steer):
    _, analysis = steer
    prepared = analysis.prepared
    whole = _whole(analysis)
    short = observability_of(prepared.model, prepared.run, prepared.trace, spans=[(21.0, 22.0)])
    judged = np.isfinite(short.evidence).all(axis=1)
    assert judged.sum() == 5 and np.allclose(short.evidence[judged], whole.evidence[judged], rtol=1e-9, atol=0)


def _reference_evidence(model, run, trace, window: int, stride: int, steps: int) -> np.ndarray:
    """The recursion of docs/algorithms.md section 10 written out per signature with numpy (the
    model's own f, F, h, H), phase j restarted at k = j * stride + q * window."""
    from logscan.verdict.observability import _fault_directions, held_inputs

    dt, u = float(trace.dt), held_inputs(run.u)[:steps]
    _, faults = _fault_directions(model, run, trace, u)
    A, D = faults.act_dirs.shape[0], faults.act_dirs.shape[0] + faults.sensor_cols.size
    J, n = window // stride, model.n_states
    P = np.diag(trace.P_post_diag[0].astype(np.float64))
    out = np.full((steps // stride + 1, D), np.nan)
    mu, lam, start = np.zeros((J, D, n)), np.zeros((J, D)), [-1] * J
    for k in range(1, steps):
        for j in range(J):
            if k >= j * stride and (k - j * stride) % window == 0:
                if start[j] >= 0:
                    out[start[j] // stride] = lam[j]
                start[j], mu[j], lam[j] = k, 0.0, 0.0
        x = trace.x_post[k - 1]
        F = model.F(x, u[k], dt)
        h = 1e-6 * (1.0 + np.abs(u[k]).max())
        G = [(model.f(x, u[k] + h * d, dt) - model.f(x, u[k] - h * d, dt)) / (2 * h) for d in faults.act_dirs]
        P = F @ P @ F.T + trace.Q
        mu = mu @ F.T
        for a in range(A):
            mu[:, a] += G[a] * faults.act_values[k, a]
        used = [g for g, name in enumerate(trace.group_names) if trace.updated[k, g]]
        H = np.vstack([model.H(trace.group_names[g], trace.x_prior[k], u[k]) for g in used])
        rows = np.concatenate([trace.group_offsets[g] + np.arange(trace.group_sizes[g]) for g in used])
        R = trace.R[np.ix_(rows, rows)]
        S = H @ P @ H.T + R
        K = P @ H.T @ np.linalg.inv(S)
        IKH = np.eye(n) - K @ H
        P = IKH @ P @ IKH.T + K @ R @ K.T
        r = mu @ H.T
        for b, col in enumerate(faults.sensor_cols):
            r[:, A + b, rows == col] += 1.0
        lam += np.einsum("jda,ab,jdb->jd", r, np.linalg.inv(S), r)
        mu -= r @ K.T
    return out


def test_the_batched_kernel_equals_the_recursion_per_signature(steer):
    _, analysis = steer
    prepared = analysis.prepared
    model, run, trace = prepared.model, prepared.run, prepared.trace
    steps, window, stride = 400, 100, 25  # 4 s: the first lane change, 4 phases
    reference = _reference_evidence(model, run, trace, window, stride, steps)
    obs = observability_of(model, run, trace, spans=[(0.0, 3.0)])  # the kernel's own arguments, cut short
    assert obs.stride_s == pytest.approx(0.25) and obs.window_s == pytest.approx(1.0)
    judged = np.isfinite(reference).all(axis=1)
    assert judged.sum() >= 10
    assert np.allclose(obs.evidence[: judged.size][judged], reference[judged], rtol=1e-7, atol=1e-12)


def _crafted() -> Observability:
    """Two directions over 0-10 s: an actuator seen only from 2 to 4 s, a sensor always seen."""
    t = np.arange(0.0, 10.0, 0.5)
    evidence = np.ones((t.size, 2)) * 1e4
    evidence[:, 0] = np.where((t >= 2.0) & (t < 4.0), 1e4, 1.0)
    evidence[-1] = np.nan  # a window the log's end cut short: not judged
    return Observability(t, evidence, [Direction("motor", "actuator"), Direction("speed", "sensor", "/speed")],
                         window_s=1.0, stride_s=0.5, t_end=10.0)  # fmt: skip


def test_verdict_of_a_fault_follows_its_span_and_size():
    from logscan.verdict.observability import SNR_MIN, snr_needed

    # the matched test at 0.1 false alarms per hour (one test per 0.25 s) with 90 % power
    assert snr_needed() == pytest.approx(4.3453 + 1.2816, abs=1e-3) == pytest.approx(SNR_MIN, abs=5e-3)
    obs = _crafted()
    assert obs.unobservable_intervals(0, "actuator-offset") == [(0.0, 2.0), (4.0, 9.5)]
    assert obs.event_verdict(FaultEvent(5.0, 8.0, "actuator-offset", "motor", -0.1)) is False
    assert obs.event_verdict(FaultEvent(3.8, 8.0, "actuator-offset", "motor", -0.1)) is True
    # 1e4 * 0.01 = 100 >= 25: seen; 1e4 * 1e-4 = 1: too small to be seen even at 2-4 s
    assert obs.event_verdict(FaultEvent(2.0, 3.0, "actuator-offset", "motor", -0.01)) is False
    assert obs.event_verdict(FaultEvent(5.0, 8.0, "bias", "x", 1.0, ("/speed",))) is True  # by channel
    assert obs.event_verdict(FaultEvent(5.0, 8.0, "bias", "elsewhere", 1.0)) is None
    assert spans_of(np.array([False, True, True, False]), np.arange(4.0), 1.0, 2.5) == [(1.0, 2.5)]


def test_evaluate_counts_misses_where_a_fault_could_not_be_seen_apart():
    from logscan.cli.render import render_observability
    from logscan.verdict.evaluation import Evaluation, LogEvaluation, kind_summary

    obs = _crafted()
    events = [
        FaultEvent(5.0, 7.0, "actuator-offset", "motor", -0.1),  # unobservable, missed
        FaultEvent(1.0, 3.0, "actuator-offset", "motor", -0.1),  # observable, detected
        FaultEvent(8.5, 9.0, "lost-actuator", "motor", 0.0),  # unobservable (lost: 1.0 < 25), detected
    ]
    score = score_log(events, [(1.5, 1.6), (8.6, 8.7)], duration_s=10.0, detector="d")
    label_observability(score, [obs.event_verdict(e) for e in events])
    assert [m.observable for m in score.matches] == [False, True, False]
    assert (score.tp, score.fn, score.unobservable, score.fn_unobservable) == (2, 1, 2, 1)
    assert score.fn_observable == 0 and score.recall_observable == 1.0
    assert score.to_dict()["events"][0]["observable"] is False
    evaluation = Evaluation(logs=[LogEvaluation("a.mcap", "toy", 10.0, events, {"d": score})])
    offset = evaluation.by_kind("d")["toy/actuator-offset"]
    summary = kind_summary(offset)
    split = (summary["unobservable"], summary["missed_unobservable"], summary["detection_rate_observable"])
    assert split == (1, 1, 1.0)
    assert evaluation.aggregate("d").fn_unobservable == 1
    text = render_observability(evaluation)
    assert "toy/actuator-offset" in text and "1/1" in text
    assert json.dumps(evaluation.to_dict())  # the JSON carries it


def test_summary_observability_validates_against_the_schema(steer, tmp_path):
    import jsonschema

    from logscan.cli.main import main

    path, _ = steer
    out = tmp_path / "summary.json"
    with pytest.raises(SystemExit):
        main(["analyze", str(path), "--no-report", "-q", "--json", str(out)])
    document = json.loads(out.read_text())
    schema = json.loads(SCHEMA.read_text(encoding="utf-8"))
    validator = jsonschema.Draft202012Validator(schema)
    assert list(validator.iter_errors(document)) == []
    observability = document["logs"][0]["observability"]
    assert any(p["kind"] == "actuator-offset" for p in observability["unobservable"])
    broken = json.loads(json.dumps(document))
    broken["logs"][0]["observability"]["unobservable"][0]["kind"] = "sideways"
    assert list(validator.iter_errors(broken))  # the schema checks it
