"""Two-sided CUSUM on each whitened innovation of the shared EKF, per measurement group and axis.

Specified in docs/algorithms.md section 1e. The sequential test for slow faults (drifts, small
biases, a stuck sensor whose innovation walks away) that the windowed NIS sees only once they are
large. Per output j of group g, at each update of the group:

    u_k   = y~_k,j / sqrt(S_k,jj)                              whitened innovation, N(0, 1) when healthy
    S+_k  = min(c h_j, max(0, S+_k-1 + u_k - kappa))           upward drift of the mean
    S-_k  = min(c h_j, max(0, S-_k-1 - u_k - kappa))           downward drift
    g_k   = S+_k if S+_k >= S-_k else -S-_k                    the signed statistic, alarm when |g_k| > h_j

(u_k clipped to +-``clip`` first: a one-sample glitch is the NIS test's to flag, not a drift.)

kappa is the reference value (half the shift, in innovation standard deviations, the test is
tuned to). h_j comes from the false-alarm budget through Siegmund's approximation of the average
run length of a one-sided CUSUM on N(0, 1) samples,

    ARL0(h) = (exp(2 kappa b) - 2 kappa b - 1) / (2 kappa^2),   b = h + 1.166,

solved for ARL0_j = margin J r_j 3600 / budget_per_hour updates, where J = 2 x (outputs over every
group) one-sided tests and r_j the group's updates per second, so that the J tests together raise at
most ``budget_per_hour`` false alarms per hour (a union bound: it holds whatever the tests'
correlation). ``arl_margin`` (default 10) covers the healthy innovations' slow wander, which
shortens the run length of a test tuned to small shifts (measured, docs/algorithms.md section 1e).

Resets to zero: when an alarm ends (|g| falls back to h or below: the alarm's evidence is spent, the
next alarm needs a full h of new evidence, which is what the ARL counts); at a filter divergence
(the filter restarts); across a gap in a group's updates longer than max(gap_s, 5 update periods).
The statistic is held at most c h (``cap``) so that an alarm ends soon after the fault does. The
same sums without the cap (restarted with them) give the size the cap hides: for each alarm whose
uncapped statistic went past its capped peak, ``info["uncapped_peaks"][signal]`` has that peak
(the report's alarm table shows it; the alarm's own peak stays the capped statistic's, 1.5 h at
most, so incidents keep quoting by the statistics as drawn).
The change time reported with each alarm (``AlarmInterval.change_time``) is Page's estimate: the
first update after the last time the alarming side was zero.
"""

from __future__ import annotations

import numba
import numpy as np

from logscan.detectors.base import Detector, DetectorResult, Needs, median_period
from logscan.detectors.budget import check_proof, design_rate
from logscan.detectors.params import (
    MIN_DESIGN_RATE_PER_HOUR,
    SLOWEST_TESTS_PER_HOUR,
    Interval,
    budget_bound,
    multiplier_bound,
)
from logscan.detectors.words import group_words
from logscan.errors import ProfileError
from logscan.numba_cache import follow_dependencies

POSITIVE = Interval(float, 0, None, closed="neither")
SIEGMUND_SHIFT = 1.166  # b = h + 1.166: the overshoot correction of Siegmund's approximation
GAP_PERIODS = 5.0  # a gap longer than this many update periods resets a test


def siegmund_arl(h, kappa: float):
    """ARL0(h) = (exp(2 kappa b) - 2 kappa b - 1) / (2 kappa^2), b = h + 1.166: the mean number of
    N(0, 1) samples before a one-sided CUSUM with reference kappa crosses h (kappa -> 0: b^2)."""
    b = np.asarray(h, dtype=np.float64) + SIEGMUND_SHIFT
    if kappa == 0:
        return b * b
    x = 2.0 * kappa * b
    return (np.expm1(x) - x) / (2.0 * kappa * kappa)


