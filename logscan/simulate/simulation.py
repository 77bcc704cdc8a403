"""One simulated log: run the closed loop for a model with faults, and expose its logged series.

`simulate_closed_loop()` (entered through `logscan.simulate.dispatch.simulate`, which picks the
simulator of a model) draws every random number from one seeded generator (process noise, sensor
noise, fault draws, the mode schedule), runs the numba kernel of `logscan.simulate.runner` once, and
returns a `Simulation` holding the true states, commands, sensor samples, the on-board estimate and
the ground-truth fault events. `Simulation.series()` lists what a log holds, channel by channel,
with sample indices on the grid; `logscan.simulate.output` writes it as MCAP or CSV.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from logscan.errors import UsageError
from logscan.profiles import dumps_toml
from logscan.results import FaultEvent
from logscan.simulate.faults import (
    FaultSpec,
    FaultTable,
    corrupt_logged_variance,
    resolve_faults,
)
from logscan.simulate.runner import closed_loop
from logscan.simulate.scenario import Scenario

MAX_DURATION_S = 24 * 3600.0
TRUTH_SCHEMA = "logscan.truth/1"
SETPOINT_RATE_HZ = 10.0  # mode and set-point channels (they change slowly or in steps)


@dataclass
class Series:
    """Samples of one logged topic: grid step indices and one value column per field."""

    topic: str
    schema: str
    steps: np.ndarray  # (k,) int64 grid indices
    fields: dict[str, np.ndarray]  # field name -> (k,) float64


@dataclass
class Simulation:
    """Everything one closed-loop run produced (arrays on the grid of period ``scenario.dt``)."""

    scenario: Scenario
    seed: int
    duration: float
    aggressive: bool
    events: list[FaultEvent]
    faults: FaultTable
    x_true: np.ndarray  # (N, n)
    u_cmd: np.ndarray  # (N, nu) commanded (logged)
    u_act: np.ndarray  # (N, nu) what the actuators delivered (truth)
    z: np.ndarray  # (N, total measurements), NaN where a group did not sample
    x_hat: np.ndarray  # (N, n) on-board estimate (logged)
    P_diag: np.ndarray  # (N, n) on-board variance as LOGGED (after cov-corruption)
    rejected: int  # sensor samples the on-board EKF skipped
    elapsed_s: float
    transients: list[FaultEvent] = field(default_factory=list)  # healthy glitches, not faults

    @property
    def dt(self) -> float:
        return self.scenario.dt

    @property
    def n_steps(self) -> int:
        return int(self.x_true.shape[0])

    @property
    def t(self) -> np.ndarray:
        return np.arange(self.n_steps) * self.dt

    def group_slices(self) -> dict[str, slice]:
        out, offset = {}, 0
        for g in self.scenario.groups:
            out[g.name] = slice(offset, offset + len(g.fields))
            offset += len(g.fields)
        return out

    def series(self) -> list[Series]:
        """Every logged topic: commands, sensors, on-board estimator, set-points/mode, truth."""
        sc = self.scenario
        n = self.n_steps
        every = np.arange(n, dtype=np.int64)
        inputs: dict[str, dict[str, np.ndarray]] = {}  # topic -> fields (/cmd; ins: /imu)
        for i, ch in enumerate(sc.input_channels):
            topic, _, name = ("/cmd", "", ch.removeprefix("/cmd/")) if ch.startswith("/cmd/") else ch.rpartition("/")
            inputs.setdefault(topic, {})[name] = self.u_cmd[:, i]
        out = [Series(topic, _schema(topic), every, fields) for topic, fields in inputs.items()]
        sensors: dict[str, Series] = {}
        for g, sl in zip(sc.groups, self.group_slices().values()):
            steps = every[:: g.ratio]
            fields = {f: self.z[steps, sl.start + j] for j, f in enumerate(g.fields)}
            if g.topic in sensors:  # groups sharing a topic share its rate (see scenario)
                sensors[g.topic].fields.update(fields)
            else:
                sensors[g.topic] = Series(g.topic, _schema(g.topic), steps, fields)
        out.extend(sensors.values())
        states = sc.model.state_names
        ratio = max(1, int(round(1.0 / (sc.dt * sc.onboard_rate_hz))))
        steps = every[::ratio]
        out.append(
            Series(
                "/ekf/state", "logscan/EstimatorState", steps, {s: self.x_hat[steps, i] for i, s in enumerate(states)}
            )
        )
        out.append(
            Series(
                "/ekf/variance",
                "logscan/EstimatorVariance",
                steps,
                {s: self.P_diag[steps, i] for i, s in enumerate(states)},
            )
        )
        extra: dict[str, dict[str, np.ndarray]] = {}
        if sc.mode_channel and sc.mode_values is not None:
            extra.setdefault(*_split(sc.mode_channel, sc.mode_values))
        for channel, values in sc.setpoints.items():
            topic, fields = _split(channel, values)
            extra.setdefault(topic, {}).update(fields)
        slow = every[:: max(1, int(round(1.0 / (sc.dt * SETPOINT_RATE_HZ))))]
        for topic, fields in extra.items():
            out.append(Series(topic, "logscan/Setpoint", slow, {k: v[slow] for k, v in fields.items()}))
        out.append(
            Series("/truth/state", "logscan/TruthState", every, {s: self.x_true[:, i] for i, s in enumerate(states)})
        )
        return out

    def truth(self) -> dict:
        """The ground-truth document embedded in the log (`logscan.truth`)."""
        sc = self.scenario
        doc = {
            "schema": TRUTH_SCHEMA,
            "generator": "logscan simulate",
            "model": sc.model_name,
            "seed": self.seed,
            "duration_s": self.duration,
            "rate_hz": 1.0 / sc.dt,
            "aggressive": self.aggressive,
            "controller_input": sc.controller_input,
            "events": [e.to_truth() for e in self.events],
            "transients": [dict(e.to_truth(), kind="glitch", cause=_glitch_cause(e.target)) for e in self.transients],
            "true_state_topic": "/truth/state",
            "true_state_fields": list(sc.model.state_names),
            "onboard_rejected_samples": int(self.rejected),
        }
        if sc.speed is not None:
            doc["speed_profile"] = sc.speed
        doc.update(sc.truth_extra)
        noisy = [g for g in sc.groups if g.noise_slope is not None]
        if noisy:  # the simulated noise std per channel, where it is not the profile's noise_std
            doc["sensor_noise_std"] = {
                ch: f"{b:g} + {k:g} |v|"
                for g in noisy
                for ch, b, k in zip(g.channels, g.noise_base.tolist(), g.noise_slope.tolist())
            }
        return doc

    def profile_dict(self) -> dict:
        """The matching profile (`[vehicle]`, `[inputs]`, `[measurements.*]`, `[onboard]`, ...)."""
        sc = self.scenario
        rate = 1.0 / sc.dt
        profile: dict = {
            "name": f"simulated {sc.model_name}",
            "description": "written by `logscan simulate`; channels as logged",
            "vehicle": {"model": sc.model_name, "rate_hz": rate},
            "inputs": {name: ch for name, ch in zip(sc.model.input_names, sc.input_channels)},
            "measurements": {},
        }
        params = sc.model.params if sc.profile_params is None else sc.profile_params
        if params:
            profile["vehicle"]["params"] = dict(params)
        for g in sc.groups:
            profile["measurements"][g.name] = {
                "channels": g.channels,
                "rate_hz": g.rate_hz,
                "stale_s": 2.5 / g.rate_hz,
                "noise_std": [float(v) for v in g.noise_std],
            }
        if sc.mode_channel:
            profile["mode"] = {"channel": sc.mode_channel}
        if sc.redundant:
            profile["redundant"] = {name: {"sensors": dict(s)} for name, s in sc.redundant.items()}
        profile["onboard"] = {"state": "/ekf/state", "variance": "/ekf/variance"}
        if sc.alarms:
            profile["alarms"] = dict(sc.alarms)
        if sc.detectors:
            profile["detectors"] = {name: dict(settings) for name, settings in sorted(sc.detectors.items())}
        return profile

    def profile_toml(self) -> str:
        return dumps_toml(self.profile_dict())


def _glitches(sc: Scenario, duration: float, per_min: float, rng: np.random.Generator) -> list[FaultSpec]:
    """Healthy transients as one- or two-sample bias specs (see `simulate`): 3-8 noise standard
    deviations (at the commanded speed for a speed sensor whose noise grows with it); an encoder
    slips (reads low), any other sensor is off either way (a GPS glitch)."""
    count = rng.poisson(per_min * duration / 60.0) if per_min > 0 else 0
    if count == 0:
        return []
    redundant = {ch for group in sc.redundant.values() for ch in group.values()}
    channels = [(ch, g, j) for g in sc.groups for j, ch in enumerate(g.channels) if not redundant or ch in redundant]
    picks = rng.integers(0, len(channels), size=count)
    starts = np.sort(rng.uniform(1.0, max(duration - 1.0, 1.0), size=count))
    sizes = rng.uniform(3.0, 8.0, size=count) * rng.choice([-1.0, 1.0], size=count)
    lengths = rng.integers(1, 3, size=count)
    out = []
    for pick, start, size, length in zip(picks.tolist(), starts.tolist(), sizes.tolist(), lengths.tolist()):
        channel, g, j = channels[pick]
        step = min(int(round(start / sc.dt)), sc.reference.shape[0] - 1)
        std = float(g.sample_std(sc.reference[step, 0])[j]) if g.noise_slope is not None else float(g.noise_std[j])
        if _glitch_cause(g.name) == "encoder-slip":
            size = -abs(size)
        period = g.ratio * sc.dt
        out.append(FaultSpec("bias", channel, round(start, 3), round(start + length * period, 3), round(size * std, 6)))
    return out


def _glitch_cause(target: str) -> str:
    """What a healthy transient on ``target`` (a fault target or group name) stands for."""
    if target.startswith("encoder"):
        return "encoder-slip"
    if target.startswith("gps"):
        return "gps-glitch"
    return "spike"


def sensor_aliases(sc: Scenario) -> dict[str, str]:
    """Other names a user may give a sensor fault's target -> the target name: the field
    (left.v), the model output (v_left), "<group>.<field>" and the redundant group's sensor name
    (left, encoder.left, gps); a name that would stand for two channels is left out."""
    redundant = {ch: name for group in sc.redundant.values() for name, ch in group.items()}
    seen: dict[str, set[str]] = {}
    for g in sc.groups:
        outputs = g.outputs or g.fields
        for target, channel, field_name, output in zip(g.targets(), g.channels, g.fields, outputs):
            names = {field_name, output, f"{g.name}.{field_name}", f"{g.name}.{output}"}
            if channel in redundant:  # left, encoder.left, gps
                names |= {redundant[channel], f"{g.name}.{redundant[channel]}"}
            for name in names - {target}:
                seen.setdefault(name, set()).add(target)
    real = {target for g in sc.groups for target in g.targets()}
    return {name: next(iter(targets)) for name, targets in seen.items() if len(targets) == 1 and name not in real}


def _schema(topic: str) -> str:
    """Schema name of a logged topic: /cmd -> logscan/Command, /imu -> logscan/Imu."""
    if topic == "/cmd":
        return "logscan/Command"
    return "logscan/" + topic.strip("/").replace("/", "_").title()


def _split(channel: str, values: np.ndarray) -> tuple[str, dict[str, np.ndarray]]:
    topic, _, field_name = channel.rpartition("/")
    return topic, {field_name: values}


def check_run_options(duration: float, seed: int, glitches_per_min: float) -> None:
    """UsageError unless ``duration``, ``seed`` and ``glitches_per_min`` are in range (any model)."""
    if not (0.0 < duration <= MAX_DURATION_S):
        raise UsageError(f"--duration {duration:g} s is out of range", hint="use 0 < duration <= 86400 s")
    if seed < 0:
        raise UsageError(f"--seed {seed} is negative", hint="use a seed >= 0")
    if not (0.0 <= glitches_per_min <= 600.0):
        raise UsageError(f"--glitches {glitches_per_min:g} per minute is out of range", hint="use 0 .. 600")


def simulate_closed_loop(
    sc: Scenario,
    faults: list[FaultSpec],
    *,
    duration: float,
    seed: int,
    aggressive: bool,
    glitches_per_min: float,
) -> Simulation:
    """Run the closed loop of scenario ``sc`` (`scenario.closed_loop_scenario`) with ``faults``;
    called by `logscan.simulate.dispatch.simulate`, which has checked its arguments."""
    rng = np.random.default_rng(seed)
    n_steps = sc.reference.shape[0]
    events, transients, table = _resolve(sc, list(faults or []), duration, seed, glitches_per_min)
    model = sc.model
    n = model.n_states
    Q = np.ascontiguousarray(model.default_Q(sc.dt))
    L_Q = np.linalg.cholesky(Q)
    # w_k ~ N(0, Q): w = L_Q e, e ~ N(0, I)
    W = rng.standard_normal((n_steps, n)) @ L_Q.T
    std = np.concatenate([g.noise_std for g in sc.groups])  # nominal: the on-board EKF's R
    base = np.concatenate([g.noise_std if g.noise_base is None else g.noise_base for g in sc.groups])
    slope = np.concatenate([np.zeros(len(g.fields)) if g.noise_slope is None else g.noise_slope for g in sc.groups])
    E = rng.standard_normal((n_steps, std.size))
    started = time.perf_counter()
    x_true, u_cmd, u_act, z, x_hat, P_diag, rejected = _closed_loop(sc, table, Q, W, E, base, slope, std)
    elapsed = time.perf_counter() - started
    return Simulation(
        scenario=sc,
        seed=seed,
        duration=duration,
        aggressive=aggressive,
        events=events,
        transients=transients,
        faults=table,
        x_true=x_true,
        u_cmd=u_cmd,
        u_act=u_act,
        z=z,
        x_hat=x_hat,
        P_diag=corrupt_logged_variance(P_diag, table),
        rejected=int(rejected),
        elapsed_s=elapsed,
    )


def _resolve(
    sc: Scenario, faults: list[FaultSpec], duration: float, seed: int, glitches_per_min: float
) -> tuple[list[FaultEvent], list[FaultEvent], FaultTable]:
    """(the faults' events, the glitches' events, the kernel's fault table) of a closed-loop run;
    state-corruption events name the logged state, cov-corruption ones the logged variance."""
    sensor_channels = [(target, ch) for g in sc.groups for target, ch in zip(g.targets(), g.channels)]
    glitches = _glitches(sc, duration, glitches_per_min, np.random.default_rng([seed, 3]))
    events, table = resolve_faults(
        faults + glitches,
        duration=duration,
        dt=sc.dt,
        sensor_channels=sensor_channels,
        imu_default=sc.imu_default,
        sensor_aliases=sensor_aliases(sc),
        actuators=sc.actuators,
        inputs=tuple(zip(sc.model.input_names, sc.input_channels)),
        state_names=sc.model.state_names,
        estimator_fields={s: f"/ekf/variance/{s}" for s in sc.model.state_names},
        rng=np.random.default_rng([seed, 2]),
    )
    events, transients = events[: len(faults)], events[len(faults) :]
    # cov-corruption's channels name the logged variance; state-corruption the logged state
    events = [
        e
        if e.kind != "state-corruption"
        else replace(e, channels=tuple(c.replace("/ekf/variance/", "/ekf/state/") for c in e.channels))
        for e in events
    ]
    return events, transients, table


def _closed_loop(sc: Scenario, table: FaultTable, Q, W, E, base, slope, std) -> tuple:
    """The closed-loop kernel (`logscan.simulate.runner.closed_loop`) on the scenario, its process
    noise W, sensor noise E (scaled by base + slope), nominal noise std and fault table."""
    model = sc.model
    g_m = np.array([len(g.fields) for g in sc.groups], dtype=np.int64)
    return closed_loop(
        model.model_id,
        model.param_vector(sc.dt),
        (sc.plant or model).param_vector(sc.dt),
        sc.dt,
        sc.x0.astype(np.float64),
        np.ascontiguousarray(sc.P0, dtype=np.float64),
        Q,
        W,
        E,
        base,
        slope,
        np.array([g.group_id for g in sc.groups], dtype=np.int64),
        g_m,
        np.concatenate([[0], np.cumsum(g_m)[:-1]]).astype(np.int64),
        np.array([g.ratio for g in sc.groups], dtype=np.int64),
        np.concatenate([g.range_lo for g in sc.groups]),
        np.concatenate([g.range_hi for g in sc.groups]),
        np.concatenate([g.wrap for g in sc.groups]).astype(np.bool_),
        np.square(std),
        sc.ctrl_id,
        sc.ctrl_params.astype(np.float64),
        sc.ctrl_state.astype(np.float64).copy(),
        np.ascontiguousarray(sc.reference),
        np.ascontiguousarray(sc.M, dtype=np.float64),
        np.ascontiguousarray(np.linalg.inv(sc.M)),
        sc.a_lo.astype(np.float64),
        sc.a_hi.astype(np.float64),
        np.ascontiguousarray(sc.a_trim, dtype=np.float64),
        table.kind,
        table.target,
        table.start,
        table.end,
        table.magnitude,
        table.uniform,
        table.bit,
        bool(sc.control_on_truth),
    )
