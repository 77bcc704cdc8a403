"""`logscan simulate`: write a simulated log with known faults, ground truth and its profile."""

from __future__ import annotations

from pathlib import Path

import click

from logscan.cli.options import echo_notice, output_option, quiet_option, seed_option, show_progress
from logscan.errors import UsageError, did_you_mean

_FAULT_HELP = (
    "Inject a fault (repeatable). KIND or KIND:TARGET:START:END:MAGNITUDE (empty fields take "
    "defaults). Kinds: bias, drift, random, bitflip, stuck, actuator-offset, lost-actuator, "
    "cov-corruption, state-corruption, control-fault (the controller's output TARGET, its first "
    "input by default, x (1 + MAGNITUDE), +0.5 for 2 s), control-stuck (held at its value before "
    "START); aliases imu-bias (1.0 m/s^2 on accel.x), imu-drift, "
    "imu-random, imu-bitflip (1.2 s burst), imu-stuck, motor-offset (-10 % thrust on motor1), "
    "lost-motor; the UBIKF paper's scenarios (hover_uav; samples k counted from 5 s, the start of "
    "its attitude excitation): roll-bias (0.1 rad on attitude.roll for k in [30, 70]), rotor-loss "
    "(rotor1 stops from k = 31)."
)


_HELP = """Simulate MODEL in closed loop with injected faults and write the log.

MODEL is quadcopter, steer_by_wire, dc_motor, hover_uav, ins or ground_robot. The log holds
commands (/cmd), sensors, the on-board EKF's state and variance (/ekf/state, /ekf/variance),
set-points and the true state (/truth/state); the fault events and the matching profile are
embedded, so `logscan analyze` and `logscan evaluate` need no other file. Same seed, same
bytes.

ins (the IMU-driven inertial navigation model) is open loop: a multirotor flies a reference
(hover at 10 m, then minimum-jerk moves between random waypoints); its IMU (/imu/gyro.*,
/imu/accel.*, 250 Hz) is the model's input and takes sensor faults (accel.x .. gyro.z, imu-*
aliases) like GNSS (/gnss), barometer (/baro), heading (/mag) and attitude (/mocap); actuator
and estimator faults do not apply.

ground_robot is the checkpointing / roll-forward-recovery paper's hierarchical robot: an outer
unicycle loop at 10 Hz (mocap, /cmd/outer.v and .w) over two DC-motor loops at 100 Hz (/enc,
/motor_cmd), each with its own on-board filter (/ekf/..., per loop) and true state (/truth/...);
its anomalies come from --scenario, its profile has one [loops.<name>] table per motor loop.
"""


def _models() -> tuple[str, ...]:
    """What `logscan simulate` simulates: the models of the scenarios, and the hierarchical robot."""
    from logscan.simulate import SIMULATED_MODELS

    return (*SIMULATED_MODELS, "ground_robot")


def _model_name(ctx: click.Context, param: click.Parameter, value: str) -> str:
    """MODEL checked first, before any output, fault or compile (exit 2, with the closest names)."""
    if value not in _models():
        raise UsageError(
            f"cannot simulate model {value!r}",
            hint=did_you_mean(value, _models()) + "simulated models: " + ", ".join(_models()),
        )
    return value


def _fault_texts(ctx: click.Context, param: click.Parameter, value: tuple[str, ...]) -> tuple[str, ...]:
    """Each --fault parsed before any output is checked or kernel compiled (exit 2 on a bad one)."""
    from logscan.simulate import parse_fault

    for text in value:
        parse_fault(text)
    return value


def _complete_models(ctx: click.Context, param: click.Parameter, incomplete: str) -> list[str]:
    return [name for name in _models() if name.startswith(incomplete)]


def _complete_faults(ctx: click.Context, param: click.Parameter, incomplete: str) -> list[str]:
    from logscan.simulate import FAULT_NAMES

    return [name for name in FAULT_NAMES if name.startswith(incomplete)]


