"""UBIKF chi-square test: robust alarms and possible faults over the interval filter's innovation box.

Specified in docs/algorithms.md section 2.2 (the UBIKF paper's section III.B, with the changes
that section states). The UBIKF (`logscan.filters.ubikf`, a second filter of the pipeline, run because
this detector's needs name it) gives per update the innovation box [r_k] = y_k - C [x_prior_k] and
the covariance bound S+. Per update:

    beta_lo = min over r in [r_k] of r^T (S+)^-1 r      (box QP, `logscan.filters.box_chi2`)
    beta_hi = max over r in [r_k] of r^T (S+)^-1 r      (vertex enumeration up to m = 12)

Window sums over the last W updates, degrees of freedom = the measurements of those updates,
delta = chi2.ppf(1 - alpha, dof), alpha from a false-alarm budget (as the NIS test). A "robust
alarm" when the lower sum exceeds delta (the statistic exceeds it for every admissible model). It
is not "guaranteed": the false-alarm probability is still about alpha per test. The paper's W = 4,
alpha = 0.01 remain selectable.

The upper sum is not a warning count: it has no distribution to spend a false-alarm budget on
(it is the statistic of the worst admissible model, so it exceeds delta wherever the innovation
box is wide, about 3,200 times per healthy hour on hover_uav with the paper's intervals). It is
drawn as the upper edge of a band over the lower sum, against delta ("possible fault": where the
band straddles delta, the model's uncertainty could hide a fault), and the share of updates where
it straddles is stated (`info["band_straddles_delta"]`).
"""

from __future__ import annotations

import numpy as np

from logscan.detectors.base import Detector, DetectorResult, Needs
from logscan.detectors.nis import chi2_threshold, window_sums
from logscan.detectors.params import PERSIST, Boolean, Interval, StringList, alpha_bound, budget_bound
from logscan.detectors.ubikf_bound import BoundView, EnvelopeView
from logscan.detectors.words import group_words
from logscan.errors import UsageError
from logscan.filters.box_chi2 import box_chi2_bounds

EXTRA_CAPTIONS = {
    "chi2.upper / delta": "The upper end of the overall test's band: the window sum of the worst admissible "
    "model's statistic (the maximum over the innovation box) over the threshold delta; the lower end is "
    "chi2.lower in the figure above. Where the band straddles 1 the model's uncertainty could hide a fault "
    "there; only the lower end raises alarms, this end has no false-alarm rate to budget.",
    "trace(P+)": "Trace of the UBIKF's covariance upper bound P+ after each update. Normal: it settles to a "
    "constant after a few steps (the paper's Fig. 4); growing without bound means the bound diverges.",
}
ENVELOPE_CAPTION = (
    "The UBIKF's state envelope (the hull of its zonotope: every admissible model's estimate lies "
    "between the lower and upper lines) around its point estimate. Normal: a narrow band hugging the "
    "estimate; it widens while the model cannot explain the data."
)


def _group_rows(ubikf, group: str | None, channel: int | None = None) -> np.ndarray:
    """(N, m) bool view: the measurement rows of one group's test (every row for the overall test;
    one row, ``channel`` of the group, for a channel's test)."""
    rows = np.ones(ubikf.r_mid.shape[1], dtype=bool)
    if group is not None:
        g = list(ubikf.group_names).index(group)
        first = int(ubikf.group_offsets[g])
        rows[:] = False
        if channel is None:
            rows[first : first + int(ubikf.group_sizes[g])] = True
        else:
            rows[first + channel] = True
    return np.broadcast_to(rows, ubikf.r_mid.shape)


