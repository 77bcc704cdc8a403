"""`logscan simulate ground_robot`: the hierarchical ground robot of "Checkpointing and roll-forward
recovery of state estimates in nonlinear, hierarchical cyber-physical systems" (section 6.3,
appendix A.6.1), with the corrections of docs/algorithms.md section 5.

Loops (each with its own on-board filter, whose estimate its controller uses, so an attack
corrupts the applied inputs as in the paper):
 - outer, 10 Hz, model `unicycle` (x, y, theta): mocap (x, y, theta; noise 0.1; theta logged
   wrapped to [-pi, pi)); EKF with Q = R = 0.1^2 I; the dynamic-inversion controller (eq. 25,
   l = 0.5, k1 = 3.3, k2 = 4.4) tracks the circle x_ref = [2 cos t, 2 sin t] (eq. 35, t in s)
   and sends the wheel-speed references of eq. 39 (Rw = 0.05 m, Lw = 0.5 m; left = (2v - w Lw) /
   (2 Rw), right = (2v + w Lw) / (2 Rw));
 - left_motor and right_motor, 100 Hz, model `linear` (states i, w; input V): the DC motor of
   eq. 26, discretised by Euler with the "x_k +" the print omits (A_d = I + A dt, B_d = B dt;
   R 1, L 0.5, K_tor = K_emf = K_fric = 0.01, J 0.01); encoder (w, noise 1 rad/s); KF with
   Q = diag(0.1^2, 0.5^2), R = 1 (the paper's 50^2 corrected); PID on the estimated wheel-speed
   error (Kp 13.2, Ki 1.525, Kd 0.275; the derivative of the error, as the paper writes it, so
   each 10 Hz jump of the reference kicks the voltage: healthy peaks of 1-2 kV; no voltage limit,
   as in the paper). The run starts on the circle at (2, 0) heading pi / 2, each motor at the
   steady state of its first reference with its PID integrator holding that voltage.
The plant obeys the on-board models exactly, with their process noise. Coupling (`coupling`):
 - "commanded" (default): the unicycle moves with the outer loop's commanded (v, w), its state
   advancing once per outer step by the model's own Euler step (the paper's eq. 23, whose input is
   the controller's u^o); the motors track their references beside it. Simplified on purpose:
   with the robot driven by the motors' actual wheel speeds (v = Rw (w_r + w_l) / 2,
   w = Rw (w_r - w_l) / Lw), the paper's PID loops are too slow for the outer loop (a closed-loop
   natural frequency of ~5 rad/s, damping ~0.33, 7 % offset before the slow integrator) and the
   healthy robot leaves the circle (RMS tracking error over 15 s, seeds 1-20: 6.5 m, 2.9-12.7 m,
   against 0.30 m, 0.25-0.35 m, with the commanded coupling);
 - "wheels": that coupled plant (unicycle Euler steps at 100 Hz with the wheel speeds), kept for
   study; not the CLI's.

Input timing (the recovery engine relies on it): an input u_k is computed at t_k from the estimate
of step k and applied over [t_k, t_{k+1}); x_{k+1} = f(x_k, u_k) + w_k. It is logged with the
timestamp t_k at which it starts to apply (outer (v, w) and wheel references at the outer steps,
voltages at every inner step). The on-board filters predict step k with u_{k-1}. Note this is one
step later than the convention of logscan's other simulators and EKF kernel (`x_k = f(x_{k-1},
u_k)`, the input logged at t_k driving the step that ends at t_k).

Scenarios: "paper": +[5, 5, 0] on the mocap (x, y, theta) and +20000 rad/s on both encoders for
t in [3.25, 5) s, the negatives for t in [8.25, 10) s, 15 s long; "random": 1-3 anomalies (from
the seed) of 0.5-2.5 s, each on a random non-empty set of the three groups, with random signs
and magnitudes (mocap x, y 2-8 m each, theta 0 as in the paper; encoders 5000-30000 rad/s);
"healthy": none. Truth events (kind "bias", the repo's step offset) are one per attacked group,
its target the group named per loop: "mocap" (the outer, primary loop's group, named as in a
single-loop profile), "left_motor.encoder", "right_motor.encoder".
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from logscan.errors import UsageError
from logscan.models import get_model
from logscan.numba_cache import follow_dependencies
from logscan.profiles import dumps_toml
from logscan.results import FaultEvent
from logscan.simulate.ground_robot_kernels import RobotParams, robot_loop, wheel_references
from logscan.simulate.simulation import TRUTH_SCHEMA, Series

SCENARIOS = ("paper", "random", "healthy")
COUPLINGS = ("commanded", "wheels")
DT = 0.01  # inner period (100 Hz)
RATIO = 10  # inner steps per outer step (10 Hz)
PAPER_DURATION_S = 15.0
# DC motor (eq. 26): R, L, K_tor = K_emf = K_fric, J
MOTOR = {"R": 1.0, "L": 0.5, "K": 0.01, "J": 0.01}
MOTOR_Q = (0.01, 0.25)  # per 10 ms step: current 0.1^2 (A^2), speed 0.5^2 ((rad/s)^2)
ENCODER_STD = 1.0  # rad/s
MOCAP_STD = 0.1
PID = {"Kp": 13.2, "Ki": 1.525, "Kd": 0.275}
CONTROL = {"radius": 2.0, "l": 0.5, "k1": 3.3, "k2": 4.4, "Rw": 0.05, "Lw": 0.5}
PAPER_ATTACKS = ((3.25, 5.0, 1.0), (8.25, 10.0, -1.0))  # (start, end, sign)
PAPER_MOCAP_OFFSET = (5.0, 5.0, 0.0)
PAPER_ENCODER_OFFSET = 20000.0
RANDOM_LENGTH_S = (0.5, 2.5)
RANDOM_MOCAP_M = (2.0, 8.0)
RANDOM_ENCODER = (5000.0, 30000.0)
MOTORS = ("left_motor", "right_motor")
SIDES = ("left", "right")
MOCAP_FIELDS = ("x", "y", "theta")
MOCAP_GROUPS = {"position": (0, 1), "heading": (2,)}
OUTER_DETECTORS = {
    "nis": {"enabled": True}
}  # the outer loop's [detectors]  # the profile's groups of the mocap's fields
# the motors' on-board estimates are logged at 50 Hz (as the other simulators log their on-board
# estimator), so that a 15 s sample log stays under 300 kB
ONBOARD_RATIO = 2
OUTER_CHANNELS = {"v": "/cmd/outer.v", "w": "/cmd/outer.w"}


def motor_matrices(dt: float = DT) -> tuple[np.ndarray, np.ndarray]:
    """(A_d, B_d) of the DC motor: A_d = I + A dt, B_d = B dt (eq. 26 with "x_k +"), with
    A = [[-R/L, -K_emf/L], [K_tor/J, -K_fric/J]], B = [1/L, 0]^T."""
    R, L, K, J = MOTOR["R"], MOTOR["L"], MOTOR["K"], MOTOR["J"]
    A = np.array([[-R / L, -K / L], [K / J, -K / J]])
    B = np.array([1.0 / L, 0.0])
    return np.eye(2) + A * dt, B * dt


def motor_params() -> dict:
    """The `linear` model's params of one motor loop (discrete matrices at 100 Hz), its prior covering
    a motor already turning (`initial_state`; P0 = I put the current 35-45 sigma off: alarms)."""
    Ad, Bd = motor_matrices()
    return {
        "A": Ad.tolist(),
        "B": Bd.reshape(2, 1).tolist(),
        "C": {"encoder": [[0.0, 1.0]]},
        "Q": np.diag(MOTOR_Q).tolist(),
        "R": {"encoder": [ENCODER_STD]},
        "continuous": False,
        "dt": DT,
        "states": ["i", "w"],
        "inputs": ["V"],
        "outputs": {"encoder": ["w"]},
        "x0": [0.0, 0.0],
        "P0": (np.abs(initial_state()[1]).max() ** 2 * np.eye(2)).tolist(),  # spread: the larger speed
    }


# ---- attacks -------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Attack:
    """Offsets added to the readings of some groups over [start, end) s: group target -> offsets
    (mocap: 3, an encoder: 1)."""

    start: float
    end: float
    offsets: dict[str, tuple[float, ...]]


def group_targets() -> dict[str, tuple[str, ...]]:
    """Fault target of each group -> its channels."""
    return {
        "mocap": tuple(f"/mocap/{f}" for f in MOCAP_FIELDS),
        **{f"{m}.encoder": (f"/enc/{s}.w",) for m, s in zip(MOTORS, SIDES)},
    }


def paper_attacks() -> list[Attack]:
    """The paper's two anomalies (section 6.3): all three groups at once."""
    return [
        Attack(
            start,
            end,
            {
                "mocap": tuple(sign * v for v in PAPER_MOCAP_OFFSET),
                **{f"{m}.encoder": (sign * PAPER_ENCODER_OFFSET,) for m in MOTORS},
            },
        )
        for start, end, sign in PAPER_ATTACKS
    ]