def threshold_for_arl(arl, kappa: float) -> np.ndarray:
    """The h whose Siegmund ARL0 is ``arl`` (vectorised bisection on the monotone ARL0(h))."""
    arl = np.atleast_1d(np.asarray(arl, dtype=np.float64))
    lo = np.zeros(arl.shape)
    hi = np.full(arl.shape, 1.0)
    while np.any(siegmund_arl(hi, kappa) < arl):  # doubles until bracketed: a few dozen at most
        hi = np.where(siegmund_arl(hi, kappa) < arl, 2.0 * hi, hi)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        low = siegmund_arl(mid, kappa) < arl
        lo, hi = np.where(low, mid, lo), np.where(low, hi, mid)
    return 0.5 * (lo + hi)


# The kernel allocates nothing and calls no other numba function (its outputs come from numpy in
# `cusum_statistics`; each side's step written out): numba's generic np.empty and a helper compile
# apart (types, LLVM, linking into the caller), about a third of this kernel's first-run compile.


@numba.njit(cache=True)
def cusum_kernel(t, y, S_diag, column, reset, gap, h, kappa, cap, clip, g, onset, free):  # pragma: no cover
    """`cusum_statistics` of one column of y and S_diag, with its gap and threshold h, into its
    outputs g, onset, free (N,), each entry written once."""
    sp = sm = fp = fm = 0.0  # S+, S-, and the same sides without the cap
    p0 = m0 = -1  # the first step of each side's run (-1: the side is at 0)
    last = -np.inf
    on = False
    top = cap * h
    for i in range(y.shape[0]):
        if reset[i]:
            sp, sm, fp, fm, p0, m0, on = 0.0, 0.0, 0.0, 0.0, -1, -1, False
        x = y[i, column] / np.sqrt(S_diag[i, column])  # u = y~ / sqrt(S_jj)
        if not np.isfinite(x):
            g[i], free[i], onset[i] = np.nan, np.nan, -1
            continue
        if t[i] - last > gap:
            sp, sm, fp, fm, p0, m0, on = 0.0, 0.0, 0.0, 0.0, -1, -1, False
        last = t[i]
        x = min(max(x, -clip), clip)
        # each side: S_k = max(0, S_k-1 + u_k - kappa) held at ``top``, its run starting at
        # the step where it leaves 0; S+ on u_k, S- on -u_k (min / max, not conditional
        # expressions: numba turns those into branches, a third slower here)
        step = sp + x - kappa
        if step <= 0.0:
            sp, p0 = 0.0, -1
        else:
            p0 = i if sp == 0.0 else p0
            sp = min(step, top)
        step = sm - x - kappa
        if step <= 0.0:
            sm, m0 = 0.0, -1
        else:
            m0 = i if sm == 0.0 else m0
            sm = min(step, top)
        fp = max(0.0, fp + x - kappa)
        fm = max(0.0, fm - x - kappa)
        now = max(sp, sm) > h
        if on and not now:  # the alarm ended: its evidence is spent, both sides restart
            sp, sm, fp, fm, p0, m0 = 0.0, 0.0, 0.0, 0.0, -1, -1
        on = now
        if sp >= sm:
            g[i], free[i], onset[i] = sp, fp, p0
        else:
            g[i], free[i], onset[i] = -sm, -fm, m0


