"""Per-model scenarios: sensor rates and channel names, actuators, controller, reference, start state.

A Scenario is everything the closed-loop kernel needs besides the random draws and the faults,
plus the naming that the log, the truth and the profile use:

 - quadcopter: accel + gyro at the grid rate (100 Hz), attitude 50 Hz, position 10 Hz; actuators
   motor1..motor4 through the model's mixer; figure-eight with a hover (``aggressive``: faster).
 - steer_by_wire: steering angle, yaw rate and lateral acceleration at the grid rate; one actuator
   (the steering motor torque); lane changes through a PD hand wheel and sliding-mode control.
 - dc_motor (Jackal-like UGV): left/right wheel encoders 20 Hz and GPS speed 10 Hz (a redundant
   speed group for A-TFM); PI speed control through constant-speed modes 0.4 .. 1.9 m/s, or the
   commanded-speed profile ``speed`` (`parse_speed`: constant, changes at given times, random).
   The speed sensors' noise grows with the speed (`SPEED_NOISE`). Its profile tolerates healthy
   sensor glitches (see `glitch_tolerance`).
 - hover_uav (the UBIKF paper's linearised hover quadcopter): position, velocity and attitude at the
   grid rate (100 Hz, a motion-capture system); actuators rotor1..rotor4 = the inputs F1..F4,
   thrust deviations from hover (faults act on the total thrust, `Scenario.a_trim`); hover for
   PAPER_SETTLE_S (5 s), then roll, pitch and yaw set-point excitation; the embedded profile
   carries every parameter, the intervals included.
 - ins (the IMU-driven inertial navigation model): no closed loop, the IMU is the model's input.
   A multirotor flies an open-loop reference (hover at 10 m, then minimum-jerk moves between random
   waypoints and holds, occasional yaw turns); the IMU at the grid rate (250 Hz) is derived from the
   truth, GNSS position and velocity 10 Hz, barometer 25 Hz, heading 10 Hz, attitude 50 Hz
   (`logscan.simulate.ins_sim`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

import logscan.simulate.controllers as ctl
from logscan.errors import UsageError, did_you_mean
from logscan.models import get_model
from logscan.models.base import Model
from logscan.simulate.faults import PAPER_SETTLE_S

DEFAULT_RATES = {"quadcopter": 100.0, "steer_by_wire": 100.0, "dc_motor": 20.0, "hover_uav": 100.0, "ins": 250.0}
SIMULATED_MODELS = tuple(DEFAULT_RATES)
DCM_MODES = (0.4, 0.7, 1.0, 1.3, 1.6, 1.9)  # m/s, the A-TFM thesis's trained modes
DCM_HOLD_S = 20.0
DCM_RANDOM_HOLD_S = (5.0, 20.0)  # `--speed random`: each speed held uniform 5 .. 20 s
DCM_MAX_SPEED = 2.0  # m/s: --speed values 0 .. 2.0 (the motor tops out near 2.06 m/s at 24 V)
# Speed-dependent sensor noise of the dc_motor speed sensors (--noise speed), group -> (base, k): a
# sample's noise std is base + k |v| at the true speed v (wheel slip and tick quantisation grow with
# the speed; a GPS speed with the distance covered between fixes). The encoders' noise grows faster
# than the GPS's, as in the thesis's Jackal data (its trained bounds, encoder / GPS: 0.04 / 0.11 at
# 0.4 m/s, 0.1 / 0.14 at 1.0 m/s). At 0.4 m/s: encoder 0.016, GPS 0.023; at 1.0: 0.034, 0.035; at
# 1.9: 0.061, 0.053. The profile (and the on-board EKF) then assume the worst case, the noise at the
# top mode (1.9 m/s): a fixed noise_std can only be sound at every speed if it is the largest.
SPEED_NOISE = {"encoder": (0.004, 0.03), "gps_speed": (0.015, 0.02)}
# --noise: "speed" (SPEED_NOISE, dc_motor only) or "constant" (the model's noise_std). Default: speed
# for the UGV scenarios (--speed given), constant for the mode cycle, whose logs stay consistent
# with the analysis filter's fixed noise (a fixed-R NIS alarms on speed-dependent noise at speed).
NOISE_KINDS = ("speed", "constant")

# model -> group -> (topic, field per output); groups not listed: ("/<group>", output names).
# Groups sharing a topic (same rate) are logged as one message, like an IMU's.
_SENSOR_TOPICS = {
    "quadcopter": {
        "accel": ("/imu", ("accel.x", "accel.y", "accel.z")),
        "gyro": ("/imu", ("gyro.x", "gyro.y", "gyro.z")),
        "position": ("/gps", ("position.x", "position.y", "position.z")),
        "attitude": ("/attitude", ("roll", "pitch", "yaw")),
    },
    "steer_by_wire": {
        "steering_angle": ("/steering", ("angle",)),
        "yaw_rate": ("/imu", ("yaw_rate",)),
        "lateral_accel": ("/imu", ("lateral_accel",)),
    },
    "dc_motor": {
        "encoder": ("/enc", ("left.v", "right.v")),
        "gps_speed": ("/gps", ("speed",)),
        "current": ("/motor", ("current",)),
    },
    "hover_uav": {
        "position": ("/mocap", ("position.x", "position.y", "position.z")),
        "velocity": ("/mocap", ("velocity.x", "velocity.y", "velocity.z")),
        "attitude": ("/mocap", ("roll", "pitch", "yaw")),
    },
    "ins": {
        "gnss_position": ("/gnss", ("position.north", "position.east", "position.down")),
        "gnss_velocity": ("/gnss", ("velocity.north", "velocity.east", "velocity.down")),
        "baro": ("/baro", ("altitude",)),
        "heading": ("/mag", ("heading",)),
        "attitude": ("/mocap", ("roll", "pitch", "yaw")),
    },
}
# model -> group -> sensor rate in Hz (None: the grid rate)
_SENSOR_RATES = {
    "quadcopter": {"accel": None, "gyro": None, "position": 10.0, "attitude": 50.0},
    "dc_motor": {"gps_speed": 10.0},
    "ins": {"gnss_position": 10.0, "gnss_velocity": 10.0, "baro": 25.0, "heading": 10.0, "attitude": 50.0},
}
# model -> groups of the model that the simulated vehicle has no sensor for
_UNSENSED = {"ins": frozenset({"odometry"})}  # a multirotor: no wheel or visual odometry
_IMU_DEFAULT = {
    "quadcopter": "accel.x",
    "steer_by_wire": "yaw_rate",
    "dc_motor": "encoder.v_left",
    "hover_uav": "attitude.roll",  # no IMU: the imu-* aliases fall on the roll output
    "ins": "accel.x",  # the IMU is the model's input; its channels are fault targets too
}
GLITCH_MAX_SAMPLES = 2  # a healthy glitch lasts one or two samples of one sensor (simulation._glitches)
NIS_WINDOW = 10  # updates per NIS window sum (the nis detector's default, written into the profile)
# e_s band width on the DC motor: its logged on-board state has float32 resolution (7 significant
# digits), and at a speed step the rounding alone moves e_s up to 24 s of its steady-state spread
# (60 healthy 180 s runs; none with unrounded logs); wheel-speed state corruption moves it > 800 s.
DCM_RHO_S = 32.0


@dataclass
class SensorGroup:
    """One measurement group as the simulator samples and logs it."""

    name: str
    group_id: int
    topic: str
    fields: tuple[str, ...]
    ratio: int  # samples every `ratio` grid steps
    rate_hz: float
    noise_std: np.ndarray
    range_lo: np.ndarray
    range_hi: np.ndarray
    wrap: np.ndarray

    @property
    def channels(self) -> list[str]:
        return [f"{self.topic}/{f}" for f in self.fields]

    outputs: tuple[str, ...] = ()
    # simulated noise std per channel: noise_base + noise_slope * |noise-free reading|
    # (None: noise_std, constant)
    noise_base: np.ndarray | None = None
    noise_slope: np.ndarray | None = None

    def sample_std(self, reading: float) -> np.ndarray:
        """Simulated noise std per channel at a noise-free reading (speed) ``reading``."""
        if self.noise_base is None or self.noise_slope is None:
            return self.noise_std
        return self.noise_base + self.noise_slope * abs(reading)

    def targets(self) -> list[str]:
        """Fault target names of the group's channels: the group (yaw_rate) when it has one,
        "<group>.<last part of the field>" (accel.x), or "<group>.<model output>"
        (encoder.v_left) when those would repeat."""
        if len(self.fields) == 1:
            return [self.name]
        short = [f"{self.name}.{f.split('.')[-1]}" for f in self.fields]
        if len(set(short)) == len(short):
            return short
        return [f"{self.name}.{o}" for o in self.outputs]


@dataclass
class Scenario:
    """A model's closed-loop setup on a grid of period dt."""

    model_name: str
    model: Model
    dt: float
    groups: list[SensorGroup]
    a_lo: np.ndarray  # the actuators' limits (the actuators themselves are the model's: `actuators`)
    a_hi: np.ndarray
    ctrl_id: int
    ctrl_params: np.ndarray
    ctrl_state: np.ndarray
    reference: np.ndarray  # (N, nr)
    x0: np.ndarray
    P0: np.ndarray
    imu_default: str
    input_channels: list[str]
    mode_channel: str | None = None
    mode_values: np.ndarray | None = None  # (N,) logged mode / set-point
    setpoints: dict[str, np.ndarray] = field(default_factory=dict)  # extra logged channels
    redundant: dict[str, dict[str, str]] = field(default_factory=dict)
    onboard_rate_hz: float = 50.0
    alarms: dict[str, float] = field(default_factory=dict)  # the profile's [alarms] table
    detectors: dict[str, dict] = field(default_factory=dict)  # the profile's [detectors.<name>] tables
    speed: str | None = None  # dc_motor's --speed as given (None: the mode cycle)
    noise: str = "constant"  # sensor noise: "speed" (SPEED_NOISE) or "constant"
    profile_params: dict | None = None  # the profile's [vehicle] params (None: those given)
    # the controller flies on the true state, not the on-board estimate (hover_uav: the UBIKF
    # paper's scenarios excite the vehicle open loop, so a sensor fault does not feed back into the
    # flight and shows in the log as itself)
    control_on_truth: bool = False
    controller_input: str = "on-board EKF estimate"  # what the truth says the vehicle flew on
    truth_extra: dict = field(default_factory=dict)  # extra entries of the truth document
    plant: Model | None = None  # the truth's model when off-nominal (`plant.draw_plant`), else `model`

    @property
    def actuators(self) -> list[str]:  # the model's (`Model.actuators`), as the observability verdict's
        return list(self.model.actuators().names)

    @property
    def M(self) -> np.ndarray:  # (n_inputs, A): inputs = M @ actuators
        return self.model.actuators().M

    @property
    def a_trim(self) -> np.ndarray:  # (A,) operating point (hover_uav: m g / 4): faults act on a_trim + a
        return self.model.actuators().trim