def random_attacks(duration: float, rng: np.random.Generator) -> list[Attack]:
    """1-3 anomalies of 0.5-2.5 s, apart, after the first second; each on a random non-empty set
    of the groups with random signs and magnitudes. A loop over the anomalies."""
    count = int(rng.integers(1, 4))
    lengths = rng.uniform(*RANDOM_LENGTH_S, size=count)
    # onsets: the free time (at least 0.5 s between anomalies) split at random points
    free = duration - 1.0 - lengths.sum() - 0.5 * count
    if free <= 0:
        raise UsageError(
            f"--duration {duration:g} s is too short for random anomalies", hint="use --duration 10 or more"
        )
    gaps = np.diff(np.concatenate([[0.0], np.sort(rng.uniform(0.0, free, size=count))]))
    targets = list(group_targets())
    out, t = [], 1.0
    for length, gap in zip(lengths.tolist(), gaps.tolist()):
        start = round(t + gap, 2)
        end = round(start + length, 2)
        chosen = [g for g in targets if rng.random() < 0.5] or [targets[int(rng.integers(len(targets)))]]
        offsets = {}
        for g in chosen:
            if g == "mocap":
                xy = rng.uniform(*RANDOM_MOCAP_M, size=2) * rng.choice([-1.0, 1.0], size=2)
                offsets[g] = (round(float(xy[0]), 3), round(float(xy[1]), 3), 0.0)
            else:
                offsets[g] = (round(float(rng.uniform(*RANDOM_ENCODER) * rng.choice([-1.0, 1.0])), 1),)
        out.append(Attack(start, end, offsets))
        t = end + 0.5
    return out