@click.command(
    help=_HELP,
    epilog="Examples:\n\n"
    "  logscan simulate quadcopter --fault imu-bias --at 30 -o q.mcap\n\n"
    "  logscan simulate quadcopter --fault imu-bitflip --at 20 --fault motor-offset:motor2:40:50 -o q.mcap\n\n"
    "  logscan simulate steer_by_wire --fault bias:yaw_rate:10:20:0.05 --format csv -o sbw.csv\n\n"
    "  logscan simulate dc_motor --duration 600 --glitches 2 --seed 3 -o jackal.mcap\n\n"
    "  logscan simulate dc_motor --speed 1.0,0.4@30 --fault bias:gps_speed:45:75:0.22 --duration 100 -o j.mcap\n\n"
    "  logscan simulate hover_uav --fault roll-bias -o hover.mcap\n\n"
    "  logscan simulate ins --duration 120 --seed 3 --fault imu-bias:accel.x:60:70:1.0 -o ins.mcap\n\n"
    "  logscan simulate ground_robot -o robot.mcap\n\n"
    "  logscan simulate ground_robot --scenario random --seed 3 -o robot_3.mcap",
)
@click.argument("model_name", metavar="MODEL", callback=_model_name, shell_complete=_complete_models)
@click.option(
    "--fault",
    "faults",
    multiple=True,
    metavar="KIND[:TARGET:START:END:MAG]",
    callback=_fault_texts,
    shell_complete=_complete_faults,
    help=_FAULT_HELP,
)
@click.option(
    "--at",
    "at",
    type=float,
    default=None,
    help="Start time (s) of the faults given by KIND alone. Default: half the log.",
)
@click.option(
    "--fault-duration",
    "fault_duration",
    type=float,
    default=None,
    help="Length (s) of those faults. Default: per kind (bias 10 s, bit flips 1.2 s, ...).",
)
@click.option(
    "--magnitude",
    type=float,
    default=None,
    help="Magnitude of those faults (unit per kind, e.g. m/s^2 for an IMU bias).",
)
@click.option(
    "--target",
    default=None,
    help="Target of those faults: a sensor (accel.x, /imu/gyro.y), an actuator (motor1) "
    "or an on-board state (vx, all).",
)
@click.option(
    "--duration", type=float, default=None, help="Log length (s). Default: 60 (ground_robot: 15, the paper's run)."
)
@click.option(
    "--scenario",
    type=click.Choice(["paper", "random", "healthy"]),
    default=None,
    help="ground_robot's anomalies: paper (+[5, 5, 0] on the mocap and +20000 rad/s on both encoders "
    "over 3.25-5 s, the negatives over 8.25-10 s; the default), random (1-3 anomalies from --seed) "
    "or healthy.",
)
@click.option(
    "--rate",
    "rate_hz",
    type=float,
    default=None,
    help="Grid rate (Hz). Default: quadcopter 100, steer_by_wire 100, dc_motor 20, hover_uav 100, ins 250 "
    "(the IMU's rate).",
)
@click.option(
    "--format",
    "fmt",
    type=click.Choice(["mcap-json", "mcap-ros2", "csv"]),
    default=None,
    help="MCAP (truth + profile embedded) or CSV (+ <log>.truth.json, <log>.profile.toml). "
    "Default: csv for an output ending in .csv, else mcap-json.",
)
@click.option("--aggressive", is_flag=True, default=False, help="Faster, larger manoeuvres (for false-alarm testing).")
@click.option(
    "--glitches",
    "glitches_per_min",
    type=float,
    default=0.0,
    show_default=True,
    metavar="PER_MIN",
    help="Healthy transients per minute: 1-2 sample spikes on a sensor (dc_motor: an encoder "
    "slip or a GPS glitch on the redundant speed sensors), listed in the truth as 'transients', "
    "not as faults.",
)
@click.option(
    "--speed",
    "speed",
    default=None,
    metavar="SPEC",
    help="dc_motor's commanded speed (/cmd_vel/linear.x, m/s): 0.7 (constant), 1.0,0.4@30 "
    "(1.0, then 0.4 from t = 30 s; any number of v@t), or random (speeds from the modes "
    "0.4 .. 1.9, each held 5-20 s; seeded). Default: the modes in turn, 20 s each.",
)
@click.option(
    "--noise",
    "noise",
    type=click.Choice(["speed", "constant"]),
    default=None,
    help="Sensor noise: speed (dc_motor: encoder std 0.004 + 0.03 |v|, GPS 0.015 + 0.02 |v|; the "
    "profile assumes the noise at 1.9 m/s) or constant (the model's noise_std). Default: speed "
    "with --speed, else constant.",
)
@click.option(
    "--plant-draw",
    "plant_draw",
    is_flag=True,
    default=False,
    help="hover_uav: fly an off-nominal plant, every interval parameter (mass, inertias, arm, k_yaw, "
    "drag, vel_scale) drawn uniformly inside its interval from the seed; the truth lists the values "
    "(plant_params), the embedded profile keeps the nominal ones.",
)
@click.option(
    "--force",
    is_flag=True,
    default=False,
    help="Replace an existing file at the output (and a CSV log's sidecars); without it that is refused.",
)
@seed_option
@quiet_option
@output_option
def simulate(
    model_name: str,
    faults: tuple[str, ...],
    at: float | None,
    fault_duration: float | None,
    magnitude: float | None,
    target: str | None,
    duration: float | None,
    scenario: str | None,
    rate_hz: float | None,
    fmt: str | None,
    aggressive: bool,
    glitches_per_min: float,
    speed: str | None,
    noise: str | None,
    plant_draw: bool,
    force: bool,
    seed: int,
    quiet: bool,
    output_path: str | None,
) -> None:
    """`logscan simulate` (its help: ``_HELP``)."""
    from logscan.filters.warmup import COMPILING_NOTE
    from logscan.simulate import simulate as run_simulation
    from logscan.simulate import write_simulation

    output_path = _checked_output(output_path)
    duration = duration if duration is not None else 15.0 if model_name == "ground_robot" else 60.0
    fmt = fmt or ("csv" if output_path.lower().endswith(".csv") else "mcap-json")
    if not force:
        _refuse_replacing(output_path, fmt)
    specs = _fault_specs(faults, at, fault_duration, magnitude, target, duration)
    options = dict(
        duration=duration, seed=seed, rate_hz=rate_hz, aggressive=aggressive, glitches_per_min=glitches_per_min,
        speed=speed, noise=noise, scenario=scenario, plant_draw=plant_draw,
    )  # fmt: skip
    _check_options(model_name, specs, options)  # every argument, before a compile note or progress line
    progress, cold = show_progress(quiet), not quiet and _simulator_cold(model_name)
    if cold:
        echo_notice(COMPILING_NOTE)
    if progress:
        click.echo(f"simulating {model_name} for {duration:g} s ...", err=True)
    sim = run_simulation(
        model_name, specs, duration=duration, seed=seed, rate_hz=rate_hz, aggressive=aggressive,
        glitches_per_min=glitches_per_min, speed=speed, noise=noise, scenario=scenario, plant_draw=plant_draw,
    )  # fmt: skip
    if progress:
        compiled = " (compiling included)" if cold else ""
        click.echo(f"simulated {sim.n_steps} steps in {sim.elapsed_s:.2f} s{compiled}; writing {output_path}", err=True)
    written = write_simulation(sim, output_path, fmt)
    if not quiet:
        for event in sim.events:
            click.echo(
                f"fault {event.kind} on {event.target}: {event.t_start:g} .. {event.t_end:g} s, "
                f"magnitude {event.magnitude:g}",
                err=True,
            )
        click.echo("wrote " + ", ".join(str(p) for p in written), err=True)


