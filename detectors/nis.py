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

import numba
import numpy as np

from logscan.detectors.base import Detector, DetectorResult, any_per_row, median_period, on_steps
from logscan.detectors.budget import check_proof, design_rate
from logscan.detectors.params import PERSIST, Boolean, Interval, alpha_bound, budget_bound
from logscan.detectors.words import group_words
from logscan.numba_cache import follow_dependencies

# A NIS beyond this (far beyond any chi-square threshold: a bit flip, a diverging filter) is summed
# apart: in the running sum it would cost every later window its precision (1e20 leaves no digit of
# the small NIS after it) or overflow the sum (1e308), making later windows NaN, false alarms.
HUGE_NIS = 1e8
_F4_MAX = float(np.finfo(np.float32).max)


def window_sums(values: np.ndarray, counts: np.ndarray, window: int):
    """Trailing sums over the last ``window`` entries of ``values`` and ``counts`` (1-D, aligned).

    Returns (sum_values, sum_counts, full) where full marks entries with a complete window.
    Non-finite values propagate into every window that contains them (they are exceedances); a
    window whose huge values add up beyond float range sums to inf. Each sum is the difference of
    two running sums (float64: `trailing_sums`, one pass; other types: numpy's cumsum, in their type).
    """
    values = np.asarray(values)
    counts = np.asarray(counts)
    if values.dtype == np.float64 and counts.dtype.kind in "iub":
        return trailing_sums(np.ascontiguousarray(values), np.ascontiguousarray(counts, dtype=np.int64), int(window))
    finite = np.isfinite(values)
    huge = finite & (np.abs(values) > HUGE_NIS)
    cv = np.concatenate(([0.0], np.cumsum(np.where(finite & ~huge, values, 0.0))))
    bad = np.concatenate(([0], np.cumsum(~finite)))
    cc = np.concatenate(([0], np.cumsum(counts)))
    idx = np.arange(values.size)
    lo = np.maximum(idx + 1 - window, 0)
    sums = cv[idx + 1] - cv[lo]
    if huge.any():
        add_huge(sums, values, window)
    sums[(bad[idx + 1] - bad[lo]) > 0] = np.inf
    return sums, cc[idx + 1] - cc[lo], idx + 1 >= window


# The kernel allocates nothing and calls no other numba function: its outputs and rings come from
# numpy in `trailing_sums`, which adds the rare huge values itself; numba's generic np.empty /
# np.zeros and min compile apart (types, LLVM, linking), half the kernel's first-run compile.


@numba.njit(cache=True)
def _running_sums(values, counts, window, sums, sum_counts, full, ring_sum, ring_bad, ring_count):  # pragma: no cover
    """`trailing_sums` but the huge values' additions, into its outputs (N,), with three rings of
    min(window, N) + 1 zeros for the running sums at the last window + 1 entries; returns the
    number of huge values."""
    size = ring_sum.size
    running, bad, counted = 0.0, 0, 0
    n_huge = 0
    for i in range(values.size):
        v = values[i]
        finite = np.isfinite(v)
        is_huge = finite and abs(v) > HUGE_NIS
        n_huge += 1 if is_huge else 0
        kept = 0.0 if is_huge or not finite else v
        running = kept if i == 0 else running + kept  # cumsum starts at the first value, not 0 + it
        bad += 0 if finite else 1
        counted += counts[i]
        lo = i + 1 - window  # the window is (lo, i]: the running sums at lo are subtracted
        if lo > 0:
            at = lo % size
            sums[i], sum_counts[i] = running - ring_sum[at], counted - ring_count[at]
            window_bad = bad - ring_bad[at]
        else:
            sums[i], sum_counts[i], window_bad = running - 0.0, counted, bad
        full[i] = lo >= 0
        if window_bad > 0:
            sums[i] = np.inf  # the huge values' additions after this cannot undo it
        at = (i + 1) % size
        ring_sum[at], ring_bad[at], ring_count[at] = running, bad, counted
    return n_huge


def trailing_sums(values: np.ndarray, counts: np.ndarray, window: int):
    """`window_sums` of contiguous float64 ``values`` and int64 ``counts``: the same running sums,
    added in the same order as numpy's cumsum (so the same bits), in one compiled pass; the running
    sums at the last ``window`` + 1 entries are kept in rings, not as (N,) arrays."""
    n = values.size
    sums, sum_counts, full = np.empty(n), np.empty(n, dtype=np.int64), np.empty(n, dtype=np.bool_)
    size = min(window, n) + 1
    # running sums (0 before the first entry) of the finite, not huge values; of the non-finite
    # ones (counted); of ``counts``
    rings = np.zeros(size), np.zeros(size, dtype=np.int64), np.zeros(size, dtype=np.int64)
    if _running_sums(values, counts, window, sums, sum_counts, full, *rings):
        add_huge(sums, values, window)
    return sums, sum_counts, full