def input_channel(name: str) -> str:
    """Log channel of a model input: tau_x -> /cmd/tau.x, thrust -> /cmd/thrust."""
    if len(name) > 2 and name[-2] == "_" and name[-1] in "xyz":
        name = f"{name[:-2]}.{name[-1]}"
    return f"/cmd/{name}"


def glitch_tolerance(groups: list[SensorGroup]) -> tuple[dict[str, float], dict[str, dict]]:
    """([alarms], [detectors.*]) settings under which a healthy glitch (at most GLITCH_MAX_SAMPLES
    samples of one sensor) cannot raise an alarm, while a fault that lasts can:

     - ``[alarms] min_duration_s``: half a period longer than the time between a glitch's first
       and last sample on the slowest sensor (10 Hz GPS: 0.1 s -> 0.15 s), a floor under every
       statistic (e_x, e_v, e_s and the rejected-sample checks see a glitch for that long);
     - ``[detectors.nis] n_persist``: a glitch stays in every NIS window sum that contains it,
       NIS_WINDOW + L - 1 sums of its group and, in the overall test, NIS_WINDOW + span - 1 where
       span counts the overall updates between its first and last sample (3 for two GPS samples
       with a 20 Hz encoder between them): n_persist = NIS_WINDOW + span (13) exceeds both.
    """
    slowest = min(g.rate_hz for g in groups)
    fastest = max(g.rate_hz for g in groups)
    span = (GLITCH_MAX_SAMPLES - 1) * int(round(fastest / slowest)) + 1
    alarms = {"min_duration_s": round((GLITCH_MAX_SAMPLES - 0.5) / slowest, 6)}
    return alarms, {"nis": {"window": NIS_WINDOW, "n_persist": NIS_WINDOW + span}}


