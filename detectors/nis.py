"""Innovation chi-square (NIS) test on the shared EKF, per measurement group and overall.

Specified in docs/algorithms.md section 1b.

Per update nis_k = y~^T S^-1 y~ with m_k measurements; the statistic is the sum over the last W
updates (of that group, or of any group for the overall test) against
delta_k = chi2.ppf(1 - alpha, sum of m over those updates) (multi-rate: the degrees of freedom follow
the updates actually in the window). alpha comes from a false-alarm budget (docs/algorithms.md
section 1b, "The false-alarm budget"):

    alpha = rate_design / (3600 * tests per second)            (union bound over every test)

tests counted over every group's updates and the overall test's, so the whole detector spends the
budget whatever the tests' correlation (consecutive windows share W - 1 terms and the overall test
repeats the groups': measured, an exceedance comes in clumps of about 2, so the union bound is
conservative by about that factor; the credit is not taken). rate_design is the rate at which a
healthy demonstration of ``proof_hours`` hours shows the budget met (the upper bound of the exact
95 % Poisson interval at or below ``budget_per_hour``) with probability 0.9 (`design_rate`); without
``proof_hours`` it is the budget itself. An alarm on a group's test names that sensor; this is the
test that catches sensor biases, which the encoded checks cannot see.
"""

from __future__ import annotations

import numpy as np

from logscan.detectors.base import Detector, DetectorResult
from logscan.detectors.params import Boolean, Interval
from logscan.detectors.words import group_words
from logscan.errors import ProfileError

# A NIS beyond this (far beyond any chi-square threshold: a bit flip, a diverging filter) is summed
# apart: in the running sum it would cost every later window its precision (1e20 leaves no digit of
# the small NIS after it) or overflow the sum (1e308), making later windows NaN, false alarms.
HUGE_NIS = 1e8
_F4_MAX = float(np.finfo(np.float32).max)


def window_sums(values: np.ndarray, counts: np.ndarray, window: int):
    """Trailing sums over the last ``window`` entries of ``values`` and ``counts`` (1-D, aligned).

    Returns (sum_values, sum_counts, full) where full marks entries with a complete window.
    Non-finite values propagate into every window that contains them (they are exceedances); a
    window whose huge values add up beyond float range sums to inf.
    """
    finite = np.isfinite(values)
    huge = finite & (np.abs(values) > HUGE_NIS)
    cv = np.concatenate(([0.0], np.cumsum(np.where(finite & ~huge, values, 0.0))))
    bad = np.concatenate(([0], np.cumsum(~finite)))
    cc = np.concatenate(([0], np.cumsum(counts)))
    idx = np.arange(values.size)
    lo = np.maximum(idx + 1 - window, 0)
    sums = cv[idx + 1] - cv[lo]
    at = np.flatnonzero(huge)
    if at.size:
        # each huge value is added to the windows that hold it, those ending at its index up to
        # window - 1 later (a window's indices are distinct: plain fancy indexing adds once each)
        big = values[at]
        with np.errstate(over="ignore", invalid="ignore"):  # beyond float range: inf, an exceedance
            for offset in range(min(window, values.size)):
                ends = at + offset
                keep = ends < values.size
                sums[ends[keep]] += big[keep]
    sums[(bad[idx + 1] - bad[lo]) > 0] = np.inf
    return sums, cc[idx + 1] - cc[lo], idx + 1 >= window


def as_float32(values: np.ndarray) -> np.ndarray:
    """``values`` as float32 for the figures; values beyond float32's range become +-inf, as a
    cast would, deliberately (without numpy's overflow warning: such a NIS is off every scale)."""
    values = np.asarray(values, dtype=np.float64)
    beyond = np.abs(values) > _F4_MAX
    if beyond.any():
        values = np.where(beyond, np.copysign(np.inf, values), values)
    return values.astype(np.float32)


# A demonstration of the budget: the exact (two-sided) Poisson interval's confidence, whose upper end
# must be within the budget, and the probability that a detector running at its design rate passes
# (the consumer's and the producer's risk of a fixed-length demonstration test, as in MIL-HDBK-781's
# plans: 2.5 % and 10 %).
PROOF_CONFIDENCE = 0.95
PROOF_PASS_PROBABILITY = 0.9


def design_rate(budget_per_hour: float, proof_hours: float | None) -> float:
    """False alarms per hour to design for, so that ``proof_hours`` healthy hours show the upper end
    of the rate's exact 95 % Poisson interval at or below ``budget_per_hour`` with probability 0.9.

    c = the most alarms whose upper end chi2.ppf(0.975, 2c + 2) / (2 T) stays within the budget;
    rate = chi2.ppf(0.1, 2c + 2) / (2 T), the rate at which P(at most c alarms in T hours) = 0.9.
    T = 100 h, budget 0.1/h: c = 3, rate 0.0174/h. None: the budget itself. A demonstration too
    short to ever show the budget (budget x T < 3.69, the upper end with no alarm) is refused when
    the detector is created (`NisDetector.check_params`)."""
    from scipy.special import chdtri  # chdtri(d, q) = chi2.ppf(1 - q, d)

    if proof_hours is None:
        return float(budget_per_hour)
    hours = float(proof_hours)
    # the upper end of c alarms in T hours, against the budget (a relative 1e-12: at exactly
    # proof_shortest_hours the two sides differ by rounding)
    upper = lambda c: chdtri(2 * c + 2, (1.0 - PROOF_CONFIDENCE) / 2.0) / (2.0 * hours) / (1.0 + 1e-12)  # noqa: E731
    if upper(0) > budget_per_hour:
        raise ValueError(f"{hours:g} h cannot show a budget of {budget_per_hour:g} per hour")
    c = 0
    while upper(c + 1) <= budget_per_hour:  # a few steps: c grows like budget x T
        c += 1
    return float(chdtri(2 * c + 2, PROOF_PASS_PROBABILITY)) / (2.0 * hours)