def cusum_statistics(t, y, S_diag, first, reset, gap, h, kappa, cap, clip):
    """Signed two-sided CUSUM per column with its resets (docs/algorithms.md section 1e).

    t (N,) grid times; y, S_diag (N, M) innovations and their variances, NaN where a column has no
    update (whitened in the kernel, u = y / sqrt(S), so no (N, M) temporaries), of which the J
    columns from ``first`` on are tested (read in place: no copy of a column);
    reset (N,) bool, steps where every test restarts (filter divergence); gap (J,) s, a longer gap
    between a column's updates restarts it; h (J,) thresholds; kappa reference; cap: statistics held
    at most cap * h; clip: each u enters at most +-clip (one glitch cannot raise an alarm alone).
    Returns g (N, J), the signed statistic (NaN without update); onset (N, J), the first step of
    the run of the side g shows (-1 when that side is zero); and free (N, J), the same sides without
    the cap (restarted with them), whose peak is an alarm's real magnitude.
    """
    shape = (gap.size, y.shape[0])  # a row per column: the kernel fills contiguous (N,) arrays
    g, free, onset = np.empty(shape), np.empty(shape), np.empty(shape, dtype=np.int64)
    settings = (kappa, cap, clip)
    for j in range(gap.size):
        cusum_kernel(t, y, S_diag, first + j, reset, float(gap[j]), float(h[j]), *settings, g[j], onset[j], free[j])
    return g.T, onset.T, free.T


def compile_kernels() -> None:
    """Compile (or load) `cusum_kernel` for the types `Cusum` passes (the EKF trace's float32
    innovations and variances): the first run calls it while the EKF compiles in its own process."""
    y = np.zeros((2, 1), dtype=np.float32)
    cusum_statistics(np.zeros(2), y, y + 1.0, 0, np.zeros(2, dtype=bool), np.ones(1), np.ones(1), 0.5, 2.0, 5.0)


def uncapped_peaks(alarms, t: np.ndarray, free: np.ndarray, h: float) -> list[dict]:
    """Where the cap hid an alarm's size: per alarm whose uncapped statistic ``free`` (N,) went
    further than its (capped) peak, ``{start, end, peak_time, peak_value, peak_threshold,
    peak_ratio}`` of the uncapped peak (the sign kept, the ratio positive). The capped statistic sits
    at cap x h for as long as the fault lasts, which says nothing of its size."""
    out = []
    for alarm in alarms:
        lo, hi = np.searchsorted(t, [alarm.start, alarm.end], side="left")
        part = free[lo : hi + 1]
        defined = np.flatnonzero(np.isfinite(part))
        if defined.size == 0 or alarm.bound == "nonfinite":
            continue
        k = int(defined[np.argmax(np.abs(part[defined]))])
        value = float(part[k])
        if abs(value) <= abs(float(alarm.peak_value)):
            continue
        threshold = h if value > 0 else -h
        out.append({
            "start": float(alarm.start), "end": float(alarm.end), "peak_time": float(t[lo + k]),
            "peak_value": value, "peak_threshold": threshold, "peak_ratio": value / threshold,
        })  # fmt: skip
    return out


def check_hiding(detector) -> None:
    """Refuse, at creation, settings under which no healthy test could alarm at the lowest design
    rate (`MIN_DESIGN_RATE_PER_HOUR`): they would hide faults. A clip at or under kappa keeps the
    statistic at zero; an ARL margin that divides the budget below the floor; a fixed h whose ARL0,
    at one update per 100 s, is over 3.6e13 updates."""
    name, kappa = detector.name, float(detector.kappa)
    if float(detector.clip) <= kappa:
        raise ProfileError(
            f"detector {name!r}: clip = {float(detector.clip):g} is not above kappa = {kappa:g}: no innovation "
            "could ever raise the statistic, it would hide faults",
            hint="clip must exceed kappa (defaults: clip 4, kappa 0.25)",
        )
    designed = design_rate(float(detector.budget_per_hour), detector.proof_hours) / float(detector.arl_margin)
    if designed < MIN_DESIGN_RATE_PER_HOUR:
        raise ProfileError(
            f"detector {name!r}: budget_per_hour {float(detector.budget_per_hour):g} with arl_margin "
            f"{float(detector.arl_margin):g} designs for {designed:.2g} false alarms per hour, under "
            f"{MIN_DESIGN_RATE_PER_HOUR:g}: it would hide faults",
            hint="lower arl_margin or raise budget_per_hour",
        )
    if detector.h is None:
        return
    longest = SLOWEST_TESTS_PER_HOUR / MIN_DESIGN_RATE_PER_HOUR  # ARL0 in updates at the lowest rate
    with np.errstate(over="ignore"):
        arl = float(siegmund_arl(float(detector.h), kappa))
    if not arl <= longest:
        highest = float(threshold_for_arl(longest, kappa)[0])
        raise ProfileError(
            f"detector {name!r}: h = {float(detector.h):g} at kappa = {kappa:g} gives a healthy test an average run "
            f"of {arl:.2g} updates, under {MIN_DESIGN_RATE_PER_HOUR:g} false alarms per hour at one update per "
            "100 s: it would hide faults",
            hint=f"use h <= {highest:.3g} at this kappa, or leave h unset to follow budget_per_hour",
        )