def prepare_scenario(
    model_name: str,
    duration: float,
    rate_hz: float | None,
    params: dict | None = None,
    speed: str | None = None,
    noise: str | None = None,
) -> tuple[Model, float, np.ndarray, list[SensorGroup], list[tuple[float, float]] | str | None, str]:
    """What every model's scenario starts from: (model, dt, t, sensor groups, the parsed ``speed``,
    the resolved ``noise``), the arguments checked (UsageError); see `dispatch.build_scenario`."""
    if model_name not in SIMULATED_MODELS:
        raise UsageError(
            f"cannot simulate model {model_name!r}",
            hint=did_you_mean(model_name, SIMULATED_MODELS) + "simulated models: " + ", ".join(SIMULATED_MODELS),
        )
    changes = check_speed(model_name, speed, duration)
    noise = resolve_noise(model_name, noise, speed)
    rate = float(rate_hz or DEFAULT_RATES[model_name])
    if not (1.0 <= rate <= 10000.0):
        raise UsageError(f"--rate {rate:g} Hz is out of range", hint="use 1 .. 10000 Hz")
    dt = 1.0 / rate
    model = get_model(model_name, params)
    n_steps = int(round(duration / dt)) + 1
    t = np.arange(n_steps) * dt
    groups = _sensor_groups(model_name, model, rate, noise)
    return model, dt, t, groups, changes, noise


