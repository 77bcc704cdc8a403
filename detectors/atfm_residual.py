"""Hybrid KF + A-TFM (thesis chapter IV): the transient fault model on one sensor's filter residual.

Specified in docs/algorithms.md section 4.4. The residual of a
channel is the shared EKF's innovation r = z - h(x_prior) at the steps where the filter updated with
its group (the group's detection grid). Training, per channel and mode value, is A-TFM's on |r|
instead of the error against the other sensors: segments of one mode value (settle time dropped),
e(eps, w) for every eps and window, the knee at the detection window w, the monotone envelope of eps
over the mode values (`detectors.atfm.train_table`), and per row the runs of |r| > eps (their rate
and lengths: `detectors.atfm_budget`). Detection: count(|r| > eps) over the last w updates against
e, the row being the next higher trained mode value than the commanded one, and e the larger of
the knee's and the smallest count whose alarm rate the run model bounds within the false-alarm
budget (`budget_per_hour`, `proof_hours`, as `nis`): the knee's e is the largest count of a few
training minutes, which new data exceeds.

Two choices the specification leaves open: as in training, the settle time after the start and
after each mode change is not judged (the residual is not stationary there: a fault that starts in
it is seen once it ends); and the row follows the commanded value alone, not A-TFM's max(commanded,
measured - margin): with the transitions not judged, the measured term only made a noisy reading at
a row's value flip between two rows whose e differ (false alarms on its own training log).
"""

from __future__ import annotations

import numpy as np

from logscan.detectors.atfm import (
    TABLE_CONSTRAINTS,
    TABLE_DEFAULTS,
    TABLE_FIT_PARAMS,
    TRAIN_COMMAND,
    check_windows,
    table_rows,
    train_table,
)
from logscan.detectors.atfm_budget import budget_count, run_rate_upper, run_statistics
from logscan.detectors.base import Detector, DetectorResult, Needs, decode_state_value
from logscan.detectors.budget import check_proof, design_rate
from logscan.detectors.modes import mode_changes, mode_segments
from logscan.detectors.params import Interval, budget_bound
from logscan.detectors.words import group_words
from logscan.errors import NotTrainedError


def residual_channels(run, trace) -> list[tuple[str, int, str, bool]]:
    """(group, column in the trace, channel, measures the mode quantity) of every channel checked:
    the measurement channels that are also [redundant] sensors, else every measurement channel."""
    redundant = {ch for group in run.redundant.values() for ch in group.channels}
    channels = []
    for g, name in enumerate(trace.group_names):
        offset = int(trace.group_offsets[g])
        for j, channel in enumerate(run.groups[name].channels):
            channels.append((name, offset + j, channel, channel in redundant))
    if any(speed for *_, speed in channels):
        return [c for c in channels if c[3]]
    return channels


def _label(group: str, channel: str, run) -> str:
    """The statistic's name part: the group, and the channel's index when the group has several."""
    channels = run.groups[group].channels
    return group if len(channels) == 1 else f"{group}[{channels.index(channel)}]"


def _settled(mode: np.ndarray, settle: int) -> np.ndarray:
    """False for the first ``settle`` samples and for ``settle`` samples after each change of mode."""
    settled = np.ones(mode.size, dtype=bool)
    for _, first, stop in mode_segments(mode, 0):
        settled[first : min(first + settle, stop)] = False
    if mode.size and not np.isfinite(mode).any():
        settled[:settle] = False
    return settled


def segment_counts(exceed: np.ndarray, mode: np.ndarray, w: int) -> np.ndarray:
    """Per step, count(exceed) over the last w steps of its own run of one mode value: like the
    training's windows, a window never reaches back across a mode change (the previous mode's
    exceedances were bounded by that mode's e, not this one's)."""
    index = np.arange(exceed.size)
    segment_start = np.maximum.accumulate(np.where(mode_changes(mode), index, 0))
    cs = np.concatenate(([0], np.cumsum(exceed)))  # cs[k] = exceedances before step k
    return cs[index + 1] - cs[np.maximum(index + 1 - w, segment_start)]


