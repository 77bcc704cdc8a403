"""Encoded EKF checks (state check e_x and variance check e_v) of the encoded-EKF paper (docs/algorithms.md section 1).

Coding vector (Lemma 1): alpha_i,k = c_k / sigma_i,k with sigma_i,k = sqrt(P_prior[i,i]) floored at
sigma_min_i = sigma_floor * state_scale_i (NaN-safe), c_k = min(1, R_max / sum_i 1/sigma_i,k).
State check, only on steps with a measurement update: e_x(k) = CV_k x_prior_k - CV_k x_post_k
(= -CV_k K_k y_k; CV_k on both terms, see docs/algorithms.md section 1.8; an angle state's difference wrapped to
[-pi, pi), section 1.2). A step where the filter diverged gets
e_x = NaN, which counts as an exceedance. How e_x is judged (``ex_statistic``, section 1.2):
  raw:        e_x against the adaptive band of eq. 4 (below), rho default 4;
  normalised: z = e_x / sqrt(CV K S K^T CV^T) against a fixed bound from the false-alarm budget;
  window_sum: the sum of z over the last W judged steps, over sqrt(W), against the same bound
              (`logscan.detectors.normalised_check`; both need the trace's K and S).
A measurement the filter rejected (non-finite or outside
the sensor's physical range: a flipped exponent bit gives 1e20) never reaches e_x, so it gets its
own statistic per group, `rejected.<group>`, alarmed at the first such sample (no persistence: an
impossible value is not noise), with the burst merged by a hold-off.
Adaptive threshold (eq. 4): mu_k +- rho s_k over the last W samples that stayed inside their band.
Variance check e_v, with its own mu +- rho_v s band:
  onboard:  e_v(k) = CV_k P_onboard_k CV_k^T - CV_k P_shadow_k CV_k^T over the logged diagonal
            entries (the paper's covariance-computation check applied to the vehicle's estimator);
  observed: e_v(k) = var_W(e_x) - mean_W(CV_k K_k S_k K_k^T CV_k^T).
  Its spread s is floored at rel_floor_v x the check variance (a departure from eq. 4: healthy e_v
  is near zero noise, and two estimators of one model that linearise at slightly different states
  differ by a few per cent in aggressive manoeuvres, which raised 129 false alarms per hour).
On-board state check e_s (when the log carries the vehicle's estimate): e_s(k) = CV_k (x_onboard_k -
x_post_k), the shadow filter checking the estimator's state computation, with a mu +- rho_s s band.
Baseline (the paper's reference [15]): constant CV_0 and a fixed threshold max|e_x| on healthy
training runs times a margin; selected with variant = "baseline", trained by `fit`. With
rejected_checks = false the rejected.<group> statistics are left out (the baseline as the paper
compares it, without a range check; the filter still refuses the samples).

Coverage (stated in the result): e_x weighs each state by 1/sigma, so accelerometer biases and slow
drifts barely move it; bias coverage comes from the NIS detector on the same trace.
"""

from __future__ import annotations

import numpy as np

from logscan.detectors.adaptive_threshold import adaptive_band, trailing_mean_var
from logscan.detectors.base import Detector, DetectorResult, Needs, any_per_row, median_period
from logscan.detectors.budget import check_proof, design_rate
from logscan.detectors.normalised_check import (
    normal_bound,
    normalised_series,
    predicted_variance,
    row_blocks,
    window_sum,
)
from logscan.detectors.params import PERSIST, Boolean, Interval, Options, RealList, budget_bound, multiplier_bound
from logscan.detectors.words import group_words
from logscan.errors import NotTrainedError, ProfileError
from logscan.needs import CodedVariance

POSITIVE = Interval(float, 0, None, closed="neither")
# mu +- rho s: `logscan train --tune` picks at most 20 plus its margin; a wider band hides faults
BAND = multiplier_bound(0, 50, "spreads of the healthy statistic around its mean")
RAW_RHO = 4.0  # rho of the raw e_x's adaptive band when unset (the specification's prototype value)
# a logged on-board estimate's relative rounding: half a unit in the 7th significant digit (7 digits:
# what text loggers print and float32's 24-bit mantissa holds, whose half-ulp is 6e-8 relative)
LOGGED_PRECISION = 5e-7