def closed_loop_scenario(
    model_name: str,
    duration: float,
    rate_hz: float | None,
    aggressive: bool,
    rng: np.random.Generator,
    params: dict | None = None,
    speed: str | None = None,
    noise: str | None = None,
) -> Scenario:
    """The scenario of a closed-loop model (all but ins, whose scenario is `ins_sim.ins_scenario`;
    `logscan.simulate.dispatch.build_scenario` picks the builder of any model)."""
    model, dt, t, groups, changes, noise = prepare_scenario(model_name, duration, rate_hz, params, speed, noise)
    if model_name == "dc_motor":
        sc = _dc_motor(model, dt, t, groups, aggressive, rng, changes)
        sc.speed, sc.noise = speed, noise
        return sc
    builder = {"quadcopter": _quadcopter, "steer_by_wire": _steer_by_wire, "hover_uav": _hover_uav}
    if model_name not in builder:
        raise ValueError(f"{model_name} has no closed-loop scenario: use logscan.simulate.dispatch.build_scenario")
    return builder[model_name](model, dt, t, groups, aggressive, rng)


def check_speed(model_name: str, speed: str | None, duration: float) -> list[tuple[float, float]] | str | None:
    """`parse_speed` of ``speed`` for ``model_name`` (None: no --speed); UsageError unless dc_motor."""
    if speed is None or model_name not in SIMULATED_MODELS:
        return None
    if model_name != "dc_motor":
        raise UsageError(f"--speed is for dc_motor, not {model_name}", hint="drop --speed or simulate dc_motor")
    return parse_speed(speed, duration)


def resolve_noise(model_name: str, noise: str | None, speed: str | None) -> str:
    """``--noise`` (None: its default, see NOISE_KINDS); UsageError on an unknown kind or speed
    noise on a model other than dc_motor."""
    if noise is None:
        return "speed" if model_name == "dc_motor" and speed is not None else "constant"
    if noise not in NOISE_KINDS:
        raise UsageError(f"--noise {noise!r} is unknown", hint="choose " + " or ".join(NOISE_KINDS))
    if noise == "speed" and model_name != "dc_motor":
        raise UsageError(f"--noise speed is for dc_motor, not {model_name}", hint="drop --noise")
    return noise


