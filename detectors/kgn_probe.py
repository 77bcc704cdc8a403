"""KGN's blindness probe: can the gain norms see a step or a drift on a sensor at all (docs/algorithms.md
section 3, "Blindness probe")?

Per mode, the longest stretch (up to ``probe_s``) of judged training windows gets the fault on a
copy of the aligned samples, and the EKF is re-run by the pipeline (`refilter` in the fit
context: the log's own filter with its gain; no detector runs a filter). Only a slice is
re-filtered, not the whole run: it starts ``probe_lead_s`` before the stretch from a checkpoint of
the clean run, the trace's posterior state and the diagonal of its covariance there (the trace
keeps P's diagonal only; the lead lets the covariance recursion forget the missing
off-diagonals). The same slice is re-filtered once without the fault (per stretch, shared by every
probe), and z = max |Nbar_fault - Nbar_clean| / s_j compares the two, so both start from the same
state; ``checkpoint_z``, the clean slice's largest distance from the log's own gains over the
stretch in the same units, says how well the lead converged (against rho).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from logscan.align import AlignedRun
from logscan.detectors.kgn_windows import column_norms, longest_stretch, window_means


def slice_run(run: AlignedRun, start: int, stop: int) -> AlignedRun:
    """Steps start..stop-1 of ``run`` (what the filter reads); no fresh sample at the first step: the
    checkpoint there is already a posterior."""
    sl = slice(start, stop)

    def group(g):
        fresh = np.array(g.fresh[sl], dtype=bool)
        if fresh.size:
            fresh[0] = False
        cut = lambda v: None if v is None else np.asarray(v)[sl]  # noqa: E731
        return dataclasses.replace(
            g,
            z=np.array(g.z[sl], dtype=np.float64),
            fresh=fresh,
            channel_fresh=cut(g.channel_fresh),
            noise_std_series=cut(g.noise_std_series),
            gate_closed=cut(g.gate_closed),
        )

    return dataclasses.replace(
        run,
        t=np.asarray(run.t)[sl],
        u=np.array(np.asarray(run.u)[sl], dtype=np.float64),
        u_fresh=np.asarray(run.u_fresh)[sl],
        groups={name: group(g) for name, g in run.groups.items()},
        mode=None if run.mode is None else np.asarray(run.mode)[sl],
        ground=None if run.ground is None else np.asarray(run.ground)[sl],
        onboard_state=None,
        onboard_variance=None,
        redundant={},
        gaps=[],
        warnings=[],
    )


def checkpoint(trace, model, step: int) -> tuple[np.ndarray, np.ndarray]:
    """(x0, P0) at ``step`` of the clean trace: its posterior state and diag(P_post) (a variance
    that is not positive and finite takes the model's prior one)."""
    x0 = np.asarray(trace.x_post[step], dtype=np.float64)
    diag = np.asarray(trace.P_post_diag[step], dtype=np.float64)
    prior = np.diag(np.asarray(model.default_P0(), dtype=np.float64))
    diag = np.where(np.isfinite(diag) & (diag > 0), diag, prior)
    return x0, np.diag(diag)


def stretches(wins, judged: list[np.ndarray], span: int) -> dict[str, tuple[int, int, int]]:
    """mode key -> (run index, first window, count): per mode the longest stretch of judged windows
    (up to ``span`` windows) over the training runs."""
    out: dict[str, tuple[int, int, int]] = {}
    for r, (w, ok) in enumerate(zip(wins, judged)):
        modes = np.asarray(w.modes, dtype=object)
        for key in sorted(set(w.modes)):
            first, count = longest_stretch(ok & (modes == key))
            best = out.get(key)
            if count and (best is None or min(count, span) > best[2]):
                out[key] = (r, first, min(count, span))
    return out


def _nbar(refilter, probe_run, x0, P0, starts: np.ndarray, period: int) -> np.ndarray:
    """Nbar of the pipeline's EKF on ``probe_run`` from (x0, P0) over the windows at ``starts``."""
    return window_means(column_norms(refilter("ekf", probe_run, x0=x0, P0=P0).K), starts, period)


def probe_stretch(detector, run, trace, w, w0: int, count: int, model, refilter, targets, kinds) -> tuple:
    """One stretch's probes, each by (target, kind): z, the probe's seconds and checkpoint_z (the clean
    slice's largest distance from the log's own Nbar over the stretch, in spreads, on the columns scored)."""
    period = detector.period(run.dt)
    lo, hi = int(w.starts[w0]), int(w.starts[w0 + count - 1] + period)
    start = max(lo - int(round(float(detector.probe_lead_s) / run.dt)), 0)
    x0, P0 = checkpoint(trace, model, start) if start > 0 else (None, None)  # at 0: the run's own start
    part = slice_run(run, start, hi)
    starts = w.starts[w0 : w0 + count] - start
    spread = detector.window_spreads(w)[w0 : w0 + count]
    clean = _nbar(refilter, part, x0, P0, starts, period)
    with np.errstate(invalid="ignore", divide="ignore"):
        off = np.abs(clean - w.nbar[w0 : w0 + count]) / spread
    k0 = lo - start
    t = part.t[k0:]
    scores, lasted, checked = {}, {}, {}
    for name, _channel, inject, cols in targets:
        for kind, size in kinds.items():
            fault = size * np.ones(t.size) if kind == "step" else size * (t - t[0])
            faulty = inject(part, k0, part.n_steps, fault)
            if faulty is None:
                continue
            with np.errstate(invalid="ignore", divide="ignore"):
                dz = np.abs(_nbar(refilter, faulty, x0, P0, starts, period)[:, cols] - clean[:, cols]) / spread[:, cols]
            scores[(name, kind)] = float(np.nanmax(dz)) if np.isfinite(dz).any() else 0.0
            lasted[(name, kind)] = float(t[-1] - t[0]) if t.size else 0.0
            checked[(name, kind)] = float(np.nanmax(off[:, cols])) if np.isfinite(off[:, cols]).any() else 0.0
    return scores, lasted, checked


def run_probe(detector, runs, traces, wins, judged, model, refilter) -> dict:
    """Blindness verdict per probe target and fault kind (see the module docstring)."""
    if model is None:
        return {"_note": "no model given to fit: the probe did not run"}
    if refilter is None:
        return {"_note": "no refilter given to fit (the pipeline's EKF for the probe): the probe did not run"}
    span = max(int(math.ceil(float(detector.probe_s) / float(detector.window_s))), 1)
    kinds = {"step": float(detector.probe_size), "drift": float(detector.probe_slope)}
    targets = detector.probe_targets(runs[0], model)
    per_mode: dict[tuple[str, str], dict[str, float]] = {}
    lasted: dict[tuple[str, str], float] = {}
    checked: dict[tuple[str, str], float] = {}
    for mode, (r, w0, count) in stretches(wins, judged, span).items():
        found = probe_stretch(detector, runs[r], traces[r], wins[r], w0, count, model, refilter, targets, kinds)
        for key, z in found[0].items():
            per_mode.setdefault(key, {})[mode] = z
            lasted[key] = max(lasted.get(key, 0.0), found[1][key])
            checked[key] = max(checked.get(key, 0.0), found[2][key])
    rho = float(detector.rho_)
    channels = {name: channel for name, channel, _, _ in targets}
    verdicts: dict = {}
    for (name, kind), z_per_mode in per_mode.items():
        z_max = max(z_per_mode.values())
        verdicts.setdefault(name, {})[kind] = {
            "size": kinds[kind],
            "unit": "unit/s" if kind == "drift" else "unit",
            "channel": channels[name],
            "z": z_max,
            "z_per_bin": z_per_mode,
            "probe_s": round(lasted[(name, kind)], 3),
            "checkpoint_z": checked[(name, kind)],
            "rho": rho,
            "blind": bool(z_max < rho),
        }
    if not verdicts:
        return {"_note": "no steady stretch in the training logs: the probe did not run"}
    return verdicts