def proof_shortest_hours(budget_per_hour: float) -> float:
    """The shortest demonstration that can show ``budget_per_hour``: no alarm, upper end = budget."""
    from scipy.special import chdtri

    return float(chdtri(2, (1.0 - PROOF_CONFIDENCE) / 2.0)) / (2.0 * budget_per_hour)


def chi2_threshold(dof: np.ndarray, alpha: float) -> np.ndarray:
    """chi2.ppf(1 - alpha, dof) per entry, evaluated once per distinct dof."""
    from scipy.special import chdtri  # here: scipy.special costs ~20 MB, paid only when NIS runs

    dof = np.asarray(dof, dtype=np.int64)
    out = np.full(dof.shape, np.nan)
    for d in np.unique(dof[dof > 0]):  # a handful of distinct values, not a per-sample loop
        out[dof == d] = chdtri(d, alpha)  # = chi2.ppf(1 - alpha, d)
    return out


class NisDetector(Detector):
    """Innovation chi-square test (windowed NIS) per measurement group and overall."""

    name = "nis"
    requires_trace = True
    reads = frozenset()  # only the NIS series, update masks and counts, which are never freed
    default_enabled = True
    defaults = {
        "window": 10,  # W updates per window sum
        "budget_per_hour": 0.1,  # false alarms per hour the whole detector may spend
        "proof_hours": 100.0,  # design so that this many healthy hours show the budget met (None: spend it all)
        "alpha": None,  # set to override the budget (e.g. the paper's 0.01)
        "n_persist": 1,
        "overall": True,  # also test the stacked update of all groups
    }

    parameter_constraints = {
        "window": [Interval(int, 1, None)],
        "budget_per_hour": [Interval(float, 0, None, closed="neither")],
        "proof_hours": [Interval(float, 0, None, closed="neither"), None],
        "alpha": [Interval(float, 0, 1, closed="neither"), None],
        "n_persist": [Interval(int, 1, None)],
        "overall": [Boolean()],
    }

    def check_params(self) -> None:
        super().check_params()
        if self.proof_hours is not None:
            try:
                design_rate(float(self.budget_per_hour), self.proof_hours)
            except ValueError as exc:
                shortest = proof_shortest_hours(float(self.budget_per_hour))
                raise ProfileError(
                    f"detector {self.name!r}: proof_hours: {exc}", hint=f"use at least {shortest:.4g} h, or null"
                ) from None

    @classmethod
    def signal_label(cls, signal: str) -> str | None:
        prefix, _, group = signal.partition(".")
        if prefix != "nis" or not group:
            return None
        if group == "all":
            return (
                "all sensors together disagree with the model's prediction beyond their noise (overall innovation test)"
            )
        return f"{group_words(group)} disagrees with the model's prediction beyond its noise (innovation test)"

    def _alpha(self, trace) -> float:
        if self.alpha is not None:
            return float(self.alpha)
        duration = max(float(trace.t[-1] - trace.t[0]), trace.dt) if trace.t.size else 1.0
        tests = trace.updated.sum() + (trace.updated.any(axis=1).sum() if self.overall else 0)
        tests_per_second = max(float(tests) / duration, 1e-9)
        # alpha = rate_design / (3600 * tests per second): a union bound over every test
        return design_rate(float(self.budget_per_hour), self.proof_hours) / (3600.0 * tests_per_second)

    def _run(self, run, trace, **context) -> DetectorResult:
        result = self.new_result()
        t = run.t
        alpha = self._alpha(trace)
        result.info["alpha"] = alpha
        result.info["design_rate_per_hour"] = design_rate(float(self.budget_per_hour), self.proof_hours)
        result.info["window_updates"] = self.window
        # (signal, NIS, updated, measurements per update: an int for a group, per step for all)
        tests = [
            (f"nis.{name}", trace.nis_group[:, g], trace.updated[:, g], int(trace.group_sizes[g]))
            for g, name in enumerate(trace.group_names)
        ]
        if self.overall:
            tests.append(("nis.all", trace.nis, trace.m_k > 0, trace.m_k))
        for signal, nis, updated, m in tests:
            steps = np.flatnonzero(updated)
            statistic = np.full(t.size, np.nan)
            threshold = np.full(t.size, np.nan)
            per_dof = np.full(t.size, np.nan, dtype=np.float32)  # about 1 on a consistent filter (figures)
            warm = np.zeros(t.size, dtype=bool)
            if steps.size:
                m_steps = np.full(steps.size, m, dtype=np.int64) if isinstance(m, int) else m[steps]
                sums, dof, full = window_sums(nis[steps], m_steps, self.window)
                statistic[steps] = sums
                threshold[steps] = chi2_threshold(dof, alpha)
                per_dof[steps] = as_float32(sums / np.maximum(dof, 1))
                warm[steps[full]] = True
            result.add_statistic(
                t, signal, statistic, upper=threshold, valid=updated, warmup=updated & ~warm, n_persist=self.n_persist
            )
            result.extras[f"{signal}.per_dof"] = per_dof
        return result