def add_huge(sums: np.ndarray, values: np.ndarray, window: int) -> None:
    """Add each huge value of ``values`` (finite, beyond HUGE_NIS: kept out of the running sums) to
    the windows of ``window`` entries that hold it, those ending at its index up to window - 1
    later: by its distance to the window's end, then by index (a window's indices are distinct:
    plain fancy indexing adds once each; a window already inf stays inf)."""
    at = np.flatnonzero(np.isfinite(values) & (np.abs(values) > HUGE_NIS))
    big = values[at]
    with np.errstate(over="ignore", invalid="ignore"):  # beyond float range: inf, an exceedance
        for offset in range(min(window, values.size)):
            ends = at + offset
            keep = ends < values.size
            sums[ends[keep]] += big[keep]


def compile_kernels() -> None:
    """Compile (or load) `trailing_sums`'s kernel for the types the NIS test and the normalised e_x
    pass: the first run calls it while the EKF compiles in its own process."""
    trailing_sums(np.zeros(2), np.ones(2, dtype=np.int64), 1)


def as_float32(values: np.ndarray) -> np.ndarray:
    """``values`` as float32 for the figures; values beyond float32's range become +-inf, as a
    cast would, deliberately (without numpy's overflow warning: such a NIS is off every scale)."""
    values = np.asarray(values, dtype=np.float64)
    beyond = np.abs(values) > _F4_MAX
    if beyond.any():
        values = np.where(beyond, np.copysign(np.inf, values), values)
    return values.astype(np.float32)


def chi2_threshold(dof: np.ndarray, alpha: float) -> np.ndarray:
    """chi2.ppf(1 - alpha, dof) per entry, evaluated once per distinct dof."""
    from scipy.special import chdtri  # here: scipy.special costs ~20 MB, paid only when NIS runs

    dof = np.asarray(dof, dtype=np.int64)
    if dof.size == 0:
        return np.full(dof.shape, np.nan)
    positive = np.where(dof > 0, dof, 0)  # 0: no threshold (NaN)
    table = np.full(int(positive.max()) + 1, np.nan)
    present = np.flatnonzero(np.bincount(positive.ravel()))
    present = present[present > 0]
    table[present] = chdtri(present, alpha)  # = chi2.ppf(1 - alpha, d), once per distinct d
    return table[positive]


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
        "budget_per_hour": [budget_bound()],
        "proof_hours": [Interval(float, 0, None, closed="neither"), None],
        "alpha": [alpha_bound(), None],
        "n_persist": [PERSIST],
        "overall": [Boolean()],
    }

    def check_params(self) -> None:
        super().check_params()
        check_proof(self)

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
        tested = trace.tested  # an outlier the filter's gate left out is tested too
        tests = np.count_nonzero(tested) + (np.count_nonzero(any_per_row(trace.updated)) if self.overall else 0)
        tests_per_second = max(float(tests) / duration, 1e-9)
        # alpha = rate_design / (3600 * tests per second): a union bound over every test
        return design_rate(float(self.budget_per_hour), self.proof_hours) / (3600.0 * tests_per_second)

    def end_delays(self, run, trace, result) -> dict[str, float]:
        """A window sum still holds an anomaly's last update W - 1 updates later: nis.<group>'s alarm
        can outlast an anomaly by W of the group's update periods, nis.all's by W periods between
        updates of any group (medians)."""
        tested = trace.tested
        delays = {
            f"nis.{name}": self.window * median_period(trace.t, tested[:, g])
            for g, name in enumerate(trace.group_names)
        }
        if self.overall:
            delays["nis.all"] = self.window * median_period(trace.t, trace.m_k > 0)
        return delays

    def _run(self, run, trace, **context) -> DetectorResult:
        result = self.new_result()
        t = run.t
        alpha = self._alpha(trace)
        result.info["alpha"] = alpha
        result.info["design_rate_per_hour"] = design_rate(float(self.budget_per_hour), self.proof_hours)
        result.info["window_updates"] = self.window
        # (signal, NIS, updated, measurements per update: an int for a group, per step for all)
        tested = trace.tested  # used in the update, or an outlier the filter's gate left out of it
        tests = [
            (f"nis.{name}", trace.nis_group[:, g], tested[:, g], int(trace.group_sizes[g]))
            for g, name in enumerate(trace.group_names)
        ]
        if self.overall:
            tests.append(("nis.all", trace.nis, trace.m_k > 0, trace.m_k))
        for signal, nis, updated, m in tests:
            steps = np.flatnonzero(updated)
            m_steps = np.full(steps.size, m, dtype=np.int64) if isinstance(m, int) else m[steps]
            sums, dof, full = window_sums(nis[steps], m_steps, self.window)
            statistic = on_steps(sums, steps, t.size)
            threshold = on_steps(chi2_threshold(dof, alpha), steps, t.size)
            per_dof = on_steps(as_float32(sums / np.maximum(dof, 1)), steps, t.size)  # about 1 when consistent
            warmup = np.zeros(t.size, dtype=bool)  # the updates before the first full window
            warmup[steps[~full]] = True
            result.add_statistic(
                t, signal, statistic, upper=threshold, valid=updated, warmup=warmup, n_persist=self.n_persist
            )
            result.extras[f"{signal}.per_dof"] = per_dof
        return result


follow_dependencies(__name__)  # the disk cache filed by what the kernels compile (logscan.numba_cache)