def parse_speed(text: str, duration: float) -> list[tuple[float, float]] | str:
    """``--speed`` of dc_motor: ``0.7`` (constant), ``1.0,0.4@30`` (1.0 m/s, then 0.4 from t = 30 s;
    any number of ``v@t`` with increasing times inside the log) -> [(t, v), ...] starting at t = 0;
    ``random`` -> "random" (`controllers.dcm_random_reference`). Raises UsageError on anything else."""
    spec = text.strip().lower()
    if spec == "random":
        return "random"
    hint = "use a speed (0.7), speed changes (1.0,0.4@30) or random; speeds 0 .. 2 m/s"
    changes: list[tuple[float, float]] = []
    for i, part in enumerate(spec.split(",")):
        value, at, when = part.partition("@")
        try:
            v = float(value)
            t = float(when) if at else 0.0
        except ValueError:
            raise UsageError(f"--speed {text!r} is not a speed profile", hint=hint) from None
        if i == 0 and at:
            raise UsageError(f"--speed {text!r}: the first speed holds from 0 s, give it without @", hint=hint)
        if i > 0 and not at:
            raise UsageError(f"--speed {text!r}: every speed after the first needs its start time (v@t)", hint=hint)
        if not (0.0 <= v <= DCM_MAX_SPEED):
            raise UsageError(f"--speed {text!r}: speed {v:g} m/s is out of range", hint=hint)
        if i > 0 and not (changes[-1][0] < t < duration):
            raise UsageError(
                f"--speed {text!r}: change at {t:g} s is not after the previous one and inside the log "
                f"(0 .. {duration:g} s)",
                hint="give increasing times within --duration",
            )
        changes.append((t, v))
    return changes


def _sensor_groups(model_name: str, model: Model, rate: float, noise: str = "constant") -> list[SensorGroup]:
    out = []
    for spec in sorted(model.groups.values(), key=lambda g: g.group_id):
        if spec.name in _UNSENSED.get(model_name, ()):
            continue
        topic, fields = _SENSOR_TOPICS.get(model_name, {}).get(spec.name, (f"/{spec.name}", spec.outputs))
        sensor_rate = _SENSOR_RATES.get(model_name, {}).get(spec.name) or rate
        ratio = max(1, int(round(rate / min(sensor_rate, rate))))
        speed = _speed_noise(spec.name, len(fields)) if noise == "speed" else {}
        out.append(
            SensorGroup(
                name=spec.name,
                group_id=spec.group_id,
                topic=topic,
                fields=tuple(fields),
                ratio=ratio,
                rate_hz=rate / ratio,
                noise_std=np.asarray(speed.pop("noise_std", spec.noise_std), dtype=np.float64),
                range_lo=np.asarray(spec.range_lo, dtype=np.float64),
                range_hi=np.asarray(spec.range_hi, dtype=np.float64),
                wrap=spec.wrap_mask(),
                outputs=tuple(spec.outputs),
                **speed,
            )
        )
    return out


def _speed_noise(group: str, m: int) -> dict[str, np.ndarray]:
    """SensorGroup noise_base / noise_slope of a speed sensor (empty: constant noise_std)."""
    if group not in SPEED_NOISE:
        return {}
    base, slope = SPEED_NOISE[group]
    worst = base + slope * max(DCM_MODES)  # what the profile and the on-board EKF assume
    return {"noise_base": np.full(m, base), "noise_slope": np.full(m, slope), "noise_std": np.full(m, worst)}


def _quadcopter(model, dt, t, groups, aggressive, rng) -> Scenario:
    ref = ctl.quad_reference(t, aggressive)
    x0 = np.zeros(12)
    x0[:3] = ref[0, :3]
    hover_motor = model.p["mass"] * model.p["g"] / 4.0
    mode = np.where(np.abs(ref[:, 3:6]).sum(axis=1) > 1e-9, 1.0, 0.0)  # 0 hover, 1 figure-eight
    return Scenario(
        model_name="quadcopter",
        model=model,
        dt=dt,
        groups=groups,
        a_lo=np.zeros(4),
        a_hi=np.full(4, 2.5 * hover_motor),
        ctrl_id=ctl.QUAD_CTRL,
        ctrl_params=ctl.quad_params(model, aggressive),
        ctrl_state=np.zeros(1),
        reference=ref,
        x0=x0,
        P0=np.diag(np.square(0.1 * model.state_scale())),
        imu_default=_IMU_DEFAULT["quadcopter"],
        input_channels=[input_channel(n) for n in model.input_names],
        mode_channel="/flight_mode/mode",
        mode_values=mode,
        setpoints={
            "/setpoint/position.x": ref[:, 0],
            "/setpoint/position.y": ref[:, 1],
            "/setpoint/position.z": ref[:, 2],
            "/setpoint/yaw": ref[:, 9],
        },
        onboard_rate_hz=min(50.0, 1.0 / dt),
    )


