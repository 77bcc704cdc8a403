"""Kalman gain norm (KGN) test on the shared EKF, per measurement group, gated to steady operation.

Specified in docs/algorithms.md section 3 (the Kalman gain norm paper, with the corrections that
section states). Its parts, one module each:

- Windows (`detectors.kgn_windows`): at every update k, for each measurement column j of the gain
  K_k, N_j(k) = ||K_k[:, j]||_2; Nbar_j(w) = their mean over windows of ``window_s`` aligned to the
  slowest group's updates; a window is judged only in steady operation (the mode unchanged for
  ``hold_s``) after the warm-up (``warmup_s``, and trace(P) settled within ``settle_tol``).
- Operating-point bins (`detectors.kgn_bins`): the mode, split by the flight's own speed, yaw rate
  and thrust where the model has them, at quantiles of the training windows; per populated bin
  (at least ``min_windows`` training windows) and column, ref_j = mean and s_j = std of Nbar_j (s_j
  floored at 1e-9 |ref_j|); d_j(w) = |Nbar_j(w) - ref_j| / s_j. A window of a bin training did not
  populate is not judged, and the result says for how long.
- rho from the false-alarm budget (`detectors.kgn_budget`): an exponential tail fitted to the
  training alarm statistic, with 95 % margins, at the budget's per-window probability.
- Alarm: kgn.<group>(w) = max over the group's columns of d_j(w) against rho for ``n_persist``
  consecutive judged windows (the shared alarm logic).
- Not judged (`detectors.kgn_operating`), said in `not checked` lines: windows outside the trained envelope,
  steady stretches after a manoeuvre beyond the trained range, and any window of a linear model.
- Blindness probe (`detectors.kgn_probe`): a step and a drift on each group's first channel (and a
  sensor-driven model's inputs), re-filtered from a checkpoint over a slice; z < rho: blind.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from logscan.detectors.base import Detector, DetectorResult, Needs, decode_state_value
from logscan.detectors.budget import check_proof, design_rate
from logscan.detectors.kgn_bins import (
    bin_keys,
    bin_references,
    bin_words,
    fit_edges,
    quantity_series,
    window_quantities,
)
from logscan.detectors.kgn_budget import alarm_statistic, budget_rho
from logscan.detectors.kgn_operating import (
    LINEAR_LINE,
    envelope_gate,
    fit_envelope,
    fit_ranges,
    inside,
    memory_gate,
    operating_features,
    outside_line,
    outside_ranges,
    range_line,
)
from logscan.detectors.kgn_probe import run_probe
from logscan.detectors.kgn_windows import (  # noqa: F401  (re-exported: the statistic's helpers)
    NO_MODE,
    GainView,
    column_norms,
    longest_stretch,
    mode_key,
    settle_time,
    steady_steps,
    window_means,
    window_starts,
)
from logscan.detectors.params import PERSIST, Interval, budget_bound, multiplier_bound
from logscan.detectors.words import group_words
from logscan.errors import InternalError, NotTrainedError
from logscan.results import NotChecked

SPREAD_FLOOR = 1e-9  # relative floor of a column's spread: a zero spread alarms on rounding


@dataclasses.dataclass
class Windows:
    """The windows of one run: start steps, end steps, Nbar (W, m), judged mask, mode key and
    operating-point bin key per window (None: no trained bin), operating-point quantities."""

    starts: np.ndarray
    ends: np.ndarray  # last step of each window (where the statistic is placed)
    nbar: np.ndarray
    judged: np.ndarray
    modes: list[str]
    warmup_end_s: float
    has_mode: bool
    op_names: list[str]  # the envelope's features (`detectors.kgn_operating`)
    op: np.ndarray  # (W, F) their values per window
    quantities: dict[str, np.ndarray]  # role -> (W,) window means (`detectors.kgn_bins`)
    bins: list[str | None] = dataclasses.field(default_factory=list)


class KgnDetector(Detector):
    """Kalman gain norm: windowed column norms of the EKF gain against a trained steady reference."""

    name = "kgn"
    requires_fit = True
    requires_trace = True
    reads = frozenset({"K", "P_post_diag", "x_post", "mode", "u"})  # x_post, u: the operating point
    trained_attributes = ("reference_", "rho_", "blindness_", "envelope_")
    # 2: the operating envelope; 3: operating-point bins, rho from the budget; 4: the operating-point
    # range and the linear model's data-independent gain
    state_version = 4
    fit_params = (
        "window_s", "hold_s", "warmup_s", "settle_tol", "probe_size", "probe_slope", "probe_s", "probe_lead_s",
        "envelope_margin", "op_bins", "min_windows", "budget_per_hour", "proof_hours", "n_persist",
    )  # fmt: skip
    defaults = {
        "window_s": 1.0,  # Nbar window, s (aligned to the slowest group's updates)
        "hold_s": 10.0,  # steady: no mode change for this long
        "warmup_s": 35.0,  # minimum warm-up, s (the prototype's P convergence time)
        "settle_tol": 0.05,  # warm-up also lasts until trace(P) stays within this of its later median
        "n_persist": 2,  # consecutive windows over rho
        "rho": None,  # set to override the trained rho
        "budget_per_hour": 0.1,  # false alarms per hour the detector may spend (rho's budget, as nis)
        "proof_hours": 100.0,  # design so that this many healthy hours show the budget met (None: spend it all)
        "op_bins": 2,  # operating-point bins per quantity (speed, yaw rate, thrust) within a mode, at most
        "min_windows": 10,  # training windows a bin needs for a reference (fewer: not judged there)
        "probe_size": 1.0,  # blindness probe: step on each group's first channel, in its unit
        "probe_slope": 0.02,  # blindness probe: drift on each group's first channel, unit per s
        # length of the probe faults, s (at most: the steady stretch may be shorter); a drift's verdict
        # holds for this long (0.02 unit/s reaches 0.3 units)
        "probe_s": 15.0,
        # the probe's slice starts this long before the fault, from a checkpoint (x_post, diag P_post): the
        # covariance recursion forgets the missing off-diagonals (quadcopter: K within 1e-7 after 30 s)
        "probe_lead_s": 30.0,
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
        "budget_per_hour": [budget_bound()],
        "proof_hours": [Interval(float, 0, None, closed="neither"), None],
        "op_bins": [Interval(int, 1, 16)],
        "min_windows": [Interval(int, 2, None)],
        "probe_size": [Interval(float, None, None)],
        "probe_slope": [Interval(float, None, None)],
        "probe_s": [Interval(float, 0, None, closed="neither")],
        "probe_lead_s": [Interval(float, 0, None)],
        "envelope_margin": [Interval(float, 0, None)],
        "envelope_share": [Interval(float, 0, 1)],
    }

    def check_params(self) -> None:
        super().check_params()
        check_proof(self)

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
        fit = ref.get("rho_fit", {})
        how = fit.get("rule", "")
        if "sigma" in fit:
            how += f": u {fit['u']:.3g}, p_u {fit['p_u']:.3g}, sigma {fit['sigma']:.3g}, alpha {fit['alpha']:.3g}"
        lines = [f"  {cls.name}: rho = {rho:.3g} ({how}), {len(ref['bins'])} operating-point bin(s) ({ref['mode']})"]
        for key, row in ref["bins"].items():
            cells = ", ".join(
                f"{g} {np.mean(row['ref'][o : o + s]):.3g}+-{np.mean(row['spread'][o : o + s]):.2g}"
                for g, o, s in zip(ref["groups"], ref["offsets"], ref["sizes"])
            )
            words = bin_words(key, ref["edges"])
            lines.append(f"    bin {words} ({row['windows']} windows): mean Nbar per group {cells}")
        for key, count in ref.get("sparse", {}).items():
            lines.append(f"    bin {bin_words(key, ref['edges'])}: {count} windows, no reference (not judged)")
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
                if "checkpoint_z" in v:
                    word += f"; re-filtered from a checkpoint, clean z {v['checkpoint_z']:.2g}"
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
    def period(self, dt: float) -> int:
        return max(int(round(float(self.window_s) / dt)), 1)

    def windows(self, run, trace, K=None) -> Windows:
        """Nbar per window of a run and its trace (``K`` overrides trace.K), with the judged mask and,
        once trained, each window's operating-point bin."""
        K = trace.K if K is None else K
        if K is None:
            raise InternalError("detector 'kgn': the EKF trace holds no gain K (its needs ask for part 'K')")
        n = run.n_steps
        period = self.period(run.dt)
        updated = np.asarray(trace.updated, dtype=bool)
        counts = updated.sum(axis=0)
        slow = int(np.argmin(np.where(counts > 0, counts, np.iinfo(np.int64).max))) if counts.size else 0
        first = int(np.argmax(updated[:, slow])) if counts.size and counts[slow] else 0
        starts = window_starts(n, period, first)
        nbar = window_means(column_norms(K), starts, period)
        t = run.t
        trace_p = window_means(np.nansum(np.asarray(trace.P_post_diag, dtype=np.float64), axis=1), starts, period)[:, 0]
        t_settle = settle_time(t[starts], trace_p, float(self.settle_tol)) if starts.size else np.inf
        warmup_end = max(float(self.warmup_s), t_settle) + float(t[0] if t.size else 0.0)
        has_mode = run.mode is not None and bool(np.isfinite(run.mode).any())
        steady = steady_steps(t, run.mode if has_mode else None, float(self.hold_s))
        bad = np.concatenate([[0], np.cumsum(~steady)])
        judged = (bad[starts + period] - bad[starts] == 0) & (t[starts] >= warmup_end) & np.isfinite(nbar).any(axis=1)
        modes = [mode_key(v) for v in run.mode[starts]] if has_mode else [NO_MODE] * starts.size
        op_names, op = operating_features(run, starts, period)
        quantities = window_quantities(quantity_series(run, trace), starts, period, window_means)
        w = Windows(starts, starts + period - 1, nbar, judged, modes, warmup_end, has_mode, op_names, op, quantities)
        if hasattr(self, "reference_"):
            w.bins = bin_keys(np.asarray(modes, dtype=object), quantities, self.reference_["edges"])
        return w

    # --- training ---------------------------------------------------------------------------------
    def _fit(self, runs, traces, **context) -> None:
        wins = [self.windows(run, trace) for run, trace in zip(runs, traces)]
        modes = np.concatenate([np.asarray(w.modes, dtype=object)[w.judged] for w in wins])
        pooled = {role: np.concatenate([w.quantities[role][w.judged] for w in wins]) for role in wins[0].quantities}
        edges = fit_edges(modes, pooled, int(self.op_bins), int(self.min_windows))
        per_bin: dict[str, list[np.ndarray]] = {}
        for w in wins:
            w.bins = bin_keys(np.asarray(w.modes, dtype=object), w.quantities, edges)
            for key in sorted({b for b, j in zip(w.bins, w.judged) if j and b is not None}):
                per_bin.setdefault(key, []).append(w.nbar[w.judged & (np.asarray(w.bins, dtype=object) == key)])
        bins, sparse = bin_references(
            {key: np.concatenate(blocks) for key, blocks in per_bin.items()}, int(self.min_windows), SPREAD_FLOOR
        )
        if not bins:
            raise NotTrainedError(
                f"detector 'kgn': no operating point with {self.min_windows} steady windows after warm-up in the "
                "training logs",
                hint=f"train on longer logs with segments of one mode longer than hold_s = {self.hold_s} s after "
                f"warm-up (warmup_s = {self.warmup_s} s), or lower min_windows",
            )
        first = traces[0]
        self.reference_: dict[str, Any] = {
            "mode": "mode channel" if any(w.has_mode for w in wins) else "no mode channel",
            "groups": list(first.group_names),
            "offsets": [int(o) for o in first.group_offsets],
            "sizes": [int(s) for s in first.group_sizes],
            "edges": edges,
            "bins": bins,
            "sparse": sparse,
        }
        self.rho_, self.reference_["rho_fit"] = self._budget_rho(wins)
        # every window after warm-up, steady or not: where the training flights flew
        # a sensor-driven model's inputs are its sensors (ins: the IMU): their means carry the very
        # faults KGN looks for, so its envelope is the manoeuvre's intensity only (the spreads)
        sensors = bool(getattr(context.get("model"), "inputs_are_sensors", False))
        keep = [f for f, name in enumerate(wins[0].op_names) if not (sensors and name.startswith("mean "))]
        warm = [w.op[run.t[w.starts] >= w.warmup_end_s][:, keep] for run, w in zip(runs, wins)]
        self.envelope_ = fit_envelope([wins[0].op_names[f] for f in keep], warm, float(self.envelope_margin))
        sources: dict[str, str] = {}
        quantity_series(runs[0], traces[0], sources)
        # the manoeuvres' range (`memory_gate`): a sensor-driven model's estimated states only
        roles = {role for role, source in sources.items() if sensors and source == "state"}
        after = [{r: w.quantities[r][run.t[w.starts] >= w.warmup_end_s] for r in roles} for run, w in zip(runs, wins)]
        self.reference_["ranges"] = fit_ranges(after)
        # a linear model's K (fixed Q, R: the Riccati recursion) never reads a measurement (`LINEAR_LINE`)
        self.reference_["linear"] = bool(getattr(context.get("model"), "gain_is_data_free", False))
        judged = [w.judged & self.known(w) for w in wins]
        self.blindness_ = run_probe(self, runs, traces, wins, judged, context.get("model"), context.get("refilter"))

    def _budget_rho(self, wins: list[Windows]) -> tuple[float, dict]:
        """rho from the budget over the training windows' alarm statistic (`detectors.kgn_budget`)."""
        alpha = design_rate(float(self.budget_per_hour), self.proof_hours) / (3600.0 / float(self.window_s))
        hs = []
        for w in wins:
            g = self._group_max(self._deviation(w))
            top = np.full(g.shape[0], np.nan)
            has = np.isfinite(g).any(axis=1) & w.judged & self.known(w)
            top[has] = np.nanmax(g[has], axis=1)
            hs.append(alarm_statistic(top, int(self.n_persist)))
        fit = budget_rho(np.concatenate(hs) if hs else np.zeros(0), alpha)
        return float(fit["rho"]), fit

    def known(self, w: Windows) -> np.ndarray:
        """(W,) the windows whose operating-point bin has a trained reference."""
        return np.isin(np.asarray(w.bins, dtype=object), list(self.reference_["bins"]))

    def _per_window(self, w: Windows, field: str) -> np.ndarray:
        """(W, m) each window's bin's ``field`` ("ref" or "spread"), NaN without a trained bin."""
        out = np.full(w.nbar.shape, np.nan)
        keys = np.asarray(w.bins, dtype=object)
        for key, row in self.reference_["bins"].items():
            out[keys == key] = np.asarray(row[field], dtype=np.float64)
        return out

    def window_spreads(self, w: Windows) -> np.ndarray:
        return self._per_window(w, "spread")

    def _deviation(self, w: Windows) -> np.ndarray:
        """(W, m) d_j = |Nbar_j - ref_j| / s_j, NaN in windows whose bin has no reference."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.abs(w.nbar - self._per_window(w, "ref")) / self._per_window(w, "spread")

    def _group_max(self, d: np.ndarray) -> np.ndarray:
        """(W, G) max over each group's columns (NaN where none is finite)."""
        ref = self.reference_
        out = np.full((d.shape[0], len(ref["groups"])), np.nan)
        for g, (o, s) in enumerate(zip(ref["offsets"], ref["sizes"])):
            block = d[:, o : o + s]
            has = np.isfinite(block).any(axis=1)
            out[has, g] = np.nanmax(block[has], axis=1)
        return out

    def probe_targets(self, run, model) -> list:
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
        if not set(envelope["names"]) <= set(w.op_names):
            result.warnings.append(
                "kgn: this log's inputs differ from the training logs' (" + ", ".join(w.op_names) + "): the "
                "trained envelope was not checked"
            )
            return judged
        op = w.op[:, [w.op_names.index(name) for name in envelope["names"]]]
        ok = inside(op, envelope)
        t_starts = run.t[w.starts]
        warm = t_starts >= w.warmup_end_s
        lost, share = envelope_gate(ok, t_starts, warm, judged, float(self.hold_s), float(self.envelope_share))
        result.info["outside_envelope_s"] = float(lost.sum() * float(self.window_s))
        result.info["outside_envelope_share"] = share
        if lost.any():
            seconds, total = lost.sum() * float(self.window_s), judged.sum() * float(self.window_s)
            result.not_checked.append(NotChecked(outside_line(op, envelope, ~ok, seconds, total)))
        return judged & ~lost

    def _in_range(self, run, w: Windows, judged: np.ndarray, result: DetectorResult) -> np.ndarray:
        """``judged`` less the steady stretches after a manoeuvre beyond the trained operating-point
        range (`detectors.kgn_operating.memory_gate`), said in a `not checked` line."""
        ranges = self.reference_.get("ranges", {})
        t_starts = run.t[w.starts]
        outside = outside_ranges(w.quantities, ranges, w.starts.size) & (t_starts >= w.warmup_end_s)
        outside &= ~w.judged  # the manoeuvres' windows (`memory_gate`)
        lost = judged & memory_gate(outside, w.judged)
        result.info["outside_range_s"] = float(lost.sum() * float(self.window_s))
        if lost.any():
            seconds = lost.sum() * float(self.window_s)
            result.not_checked.append(NotChecked(range_line(w.quantities, ranges, outside, seconds)))
        return judged & ~lost

    def _unbinned(self, w: Windows, known: np.ndarray, result: DetectorResult) -> None:
        """Say where steady windows had no trained operating-point bin (not judged there)."""
        missing = w.judged & ~known
        result.info["no_reference_s"] = float(missing.sum() * float(self.window_s))
        if not missing.any():
            return
        keys = [b for b, m in zip(w.bins, missing) if m]
        unseen_modes = sorted({mode for mode, m in zip(w.modes, missing) if m} - set(self.reference_["edges"]))
        named = sorted({k for k in keys if k is not None}, key=lambda k: -keys.count(k))[:2]
        words = "; ".join(bin_words(k, self.reference_["edges"]) for k in named)
        if unseen_modes:
            words = "mode value(s) " + ", ".join(unseen_modes) + (f"; {words}" if words else "")
        result.warnings.append(
            f"kgn: no trained reference for {missing.sum() * float(self.window_s):.0f} s of steady windows "
            f"({words}): not judged there"
        )

    def _run(self, run, trace, **context) -> DetectorResult:
        result = self.new_result()
        t = run.t
        n = run.n_steps
        w = self.windows(run, trace)
        rho = float(self.rho) if self.rho is not None else float(self.rho_)
        known = self.known(w)
        self._unbinned(w, known, result)
        judged = self._in_envelope(run, w, w.judged & known, result)
        if self.reference_.get("linear"):  # nothing to compare (`LINEAR_LINE`)
            result.not_checked.append(NotChecked(LINEAR_LINE.format(seconds=judged.sum() * float(self.window_s))))
            judged = np.zeros_like(judged)
        judged = self._in_range(run, w, judged, result)
        stat = self._group_max(self._deviation(w))
        result.info["rho"] = rho
        result.info["rho_rule"] = self.reference_.get("rho_fit", {}).get("rule", "")
        result.info["window_s"] = float(self.window_s)
        result.info["warmup_end_s"] = float(w.warmup_end_s)
        result.info["judged_windows"] = int(judged.sum())
        result.info["blindness"] = {k: v for k, v in self.blindness_.items() if not k.startswith("_")}
        if "_note" in self.blindness_:
            result.info["blindness_note"] = self.blindness_["_note"]
        if not w.has_mode:
            result.info["steady_gate"] = "none (no mode channel)"
            result.warnings.append("kgn: the run has no mode channel: every window after warm-up counts as steady")
        else:
            result.info["steady_gate"] = f"mode unchanged for {self.hold_s:g} s"
        for kind in ("step", "drift"):
            blind = sorted(g for g, v in result.info["blindness"].items() if v.get(kind, {}).get("blind"))
            if blind:
                result.warnings.append(
                    f"kgn cannot see a {kind} on {', '.join(blind)} (blindness probe: z below rho; open loop)"
                )
        result.info["gain_view"] = self._view(run, w, judged, rho)
        for g, name in enumerate(self.reference_["groups"]):
            statistic = np.full(n, np.nan)
            valid = np.zeros(n, dtype=bool)
            statistic[w.ends] = stat[:, g]
            valid[w.ends] = judged & np.isfinite(stat[:, g])
            result.add_statistic(t, f"kgn.{name}", statistic, upper=rho, valid=valid, n_persist=int(self.n_persist))
        return result

    def _view(self, run, w: Windows, judged: np.ndarray, rho: float) -> GainView:
        """The per-window gain norms and bands the report draws (`detectors.kgn_windows.GainView`)."""
        ref = self.reference_
        columns = [
            (run.groups[name].channels + [""] * size)[j] if name in run.groups else f"{name}[{j}]"
            for name, size in zip(ref["groups"], ref["sizes"])
            for j in range(size)
        ]
        words = {key: bin_words(key, ref["edges"]) for key in set(w.bins) if key is not None}
        return GainView(
            t=run.t[w.ends],
            nbar=w.nbar.astype(np.float32),
            ref=self._per_window(w, "ref").astype(np.float32),
            spread=self._per_window(w, "spread").astype(np.float32),
            judged=judged,
            bins=[words.get(key, "") if key is not None else "" for key in w.bins],
            rho=rho,
            groups=list(ref["groups"]),
            offsets=list(ref["offsets"]),
            sizes=list(ref["sizes"]),
            columns=columns,
        )
