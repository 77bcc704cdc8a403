"""The frozen-sensor ("stuck") check: a measurement channel whose fresh samples stop changing.

Specified in docs/algorithms.md section 1f. Per channel of every measurement group, over its fresh
samples v_1 .. v_M (the steps where the channel has a new sample, `AlignedGroup.channel_fresh`):

    still_i  = |v_i - v_a(i)| <= tol,  tol = still_ratio * sigma       a(i): the run's anchor sample
    r_i      = i - a(i) + 1                                           samples held within tol (run)
    L        = median run length over the log (>= 1)                 fill factor: 1, or a CSV's repeats
    g_i      = r_i / L                                                the statistic: held samples, in
                                                                      units of the channel's own rate

At rest (`Model.at_rest`: a ground robot whose wheels report, or are commanded, no speed) a sensor
holding its value is stillness, not a freeze: those samples are not judged, and a run counts only
the samples after the last one at rest (a GNSS receiver's static hold ends once the robot moves).
The inputs that test reads (`Model.rest_inputs`: the wheel speed) are checked the same way, as
``frozen.input.<input>``: held at a moving value, one would call the robot moving while it stands,
and the still sensors stuck (the real Husky drive's wheel speed held for 100 s named its GNSS). So
is every other input of a model whose inputs are sensor readings (`Model.inputs_are_sensors`: the
gyro's yaw rate), not exempt near zero: a live sensor's noise changes its reading on every sample,
also at rest (the real Husky drive's gyro held for 50 s named the wheels' yaw rate). An input is
held on the grid between its samples: the fill factor L counts its own samples. Rest that the
gyro and the GNSS both deny (`Model.motion_inputs`, `Model.motion_group`: they say the robot moves)
is motion: a wheel speed stuck at exactly 0 while driving claims rest (`logscan.detectors.frozen_rest`).

The anchor a(i) is the first sample of the current run: a run ends when a sample leaves the band
+-tol around it, so a slow healthy ramp (each step small, the sum not) is not a run. sigma is the
channel's noise: the profile's noise_std, else the model's default, never larger than the channel's
own noise read from the log (the median absolute successive difference / (0.6745 sqrt 2)), so a
profile that overstates the noise cannot make healthy samples look still. An exact freeze has
|v_i - v_a| = 0; a frozen value with quantisation noise far below the sensor's stays within tol.

Forward-filled channels: a wide CSV that repeats a slow channel's last value on every row of a
faster one gives every run the length of the ratio of the rates; L, the median run length, is that
ratio (1 for a channel whose samples are all new), so g counts the channel's own samples and the
fill is never called stuck. L is taken from the runs only when there are at least MIN_RUNS of them.

Threshold: an alarm when g > h, h = max(n_samples, h_budget). Healthy runs are taken as geometric
in g (a repeat has probability p, P(g >= r) = p^(r - 1)), p estimated from the log's runs (the share
of runs of at least 1.5 L samples, with half a run added: one long stuck run counts once), and
h_budget = 1 + ln(q) / ln(p) with q = budget_per_hour / (channels x runs per hour): the channel's
healthy repeats (a quantised sensor) raise its threshold so that all channels together stay within
``budget_per_hour`` false alarms. The change time of each alarm is the run's second sample, the
first that repeated the frozen value.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from logscan.alarms import true_runs
from logscan.detectors.base import Detector, DetectorResult, on_steps
from logscan.detectors.frozen_rest import denied_rest
from logscan.detectors.params import Interval, budget_bound, multiplier_bound
from logscan.detectors.raw_topics import skipped_lines
from logscan.detectors.words import group_words
from logscan.numba_cache import follow_dependencies
from logscan.results import NotChecked

PREFIX = "frozen"
MIN_RUNS = 20  # fewer runs than this: too few to read a fill factor from (L = 1)
# A channel that repeats its sample on at least HELD_SHARE of its steps, spread over at least
# NOISELESS_P of its runs (not one long freeze), shows no noise between samples: a quantised or
# noiseless sensor (a simulator's GNSS velocity reads exactly 0 at rest) that holds its value
# whenever the quantity is still; stillness cannot be told from a freeze there: not checked.
HELD_SHARE = 0.5
NOISELESS_P = 0.1
MAD_TO_STD = 0.6745 * np.sqrt(2.0)  # median |v_i - v_i-1| of N(0, sigma^2) noise = 0.6745 sqrt(2) sigma


# The kernel allocates nothing and calls no other numba function (its outputs come from numpy in
# `held_runs`; Python's min / max written out): numba's generic np.empty and min / max compile
# apart (types, LLVM, linking into the caller), about half of the kernel's first-run compile.


@numba.njit(cache=True)
def _held_runs_kernel(v, tol, still, anchor, held, lengths):  # pragma: no cover - compiled
    """`held_runs` into its outputs (N,) (the run lengths in the first entries of ``lengths``);
    returns the number of runs."""
    n = v.size
    a = 0
    last_rest = -1
    n_runs = 0
    run_start = 0
    for i in range(n):
        if i == 0 or not (abs(v[i] - v[a]) <= tol):
            a = i
        if still.size and still[i]:
            last_rest = i
        b = last_rest + 1 if last_rest + 1 > a else a  # min(max(a, last_rest + 1), i)
        b = i if i < b else b
        anchor[i] = b
        held[i] = i + 1 - b
        if b == i:  # a run starts here: the previous one ended at i - 1
            if n_runs:
                lengths[n_runs - 1] = i - run_start
            run_start = i
            n_runs += 1
    if n_runs:
        lengths[n_runs - 1] = n - run_start
    return n_runs


def held_runs(v: np.ndarray, tol: float, still: np.ndarray):
    """(anchor, held, run lengths): per sample the first index of its run, r_i (samples held since
    it, 1 at it), and the length of each run in order. A run lasts while samples stay within
    ``tol`` of its first sample (a NaN never joins a run); ``still`` (bool per sample, or empty:
    none) marks samples at rest: each starts a run of its own and the next sample starts a new
    one (a run counts only the samples after the last one at rest)."""
    anchor, held, lengths = (np.empty(v.size, dtype=np.int64) for _ in range(3))
    n_runs = _held_runs_kernel(v, tol, still, anchor, held, lengths)
    return anchor, held, lengths[:n_runs]


def compile_kernels() -> None:
    """Compile (or load) `held_runs`'s kernel for the types `Frozen` passes: the first run calls it
    while the EKF compiles in its own process."""
    held_runs(np.zeros(2), 0.0, np.zeros(0, dtype=np.bool_))


def channel_noise(values: np.ndarray) -> float:
    """A channel's noise std from its own samples: median |v_i - v_i-1| / (0.6745 sqrt 2) (motion
    adds to it, a stuck stretch shorter than half the log does not move the median)."""
    steps = np.diff(values)
    np.abs(steps, out=steps)
    finite = np.isfinite(steps)
    if not finite.all():
        steps = steps[finite]
    # its own temporary: partitioned in place, not copied first
    return float(np.median(steps, overwrite_input=True)) / MAD_TO_STD if steps.size else np.nan


def fill_factor(lengths: np.ndarray) -> float:
    """L: the median length of a channel's runs of exactly repeated samples, 1 with fewer than
    MIN_RUNS runs (a forward fill repeats a slow channel about L times; a channel whose samples are
    all new has L = 1)."""
    if lengths.size < MIN_RUNS:
        return 1.0
    return max(float(np.median(lengths)), 1.0)


def repeat_probability(lengths: np.ndarray, fill: float) -> float:
    """p: the share of runs of at least 1.5 L samples (a repeat of the channel's own sample), with
    half a run added; one long stuck run counts once."""
    return (np.count_nonzero(lengths >= 1.5 * fill) + 0.5) / (lengths.size + 1.0)


def run_threshold(lengths: np.ndarray, fill: float, tests: int, duration_s: float, budget: float) -> float:
    """h_budget = 1 + ln(q) / ln(p) (module docstring): the held length (in units of the channel's
    rate) that healthy runs of this channel exceed with the channel's share of the budget."""
    runs = lengths.size
    p = repeat_probability(lengths, fill)
    runs_per_hour = runs / max(duration_s, 1e-9) * 3600.0
    q = budget / (max(tests, 1) * max(runs_per_hour, 1e-9))
    if p >= 1.0 or q >= 1.0:
        return 1.0
    return 1.0 + np.log(q) / np.log(p)


@dataclass
class InputColumn:
    """A model input checked as a group of one channel is (its samples: the grid's held values, new
    or not; no stated noise: its own): one `Model.at_rest` reads, or a sensor's reading that drives
    the prediction (`Model.inputs_are_sensors`: a gyro's yaw rate)."""

    name: str  # "input.<input>"
    channels: list[str]
    z: np.ndarray  # (N, 1)
    fresh: np.ndarray  # (N,) bool: finite
    channel_fresh: None = None
    noise_std: None = None
    # read by the rest test (a wheel speed): within its own noise of zero it is at rest, not held
    rest: bool = True


def checked_inputs(run, model) -> list[InputColumn]:
    """The model inputs the check reads: the ones its rest test reads (`Model.rest_inputs`), and
    every other one when the inputs are sensor readings (`Model.inputs_are_sensors`)."""
    u = getattr(run, "u", None)
    if model is None or u is None or u.ndim != 2:
        return []
    names, channels = list(model.input_names), list(getattr(run, "input_channels", ()))
    rest = tuple(getattr(model, "rest_inputs", ()))
    sensors = range(len(names)) if getattr(model, "inputs_are_sensors", False) else ()
    out = []
    for k in sorted(set(rest) | set(sensors)):
        if k < u.shape[1] and k < len(names):
            column = u[:, k : k + 1]
            channel = channels[k] if k < len(channels) else names[k]
            out.append(InputColumn(f"input.{names[k]}", [channel], column, _samples(column[:, 0]), rest=k in rest))
    return out


def _samples(column: np.ndarray) -> np.ndarray:
    """(N,) bool: the grid steps of an input column to judge: finite, but for the repeats that run
    into a stretch without the input (the alignment holding its last sample until its staleness
    limit: a sensor that stopped, which the missing-input rule reports, not one repeating itself)."""
    finite = np.isfinite(column)
    same = np.zeros(column.size, dtype=bool)
    same[1:] = column[1:] == column[:-1]  # NaN never equals: a gap starts a run
    run = np.cumsum(~same)
    ends = np.flatnonzero(~np.append(same[1:], False))  # each run's last step
    into_gap = ends[(ends < column.size - 1) & ~finite[np.minimum(ends + 1, column.size - 1)]]
    return finite & ~(same & np.isin(run, run[into_gap]))


class FrozenSensorDetector(Detector):
    """Frozen-sensor check: a channel whose fresh samples stop changing ("stuck"), per channel."""

    name = "frozen"
    group_verdict = "stuck (its samples repeat one value)"
    requires_trace = False
    reads = frozenset({"z", "u"})  # the measurement groups' samples and fresh masks; the inputs (at rest)
    default_enabled = True
    defaults = {
        "n_samples": 5,  # at least this many held samples (of the channel's own rate) to be stuck
        "still_ratio": 0.01,  # a sample within this share of the noise std of the run's first is "held"
        "budget_per_hour": 0.1,  # false alarms per hour all channels together may spend
    }
    parameter_constraints = {
        "n_samples": [multiplier_bound(2, 100_000, "held samples before a sensor is stuck", closed="both", kind=int)],
        "still_ratio": [Interval(float, 0, 1, closed="left")],
        "budget_per_hour": [budget_bound()],
    }

    @classmethod
    def signal_label(cls, signal: str) -> str | None:
        prefix, _, rest = signal.partition(".")
        if prefix != PREFIX or not rest:
            return None
        group, _, output = rest.partition(".")
        if group == "input" and output:
            what = f"model input {output}"
        else:
            what = group_words(group) + (f" {output}" if output else "")
        return f"{what} stopped changing: its samples repeat one value (stuck sensor)"

    @classmethod
    def judged_input(cls, signal: str) -> str | None:
        prefix, _, rest = signal.partition(".")
        group, _, name = rest.partition(".")
        return name if prefix == PREFIX and group == "input" and name else None

    @classmethod
    def signal_words(cls, signal: str) -> str | None:
        prefix, _, rest = signal.partition(".")
        return "a stuck sensor (its samples stopped changing)" if prefix == PREFIX and rest else None

    def _run(self, run, trace, **context) -> DetectorResult:
        result = self.new_result()
        model = context.get("model")
        columns = [
            (group, j, self._signal(model, group, j))
            for group in run.groups.values()
            if group.z is not None
            for j in range(group.z.shape[1])
        ] + [(column, 0, f"{PREFIX}.{column.name}") for column in checked_inputs(run, model)]
        duration = max(float(run.t[-1] - run.t[0]), run.dt) if run.t.size else 1.0
        info: dict = {"channels": {}, "fill": {}, "h": {}, "sigma": {}, "not_checked": {}}
        rest = model.at_rest(run.u) if model is not None and getattr(run, "u", None) is not None else None
        # rest the gyro and the GNSS both deny is motion: a wheel speed stuck at 0 (frozen_rest.py)
        denied = denied_rest(run, model, rest, float(self.budget_per_hour))
        if denied is not None and denied.any():
            rest = rest & ~denied
            info["rest_denied"] = [[float(run.t[a]), float(run.t[b - 1])] for a, b in zip(*true_runs(denied))]
        for group, j, signal in columns:  # one pass per channel: a few dozen at most
            info["channels"][signal] = group.channels[j] if j < len(group.channels) else group.name
            spec = getattr(model, "groups", {}).get(group.name) if model is not None else None
            if spec is not None and spec.steady:
                info["not_checked"][signal] = (
                    "holds one value over long stretches of healthy operation (the model says so): a freeze "
                    "cannot be told from it"
                )
                continue
            stat, h, sigma, fill, steps, anchor = self._channel(
                run, group, j, model, len(columns), duration, rest, denied
            )
            if stat is None:
                info["not_checked"][signal] = (
                    "fewer than 2 samples"
                    if np.isnan(fill)
                    else "repeats its sample on most steps: a quantised or noiseless sensor that reads "
                    "constant whenever the quantity is still (a freeze cannot be told from stillness)"
                )
                continue
            fresh = np.isfinite(stat)
            alarms = result.add_statistic(run.t, signal, stat, upper=h, valid=fresh)
            for alarm in alarms:  # the first sample that repeated the frozen value: its run's second
                i = int(np.searchsorted(steps, np.searchsorted(run.t, alarm.start)))
                alarm.change_time = float(run.t[steps[anchor[i] + 1]]) if i > anchor[i] else None
            info["fill"][signal], info["h"][signal], info["sigma"][signal] = float(fill), float(h), float(sigma)
        result.info.update(info)
        # listed beside the verdict (logscan.verdict.coverage.skipped_checks), not only in the JSON's info
        result.not_checked = [NotChecked(line) for line in skipped_lines(info["not_checked"], self.name)]
        return result

    def _channel(self, run, group, j: int, model, tests: int, duration: float, rest=None, denied=None):
        """(statistic (N,) NaN off the channel's fresh steps, or None when the channel is not
        checked; threshold h; sigma; fill factor L; the grid steps of its fresh samples; per fresh
        sample the index of its run's first sample, the anchor). Temporaries are the channel's
        samples, not (N,) copies of the grid."""
        fresh = group.channel_fresh[:, j] if group.channel_fresh is not None else group.fresh
        column = group.z[:, j]
        steps = np.flatnonzero(np.asarray(fresh, dtype=bool) & np.isfinite(column))
        none = np.zeros(0, dtype=np.int64)
        if steps.size < 2:  # nothing to compare (the group's own gaps are the other checks' to report)
            return None, np.nan, np.nan, np.nan, none, none
        # a sample on every step: the column itself, copied whole (faster than gathering it)
        v = np.array(column, dtype=np.float64) if steps.size == column.size else np.asarray(column[steps], np.float64)
        # exact repeats first: their typical run is a forward fill's L; repeats on most steps and
        # in many runs: a sensor that holds its value whenever the quantity is still (not checked)
        new = np.concatenate(([True], v[1:] != v[:-1]))
        n_new = int(np.count_nonzero(new))
        fill = 1.0  # no exact repeat: every run is one sample long (L = 1, no sample held)
        if n_new < v.size:
            exact = np.diff(np.append(np.flatnonzero(new), v.size))
            fill = fill_factor(exact)
            if 1.0 - n_new / v.size >= HELD_SHARE and repeat_probability(exact, fill) >= NOISELESS_P:
                return None, np.nan, np.nan, fill, none, none
        noise = channel_noise(v if n_new == v.size else v[new])
        sigma = float(np.fmin(self._stated_sigma(group, j, model), noise))
        # a run starts again after the last sample at rest (module docstring)
        still = np.zeros(0, dtype=bool) if rest is None else np.asarray(rest, dtype=bool)[steps]
        if isinstance(group, InputColumn) and group.rest and np.isfinite(noise):
            # an input held within its own noise of zero (a wheel speed creeping at a count or two
            # of its encoder, 2 mm/s on the real Husky drive against its 7 mm/s) cannot be told from
            # rest: stillness too, as `Model.at_rest`'s
            near_zero = np.abs(v) <= noise
            if denied is not None:  # not where the gyro and the GNSS say it moved
                near_zero &= ~denied[steps]
            still = near_zero if still.size == 0 else still | near_zero
        # r_i: samples held since the anchor (1 at it), and the length of each run
        # an input only repeats exactly when held: a controlled wheel speed cruising at 1.003 m/s
        # stays within still_ratio of its noise for 4 samples on the real Husky drive, by control
        tol = float(self.still_ratio) * sigma if np.isfinite(sigma) and not isinstance(group, InputColumn) else 0.0
        anchor, held, lengths = held_runs(v, tol, still)
        del v, new
        # g_i = r_i / L: samples held since the anchor, in units of the channel's own rate
        stat = on_steps(held / fill, steps, run.n_steps)
        if still.size:
            stat[steps[still]] = np.nan  # stillness, not judged
        h = max(float(self.n_samples), run_threshold(lengths, fill, tests, duration, float(self.budget_per_hour)))
        return stat, h, sigma, fill, steps, anchor

    @staticmethod
    def _stated_sigma(group, j: int, model) -> float:
        """The channel's noise std as the profile states it, else the model's default (NaN: none)."""
        stated = np.nan
        if group.noise_std is not None:
            stated = float(np.broadcast_to(np.asarray(group.noise_std, float), (group.z.shape[1],))[j])
        else:
            spec = getattr(model, "groups", {}).get(group.name) if model is not None else None
            if spec is not None and len(spec.noise_std) == group.z.shape[1]:
                stated = float(spec.noise_std[j])
        return stated

    @staticmethod
    def _signal(model, group, j: int) -> str:
        """frozen.<group>.<output> (the model's output name, else the channel's index); a group of
        one channel: frozen.<group>."""
        width = group.z.shape[1]
        if width == 1:
            return f"{PREFIX}.{group.name}"
        spec = getattr(model, "groups", {}).get(group.name) if model is not None else None
        outputs = list(spec.outputs) if spec is not None and len(spec.outputs) == width else None
        return f"{PREFIX}.{group.name}.{outputs[j] if outputs else j}"


follow_dependencies(__name__)  # the disk cache filed by what the kernels compile (logscan.numba_cache)