def _steer_by_wire(model, dt, t, groups, aggressive, rng) -> Scenario:
    cp = ctl.sbw_params(model)
    ref = ctl.sbw_reference(t, cp[8], aggressive)
    limit = float(model.p.get("tau_max", 200.0))
    return Scenario(
        model_name="steer_by_wire",
        model=model,
        dt=dt,
        groups=groups,
        a_lo=np.array([-limit]),
        a_hi=np.array([limit]),
        ctrl_id=ctl.SBW_CTRL,
        ctrl_params=cp,
        ctrl_state=np.zeros(2),
        reference=ref,
        x0=np.zeros(4),
        P0=np.diag(np.square(0.1 * model.state_scale())),
        imu_default=_IMU_DEFAULT["steer_by_wire"],
        input_channels=[input_channel(n) for n in model.input_names],
        mode_channel="/handwheel/reference",
        mode_values=ref[:, 0],
        onboard_rate_hz=min(50.0, 1.0 / dt),
    )


def _dc_motor(model, dt, t, groups, aggressive, rng, changes=None) -> Scenario:
    if changes is None:
        ref = ctl.dcm_reference(t, DCM_MODES, DCM_HOLD_S / (2.0 if aggressive else 1.0), rng)
    elif changes == "random":
        ref = ctl.dcm_random_reference(t, DCM_MODES, DCM_RANDOM_HOLD_S, rng)
    else:
        ref = ctl.dcm_steps_reference(t, changes)
    supply = float(model.p["Va"])
    radius = float(model.p["wheel_radius"])
    # feed-forward: the steady-state voltage per m/s of the exactly discretised model
    ff = supply / (radius * model.steady_state(supply)[1])
    cp = np.array([20.0, 40.0, -supply, supply, 1.0, 1.0, radius, ff])
    x0 = model.steady_state(ff * ref[0, 0])
    names = {g.name: g for g in groups}
    enc, gps = names["encoder"].channels, names["gps_speed"].channels
    alarms, detectors = glitch_tolerance(groups)
    return Scenario(
        model_name="dc_motor",
        model=model,
        dt=dt,
        groups=groups,
        a_lo=np.array([-supply]),
        a_hi=np.array([supply]),
        ctrl_id=ctl.DCM_CTRL,
        ctrl_params=cp,
        ctrl_state=np.zeros(1),
        reference=ref,
        x0=x0,
        P0=np.diag(np.square(0.1 * model.state_scale())),
        imu_default=_IMU_DEFAULT["dc_motor"],
        input_channels=[input_channel(n) for n in model.input_names],
        mode_channel="/cmd_vel/linear.x",
        mode_values=ref[:, 0],
        redundant={"speed": {"left": enc[0], "right": enc[1], "gps": gps[0]}},
        onboard_rate_hz=1.0 / dt,
        alarms=alarms,
        detectors={**detectors, "encoded_ekf": {"rho_s": DCM_RHO_S}},
    )


def _hover_uav(model, dt, t, groups, aggressive, rng) -> Scenario:
    ref = ctl.hover_reference(t, aggressive, PAPER_SETTLE_S)
    hover = model.hover_thrust()
    return Scenario(
        model_name="hover_uav",
        model=model,
        dt=dt,
        groups=groups,
        a_lo=np.full(4, -hover),  # a rotor cannot pull down: total thrust >= 0
        a_hi=np.full(4, 1.5 * hover),  # total <= 2.5 x hover, as the quadcopter's motors
        ctrl_id=ctl.HOVER_CTRL,
        ctrl_params=ctl.hover_params(model, aggressive),
        ctrl_state=np.zeros(3),
        reference=ref,
        x0=np.zeros(12),
        P0=np.diag(np.square(0.1 * model.state_scale())),
        imu_default=_IMU_DEFAULT["hover_uav"],
        input_channels=[input_channel(n) for n in model.input_names],
        mode_channel="/flight_mode/mode",
        mode_values=np.where(t >= PAPER_SETTLE_S, 1.0, 0.0),  # 0 hover, 1 attitude excitation
        setpoints={
            "/setpoint/roll": ref[:, 3],
            "/setpoint/pitch": ref[:, 4],
            "/setpoint/yaw": ref[:, 5],
        },
        onboard_rate_hz=min(50.0, 1.0 / dt),
        profile_params=dict(model.p),
        control_on_truth=True,
    )
