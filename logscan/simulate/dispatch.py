"""The per-model entry points of `logscan simulate`: `build_scenario` and `simulate` pick the
simulator of a model. The only module that imports the model-specific simulators
(`ground_robot_sim`, `ins_sim`); the shared pieces they build on (`scenario`, `simulation`) import
none of them, so no import cycle runs through the simulators.
"""

from __future__ import annotations

import numpy as np

from logscan.errors import UsageError
from logscan.simulate.faults import FaultSpec
from logscan.simulate.ground_robot_sim import check_ground_robot_options, simulate_ground_robot
from logscan.simulate.ins_sim import check_ins_faults, ins_scenario, simulate_ins
from logscan.simulate.plant import check_plant_draw, draw_plant
from logscan.simulate.scenario import Scenario, closed_loop_scenario, prepare_scenario
from logscan.simulate.simulation import Simulation, check_run_options, simulate_closed_loop


def build_scenario(
    model_name: str,
    duration: float,
    rate_hz: float | None,
    aggressive: bool,
    rng: np.random.Generator,
    params: dict | None = None,
    speed: str | None = None,
    noise: str | None = None,
) -> Scenario:
    """The scenario of ``model_name`` for a log of ``duration`` seconds (``speed``: the dc_motor's
    commanded-speed profile, see `scenario.parse_speed`, None: its mode cycle; ``noise``: see
    `scenario.NOISE_KINDS`)."""
    if model_name == "ins":
        model, dt, t, groups, _, _ = prepare_scenario(model_name, duration, rate_hz, params, speed, noise)
        return ins_scenario(model, dt, t, groups, aggressive, rng)
    return closed_loop_scenario(model_name, duration, rate_hz, aggressive, rng, params, speed, noise)


def simulate(
    model_name: str,
    faults: list[FaultSpec] | None = None,
    *,
    duration: float = 60.0,
    seed: int = 0,
    rate_hz: float | None = None,
    aggressive: bool = False,
    params: dict | None = None,
    glitches_per_min: float = 0.0,
    speed: str | None = None,
    noise: str | None = None,
    scenario: str | None = None,
    plant_draw: bool = False,
) -> Simulation:
    """Simulate ``model_name`` for ``duration`` seconds with ``faults``; deterministic in ``seed``.

    ``glitches_per_min`` adds healthy transients (docs/algorithms.md section 6.5): one- or two-sample
    spikes of 3-8 noise standard deviations on a random sensor channel (the redundant group's
    when the model has one), Poisson in time. They are listed in the truth as ``transients``, not
    as fault ``events``: a detector should tolerate them. On dc_motor they are encoder slips (one
    encoder reads low) and GPS glitches, sized by the noise at the commanded speed.

    ``speed`` (dc_motor only): the commanded-speed profile, ``0.7``, ``1.0,0.4@30`` or ``random``
    (`logscan.simulate.scenario.parse_speed`); None: the mode cycle. ``noise``: "speed" (the speed
    sensors' noise std grows with the speed, `scenario.SPEED_NOISE`; dc_motor only) or "constant"
    (the model's noise_std); None: speed when ``speed`` is given, else constant.

    ``model_name`` "ground_robot" is the hierarchical robot of `logscan.simulate.ground_robot_sim`
    (not a model: an outer unicycle loop over two DC-motor loops); it takes ``scenario`` ("paper",
    the default, "random" or "healthy"), ``duration`` and ``seed`` only, and returns a
    `GroundRobotSimulation`. ``scenario`` is for ground_robot alone.
    ``plant_draw`` (hover_uav): the truth flies a plant drawn inside the intervals (`plant.draw_plant`).
    """
    check_run_options(duration, seed, glitches_per_min)
    check_plant_draw(model_name, plant_draw)
    if model_name == "ground_robot":  # several loops, several rates (logscan.simulate.ground_robot_sim)
        check_ground_robot_options(faults, rate_hz, aggressive, glitches_per_min, speed, noise)
        return simulate_ground_robot(scenario or "paper", duration=duration, seed=seed)
    if scenario is not None:
        raise UsageError("--scenario is for ground_robot", hint="drop --scenario")
    scenario_rng = np.random.default_rng([seed, 1])
    # ins: the IMU is the model's input, no closed loop (logscan.simulate.ins_sim)
    if model_name == "ins":
        check_ins_faults(faults or [])
    run = simulate_ins if model_name == "ins" else simulate_closed_loop
    sc = build_scenario(model_name, duration, rate_hz, aggressive, scenario_rng, params, speed, noise)
    if plant_draw:
        sc.plant, drawn = draw_plant(sc.model, seed)
        sc.truth_extra["plant_params"] = drawn
    return run(
        sc,
        list(faults or []),
        duration=duration,
        seed=seed,
        aggressive=aggressive,
        glitches_per_min=glitches_per_min,
    )
