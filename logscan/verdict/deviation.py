"""How big a fault looked in the sensor's own units: the deviation an incident's headline quotes.

An incident spans every alarm that overlaps it (`logscan.verdict.incidents`): a 10 s accelerometer bias
trips the accelerometer's test and, later, the checks of the sensors the drifting estimate then
disagrees with, so the incident spans 30-60 s for a 30-40 s fault. The headline a user reads first
(terminal, JSON and report alike: `logscan.results.Incident.headline_in`) gives the span of the check
it quotes and how big the deviation is: the largest half-second mean of the innovation (measured -
predicted) during that check's alarm, on the channel that left its band the most ("+0.92 m/s² (9.2σ)
on accel ax for 11.3 s").

The innovations come from the filter's packed per-group views (the report's
`logscan.report.sensor_views.Innovations`, read here through `GroupViews`): kept when a report is
written; without them the headline gives the span and no size.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from logscan.alarms import AlarmInterval
from logscan.errors import ModelError
from logscan.models import model_class

DEVIATION_WINDOW_S = 0.5  # the deviation is the largest mean innovation over this long
MIN_WINDOW_SAMPLES = 3  # updates in a window for its mean to count
UNIT_TEXT = {"^2": "²", "^3": "³", "^-1": "⁻¹", "^-2": "⁻²"}  # as a model's GroupSpec writes them


class GroupView(Protocol):
    """One measurement group on the analysis grid: (N, k) arrays, NaN where not updated."""

    group: str
    channels: list[str]
    measured: np.ndarray
    predicted: np.ndarray
    normalised: np.ndarray


class GroupViews(Protocol):
    """Every group's view (`logscan.report.sensor_views.Innovations`; block mode's kept rows,
    `logscan.report.kept_views.KeptRows`) and the times of its rows (``t``: the analysis grid)."""

    group_names: list[str]

    def view(self, group: str) -> GroupView | None: ...
    def times(self, group: str, t: np.ndarray) -> np.ndarray: ...


@dataclass
class Deviation:
    """The largest windowed mean innovation during an alarm, on the channel that left its band the most."""

    channel: int  # column in the group's view
    name: str  # "accel ax": the group and the model's output name
    size: float  # mean measured - predicted, in the sensor's units
    sigmas: float  # mean normalised innovation
    unit: str
    duration: float  # of the alarm, s

    def text(self) -> str:
        """'+0.92 m/s² (9.2σ) on accel ax for 11.3 s'."""
        unit = f" {self.unit}" if self.unit else ""
        sigmas = significant(abs(self.sigmas)).lstrip("+")
        return f"{significant(self.size)}{unit} ({sigmas}σ) on {self.name} for {self.duration:.1f} s"


def significant(value: float, digits: int = 2) -> str:
    """``value`` with a sign and ``digits`` significant figures, trailing zeros kept: '+1.0', '-0.034'."""
    if not math.isfinite(value) or value == 0:
        return f"{value:+g}"
    decimals = max(digits - 1 - math.floor(math.log10(abs(value))), 0)
    return f"{value:+.{decimals}f}"


def unit_text(unit: str) -> str:
    for plain, pretty in UNIT_TEXT.items():
        unit = unit.replace(plain, pretty)
    return unit


def group_units(model: Mapping, group: str) -> list[str]:
    """The units of a group's outputs as its model class declares them ([] when it does not: a
    model whose groups come from its parameters, or no model)."""
    try:
        groups = getattr(model_class(str(model.get("name", ""))), "groups", None)
    except ModelError:
        return []
    spec = groups.get(group) if isinstance(groups, dict) else None
    return [str(u) for u in getattr(spec, "units", ())]


def _window_means(values: np.ndarray, width: int) -> tuple[np.ndarray, np.ndarray]:
    """(means, counts) of each column's defined values over every run of ``width`` rows."""
    defined = np.isfinite(values)
    sums = np.vstack([np.zeros((1, values.shape[1])), np.cumsum(np.where(defined, values, 0.0), axis=0)])
    counts = np.vstack([np.zeros((1, values.shape[1])), np.cumsum(defined, axis=0)])
    width = min(width, values.shape[0])
    n = counts[width:] - counts[:-width]
    with np.errstate(invalid="ignore", divide="ignore"):
        return (sums[width:] - sums[:-width]) / n, n


def deviation(view: GroupView, t: np.ndarray, alarm: AlarmInterval, model: Mapping) -> Deviation | None:
    """How far the sensor left its prediction during ``alarm``: on the channel whose normalised
    innovation had the largest mean over DEVIATION_WINDOW_S (the whole alarm when shorter), that
    window's mean innovation. A window, not the whole alarm: the filter absorbs a bias bit by bit,
    so the innovation is largest when the fault begins. None: no update of the group in the alarm.
    ``model``: `Model.describe()` (the group's output names; its class gives their units)."""
    start, end = float(alarm.start), float(alarm.end)
    rows = np.flatnonzero((t >= start) & (t <= end))
    if rows.size == 0:
        return None
    normalised = view.normalised[rows].astype(np.float64)
    innovation = (view.measured[rows] - view.predicted[rows]).astype(np.float64)
    innovation[~np.isfinite(normalised)] = np.nan
    # the step between the rows in the alarm (block mode's kept rows are full-rate only around alarms)
    dt = float(np.median(np.diff(t[rows] if rows.size > 1 else t))) if t.size > 1 else 1.0
    width = max(int(round(DEVIATION_WINDOW_S / dt)), 1) if dt > 0 else rows.size
    sigmas, counts = _window_means(normalised, width)
    score = np.where(counts >= MIN_WINDOW_SAMPLES, np.abs(sigmas), -1.0)
    if not np.isfinite(score).any() or score.max() < 0:
        return None
    at, j = np.unravel_index(int(np.nanargmax(score)), score.shape)
    size = _window_means(innovation[:, [j]], width)[0][at, 0]
    outputs = list(((model.get("groups") or {}).get(view.group) or {}).get("outputs") or [])
    output = outputs[j] if j < len(outputs) else view.channels[j]
    units = group_units(model, view.group)
    unit = unit_text(units[j]) if j < len(units) else ""
    return Deviation(int(j), f"{view.group} {output}", float(size), float(sigmas[at, j]), unit, end - start)