def _tests(ubikf, per_group: bool, per_channel: bool) -> list[tuple[str, str | None, str | None, int | None]]:
    """(lower sum's name, upper sum's name or None, group or None, channel or None) of every test:
    the overall one (the paper's), one per measurement group and one per channel of a group of
    several (as the NIS test: a fault of one sensor, or of one channel, is not diluted by the
    others' degrees of freedom, and the alarm names it)."""
    tests: list[tuple[str, str | None, str | None, int | None]] = [("chi2.lower", "chi2.upper", None, None)]
    several = len(ubikf.group_names) > 1
    for g, size in zip(ubikf.group_names, ubikf.group_sizes):
        if per_group and several:
            tests.append((f"chi2.lower.{g}", None, g, None))
        if per_channel and (size > 1 or several):
            tests += [(f"chi2.lower.{g}[{j}]", None, g, j) for j in range(int(size))]
    return tests


def _report_views(result: DetectorResult, ubikf, point_trace, truth: dict | None) -> None:
    """What the report draws of the UBIKF beside the statistics: its bound against the point EKF's
    covariance (`BoundView`, when that trace has P_post_diag) and, on a simulated log whose ground
    truth names the true state of some of its states, its envelopes (`EnvelopeView`; the true state
    itself reaches the report in its run context, `logscan.report.run_context.true_states`)."""
    point = getattr(point_trace, "P_post_diag", None)
    if point is not None and point.shape[1] == ubikf.P_diag.shape[1]:
        result.info["bound_view"] = BoundView(
            ubikf.t, ubikf.P_trace, np.asarray(point, dtype=np.float64).sum(axis=1), ~ubikf.diverged
        )
    if set((truth or {}).get("true_state_fields") or ()) & set(ubikf.state_names):
        result.info["envelope_view"] = EnvelopeView(
            ubikf.t, tuple(ubikf.state_names), ubikf.x_mid, ubikf.x_lo, ubikf.x_hi, ubikf.P_diag, ~ubikf.diverged
        )