# The paper's initial coding vectors (section VI), used by the constant-CV baseline.
PAPER_CV0 = {
    "quadcopter": [0.25, 0.25, 0.25, 1.0, 1.0, 0.125, 4.0, 4.0, 4.0, 2.0, 2.0, 2.0],
    "steer_by_wire": [1.0, 1.0, 1.0, 1.0],
}

COVERAGE_NOTE = (
    "e_x weighs each state by 1/sigma: it catches bit flips, actuator offsets and estimator "
    "corruption, but an accelerometer bias or a slow drift barely moves it (see the NIS detector)."
)


def coding_vectors(P_prior_diag: np.ndarray, state_scale: np.ndarray, sigma_floor: float, r_max: float):
    """Time-varying coding vectors CV_k (N, n) from the prior variances (Lemma 1 with the sum bound)."""
    floor = sigma_floor * np.asarray(state_scale, dtype=np.float64)
    # one (N, n) array, worked in place (a 1-hour log: 35 MB, not 4 x 35 MB)
    with np.errstate(invalid="ignore"):
        cv = np.sqrt(P_prior_diag)
    np.fmax(cv, floor, out=cv)  # the floor, NaN-safe: fmax(NaN, floor) = floor
    np.divide(1.0, cv, out=cv)  # 1 / sigma
    # c_k = min(1, R_max / sum_i 1/sigma_i,k): the paper's overflow guard
    c = np.minimum(1.0, r_max / cv.sum(axis=1))
    cv *= c[:, None]
    return cv


SIGNAL_LABELS = {
    "e_x": "the state prediction disagrees with the measurements (encoded check of the state)",
    "e_v": "the filter's uncertainty disagrees with what the measurements show (encoded check of the variance)",
    "e_s": "the vehicle's own estimate disagrees with the filter's (encoded check of the on-board state)",
}