def attack_offsets(attacks: list[Attack], t_outer: np.ndarray, t_inner: np.ndarray):
    """(A_o (No, 3), A_m (N, 2)): the offsets added to each mocap and encoder sample (a sample at
    t is attacked when start <= t < end; vectorised per anomaly)."""
    A_o = np.zeros((t_outer.size, 3))
    A_m = np.zeros((t_inner.size, 2))
    eps = 1e-9  # grid times are k * dt in floating point
    for a in attacks:
        on_o = (t_outer >= a.start - eps) & (t_outer < a.end - eps)
        on_m = (t_inner >= a.start - eps) & (t_inner < a.end - eps)
        if "mocap" in a.offsets:
            A_o[on_o] += np.array(a.offsets["mocap"])
        for j, m in enumerate(MOTORS):
            if f"{m}.encoder" in a.offsets:
                A_m[on_m, j] += a.offsets[f"{m}.encoder"][0]
    return A_o, A_m


def truth_events(attacks: list[Attack]) -> list[FaultEvent]:
    """One "bias" event per attacked measurement group of the profile (the mocap's offsets split
    into its `position` (x, y) and `heading` (theta) groups); magnitude: its largest offset
    (signed), channels: the channels with a non-zero offset."""
    channels = group_targets()
    events = []
    for a in attacks:
        for target, offsets in a.offsets.items():
            parts = MOCAP_GROUPS.items() if target == "mocap" else [(target, range(len(offsets)))]
            for group, columns in parts:
                values = [offsets[i] for i in columns]
                hit = tuple(channels[target][i] for i in columns if offsets[i] != 0.0)
                if hit:
                    events.append(FaultEvent(a.start, a.end, "bias", group, float(max(values, key=abs)), hit))
    return events


# ---- one run -------------------------------------------------------------------------------------


