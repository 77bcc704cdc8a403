"""Kalman gain norm (KGN) test on the shared EKF, per measurement group, gated to steady operation.

Specified in docs/algorithms.md section 3 (the Kalman gain norm paper, with the corrections that
section states).

- Column norms: at every update k, for each measurement column j of the gain K_k (n x m),
  N_j(k) = ||K_k[:, j]||_2 (NaN where column j was not updated at step k).
- Window means: Nbar_j(w) = mean of N_j(k) over the updates k in window w; windows are blocks of
  fixed time (``window_s``, default 1 s) that start at the first update of the slowest group, so
  each window holds the same number of slow updates (the norms jump at every slow update).
- Steady gate (mandatory): a window is judged only when the profile's mode channel has not changed
  for ``hold_s`` seconds up to the window's start and does not change inside it; without a mode
  channel the whole run after warm-up counts as steady (said in the result's info and warnings).
- Warm-up: no window is judged before t_w = max(warmup_s, t_P), t_P the first time after which
  the window mean of trace(P_post) stays within ``settle_tol`` of its median over the run's second
  half (the filter's covariance has converged: K is then a function of the operating point only).
- Reference (`fit`, healthy runs): per operating-point bin (the mode value; one bin without a
  mode) and column, ref_j = mean and s_j = std of Nbar_j over the judged training windows,
  s_j floored at 1e-9 * |ref_j|. Deviation d_j(w) = |Nbar_j(w) - ref_j| / s_j;
  rho = max over the training windows of d_j(w) + 1 (the smallest false-alarm-free value plus 1).
- Alarm: statistic kgn.<group>(w) = max over the group's columns of d_j(w), against rho, for
  ``n_persist`` consecutive judged windows (the shared alarm logic).
- Operating envelope (`fit`; `detectors.kgn_operating`): the box of the training windows' input
  means and spreads (widened by ``envelope_margin``); a window outside it, or within ``hold_s``
  after one, is not judged, and the result says so in a `not checked` line, not in alarms.
- Blindness probe (`fit`, needs the model): a step of ``probe_size`` (the group's unit) on the
  first channel of each group, and on the first input of each sensor that drives a sensor-driven
  model (ins: gyro_x, accel_x), for ``probe_s`` seconds in a judged segment of the training runs,
  re-filtered by the pipeline (the EKF with its gain: a probe of the needs, `refilter` in the fit
  context; the detector runs no filter itself); z_g = max over the probe windows and the group's
  columns (every column for an input) of |Nbar_fault - Nbar_clean| / s_j. z_g < rho: KGN cannot see
  that fault on this model and filter (`blindness_`, result.info["blindness"] and a warning naming
  the groups).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from logscan.detectors.base import Detector, DetectorResult, Needs, decode_state_value
from logscan.detectors.kgn_operating import envelope_gate, fit_envelope, inside, operating_features, outside_line
from logscan.detectors.modes import mode_changes
from logscan.detectors.params import PERSIST, Interval, multiplier_bound
from logscan.detectors.words import group_words
from logscan.errors import InternalError, NotTrainedError
from logscan.results import NotChecked

SPREAD_FLOOR = 1e-9  # relative floor of a column's spread: a zero spread alarms on rounding
NO_MODE = "all"  # the single operating-point bin of a run without a mode channel


# --- window means -----------------------------------------------------------------------------------


def column_norms(K: np.ndarray) -> np.ndarray:
    """(N, m) N_j(k) = ||K_k[:, j]||_2 of a (N, n, m) gain series, NaN where column j has no update."""
    K = np.asarray(K, dtype=np.float64)
    return np.sqrt(np.einsum("knm,knm->km", K, K))


def window_starts(n_steps: int, period: int, first: int) -> np.ndarray:
    """First step of every complete window of ``period`` steps, the first one starting at ``first``."""
    first = max(int(first), 0)
    count = max((n_steps - first) // period, 0)
    return first + period * np.arange(count, dtype=np.int64)


def window_means(values: np.ndarray, starts: np.ndarray, period: int) -> np.ndarray:
    """(W, m) mean of the finite entries of ``values`` (N, m) over steps [s, s + period) of each
    window start s (NaN where a column has no finite entry in the window), by cumulative sums."""
    values = np.asarray(values, dtype=np.float64)
    if values.ndim == 1:
        values = values[:, None]
    finite = np.isfinite(values)
    cv = np.concatenate([np.zeros((1, values.shape[1])), np.cumsum(np.where(finite, values, 0.0), axis=0)])
    cc = np.concatenate([np.zeros((1, values.shape[1]), dtype=np.int64), np.cumsum(finite, axis=0)])
    sums = cv[starts + period] - cv[starts]
    counts = cc[starts + period] - cc[starts]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)


def steady_steps(t: np.ndarray, mode: np.ndarray | None, hold_s: float) -> np.ndarray:
    """(N,) bool: the mode has not changed for ``hold_s`` seconds (the log's start counts as a change;
    a NaN mode is never steady). All True without a mode channel."""
    t = np.asarray(t, dtype=np.float64)
    if mode is None:
        return np.ones(t.size, dtype=bool)
    mode = np.asarray(mode, dtype=np.float64)
    if mode.size == 0:
        return np.zeros(0, dtype=bool)
    changed = mode_changes(mode)
    last = np.maximum.accumulate(np.where(changed, np.arange(mode.size), 0))
    return (t - t[last] >= hold_s) & np.isfinite(mode)


def settle_time(t_windows: np.ndarray, trace_p: np.ndarray, tol: float) -> float:
    """First window time after which the window mean of trace(P) stays within ``tol`` (relative) of
    its median over the second half of the windows; inf when it never settles."""
    ok = np.isfinite(trace_p)
    if not ok.any():
        return math.inf
    tail = trace_p[ok][ok.sum() // 2 :]
    median = float(np.median(tail))
    inside = ok & (np.abs(trace_p - median) <= tol * abs(median))
    outside = np.flatnonzero(~inside)
    if outside.size == 0:
        return float(t_windows[0]) if t_windows.size else 0.0
    if outside[-1] + 1 >= t_windows.size:
        return math.inf
    return float(t_windows[outside[-1] + 1])


@dataclasses.dataclass
class Windows:
    """The windows of one run: start steps, end steps, Nbar (W, m), judged mask, bin key per window."""

    starts: np.ndarray
    ends: np.ndarray  # last step of each window (where the statistic is placed)
    nbar: np.ndarray
    judged: np.ndarray
    bins: list[str]
    warmup_end_s: float
    has_mode: bool
    op_names: list[str]  # the operating-point features (`detectors.kgn_operating`)
    op: np.ndarray  # (W, F) their values per window


def longest_stretch(mask: np.ndarray) -> tuple[int, int]:
    """(first index, length) of the longest run of True in ``mask`` ((0, 0) when none)."""
    mask = np.asarray(mask, dtype=bool)
    if not mask.any():
        return 0, 0
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    first, stop = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    k = int(np.argmax(stop - first))
    return int(first[k]), int(stop[k] - first[k])


def mode_key(value: float) -> str:
    """The operating-point bin of a mode value (a JSON key)."""
    return NO_MODE if not np.isfinite(value) else f"{float(value):g}"


# --- the detector ---------------------------------------------------------------------------------


class KgnDetector(Detector):
    """Kalman gain norm: windowed column norms of the EKF gain against a trained steady reference."""

    name = "kgn"
    requires_fit = True
    requires_trace = True
    reads = frozenset({"K", "P_post_diag", "mode"})
    trained_attributes = ("reference_", "rho_", "blindness_", "envelope_")
    state_version = 2  # 2: the operating envelope
    fit_params = (
        "window_s", "hold_s", "warmup_s", "settle_tol", "probe_size", "probe_slope", "probe_s", "envelope_margin",
    )  # fmt: skip
    defaults = {
        "window_s": 1.0,  # Nbar window, s (aligned to the slowest group's updates)
        "hold_s": 10.0,  # steady: no mode change for this long
        "warmup_s": 35.0,  # minimum warm-up, s (the prototype's P convergence time)
        "settle_tol": 0.05,  # warm-up also lasts until trace(P) stays within this of its later median
        "n_persist": 2,  # consecutive windows over rho
        "rho": None,  # set to override the trained rho
        "probe_size": 1.0,  # blindness probe: step on each group's first channel, in its unit
        "probe_slope": 0.02,  # blindness probe: drift on each group's first channel, unit per s
        # length of the probe faults, s (at most: the steady stretch may be shorter); a drift's verdict
        # holds for this long (0.02 unit/s reaches 0.3 units)
        "probe_s": 15.0,
        "envelope_margin": 1.0,  # the trained envelope's box widened by this x its width on each side
        "envelope_share": 0.5,  # a flight with more of its windows outside the envelope is not checked at all
    }
    parameter_constraints = {
        "window_s": [Interval(float, 0, None, closed="neither")],
        "hold_s": [Interval(float, 0, None)],
        "warmup_s": [Interval(float, 0, None)],
        "settle_tol": [Interval(float, 0, None, closed="neither")],
        "n_persist": [PERSIST],
        "rho": [multiplier_bound(0, 1e6, "the Kalman gain norm's distance from its healthy reference"), None],
        "probe_size": [Interval(float, None, None)],
        "probe_slope": [Interval(float, None, None)],
        "probe_s": [Interval(float, 0, None, closed="neither")],
        "envelope_margin": [Interval(float, 0, None)],
        "envelope_share": [Interval(float, 0, 1)],
    }

    @classmethod
    def signal_label(cls, signal: str) -> str | None:
        prefix, _, group = signal.partition(".")
        if prefix != "kgn" or not group:
            return None
        return f"the filter weighs the {group_words(group)} unlike on healthy runs (Kalman gain norm)"

    def needs(self, run=None) -> Needs:
        # the log's EKF with its gain; the same EKF again on the blindness probe's faulty runs (`fit`)
        return Needs.of(ekf=("K",), probes=("ekf",))

    def learns(self) -> bool:
        return True

    @classmethod
    def state_lines(cls, state) -> list[str]:
        """rho, the reference per bin and group, and the blindness verdicts."""
        st = decode_state_value(state["state"])
        ref, rho, blind = st["reference_"], st["rho_"], st["blindness_"]
        lines = [f"  {cls.name}: rho = {rho:.3g}, {len(ref['bins'])} operating-point bin(s) ({ref['mode']})"]
        for key, row in ref["bins"].items():
            cells = ", ".join(
                f"{g} {np.mean(row['ref'][o : o + s]):.3g}+-{np.mean(row['spread'][o : o + s]):.2g}"
                for g, o, s in zip(ref["groups"], ref["offsets"], ref["sizes"])
            )
            lines.append(f"    bin {key} ({row['windows']} windows): mean Nbar per group {cells}")
        envelope = st["envelope_"]
        for name, lo, hi in zip(envelope["names"], envelope["lo"], envelope["hi"]):
            lines.append(f"    envelope: {name} {lo:.3g} to {hi:.3g}")
        for group, verdict in blind.items():
            if not isinstance(verdict, dict):
                lines.append(f"    probe: {verdict}")
                continue
            for kind, v in verdict.items():
                word = "cannot see it" if v["blind"] else "sees it"
                lasted = f" for {v['probe_s']:.3g} s" if "probe_s" in v else ""
                lines.append(
                    f"    probe {group} {kind} {v['size']:g} ({v['unit']}){lasted} on {v['channel']}: "
                    f"z = {v['z']:.3g} vs rho {v['rho']:.3g} ({word})"
                )
        return lines

    def check_trained(self) -> None:
        if not all(hasattr(self, name) for name in self.trained_attributes):
            raise NotTrainedError(
                "detector 'kgn' has no reference gain norms",
                hint="train it with `logscan train HEALTHY_LOG... -o tables.json` (and --profile FILE, the "
                "profile enabling [detectors.kgn], when the logs embed none), then pass --tables tables.json",
            )

    # --- windows ----------------------------------------------------------------------------------
    def _period(self, dt: float) -> int:
        return max(int(round(float(self.window_s) / dt)), 1)

    def windows(self, run, trace, K=None) -> Windows:
        """Nbar per window of a run and its trace (``K`` overrides trace.K), with the judged mask."""
        K = trace.K if K is None else K
        if K is None:
            raise InternalError("detector 'kgn': the EKF trace holds no gain K (its needs ask for part 'K')")
        n = run.n_steps
        period = self._period(run.dt)
        updated = np.asarray(trace.updated, dtype=bool)
        counts = updated.sum(axis=0)
        slow = int(np.argmin(np.where(counts > 0, counts, np.iinfo(np.int64).max))) if counts.size else 0
        first = int(np.argmax(updated[:, slow])) if counts.size and counts[slow] else 0
        starts = window_starts(n, period, first)
        ends = starts + period - 1
        nbar = window_means(column_norms(K), starts, period)
        t = run.t
        trace_p = window_means(np.nansum(np.asarray(trace.P_post_diag, dtype=np.float64), axis=1), starts, period)[:, 0]
        t_settle = settle_time(t[starts], trace_p, float(self.settle_tol)) if starts.size else math.inf
        warmup_end = max(float(self.warmup_s), t_settle) + float(t[0] if t.size else 0.0)
        has_mode = run.mode is not None and bool(np.isfinite(run.mode).any())
        steady = steady_steps(t, run.mode if has_mode else None, float(self.hold_s))
        bad = np.concatenate([[0], np.cumsum(~steady)])
        judged = (bad[starts + period] - bad[starts] == 0) & (t[starts] >= warmup_end) & np.isfinite(nbar).any(axis=1)
        bins = [mode_key(v) for v in run.mode[starts]] if has_mode else [NO_MODE] * starts.size
        op_names, op = operating_features(run, starts, period)
        return Windows(starts, ends, nbar, judged, bins, warmup_end, has_mode, op_names, op)

    # --- training ---------------------------------------------------------------------------------
    def _fit(self, runs, traces, **context) -> None:
        per_bin: dict[str, list[np.ndarray]] = {}
        first = traces[0]
        wins = [self.windows(run, trace) for run, trace in zip(runs, traces)]
        for w in wins:
            for key in sorted(set(w.bins)):
                sel = w.judged & (np.asarray(w.bins) == key)
                if sel.any():
                    per_bin.setdefault(key, []).append(w.nbar[sel])
        if not per_bin:
            raise NotTrainedError(
                "detector 'kgn': no steady window after warm-up in the training logs",
                hint=f"train on logs with segments of one mode longer than hold_s = {self.hold_s} s after "
                f"warm-up (warmup_s = {self.warmup_s} s)",
            )
        bins = {}
        for key, blocks in per_bin.items():
            values = np.concatenate(blocks)
            ref = np.nanmean(values, axis=0)
            spread = np.maximum(np.nanstd(values, axis=0), SPREAD_FLOOR * np.abs(ref))
            bins[key] = {"ref": ref, "spread": spread, "windows": int(values.shape[0])}
        self.reference_ = {
            "mode": "mode channel" if any(w.has_mode for w in wins) else "no mode channel",
            "groups": list(first.group_names),
            "offsets": [int(o) for o in first.group_offsets],
            "sizes": [int(s) for s in first.group_sizes],
            "bins": bins,
        }
        worst = 0.0
        for w in wins:
            d = self._deviation(w)
            if np.isfinite(d[w.judged]).any():
                worst = max(worst, float(np.nanmax(d[w.judged])))
        self.rho_ = worst + 1.0
        # every window after warm-up, steady or not: where the training flights flew
        warm = [w.op[run.t[w.starts] >= w.warmup_end_s] for run, w in zip(runs, wins)]
        self.envelope_ = fit_envelope(wins[0].op_names, warm, float(self.envelope_margin))
        self.blindness_ = self._probe(runs, wins, context.get("model"), context.get("refilter"))

    def _deviation(self, w: Windows) -> np.ndarray:
        """(W, m) d_j = |Nbar_j - ref_j| / s_j, NaN in windows whose bin has no reference."""
        bins = self.reference_["bins"]
        m = w.nbar.shape[1]
        ref = np.full((len(w.bins), m), np.nan)
        spread = np.full((len(w.bins), m), np.nan)
        keys = np.asarray(w.bins)
        for key, row in bins.items():
            sel = keys == key
            ref[sel] = np.asarray(row["ref"], dtype=np.float64)
            spread[sel] = np.asarray(row["spread"], dtype=np.float64)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.abs(w.nbar - ref) / spread

    def _group_max(self, d: np.ndarray) -> np.ndarray:
        """(W, G) max over each group's columns (NaN where none is finite)."""
        ref = self.reference_
        out = np.full((d.shape[0], len(ref["groups"])), np.nan)
        for g, (o, s) in enumerate(zip(ref["offsets"], ref["sizes"])):
            block = d[:, o : o + s]
            has = np.isfinite(block).any(axis=1)
            out[has, g] = np.nanmax(block[has], axis=1)
        return out

    def _probe(self, runs, wins: list[Windows], model, refilter) -> dict:
        """Blindness verdict per group and fault kind (see the module docstring): per operating-point
        bin, the longest stretch (up to ``probe_s``) of judged windows of that bin in the training
        runs gets the fault on the group's first channel; z = max |Nbar_fault - Nbar_clean| / s_j
        over the stretch and the group's columns; blind when z < rho in every bin. ``refilter``: the
        pipeline's EKF on a faulty run (`logscan.pipeline.stages.fit_context`)."""
        if model is None:
            return {"_note": "no model given to fit: the probe did not run"}
        if refilter is None:
            return {"_note": "no refilter given to fit (the pipeline's EKF for the probe): the probe did not run"}

        span = max(int(math.ceil(float(self.probe_s) / float(self.window_s))), 1)
        stretches = {}  # bin -> (run index, first window, count)
        for r, w in enumerate(wins):
            keys = np.asarray(w.bins)
            for key in self.reference_["bins"]:
                first, count = longest_stretch(w.judged & (keys == key))
                best = stretches.get(key)
                if count and (best is None or min(count, span) > best[2]):
                    stretches[key] = (r, first, min(count, span))
        rho = float(self.rho_)
        kinds = {"step": float(self.probe_size), "drift": float(self.probe_slope)}
        verdicts: dict = {}
        for name, channel, inject, cols in self._probe_targets(runs[0], model):
            for kind, size in kinds.items():
                scores = {}
                lasted = 0.0  # the longest probe, s
                for key, (r, w0, count) in stretches.items():
                    run, w = runs[r], wins[r]
                    period = self._period(run.dt)
                    lo, hi = int(w.starts[w0]), int(w.starts[w0 + count - 1] + period)
                    fault = size * np.ones(hi - lo) if kind == "step" else size * (run.t[lo:hi] - run.t[lo])
                    faulty = inject(run, lo, hi, fault)
                    if faulty is None:
                        continue
                    ftrace = refilter("ekf", faulty)
                    fw = self.windows(faulty, ftrace)
                    spread = np.asarray(self.reference_["bins"][key]["spread"], dtype=np.float64)[cols]
                    sl = slice(w0, w0 + count)
                    with np.errstate(invalid="ignore", divide="ignore"):
                        dz = np.abs(fw.nbar[sl, cols] - w.nbar[sl, cols]) / spread
                    scores[key] = float(np.nanmax(dz)) if np.isfinite(dz).any() else 0.0
                    lasted = max(lasted, float(run.t[hi - 1] - run.t[lo]) if hi > lo else 0.0)
                if not scores:
                    continue
                z_max = max(scores.values())
                unit = "unit/s" if kind == "drift" else "unit"
                verdicts.setdefault(name, {})[kind] = {
                    "size": size,
                    "unit": unit,
                    "channel": channel,
                    "z": z_max,
                    "z_per_bin": scores,
                    "probe_s": round(lasted, 3),
                    "rho": rho,
                    "blind": bool(z_max < rho),
                }
        if not verdicts:
            return {"_note": "no steady stretch in the training logs: the probe did not run"}
        return verdicts

    def _probe_targets(self, run, model) -> list:
        """(name, channel, inject(run, lo, hi, fault) -> faulty run or None, K columns scored) of every
        probe: each measurement group's first channel (scored on the group's columns) and, for a model
        driven by sensors (ins: the IMU), the first input of each sensor (gyro_x, accel_x), scored on
        every column (an input has none of its own)."""
        ref = self.reference_

        def on_group(name):
            def inject(r, lo, hi, fault):
                group = r.groups.get(name)
                if group is None:
                    return None
                z = np.array(group.z, dtype=np.float64, copy=True)
                (z if z.ndim == 1 else z[:, 0])[lo:hi] += fault
                return dataclasses.replace(r, groups={**r.groups, name: dataclasses.replace(group, z=z)})

            return inject

        def on_input(col):
            def inject(r, lo, hi, fault):
                u = np.array(r.u, dtype=np.float64, copy=True)
                u[lo:hi, col] += fault
                return dataclasses.replace(r, u=u)

            return inject

        out = []
        for g, name in enumerate(ref["groups"]):
            o, s = ref["offsets"][g], ref["sizes"][g]
            channel = run.groups[name].channels[0] if name in run.groups else ""
            out.append((name, channel, on_group(name), slice(o, o + s)))
        if getattr(model, "inputs_are_sensors", False):
            every = slice(0, int(sum(ref["sizes"])))
            seen = set()
            for col, input_name in enumerate(model.input_names):
                sensor = input_name.rsplit("_", 1)[0]
                if sensor in seen:
                    continue
                seen.add(sensor)
                channel = run.input_channels[col] if col < len(run.input_channels) else input_name
                out.append((f"{sensor} (input)", channel, on_input(col), every))
        return out

    # --- detection ----------------------------------------------------------------------------------
    def _in_envelope(self, run, w: Windows, judged: np.ndarray, result: DetectorResult) -> np.ndarray:
        """``judged`` less the windows outside the trained envelope or within hold_s after one; a
        `not checked` line says for how long and where (`detectors.kgn_operating`)."""
        envelope = self.envelope_
        if w.op_names != envelope["names"]:
            result.warnings.append(
                "kgn: this log's inputs differ from the training logs' (" + ", ".join(w.op_names) + "): the "
                "trained envelope was not checked"
            )
            return judged
        ok = inside(w.op, envelope)
        t_starts = run.t[w.starts]
        warm = t_starts >= w.warmup_end_s
        lost, share = envelope_gate(ok, t_starts, warm, judged, float(self.hold_s), float(self.envelope_share))
        result.info["outside_envelope_s"] = float(lost.sum() * float(self.window_s))
        result.info["outside_envelope_share"] = share
        if lost.any():
            seconds, total = lost.sum() * float(self.window_s), judged.sum() * float(self.window_s)
            result.not_checked.append(NotChecked(outside_line(w.op, envelope, ~ok, seconds, total)))
        return judged & ~lost

    def _run(self, run, trace, **context) -> DetectorResult:
        result = self.new_result()
        t = run.t
        n = run.n_steps
        w = self.windows(run, trace)
        rho = float(self.rho) if self.rho is not None else float(self.rho_)
        known = np.isin(np.asarray(w.bins, dtype=object), list(self.reference_["bins"]))
        judged = self._in_envelope(run, w, w.judged & known, result)
        stat = self._group_max(self._deviation(w))
        result.info["rho"] = rho
        result.info["window_s"] = float(self.window_s)
        result.info["warmup_end_s"] = float(w.warmup_end_s)
        result.info["judged_windows"] = int(judged.sum())
        result.info["blindness"] = {k: v for k, v in self.blindness_.items() if not k.startswith("_")}
        if "_note" in self.blindness_:
            result.info["blindness_note"] = self.blindness_["_note"]
        if not w.has_mode:
            note = "kgn: the run has no mode channel: every window after warm-up counts as steady"
            result.info["steady_gate"] = "none (no mode channel)"
            result.warnings.append(note)
        else:
            result.info["steady_gate"] = f"mode unchanged for {self.hold_s:g} s"
        unknown = sorted({b for b, j, k in zip(w.bins, w.judged, known) if j and not k})
        if unknown:
            names = ", ".join(unknown)
            result.warnings.append(f"kgn: no trained reference for mode value(s) {names}: not judged there")
        for kind in ("step", "drift"):
            blind = sorted(g for g, v in result.info["blindness"].items() if v.get(kind, {}).get("blind"))
            if blind:
                result.warnings.append(
                    f"kgn cannot see a {kind} on {', '.join(blind)} (blindness probe: z below rho; open loop)"
                )
        for g, name in enumerate(self.reference_["groups"]):
            statistic = np.full(n, np.nan)
            valid = np.zeros(n, dtype=bool)
            statistic[w.ends] = stat[:, g]
            valid[w.ends] = judged & np.isfinite(stat[:, g])
            result.add_statistic(t, f"kgn.{name}", statistic, upper=rho, valid=valid, n_persist=int(self.n_persist))
        return result