class EncodedEkfDetector(Detector):
    """Encoded EKF checks: state check e_x and variance check e_v with adaptive thresholds."""

    name = "encoded_ekf"
    requires_trace = True
    reads = frozenset(
        {"x_prior", "x_post", "P_prior_diag", "P_post_diag", "ex_variance", "onboard_state", "onboard_variance"}
    )
    default_enabled = True
    trained_attributes = ("threshold_",)
    fit_params = ("margin",)
    defaults = {
        "variant": "adaptive",  # "adaptive" (time-varying CV, mu +- rho s) or "baseline" (CV_0, fixed)
        # how the adaptive variant judges e_x: "raw" (eq. 4's band), "normalised" or "window_sum"
        # (over its predicted spread, against the budget's bound; docs/algorithms.md section 1.2)
        "ex_statistic": "window_sum",
        "rho": None,  # e_x's band factor (raw: 4.0) or bound (normalised, window_sum: from the budget)
        "window": 100,  # W, samples of the trailing window (raw: the band's; window_sum: the sum's)
        "budget_per_hour": 0.1,  # false alarms per hour the normalised e_x may spend
        "proof_hours": 100.0,  # design so that this many healthy hours show it (None: the budget itself)
        "n_persist": 3,
        "variance_check": "auto",  # "auto", "onboard", "observed" or "off"
        "rho_v": 8.0,
        "window_v": 100,
        "sigma_floor": 1e-9,  # sigma_min = sigma_floor * state scale
        "r_max": 1e6,
        "cv0": None,  # baseline coding vector; default: the paper's for the model, else ones
        "margin": 1.0,  # baseline threshold = margin * max |e_x| on healthy training runs
        "threshold": None,  # baseline: a fixed threshold given directly instead of trained
        "rejected_hold_off_s": 1.0,  # rejected samples closer than this form one alarm
        "rel_floor_v": 0.02,  # e_v spread floor, as a fraction of the check variance CV P CV^T
        "onboard_state_check": True,  # e_s: the logged on-board state against the shadow filter
        "rho_s": 8.0,
        # the rejected.<group> statistics; false for the paper's baseline of reference [15], which
        # has no range check (its Table III: constant CV and threshold alone)
        "rejected_checks": True,
    }

    # `logscan train --tune`: each band factor decides the alarms of its own check alone
    tunable = {"rho": ("e_x",), "rho_v": ("e_v",), "rho_s": ("e_s",)}

    parameter_constraints = {
        "variant": [Options("adaptive", "baseline")],
        "ex_statistic": [Options("raw", "normalised", "window_sum")],
        "rho": [BAND, None],
        "budget_per_hour": [budget_bound()],
        "proof_hours": [Interval(float, 0, None, closed="neither"), None],
        "window": [Interval(int, 1, None)],
        "n_persist": [PERSIST],
        "variance_check": [Options("auto", "onboard", "observed", "off")],
        "rho_v": [BAND],
        "window_v": [Interval(int, 1, None)],
        "sigma_floor": [POSITIVE],
        "r_max": [POSITIVE],
        "cv0": [RealList(), None],
        "margin": [multiplier_bound(0, 100, "times the largest healthy |e_x| of training")],
        "threshold": [POSITIVE, None],
        "rejected_hold_off_s": [POSITIVE],
        "rel_floor_v": [Interval(float, 0, None)],
        "onboard_state_check": [Boolean()],
        "rho_s": [BAND],
        "rejected_checks": [Boolean()],
    }

    def check_params(self) -> None:
        super().check_params()
        check_proof(self)

    @classmethod
    def signal_label(cls, signal: str) -> str | None:
        if signal.startswith("rejected."):
            group = group_words(signal.removeprefix("rejected."))
            return f"{group} sample outside its physical range: the filter refused it"
        return SIGNAL_LABELS.get(signal)

    def learns(self) -> bool:
        """Only the baseline variant learns (its fixed threshold); the adaptive one needs nothing."""
        return self.variant == "baseline"

    def needs(self, run=None) -> Needs:
        """The EKF trace; with e_x's predicted variance CV K S K^T CV^T (computed by the filter,
        `CodedVariance`) when e_x is normalised by it or when the variance check may run in observed
        mode (no on-board variances in the log), since e_v then compares var(e_x) with it."""
        predicted = Needs.of(ekf=(CodedVariance(float(self.sigma_floor), float(self.r_max)),))
        if self._normalised():
            return predicted
        no_onboard = run is None or run.onboard_variance is None
        if self.variance_check == "observed" or (self.variance_check == "auto" and no_onboard):
            return predicted
        return Needs.of(ekf=())

    def predicted_variance(self, trace, cv_of):
        """CV_k K_k S_k K_k^T CV_k^T per step (0 where not updated): the filter's (`ex_variance`),
        else from a trace that holds K and S (a trace filtered outside the pipeline); None without."""
        if trace.ex_variance is not None:
            return trace.ex_variance
        if trace.K is None or trace.S is None:
            return None
        return predicted_variance(cv_of, trace.K, trace.S)

    def _normalised(self) -> bool:
        """e_x judged over its predicted spread (the adaptive variant's normalised statistics)."""
        return self.variant == "adaptive" and self.ex_statistic != "raw"

    # --- the check quantities -----------------------------------------------------------------
    def _coding_vectors(self, trace, model):
        """rows -> CV_k over those steps, float64 (N, n) never held at once: recomputing a block from
        P_prior_diag is cheaper than keeping 35 MB per log-hour."""
        n_steps, n = trace.x_prior.shape
        if self.variant == "baseline":
            cv0 = self.cv0 if self.cv0 is not None else PAPER_CV0.get(trace.model_name, [1.0] * n)
            cv0 = np.asarray(cv0, dtype=np.float64)
            if cv0.shape != (n,):
                raise ProfileError(f"detector {self.name!r}: cv0 needs {n} entries, got {cv0.size}")
            return lambda rows: np.broadcast_to(cv0, (len(range(n_steps)[rows]), n))
        scale = model.state_scale() if model is not None else np.ones(n)
        return lambda rows: coding_vectors(trace.P_prior_diag[rows], scale, self.sigma_floor, self.r_max)

    def state_check(self, trace, model=None, cv_dtype=np.float64, cv_of=None):
        """(e_x (N,), defined (N,), CV (N, n) as ``cv_dtype``, None when ``cv_dtype`` is None):
        e_x = CV_k (x_prior_k - x_post_k) on update steps, the difference of an angle state wrapped
        to [-pi, pi) (a heading crossing +-pi is wrapped by the filter, not corrected by 2 pi).
        ``cv_of(rows)``: the coding vectors of those steps (default: computed from the trace)."""
        cv_of = self._coding_vectors(trace, model) if cv_of is None else cv_of
        defined = any_per_row(trace.updated) | trace.diverged
        n_steps, n = trace.x_prior.shape
        angles = _angle_states(model, n)
        e_x = np.empty(n_steps)
        cv = None if cv_dtype is None else np.empty((n_steps, n), dtype=cv_dtype)
        for rows in row_blocks(n_steps):  # no (N, n) float64 temporary
            block = cv_of(rows)
            if cv is not None:
                cv[rows] = block
            diff = trace.x_prior[rows] - trace.x_post[rows]
            diff[:, angles] = (diff[:, angles] + np.pi) % (2.0 * np.pi) - np.pi
            e_x[rows] = np.einsum("kn,kn->k", block, diff)
        e_x[~defined] = np.nan
        e_x[trace.diverged] = np.nan  # a divergence is an exceedance, never silence
        return e_x, defined, cv

    def _fit(self, runs, traces, **context):
        model = context.get("model")
        peak = 0.0
        for trace in traces:
            e_x, defined, _ = self.state_check(trace, model, None)
            finite = e_x[defined & np.isfinite(e_x)]
            if finite.size:
                peak = max(peak, float(np.abs(finite).max()))
        self.threshold_ = self.margin * peak

    # --- run ----------------------------------------------------------------------------------
    def _run(self, run, trace, **context) -> DetectorResult:
        model = context.get("model")
        result = self.new_result()
        # CV for the figure, float32 (half the (N, n) array it keeps). From the trace's float32
        # variances the coding vectors are float32 themselves: the checks then read this one copy,
        # made once, instead of computing them again for each check
        cv_of = self._coding_vectors(trace, model)
        cv = result.extras["coding_vector"] = np.empty(trace.x_prior.shape, dtype=np.float32)
        exact = True
        for rows in row_blocks(cv.shape[0]):
            block = cv_of(rows)
            cv[rows] = block
            exact = exact and block.dtype == np.float32
        self._checks(result, run, trace, model, (lambda rows: cv[rows]) if exact else cv_of)
        return result

    def _checks(self, result, run, trace, model, cv_of) -> None:
        """The state check, and in the adaptive variant the variance and on-board state checks;
        ``cv_of(rows)``: the coding vectors of those steps."""
        t = run.t
        e_x, defined, _ = self.state_check(trace, model, None, cv_of)
        result.info["coverage"] = COVERAGE_NOTE
        result.info["variant"] = self.variant
        result.info["rejected_samples"] = int(trace.rejected.sum())
        if self.rejected_checks:
            self._rejected_checks(result, run, trace)
        if self.variant == "baseline":
            limit = self.threshold if self.threshold is not None else getattr(self, "threshold_", None)
            if limit is None:
                raise NotTrainedError(
                    f"detector {self.name!r} with variant = 'baseline' has no fixed threshold",
                    hint="set [detectors.encoded_ekf] threshold = ..., or train it on healthy logs "
                    "(`logscan train ... -o tables.json`, then --tables tables.json), or use variant = 'adaptive'",
                )
            limit = float(limit)
            result.add_statistic(t, "e_x", e_x, upper=limit, lower=-limit, valid=defined, n_persist=self.n_persist)
            return

        result.info["ex_statistic"] = self.ex_statistic
        if self._normalised():
            self._normalised_check(result, t, trace, cv_of, e_x, defined)
        else:
            self._adaptive_check(result, t, "e_x", e_x, defined, self.window, RAW_RHO if self.rho is None else self.rho)

        mode = self._variance_mode(run, trace)
        result.info["variance_check"] = mode
        if mode != "off":
            e_v, defined_v, scale_v = self.variance_check_series(mode, run, trace, cv_of, e_x, defined)
            # spread floored at a fraction of the check's own variance: two estimators of one model
            # that linearise at slightly different states differ by a few per cent in manoeuvres
            self._adaptive_check(
                result, t, "e_v", e_v, defined_v, self.window_v, self.rho_v, self.rel_floor_v * np.abs(scale_v)
            )
        if self.onboard_state_check and _any_finite(run.onboard_state):
            e_s, defined_s, floor_s = self.onboard_state_series(run, trace, cv_of, model, defined)
            self._adaptive_check(result, t, "e_s", e_s, defined_s, self.window_v, self.rho_s, floor_s)
            result.info["onboard_state_check"] = True

    def end_delays(self, run, trace, result) -> dict[str, float]:
        """e_x summed over the last W checked steps (window_sum) and the observed e_v (a variance over
        the last window_v) can alarm that long after an anomaly (median period between checked
        steps); the other checks judge each sample alone."""
        period = median_period(trace.t, any_per_row(trace.updated))
        delays = {"e_v": self.window_v * period} if result.info.get("variance_check") == "observed" else {}
        if self.variant == "adaptive" and self.ex_statistic == "window_sum":
            delays["e_x"] = self.window * period
        return delays

    def _normalised_check(self, result, t, trace, cv_of, e_x, defined) -> None:
        """e_x over its predicted spread, per sample or summed over W, against +-bound (section 1.2)."""
        predicted = self.predicted_variance(trace, cv_of)
        if predicted is None:
            raise ProfileError(
                f"detector {self.name!r}: ex_statistic = {self.ex_statistic!r} needs e_x's predicted variance "
                "(or K and S) on the trace",
                hint="run it through `logscan analyze` (it asks the pipeline for it), or set ex_statistic = 'raw'",
            )
        z, valid = normalised_series(e_x, defined, predicted)
        warm = valid
        if self.ex_statistic == "window_sum":
            z, warm = window_sum(z, valid, self.window)
        if self.rho is not None:
            bound = float(self.rho)
        else:
            duration = max(float(t[-1] - t[0]), trace.dt) if t.size else 1.0
            rate = design_rate(float(self.budget_per_hour), self.proof_hours)
            bound = normal_bound(rate, float(valid.sum()) / duration)
            result.info["design_rate_per_hour"] = rate
        result.info["ex_bound"] = bound
        result.add_statistic(
            t, "e_x", z, upper=bound, lower=-bound, valid=valid, warmup=valid & ~warm, n_persist=self.n_persist
        )

    def _adaptive_check(self, result, t, name, e, defined, window, rho, s_floor=None) -> None:
        """mu +- rho s band over the masked trailing window, then the shared alarm logic."""
        floor = np.zeros(e.size) if s_floor is None else np.where(np.isfinite(s_floor), s_floor, 0.0)
        _, _, lower, upper, _, warm = adaptive_band(e, defined, window, float(rho), floor)
        result.add_statistic(
            t, name, e, upper=upper, lower=lower, valid=defined, warmup=defined & ~warm, n_persist=self.n_persist
        )

    def _rejected_checks(self, result, run, trace) -> None:
        """One statistic per group with rejected samples: 1 where the filter refused a sample."""
        for g in np.flatnonzero(trace.rejected.any(axis=0)):
            result.add_statistic(
                run.t,
                f"rejected.{trace.group_names[g]}",
                trace.rejected[:, g].astype(np.float64),
                upper=0.5,
                n_persist=1,
                hold_off_s=float(self.rejected_hold_off_s),
                check="e_x",  # a refused sample is a corrupted update, like an e_x exceedance
            )

    def _variance_mode(self, run, trace) -> str:
        has_onboard = _any_finite(run.onboard_variance)
        if self.variance_check == "auto":
            if has_onboard:
                return "onboard"
            has_variance = trace.ex_variance is not None or (trace.K is not None and trace.S is not None)
            return "observed" if has_variance else "off"
        if self.variance_check == "onboard" and not has_onboard:
            raise ProfileError(
                f"detector {self.name!r}: variance_check = 'onboard' needs [onboard] variance channels in the profile"
            )
        return self.variance_check

    def variance_check_series(self, mode, run, trace, cv_of, e_x, defined):
        """(e_v (N,), defined (N,)) for the on-board or observed-vs-predicted variance check;
        ``cv_of(rows)``: the coding vectors of those steps."""
        if mode == "onboard":
            n_steps = trace.n_steps
            e_v, scale, any_logged = np.empty(n_steps), np.empty(n_steps), np.empty(n_steps, dtype=bool)
            for rows in row_blocks(n_steps):  # (N, n) temporaries a block at a time
                onboard, P_post = run.onboard_variance[rows], trace.P_post_diag[rows]
                logged = np.isfinite(onboard)
                every = logged.all()  # the usual block: no entry to leave out
                cv = cv_of(rows)
                alpha_sq = cv * cv
                # e_v = CV P_onboard CV^T - CV P_shadow CV^T over the logged diagonal entries
                difference = onboard - P_post
                e_v[rows] = np.einsum("kn,kn->k", alpha_sq, difference if every else np.where(logged, difference, 0.0))
                scale[rows] = np.einsum("kn,kn->k", alpha_sq, P_post if every else np.where(logged, P_post, 0.0))
                any_logged[rows] = True if every else logged.any(axis=1)
            defined_v = defined & any_logged
            e_v[~defined_v] = np.nan
            return e_v, defined_v, scale
        predicted = self.predicted_variance(trace, cv_of)
        if predicted is None:
            raise ProfileError(
                f"detector {self.name!r}: the observed variance check needs e_x's predicted variance "
                "(or K and S) on the trace"
            )
        _, var_obs = trailing_mean_var(e_x, defined, self.window_v)
        mean_pred, _ = trailing_mean_var(predicted, defined, self.window_v)
        e_v = var_obs - mean_pred
        defined_v = defined & np.isfinite(e_v)
        return e_v, defined_v, mean_pred

    def onboard_state_series(self, run, trace, cv_of, model, defined):
        """(e_s (N,), defined (N,), spread floor (N,)): e_s = CV_k (x_onboard_k - x_post_k) over the
        logged states.

        The offline analogue of the paper's check on the estimator's state computation: the vehicle's
        own estimate against logscan's shadow filter on the same data. Angle states (those a wrapped
        measurement observes directly) are compared modulo 2 pi.

        The two estimators run one model on one data, so e_s is mostly the rounding of the logged
        estimate, and that grows with the value: a logged number keeps about 7 significant digits
        (float32: 7.2; text loggers print 7), so it is within LOGGED_PRECISION |x| of the estimate. An
        unwrapped heading crossing 100 or 1000 rad loses a digit at once, and a band fitted on the
        finer digits alarmed there (8 false alarms in 2 h of the ground robot). The floor is that
        rounding's spread, sqrt(sum_i (CV_i LOGGED_PRECISION x_i)^2 / 3) (uniform error), the least
        that e_s can be trusted to.
        """
        n_steps, n = trace.x_post.shape
        angles = _angle_states(model, n)
        e_s, floor, any_logged = np.empty(n_steps), np.empty(n_steps), np.empty(n_steps, dtype=bool)
        for rows in row_blocks(n_steps):  # (N, n) temporaries a block at a time
            onboard = run.onboard_state[rows]
            logged = np.isfinite(onboard)
            every = logged.all()  # the usual block: no entry to leave out
            cv = cv_of(rows)
            diff = onboard - trace.x_post[rows]
            diff = diff if every else np.where(logged, diff, 0.0)
            diff[:, angles] = (diff[:, angles] + np.pi) % (2.0 * np.pi) - np.pi
            e_s[rows] = np.einsum("kn,kn->k", cv, diff)
            rounding = cv * (LOGGED_PRECISION * np.abs(onboard))
            rounding = rounding if every else np.where(logged, rounding, 0.0)
            floor[rows] = np.sqrt(np.einsum("kn,kn->k", rounding, rounding) / 3.0)
            any_logged[rows] = True if every else logged.any(axis=1)
        defined_s = defined & any_logged
        e_s[~defined_s] = np.nan
        return e_s, defined_s, floor


def _any_finite(series: np.ndarray | None) -> bool:
    """Any finite entry, a block at a time (no (N, n) mask)."""
    if series is None:
        return False
    return any(np.isfinite(series[rows]).any() for rows in row_blocks(series.shape[0]))


def _angle_states(model, n: int) -> np.ndarray:
    """Indices of the states that a wrapped (angular) measurement observes directly."""
    if model is None:
        return np.zeros(0, dtype=np.int64)
    angles = {
        state
        for spec in model.groups.values()
        for state, wrapped in zip(spec.direct_states or (), spec.wrap or ())
        if wrapped and 0 <= state < n
    }
    return np.array(sorted(angles), dtype=np.int64)