@dataclass
class GroundRobotSimulation:
    """One run: every array on its loop's grid (outer: No steps of 0.1 s; inner: N of 0.01 s).
    `write_simulation` writes it like a `Simulation` (dt, n_steps, series, truth, profile_toml)."""

    scenario: str
    seed: int
    duration: float
    coupling: str
    attacks: list[Attack]
    events: list[FaultEvent]
    x_true: np.ndarray  # (No, 3) true unicycle state at the outer steps
    m_true: np.ndarray  # (N, 2, 2) true [i, w] of the left and right motor
    u_outer: np.ndarray  # (No, 2) commanded (v, w), applied over [t_k, t_k + 0.1)
    w_ref: np.ndarray  # (No, 2) left, right wheel-speed references
    voltage: np.ndarray  # (N, 2) applied voltages, over [t_k, t_k + 0.01)
    z_mocap: np.ndarray  # (No, 3) logged mocap (attacks included; theta wrapped)
    z_enc: np.ndarray  # (N, 2) logged encoders
    x_hat: np.ndarray  # (No, 3) on-board outer EKF posterior
    P_hat: np.ndarray  # (No, 3) its variance
    m_hat: np.ndarray  # (N, 2, 2) on-board motor KF posteriors
    m_P: np.ndarray  # (N, 2, 2) their variances
    elapsed_s: float
    transients: list[FaultEvent] = field(default_factory=list)

    dt = DT
    ratio = RATIO

    @property
    def n_steps(self) -> int:
        return int(self.m_true.shape[0])

    @property
    def t(self) -> np.ndarray:
        return np.arange(self.n_steps) * DT

    @property
    def t_outer(self) -> np.ndarray:
        return np.arange(self.x_true.shape[0]) * DT * RATIO

    def series(self) -> list[Series]:
        """Every logged topic with its grid (100 Hz) step indices."""
        every = np.arange(self.n_steps, dtype=np.int64)
        outer = every[::RATIO][: self.x_true.shape[0]]
        onboard = every[::ONBOARD_RATIO]
        out = [
            Series("/cmd", "logscan/Command", outer, {"outer.v": self.u_outer[:, 0], "outer.w": self.u_outer[:, 1]}),
            Series("/wheel_ref", "logscan/Setpoint", outer, {s: self.w_ref[:, j] for j, s in enumerate(SIDES)}),
            Series(
                "/motor_cmd",
                "logscan/Command",
                every,
                {f"{s}.voltage": self.voltage[:, j] for j, s in enumerate(SIDES)},
            ),
            Series("/mocap", "logscan/Mocap", outer, {f: self.z_mocap[:, i] for i, f in enumerate(MOCAP_FIELDS)}),
            Series("/enc", "logscan/Enc", every, {f"{s}.w": self.z_enc[:, j] for j, s in enumerate(SIDES)}),
            Series("/ekf/state", "logscan/EstimatorState", outer, _fields(MOCAP_FIELDS, self.x_hat)),
            Series("/ekf/variance", "logscan/EstimatorVariance", outer, _fields(MOCAP_FIELDS, self.P_hat)),
            Series("/truth/state", "logscan/TruthState", outer, _fields(MOCAP_FIELDS, self.x_true)),
        ]
        for j, m in enumerate(MOTORS):  # a motor's estimate and variance in one message (a sample log stays small)
            fields = {
                **_fields(("state.i", "state.w"), self.m_hat[:, j]),
                **_fields(("variance.i", "variance.w"), self.m_P[:, j]),
            }
            out.append(
                Series(f"/ekf/{m}", "logscan/EstimatorState", onboard, {k: v[onboard] for k, v in fields.items()})
            )
        truth = {f"{m}.{s}": self.m_true[:, j, i] for j, m in enumerate(MOTORS) for i, s in enumerate(("i", "w"))}
        out.append(Series("/truth/motors", "logscan/TruthState", every, truth))
        return out

    def truth(self) -> dict:
        """The ground-truth document (`logscan.truth`): the events, per loop its true-state topic
        and rate, the attacks' offsets per channel and the input timing."""
        channels = group_targets()
        return {
            "schema": TRUTH_SCHEMA,
            "generator": "logscan simulate",
            "model": "ground_robot",
            "scenario": self.scenario,
            "seed": self.seed,
            "duration_s": self.duration,
            "rate_hz": 1.0 / DT,
            "aggressive": False,
            "controller_input": "on-board estimate of each loop (outer EKF, motor KFs)",
            "coupling": self.coupling,
            "input_timing": "u_k applied over [t_k, t_k+1): x_k+1 = f(x_k, u_k); logged at t_k",
            "events": [e.to_truth() for e in self.events],
            "transients": [],
            "true_state_topic": "/truth/state",
            "true_state_fields": list(MOCAP_FIELDS),
            "loops": {
                "outer": {
                    "rate_hz": 1.0 / (DT * RATIO),
                    "true_state_channels": [f"/truth/state/{f}" for f in MOCAP_FIELDS],
                },
                **{
                    m: {"rate_hz": 1.0 / DT, "true_state_channels": [f"/truth/motors/{m}.i", f"/truth/motors/{m}.w"]}
                    for m in MOTORS
                },
            },
            "attack_offsets": [
                {
                    "start": a.start,
                    "end": a.end,
                    "offsets": {ch: v for g, o in a.offsets.items() for ch, v in zip(channels[g], o)},
                }
                for a in self.attacks
            ],
            "onboard_rejected_samples": 0,
        }

    def profile_dict(self) -> dict:
        """The hierarchical profile: the outer loop as a single-model profile, each motor loop
        under [loops.<name>] with the same keys."""
        return {
            "name": "simulated ground_robot",
            "description": "written by `logscan simulate ground_robot`; channels as logged",
            "vehicle": {"model": "unicycle", "rate_hz": 1.0 / (DT * RATIO), "loop": "outer"},
            # u_k is logged at t_k and applied over [t_k, t_k+1): held from the filter's next step
            "inputs": {**OUTER_CHANNELS, "stamp": "start"},
            "measurements": {
                group: {
                    "channels": [f"/mocap/{MOCAP_FIELDS[i]}" for i in columns],
                    "rate_hz": 1.0 / (DT * RATIO),
                    "stale_s": 2.5 * DT * RATIO,
                    "noise_std": [MOCAP_STD] * len(columns),
                }
                for group, columns in MOCAP_GROUPS.items()
            },
            "onboard": {"state": "/ekf/state", "variance": "/ekf/variance"},
            # a 15 s log at 10 Hz is too short for the encoded checks' windows: NIS alone outside
            "detectors": OUTER_DETECTORS,
            # what the estimator should have believed during each anomaly (logscan.recovery), driven
            # by the outer loop's detector (per sensor group: a specific detector)
            "recovery": {"detector": next(iter(OUTER_DETECTORS)), "allowed_error": {"outer.x": 1.0, "outer.y": 1.0}},
            "loops": {
                m: {
                    "vehicle": {"model": "linear", "rate_hz": 1.0 / DT, "params": motor_params()},
                    "inputs": {"V": f"/motor_cmd/{s}.voltage", "stamp": "start"},
                    "measurements": {
                        "encoder": {
                            "channels": [f"/enc/{s}.w"],
                            "rate_hz": 1.0 / DT,
                            "stale_s": 2.5 * DT,
                            "noise_std": [ENCODER_STD],
                        }
                    },
                }
                for m, s in zip(MOTORS, SIDES)
            },
        }

    def profile_toml(self) -> str:
        return dumps_toml(self.profile_dict())


