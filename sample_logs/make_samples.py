"""Regenerate the sample logs of this folder (and its README table), byte for byte.

    python sample_logs/make_samples.py                 # all logs into sample_logs/
    python sample_logs/make_samples.py --out /tmp/s quad_imu_bias.mcap   # some, elsewhere

Every log is `logscan simulate` output: the same model, faults, seed and duration give the same
bytes on any machine with the same numpy/numba versions (tests/test_sample_logs.py checks one).
`ros2_ins.mcap` (format "ros2-mcap") is an `ins` simulation written as a ROS 2 recording by
`logscan.simulate.ros2_export.write_ros2_mcap`: standard message types, no embedded profile or truth.
The ground robot's logs (`ROBOT_SAMPLES`, `logscan simulate ground_robot --scenario ...`) are made
alone with `python sample_logs/make_samples.py ground_robot_attack.mcap ground_robot_healthy.mcap`.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parent


@dataclass(frozen=True)
class Sample:
    name: str  # file name in sample_logs/
    model: str
    faults: tuple[str, ...]  # `--fault` texts (KIND:TARGET:START:END:MAGNITUDE)
    seed: int
    duration: float
    fmt: str = "mcap-json"  # or "csv", "ros2-mcap" (`logscan.simulate.ros2_export`)
    about: str = ""
    glitches: float = 0.0  # healthy transients per minute (`--glitches`)
    speed: str | None = None  # dc_motor's commanded speed (`--speed`; None: the modes, 20 s each)
    noise: str | None = None  # `--noise` (None: speed with --speed, else constant)


SAMPLES = (
    Sample("quad_healthy.mcap", "quadcopter", (), 1, 60.0, about="hover, then a figure-eight; no fault"),
    Sample(
        "quad_imu_bias.mcap",
        "quadcopter",
        ("imu-bias:accel.x:30:40:1.0",),
        2,
        60.0,
        about="+1.0 m/s^2 step on accelerometer x (Kalman-gain-norm paper)",
    ),
    Sample(
        "quad_imu_bitflip.mcap",
        "quadcopter",
        ("imu-bitflip:accel.x:30:31.2:1.0",),
        3,
        60.0,
        about="1.2 s burst of float32 high-order bit flips on accelerometer x (encoded-EKF paper)",
    ),
    Sample(
        "quad_motor_offset.mcap",
        "quadcopter",
        ("motor-offset:motor1:30:40:-0.10",),
        4,
        60.0,
        about="-10 % thrust on motor 1",
    ),
    Sample(
        "quad_cov_corruption.mcap",
        "quadcopter",
        ("cov-corruption:all:30:31:100",),
        5,
        60.0,
        about="logged on-board variances x100 for 1 s",
    ),
    Sample("sbw_healthy.mcap", "steer_by_wire", (), 6, 60.0, about="lane changes at 10 m/s; no fault"),
    Sample(
        "sbw_yaw_rate_bitflip.mcap",
        "steer_by_wire",
        ("bitflip:yaw_rate:30:31.2:1.0",),
        7,
        60.0,
        about="1.2 s burst of bit flips on the yaw-rate sensor",
    ),
    Sample(
        "jackal_healthy.mcap",
        "dc_motor",
        (),
        8,
        180.0,
        glitches=2.0,
        about="PI speed control through the modes 0.4 .. 1.9 m/s (20 s each); no fault, "
        "~2 healthy one- or two-sample glitches per minute on the speed sensors (truth "
        "`transients`), which its profile's alarm floors tolerate (below)",
    ),
    Sample(
        "jackal_train_1.mcap",
        "dc_motor",
        (),
        10,
        120.0,
        glitches=2.0,
        noise="speed",
        about="A-TFM training: every mode 0.4 .. 1.9 m/s for 20 s (seeded order), speed-dependent "
        "sensor noise, ~2 encoder slips / GPS glitches per minute (truth `transients`); no fault",
    ),
    Sample(
        "jackal_train_2.mcap",
        "dc_motor",
        (),
        11,
        120.0,
        glitches=2.0,
        noise="speed",
        about="A-TFM training, as jackal_train_1.mcap with another seed (another mode order and noise)",
    ),
    Sample(
        "jackal_gps_bias.mcap",
        "dc_motor",
        ("bias:gps_speed:45:75:0.22",),
        12,
        100.0,
        speed="1.0,0.4@30",
        about="1.0 m/s, then 0.4 from 30 s; +0.22 m/s on the GPS speed in the slow part (A-TFM "
        "thesis's attack); speed-dependent sensor noise",
    ),
    Sample(
        "ins_imu_bias.mcap",
        "ins",
        ("imu-bias:accel.x:15:25:1.0",),
        15,
        30.0,
        about="the IMU-driven INS (250 Hz IMU as the model's input; GNSS, baro, heading, attitude): "
        "+1.0 m/s^2 on accelerometer x in the first hover",
    ),
    Sample(
        "hover_healthy.mcap",
        "hover_uav",
        (),
        13,
        20.0,
        about="the UBIKF paper's hover quadcopter (interval mass, inertias, arm, drag, velocity scale): hover "
        "with attitude excitation; no fault",
    ),
    Sample(
        "hover_rotor_offset.mcap",
        "hover_uav",
        ("actuator-offset:rotor1:10:11:-0.2",),
        14,
        20.0,
        about="rotor 1 gives 20 % less thrust for 1 s",
    ),
    Sample(
        "ros2_ins.mcap",
        "ins",
        (),
        21,
        35.0,
        fmt="ros2-mcap",
        about="the ins flight as a ROS 2 recording (CDR; /imu/data Imu 250 Hz, /gps/fix NavSatFix 10 Hz, "
        "/odom Odometry 50 Hz; ENU / FLU frames): no profile embedded, it gets the built-in ros2 profile; no fault",
    ),
    Sample(
        "quad_healthy.csv",
        "quadcopter",
        (),
        9,
        60.0,
        fmt="csv",
        about="wide CSV + quad_healthy.truth.json + quad_healthy.profile.toml",
    ),
)


@dataclass(frozen=True)
class RobotSample:
    """A `logscan simulate ground_robot` log: its anomalies come from a scenario, not faults."""

    name: str
    scenario: str  # paper, random or healthy
    seed: int
    duration: float
    fmt: str = "mcap-ros2"  # binary fields: under 300 kB at 100 Hz
    about: str = ""
    model: str = "ground_robot"


ROBOT_SAMPLES = (
    RobotSample(
        "ground_robot_attack.mcap",
        "paper",
        16,
        12.0,
        about="the checkpointing / roll-forward-recovery paper's hierarchical robot (unicycle loop 10 Hz, two "
        "DC-motor loops 100 Hz) on its circle: +[5, 5, 0] on the mocap and +20000 rad/s on both encoders over "
        "3.25-5 s, the negatives over 8.25-10 s (6 truth events, one per group and anomaly); 12 s, not the "
        "paper's 15, to stay small",
    ),
    RobotSample(
        "ground_robot_healthy.mcap",
        "healthy",
        17,
        12.0,
        about="the hierarchical robot on its circle; no anomaly",
    ),
)


def generate(sample: Sample | RobotSample, out_dir: Path) -> list[Path]:
    """Write one sample log (and its sidecars) into ``out_dir``."""
    from logscan.simulate import parse_fault, simulate, write_simulation

    if isinstance(sample, RobotSample):
        sim = simulate(sample.model, duration=sample.duration, seed=sample.seed, scenario=sample.scenario)
        return write_simulation(sim, out_dir / sample.name, sample.fmt)

    sim = simulate(
        sample.model,
        [parse_fault(f) for f in sample.faults],
        duration=sample.duration,
        seed=sample.seed,
        glitches_per_min=sample.glitches,
        speed=sample.speed,
        noise=sample.noise,
    )
    if sample.fmt == "ros2-mcap":
        from logscan.simulate.ros2_export import write_ros2_mcap

        return [write_ros2_mcap(sim, out_dir / sample.name, truth=False)]  # a recording: no truth, no profile
    return write_simulation(sim, out_dir / sample.name, sample.fmt)


def readme_table() -> str:
    """The README's table of the sample logs and their faults (markdown)."""
    lines = [
        "| log | model | duration | seed | speed (m/s) | faults (kind, target, start-end s, magnitude) | what |",
        "|---|---|---|---|---|---|---|",
    ]
    from logscan.simulate import parse_fault
    from logscan.simulate.faults import ALIASES

    for s in SAMPLES:
        faults = (
            "; ".join(
                f"{ALIASES.get(p.kind, (p.kind,))[0]} {p.target} {p.start:g}-{p.end:g} {p.magnitude:g}"
                for p in (parse_fault(f) for f in s.faults)
            )
            or "none"
        )
        speed = s.speed or ("modes" if s.model == "dc_motor" else "-")
        lines.append(f"| `{s.name}` | {s.model} | {s.duration:g} s | {s.seed} | {speed} | {faults} | {s.about} |")
    for r in ROBOT_SAMPLES:
        scenario = f"scenario {r.scenario}"
        lines.append(f"| `{r.name}` | {r.model} | {r.duration:g} s | {r.seed} | - | {scenario} | {r.about} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help="sample file names (default: all)")
    parser.add_argument("--out", type=Path, default=HERE, help="output folder (default: sample_logs/)")
    args = parser.parse_args(argv)
    known = {s.name: s for s in (*SAMPLES, *ROBOT_SAMPLES)}
    unknown = [n for n in args.names if n not in known]
    if unknown:
        print(f"unknown sample(s): {', '.join(unknown)}; known: {', '.join(known)}", file=sys.stderr)
        return 2
    for sample in [known[n] for n in args.names] or list(known.values()):
        for path in generate(sample, args.out):
            print(f"{path}  {path.stat().st_size / 1e6:.2f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
