"""`logscan simulate`: closed-loop vehicle simulation with fault injection and ground truth.

Modules: `faults` (kinds, defaults, parsing), `controllers` (numba controllers and references),
`scenario` (per-model sensors, actuators and naming), `runner` (the numba closed-loop kernel),
`simulation` (one seeded run and its logged series), `output` (MCAP / CSV writing),
`dispatch` (`simulate` and `build_scenario` of any model: the only importer of `ins_sim` and
`ground_robot_sim`).
"""

from __future__ import annotations

from logscan.simulate.dispatch import simulate
from logscan.simulate.faults import ALL_NAMES as FAULT_NAMES
from logscan.simulate.faults import FaultSpec, parse_fault
from logscan.simulate.output import FORMATS, write_simulation
from logscan.simulate.scenario import SIMULATED_MODELS
from logscan.simulate.simulation import Simulation

__all__ = [
    "FAULT_NAMES",
    "FORMATS",
    "SIMULATED_MODELS",
    "FaultSpec",
    "Simulation",
    "parse_fault",
    "simulate",
    "write_simulation",
]