class Chi2Detector(Detector):
    """UBIKF chi-square test: robust alarms (lower bound), the upper bound drawn as a band."""

    name = "chi2"
    requires_trace = False  # it reads the UBIKF's trace, not the EKF's
    # the UBIKF trace's S+ and the point EKF's P_post_diag (the pipeline frees what nobody reads)
    reads = frozenset({"S", "P_post_diag"})
    defaults = {
        "window": 10,  # W updates per window sum (the paper: 4)
        "budget_per_hour": 0.1,  # false alarms per hour the test may spend
        "alpha": None,  # set to override the budget (the paper: 0.01)
        "n_persist": 1,
        "states": [],  # states whose envelopes the report draws; empty: the attitude, else the first 3
        "per_group": True,  # also a test per measurement group (False: the paper's overall test only)
        "per_channel": True,  # also a test per channel of each group
    }
    parameter_constraints = {
        "window": [Interval(int, 1, None)],
        "budget_per_hour": [budget_bound()],
        "alpha": [alpha_bound(), None],
        "n_persist": [PERSIST],
        "states": [StringList()],
        "per_group": [Boolean()],
        "per_channel": [Boolean()],
    }

    @classmethod
    def signal_label(cls, signal: str) -> str | None:
        if signal == "chi2.lower":
            return "the measurements disagree with the model whatever its uncertain parameters (robust interval test)"
        if signal == "chi2.upper":
            return "the measurements may disagree with the model for some of its parameters (possible fault)"
        if signal.startswith("chi2.lower."):
            group = group_words(signal.removeprefix("chi2.lower."))
            return f"{group} disagrees with the model whatever its uncertain parameters (robust interval test)"
        return None

    def needs(self, run=None) -> Needs:
        # the point EKF too: the report draws the bound against the point filter's covariance
        return Needs.of(ubikf=(), ekf=())

    def _alpha(self, trace, n_tests: int) -> float:
        if self.alpha is not None:
            return float(self.alpha)
        duration = max(float(trace.t[-1] - trace.t[0]), 1e-9) if trace.t.size > 1 else 1.0
        tests_per_second = max(n_tests / duration, 1e-9)
        return float(self.budget_per_hour) / (3600.0 * tests_per_second)  # alpha = budget / (3600 tests/s)

    def _run(self, run, trace, **context) -> DetectorResult:
        ubikf = (context.get("traces") or {}).get("ubikf")
        if ubikf is None:
            raise UsageError("detector 'chi2' needs the UBIKF trace, but the pipeline did not run it")
        result = self.new_result()
        t = run.t
        tests = _tests(ubikf, bool(self.per_group), bool(self.per_channel))
        bounds = {}
        n_tests = 0
        for lower_name, _, group, channel in tests:
            rows = _group_rows(ubikf, group, channel)
            beta_lo, beta_hi = box_chi2_bounds(ubikf.r_mid, ubikf.r_rad, ubikf.S, rows)
            used = np.isfinite(ubikf.r_mid) & rows
            updated = used.any(axis=1) & ~ubikf.diverged & np.isfinite(beta_lo)
            m_k = used.sum(axis=1)
            bounds[lower_name] = (beta_lo, beta_hi, updated, m_k)
            n_tests += int(updated.sum())
        alpha = self._alpha(ubikf, n_tests)  # the budget is spent over every test
        result.info["alpha"] = alpha
        result.info["window_updates"] = int(self.window)
        for lower_name, upper_name, _, _ in tests:
            beta_lo, beta_hi, updated, m_k = bounds[lower_name]
            steps = np.flatnonzero(updated)
            lower, upper_sum = np.full(t.size, np.nan), np.full(t.size, np.nan)
            delta = np.full(t.size, np.nan)
            warm = np.zeros(t.size, dtype=bool)
            if steps.size:
                m_steps = m_k[steps].astype(np.int64)
                sums_lo, dof, full = window_sums(beta_lo[steps], m_steps, int(self.window))
                sums_hi, _, _ = window_sums(beta_hi[steps], m_steps, int(self.window))
                lower[steps], upper_sum[steps] = sums_lo, sums_hi
                delta[steps] = chi2_threshold(dof, alpha)  # delta = chi2.ppf(1 - alpha, dof)
                warm[steps[~full]] = True
            options = {"valid": updated, "warmup": warm, "n_persist": int(self.n_persist)}
            result.add_statistic(t, lower_name, lower, upper=delta, **options)
            if upper_name is not None:  # the overall test's upper sum: a band over the lower, not a count
                # drawn as its ratio to delta under the lower sums' shared ratio figure (an extra: no
                # alarm, no margin, it is not a statistic with a false-alarm rate)
                with np.errstate(divide="ignore", invalid="ignore"):
                    result.extras[f"{upper_name} / delta"] = (upper_sum / delta).astype(np.float32)
                judged = updated & ~warm
                straddles = judged & (upper_sum > delta) & ~(lower > delta)
                result.info["band_straddles_delta"] = float(straddles.sum() / max(int(judged.sum()), 1))
        if ubikf.diverged.any():
            result.warnings.append(
                f"the UBIKF bound diverged on {int(ubikf.diverged.sum())} steps and restarted; those are not judged"
            )
        self._envelopes(result, ubikf)
        _report_views(result, ubikf, trace or (context.get("traces") or {}).get("ekf"), context.get("truth"))
        result.info["extra_captions"] = {**EXTRA_CAPTIONS, **{s: ENVELOPE_CAPTION for s in self._states(ubikf)}}
        return result

    def _states(self, ubikf) -> list[str]:
        names = list(ubikf.state_names)
        chosen = [s for s in (self.states or []) if s in names]
        if chosen:
            return chosen
        attitude = [s for s in ("roll", "pitch", "yaw") if s in names]
        return attitude or names[:3]

    def _envelopes(self, result: DetectorResult, ubikf) -> None:
        """The selected states' envelopes around the point estimate, and trace(P+), as extras."""
        names = list(ubikf.state_names)
        for state in self._states(ubikf):
            i = names.index(state)
            result.extras[f"lower.{state}"] = ubikf.x_lo[:, i].astype(np.float32)
            result.extras[f"estimate.{state}"] = ubikf.x_mid[:, i].astype(np.float32)
            result.extras[f"upper.{state}"] = ubikf.x_hi[:, i].astype(np.float32)
        result.extras["trace(P+)"] = ubikf.P_trace.astype(np.float32)