def _checked_output(output_path: str | None) -> str:
    """-o, refused when missing, a directory, or named like anything but a log (exit 2)."""
    if not output_path:
        raise UsageError("no output file", hint="give -o OUT (e.g. -o q.mcap)")
    if Path(output_path).is_dir():
        raise UsageError("the output is a directory", path=output_path, hint="give a file name, e.g. -o q.mcap")
    if output_path.lower().endswith(_NOT_LOG_SUFFIXES):
        # such a name is a profile, a CSV log's sidecar, a JSON summary or a report: never replace one with a log
        raise UsageError(
            "the output is named like a profile, a sidecar, a JSON summary or a report",
            path=output_path,
            hint="give the log a .mcap or .csv name, e.g. -o q.mcap",
        )
    return output_path


def _fault_specs(faults, at, fault_duration, magnitude, target, duration: float) -> list:
    """The --fault specs; those given by KIND alone take --at, --fault-duration, --magnitude and
    --target (`logscan.simulate.faults.FaultSpec`)."""
    from logscan.simulate import parse_fault
    from logscan.simulate.faults import FaultSpec

    specs = []
    for text in faults:
        spec = parse_fault(text)
        if ":" not in text:
            end = None if fault_duration is None else (at if at is not None else 0.5 * duration) + fault_duration
            spec = FaultSpec(spec.kind, target, at, end, magnitude)
        specs.append(spec)
    return specs