def output_names(model, group: str, size: int) -> list[str]:
    """The group's output names from the model ("ax", "ay", "az"), else "0", "1", ...; a group of
    one output is named by the group alone."""
    spec = getattr(model, "groups", {}).get(group) if model is not None else None
    names = list(spec.outputs) if spec is not None and len(spec.outputs) == size else [str(i) for i in range(size)]
    return [""] if size == 1 else names


class CusumDetector(Detector):
    """Two-sided CUSUM on each whitened innovation (per group and axis): slow drifts and small biases."""

    name = "cusum"
    requires_trace = True
    reads = frozenset({"y", "S_diag"})
    default_enabled = True
    defaults = {
        "kappa": 0.25,  # reference value: half the mean shift (in innovation std) the test is tuned to
        "budget_per_hour": 0.1,  # false alarms per hour the whole detector may spend (sets h)
        "arl_margin": 10.0,  # design ARL x this: healthy innovations wander slowly (docs/algorithms.md 1e)
        "proof_hours": 100.0,  # design so that this many healthy hours show the budget met (as nis)
        "h": None,  # set to override the budget: one threshold for every test
        "cap": 1.5,  # the statistic is held at most cap x h
        "clip": 4.0,  # each whitened innovation enters at most +-clip (a glitch is NIS's, not a drift)
        "gap_s": 1.0,  # a longer gap in a group's updates (and at least 5 update periods) restarts it
        "hold_off_s": 1.0,  # crossings closer than this form one alarm
    }
    parameter_constraints = {
        "kappa": [Interval(float, 0, None)],
        "budget_per_hour": [budget_bound()],
        "arl_margin": [multiplier_bound(1, 1e6, "times the budget's design run length", closed="both")],
        "proof_hours": [POSITIVE, None],
        "h": [multiplier_bound(0, 1000, "innovation standard deviations of drift before an alarm"), None],
        "cap": [Interval(float, 1, None, closed="neither")],
        "clip": [POSITIVE],
        "gap_s": [POSITIVE],
        "hold_off_s": [Interval(float, 0, None)],
    }

    @classmethod
    def signal_label(cls, signal: str) -> str | None:
        prefix, _, rest = signal.partition(".")
        if prefix != "cusum" or not rest:
            return None
        group, _, output = rest.partition(".")
        what = group_words(group) + (f" {output}" if output else "")
        return f"{what} drifts away from the model's prediction (cumulative innovation test, CUSUM)"

    def check_params(self) -> None:
        super().check_params()
        check_proof(self)
        check_hiding(self)

    def needs(self, run=None) -> Needs:
        return Needs.of(ekf=("y",))

    def thresholds(self, trace) -> tuple[np.ndarray, np.ndarray]:
        """(h per measurement column, the ARL0 in updates it was solved for)."""
        sizes = trace.group_sizes.astype(np.int64)
        duration = max(float(trace.t[-1] - trace.t[0]), trace.dt) if trace.t.size else 1.0
        rate = np.repeat(trace.tested.sum(axis=0) / duration, sizes)  # updates per second per column
        tests = 2 * int(sizes.sum())  # two one-sided tests per column
        # ARL0_j = margin J r_j 3600 / rate_design: J equal shares of the rate a proof_hours demonstration
        # shows within the budget (`detectors.budget`), with the design margin
        designed = design_rate(float(self.budget_per_hour), self.proof_hours)
        arl = np.maximum(float(self.arl_margin) * tests * rate * 3600.0 / designed, 1.0)
        if self.h is not None:
            return np.full(arl.size, float(self.h)), siegmund_arl(np.full(arl.size, float(self.h)), self.kappa)
        return threshold_for_arl(arl, float(self.kappa)), arl

    def _run(self, run, trace, **context) -> DetectorResult:
        result = self.new_result()
        t = run.t
        h, arl = self.thresholds(trace)
        settings = (float(self.kappa), float(self.cap), float(self.clip))
        gaps = self._gaps(trace)
        model = context.get("model")
        y, S_diag = np.ascontiguousarray(trace.y), np.ascontiguousarray(trace.S_diag)  # no copy: the trace's own
        result.info.update(kappa=float(self.kappa), budget_per_hour=float(self.budget_per_hour), tests=2 * h.size)
        result.info["h"], result.info["arl0_updates"] = {}, {}
        for g, group in enumerate(trace.group_names):
            for j, output in zip(self._columns(trace, g), output_names(model, group, int(trace.group_sizes[g]))):
                signal = f"cusum.{group}" + (f".{output}" if output else "")
                # one column at a time: (N,) temporaries, not the (N, J) statistic and onsets at once
                column = slice(j, j + 1)
                inputs = (t, y, S_diag, j, trace.diverged, gaps[column], h[column])
                stat, onset, free = cusum_statistics(*inputs, *settings)
                stat, onset, free = stat[:, 0], onset[:, 0], free[:, 0]
                valid = np.isfinite(stat)
                alarms = result.add_statistic(
                    t, signal, stat, upper=h[j], lower=-h[j], valid=valid, hold_off_s=self.hold_off_s
                )
                for alarm in alarms:  # Page's change-time estimate at the crossing
                    first = int(onset[np.searchsorted(t, alarm.start)])
                    alarm.change_time = float(t[first]) if first >= 0 else None
                saturated = uncapped_peaks(alarms, t, free, float(h[j]))
                if saturated:
                    result.info.setdefault("uncapped_peaks", {})[signal] = saturated
                result.info["h"][signal] = float(h[j])
                result.info["arl0_updates"][signal] = float(arl[j])
        return result

    def end_delays(self, run, trace, result) -> dict[str, float]:
        """After an anomaly the capped statistic falls from cap h back to h by kappa per update on
        average (healthy whitened innovations have mean 0): (cap - 1) h / kappa of the group's update
        periods (median); kappa = 0 never falls back (inf)."""
        kappa, delays = float(self.kappa), {}
        tested = trace.tested
        for g, group in enumerate(trace.group_names):
            period = median_period(trace.t, tested[:, g])
            for signal, h in result.info.get("h", {}).items():
                if signal == f"cusum.{group}" or signal.startswith(f"cusum.{group}."):
                    updates = (float(self.cap) - 1.0) * h / kappa if kappa > 0 else np.inf
                    delays[signal] = updates * period
        return delays

    def _gaps(self, trace) -> np.ndarray:
        """Per measurement column, the gap between updates that restarts its tests (s)."""
        gap = np.zeros(int(trace.group_sizes.sum()))
        tested = trace.tested
        for g in range(len(trace.group_names)):  # a handful of groups
            steps = tested[:, g]
            period = median_period(trace.t, steps) if np.count_nonzero(steps) > 1 else trace.dt
            gap[self._columns(trace, g)] = max(float(self.gap_s), GAP_PERIODS * period)
        return gap

    @staticmethod
    def _columns(trace, g: int) -> np.ndarray:
        offset = int(trace.group_offsets[g])
        return np.arange(offset, offset + int(trace.group_sizes[g]))


follow_dependencies(__name__)  # the disk cache filed by what the kernels compile (logscan.numba_cache)