class AtfmResidualDetector(Detector):
    """Hybrid KF + A-TFM: count of large filter residuals per sensor against a trained speed table."""

    name = "atfm_residual"
    requires_fit = True
    requires_trace = True
    reads = frozenset({"y", "mode"})
    trained_attributes = ("tables_",)
    state_version = 2  # 2: each table keeps the runs of |r| > eps per row (the budget's count model)
    fit_params = TABLE_FIT_PARAMS
    defaults = {
        **TABLE_DEFAULTS,  # window: w in updates of the channel's group; row by the command
        "budget_per_hour": 0.1,  # false alarms per hour the whole detector may spend
        "proof_hours": 100.0,  # design so that this many healthy hours show the budget met (None: spend it all)
    }
    parameter_constraints = {
        **TABLE_CONSTRAINTS,
        "budget_per_hour": [budget_bound()],
        "proof_hours": [Interval(float, 0, None, closed="neither"), None],
    }

    @classmethod
    def signal_label(cls, signal: str) -> str | None:
        prefix, _, channel = signal.partition(".")
        if prefix != cls.name or not channel:
            return None
        return (
            f"{group_words(channel)} strays from the filter's prediction longer than a healthy transient "
            "does at this speed (A-TFM on the filter residual)"
        )

    def check_params(self) -> None:
        super().check_params()
        check_windows(self)
        check_proof(self)

    def needs(self, run=None) -> Needs:
        return Needs.of(ekf=("y",))

    def check_trained(self) -> None:
        if not hasattr(self, "tables_"):
            raise NotTrainedError(
                f"detector {self.name!r} has no lookup table",
                hint=f"train one with `{TRAIN_COMMAND}` (its profile enabling [detectors.{self.name}]), "
                "then pass --tables tables.json",
            )

    @classmethod
    def state_lines(cls, state) -> list[str]:
        lines = []
        for label, table in decode_state_value(state["state"]["tables_"]).items():
            cells = ", ".join(
                f"{m:g}: {eps:.4g} ({int(e)}; {int(k)} runs in {int(n)})"
                for m, eps, e, k, n in zip(
                    table["modes"], table["eps"][:, 0], table["e"][:, 0], table["runs"], table["updates"]
                )
            )
            lines.append(
                f"  {cls.name} {label}: w = {table['w']}, eps (knee e; runs of |r| > eps in updates) by mode "
                f"value {cells}"
            )
        return lines

    @staticmethod
    def _residuals(run, trace, column: int) -> tuple[np.ndarray, np.ndarray]:
        """(steps where the filter updated with the channel, |r| there)."""
        r = trace.y[:, column]
        steps = np.flatnonzero(np.isfinite(r))
        return steps, np.abs(r[steps].astype(np.float64))

    # --- training -----------------------------------------------------------------------------------
    def _fit(self, runs, traces, **context) -> None:
        segments: dict[str, dict[float, list[np.ndarray]]] = {}
        for run, trace in zip(runs, traces):
            if trace.y is None:
                raise NotTrainedError(f"detector {self.name!r} needs the filter's innovations to train")
            for group, column, channel, _ in residual_channels(run, trace):
                steps, residual = self._residuals(run, trace, column)
                if steps.size < 2 or run.mode is None:
                    continue
                dt = float(np.median(np.diff(run.t[steps])))
                settle = int(round(self.settle_s / max(dt, 1e-9)))
                by_mode = segments.setdefault(_label(group, channel, run), {})
                for value, first, stop in mode_segments(run.mode[steps], settle):
                    by_mode.setdefault(value, []).append(residual[first:stop, None])
        if not any(segments.values()):
            raise NotTrainedError(
                f"detector {self.name!r}: no residuals with a mode value to train on",
                hint="the training logs need the profile's [mode] channel",
            )
        windows = [int(w) for w in self.windows]
        self.tables_ = {
            label: _with_runs(train_table([label], by_mode, windows, int(self.window), int(self.eps_points)), by_mode)
            for label, by_mode in segments.items()
            if by_mode
        }

    # --- detection ----------------------------------------------------------------------------------
    def _alpha(self, run, trace) -> float:
        """Per update, the alarm-start probability the budget allows: rate_design / (3600 tests
        per second), every update of every channel checked a test (a union bound, as `nis`)."""
        updates = sum(int(np.isfinite(trace.y[:, column]).sum()) for _, column, _, _ in residual_channels(run, trace))
        duration = max(float(run.t[-1] - run.t[0]), run.dt) if run.t.size else 1.0
        tests_per_second = max(updates / duration, 1e-9)
        return design_rate(float(self.budget_per_hour), self.proof_hours) / (3600.0 * tests_per_second)

    def thresholds(self, table: dict, alpha: float) -> np.ndarray:
        """Per table row, the count threshold: the larger of the knee's e and the budget's."""
        w = int(table["w"])
        knee = np.asarray(table["e"], dtype=np.int64)[:, 0]
        budget = [
            budget_count(run_rate_upper(int(k), int(n)), table["run_lengths"], w, alpha)
            for k, n in zip(table["runs"], table["updates"])
        ]
        return np.maximum(knee, np.asarray(budget, dtype=np.int64))

    def _run(self, run, trace, **context) -> DetectorResult:
        result = self.new_result()
        t = run.t
        alpha = self._alpha(run, trace)
        result.info["alpha"] = alpha
        result.info["design_rate_per_hour"] = design_rate(float(self.budget_per_hour), self.proof_hours)
        for group, column, channel, _ in residual_channels(run, trace):
            label = _label(group, channel, run)
            table = self.tables_.get(label)
            if table is None:
                raise NotTrainedError(
                    f"detector {self.name!r}: the tables have no {label!r}", hint=f"retrain with `{TRAIN_COMMAND}`"
                )
            thresholds = self.thresholds(table, alpha)
            result.info[f"e.{label}"] = ", ".join(f"{m:g}: {int(e)}" for m, e in zip(table["modes"], thresholds))
            steps, residual = self._residuals(run, trace, column)
            commanded = run.mode[steps] if run.mode is not None else np.full(steps.size, np.nan)
            dt = float(np.median(np.diff(t[steps]))) if steps.size > 1 else run.dt
            # as in training, the settle time after the start and after each mode change is not
            # judged: the residual is not stationary there (the filter converging, the speed changing)
            settled = _settled(commanded, int(round(self.settle_s / max(dt, 1e-9))))
            residual = np.where(settled, residual, np.nan)
            modes = np.asarray(table["modes"], dtype=np.float64)
            # the commanded value selects the row: the settle time after each change is not judged,
            # and a noisy reading near a row's value would flip between rows whose e differ
            rows, _ = table_rows(self.name, modes, self.row, 0.0, commanded, commanded)
            eps = np.asarray(table["eps"], dtype=np.float64)[rows, 0]
            e = thresholds[rows].astype(np.float64)
            w = int(table["w"])
            count = segment_counts(residual > eps, commanded, w)
            statistic, upper = np.full(t.size, np.nan), np.full(t.size, np.nan)
            valid = np.zeros(t.size, dtype=bool)
            statistic[steps], upper[steps], valid[steps] = count, e, settled
            result.add_statistic(t, f"{self.name}.{label}", statistic, upper=upper, valid=valid, hold_off_s=w * dt)
        result.info["window"] = int(self.window)
        result.info["row"] = self.row
        return result


def _with_runs(table: dict, by_mode: dict[float, list[np.ndarray]]) -> dict:
    """``table`` with, per row, the training updates and the runs of |r| > eps (eps after the
    envelope: the value detection uses) in them, and the channel's run lengths pooled over its
    modes (a histogram, index = length): the budget's count model (`detectors.atfm_budget`)."""
    updates, runs, histogram = [], [], np.zeros(2, dtype=np.int64)
    for r, value in enumerate(table["modes"]):
        n, k, lengths = run_statistics([s[:, 0] for s in by_mode[float(value)]], float(table["eps"][r, 0]))
        updates.append(n)
        runs.append(k)
        size = max(histogram.size, lengths.size)
        histogram = np.pad(histogram, (0, size - histogram.size)) + np.pad(lengths, (0, size - lengths.size))
    table["updates"] = np.asarray(updates, dtype=np.int64)
    table["runs"] = np.asarray(runs, dtype=np.int64)
    table["run_lengths"] = histogram
    return table