def _check_options(model_name: str, specs: list, options: dict) -> None:
    """What the simulator would refuse, refused before anything is compiled or printed (exit 2)."""
    from logscan.simulate.plant import check_plant_draw
    from logscan.simulate.scenario import check_speed, resolve_noise
    from logscan.simulate.simulation import check_run_options

    check_run_options(options["duration"], options["seed"], options["glitches_per_min"])
    check_plant_draw(model_name, options["plant_draw"])
    rate = options["rate_hz"]
    if rate is not None and not (1.0 <= rate <= 10000.0):
        raise UsageError(f"--rate {rate:g} Hz is out of range", hint="use 1 .. 10000 Hz")
    if model_name == "ground_robot":
        from logscan.simulate.ground_robot_sim import check_ground_robot_options

        opts = options
        check_ground_robot_options(
            specs, rate, opts["aggressive"], opts["glitches_per_min"], opts["speed"], opts["noise"]
        )
        return
    if options["scenario"] is not None:
        raise UsageError("--scenario is for ground_robot", hint="drop --scenario")
    if model_name == "ins":  # an actuator or estimator fault
        from logscan.simulate.ins_sim import check_ins_faults

        check_ins_faults(specs)
    check_speed(model_name, options["speed"], options["duration"])
    resolve_noise(model_name, options["noise"], options["speed"])


_NOT_LOG_SUFFIXES = (".toml", ".json", ".html", ".htm", ".xml", ".js")


def _simulator_cold(model_name: str = "") -> bool:
    """The simulator's kernel is not in numba's disk cache yet (its first run compiles it)."""
    from logscan.filters.warmup import kernel_cached

    if model_name == "ins":
        from logscan.simulate.ins_sim import apply_sensor_faults

        return not kernel_cached(apply_sensor_faults)
    if model_name == "ground_robot":
        from logscan.simulate.ground_robot_kernels import robot_loop

        return not kernel_cached(robot_loop)
    from logscan.simulate.runner import closed_loop

    return not kernel_cached(closed_loop)


def _refuse_replacing(output_path: str, fmt: str) -> None:
    """UsageError when the output (or, for a CSV log, one of its sidecars) is an existing regular
    file: a simulated log never silently replaces a log (`--force` allows it). A FIFO or a device
    (/dev/null) is written into, not replaced."""
    from logscan.simulate.output import sidecar_paths

    paths = [Path(output_path), *(sidecar_paths(output_path) if fmt == "csv" else ())]
    existing = [str(p) for p in paths if p.is_file()]
    if existing:
        what = "already exists" if existing == [output_path] else f"would replace {', '.join(existing)}"
        raise UsageError(what, path=output_path, hint="pass --force to replace it, or give another -o")