def _fields(names, values: np.ndarray) -> dict[str, np.ndarray]:
    return {name: values[:, i] for i, name in enumerate(names)}


def initial_state() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x0, motors (2, 2), PID integrators (2,)): the robot on the circle at (2, 0) heading along
    it (pi / 2); each motor at the steady state of its first reference (2 m/s, 1 rad/s), the PID
    integrator holding that voltage, so the run starts in equilibrium."""
    Ad, Bd = motor_matrices()
    # steady state: x = Ad x + Bd V -> x = (I - Ad)^-1 Bd V
    gain = np.linalg.solve(np.eye(2) - Ad, Bd)
    p = _params("commanded")
    refs = wheel_references(CONTROL["radius"], 1.0, p)
    m0 = np.array([gain * (w / gain[1]) for w in refs])
    integ0 = np.array([w / gain[1] / PID["Ki"] for w in refs])
    return np.array([CONTROL["radius"], 0.0, np.pi / 2.0]), m0, integ0


def _params(coupling: str) -> RobotParams:
    c = CONTROL
    return RobotParams(
        DT, float(RATIO), c["radius"], c["l"], c["k1"], c["k2"], c["Rw"], c["Lw"],
        PID["Kp"], PID["Ki"], PID["Kd"], np.inf, MOCAP_STD, ENCODER_STD, float(coupling == "wheels"),
    )  # fmt: skip


def check_ground_robot_options(faults, rate_hz, aggressive, glitches_per_min, speed, noise) -> None:
    """UsageError for an option the ground robot does not take (its anomalies come from
    --scenario, its rates are the paper's)."""
    given = {
        "--fault": bool(faults),
        "--rate": rate_hz is not None,
        "--aggressive": aggressive,
        "--glitches": glitches_per_min > 0,
        "--speed": speed is not None,
        "--noise": noise is not None,
    }
    for option, used in given.items():
        if used:
            raise UsageError(
                f"{option} does not apply to ground_robot",
                hint="its anomalies come from --scenario paper|random|healthy (with --seed); "
                "its loops run at 10 and 100 Hz",
            )


def scenario_attacks(scenario: str, duration: float, rng: np.random.Generator) -> list[Attack]:
    """The anomalies of ``scenario``; the paper's cut at the end of a shorter log."""
    if scenario == "paper":
        return [Attack(a.start, min(a.end, duration), a.offsets) for a in paper_attacks() if a.start < duration]
    if scenario == "random":
        return random_attacks(duration, rng)
    if scenario == "healthy":
        return []
    raise UsageError(f"unknown ground_robot scenario {scenario!r}", hint="choose " + ", ".join(SCENARIOS))


def simulate_ground_robot(
    scenario: str = "paper",
    *,
    duration: float = PAPER_DURATION_S,
    seed: int = 0,
    coupling: str = "commanded",
    process_noise: bool = True,
) -> GroundRobotSimulation:
    """One run of ``scenario`` (see the module docstring), deterministic in ``seed``.
    ``process_noise`` False: the plant without its process noise (the sensors keep theirs), for
    checking the input timing."""
    if coupling not in COUPLINGS:
        raise UsageError(f"unknown coupling {coupling!r}", hint="choose " + " or ".join(COUPLINGS))
    if not (1.0 <= duration <= 3600.0):
        raise UsageError(f"--duration {duration:g} s is out of range for ground_robot", hint="use 1 .. 3600 s")
    if seed < 0:
        raise UsageError(f"--seed {seed} is negative", hint="use a seed >= 0")
    attacks = scenario_attacks(scenario, duration, np.random.default_rng([seed, 2]))
    rng = np.random.default_rng(seed)
    n_outer = int(round(duration / (DT * RATIO)))
    N = n_outer * RATIO
    t_outer, t_inner = np.arange(n_outer) * DT * RATIO, np.arange(N) * DT
    A_o, A_m = attack_offsets(attacks, t_outer, t_inner)
    Qo = get_model("unicycle").default_Q(DT * RATIO)
    Qm = np.diag(MOTOR_Q)
    # process noise: per outer step (commanded) or per inner step (wheels), N(0, Qo (dt / dt_o))
    step_std = np.sqrt(np.diag(Qo) * (1.0 if coupling == "commanded" else 1.0 / RATIO))
    on = 1.0 if process_noise else 0.0
    W_o = rng.standard_normal((N, 3)) * step_std * on
    W_m = rng.standard_normal((N, 2, 2)) * np.sqrt(MOTOR_Q) * on
    E_o, E_m = rng.standard_normal((n_outer, 3)), rng.standard_normal((N, 2))
    x0, m0, integ0 = initial_state()
    Ad, Bd = motor_matrices()
    started = time.perf_counter()
    out = robot_loop(_params(coupling), x0, m0, integ0, Ad, Bd, Qo, Qm, W_o, W_m, E_o, E_m, A_o, A_m)
    elapsed = time.perf_counter() - started
    x_true, m_true, u_o, w_ref, V, z_o, z_m, xh_o, Ph_o, xh_m, Ph_m = out
    return GroundRobotSimulation(
        scenario=scenario,
        seed=seed,
        duration=n_outer * DT * RATIO,
        coupling=coupling,
        attacks=attacks,
        events=truth_events(attacks),
        x_true=x_true,
        m_true=m_true,
        u_outer=u_o,
        w_ref=w_ref,
        voltage=V,
        z_mocap=z_o,
        z_enc=z_m,
        x_hat=xh_o,
        P_hat=Ph_o,
        m_hat=xh_m,
        m_P=Ph_m,
        elapsed_s=elapsed,
    )


follow_dependencies(__name__)
