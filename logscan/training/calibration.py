"""Calibration of the filter's noise from healthy logs' innovations (`logscan train --calibrate`).

Measurement noise R. On a healthy log a consistent filter's NIS per measurement group averages the
group's size: E[y^T S^-1 y] = m with S = H P H^T + R. A profile's guessed noise_std is rarely that:
on real PX4 logs the mean NIS per output ran from 0.001 to 2 with PX4's own EKF2 noise values.
Training scales each group's noise variance by the ratio of its mean NIS per output to 1, re-filters
every training log with the new R, and repeats: the update is exact for a group whose innovation
covariance is all R, and converges in a few steps when H P H^T is a part of S. The result is one
noise_std per output of each group (the profile's per-output proportions kept).

Process noise Q. The NIS cannot tell a Q too large from an R too large (both widen S), so Q is fitted
on what can: the innovations' likelihood (`logscan.training.process_noise`, whose docstring says why not
covariance matching). The model's states are grouped in blocks of like meaning (for `ins`: position,
velocity, attitude, gyro bias, accelerometer bias, barometer offset) and each block's Q is scaled
(Q' = D^1/2 Q D^1/2, symmetric positive semi-definite, the model's proportions inside a block kept)
to the least -2 log-likelihood of the training logs' innovations, one parabolic step per block and
iteration. Each iteration scales R first, then Q, and the loop stops when every group's mean NIS per
output is within CAL_NIS_BAND and no block's scale moved more than CAL_Q_TOLERANCE, or after
CAL_ITERATIONS. Scales are clipped to [1e-4, 1e4]; a block whose Q does not change the likelihood
(nothing observes it, or what does is all measurement noise: the position of a model whose velocity
is measured) keeps scale 1 and is reported as not identified.

A calibration that did not converge in CAL_ITERATIONS, or whose Q scale of a block ran to its bound
(`logscan.training.process_noise.Q_SCALE_MIN`, Q_SCALE_MAX: the likelihood still falling there, so the logs
do not fix it) or whose noise_std ran to its ceiling, has failed: ``failures`` says why, the train
summary and training report say it failed, and `logscan analyze --tables` refuses it.

Both are written in the tables as ``calibration`` (``groups``: each group's noise_std;
``process_noise_scale``: each state's Q scale, ``process_noise_blocks``, the iterations used) and
applied by `logscan analyze --tables` before the filter runs (R in the profile's noise_std, Q through
the filter's Q override: `logscan.filters.q_scale.calibrated_Q`), so the detectors trained in the same
run are fitted on the calibrated filter. ``calibrate(..., process_noise=False)`` calibrates R alone.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from logscan.errors import InputError
from logscan.filters.ekf import pack_run
from logscan.training.process_noise import Q_SCALE_MAX, Q_SCALE_MIN, BlockFit, evaluate, fit_blocks, state_blocks

CAL_ITERATIONS = 10
CAL_FLOOR = 1e-6  # the smallest calibrated variance, relative to the profile's (std / 1000)
CAL_CEILING = 1e6  # the largest (std x 1000)
CAL_MIN_UPDATES = 20  # updates of a group over the training logs to calibrate it
CAL_NIS_BAND = (0.8, 1.25)  # calibrated: every group's mean NIS per output within this band ...
CAL_Q_TOLERANCE = float(np.log(1.25))  # ... and no block's Q scale moved by more than 25 % in an iteration


def base_noise_std(model, run) -> dict[str, np.ndarray]:
    """Each group's noise std as the filter takes it (`logscan.filters.ekf.pack_run`: the
    profile's, else the model's default R), from the diagonal of its block of R."""
    packed = pack_run(model, run)
    diagonal = np.sqrt(np.diag(packed.R_all))
    return {
        name: diagonal[o : o + m].copy()
        for name, o, m in zip(packed.group_names, packed.group_offsets.tolist(), packed.group_sizes.tolist())
    }


def mean_nis_per_output(model, runs: Sequence, noise_std: dict[str, np.ndarray]) -> dict[str, tuple[float, int]]:
    """(mean NIS per output, updates) of each group over ``runs`` filtered with ``noise_std``."""
    return evaluate(model, runs, noise_std, np.ones(model.n_states)).nis


def _within_band(nis: dict[str, tuple[float, int]], kept: Sequence[str] = ()) -> bool:
    """Every calibrated group's mean NIS per output within `CAL_NIS_BAND` (but those ``kept`` at
    the profile's noise: no noise_std brings them to 1, `_below_band_at_floor`)."""
    low, high = CAL_NIS_BAND
    return all(
        low <= ratio <= high for name, (ratio, count) in nis.items() if count >= CAL_MIN_UPDATES and name not in kept
    )


def calibrate(model, runs: Sequence, process_noise: bool = True, judged: Sequence | None = None) -> dict:
    """The calibration document: per group the calibrated noise std, the profile's, and the mean NIS
    per output before and after; with ``process_noise`` each block's Q scale too (see the module
    docstring). ``judged``: per run, the steps the detectors judge ((N,) bool, or None for all),
    the only ones calibrated on (`judged_steps`)."""
    if not runs:
        raise InputError("calibration needs at least one healthy log")
    base = base_noise_std(model, runs[0])
    scale = {name: 1.0 for name in base}
    blocks = {name: BlockFit(states) for name, states in state_blocks(model).items()} if process_noise else {}

    def q_scale() -> np.ndarray:
        out = np.ones(model.n_states)
        for fit in blocks.values():
            out[fit.states] = np.exp(fit.log_scale)
        return out

    def noise() -> dict[str, np.ndarray]:
        return {name: base[name] * np.sqrt(scale[name]) for name in base}

    def scaled() -> list:  # a group's logged per-sample std scales with it
        return with_noise_factors(runs, {name: float(np.sqrt(value)) for name, value in scale.items()})

    before = current = evaluate(model, runs, base, q_scale(), judged)
    iterations, converged = 0, False
    while iterations < CAL_ITERATIONS and not converged:
        iterations += 1
        # R first: each group's variance times its mean NIS per output (exact when S is all R)
        for name, (ratio, count) in current.nis.items():
            if count >= CAL_MIN_UPDATES and np.isfinite(ratio) and ratio > 0:
                scale[name] = float(np.clip(scale[name] * ratio, CAL_FLOOR, CAL_CEILING))
        floored = frozenset(name for name in base if _at_floor(scale[name]))
        now = scaled()
        current = evaluate(model, now, noise(), q_scale(), judged, floored)
        moved = 0.0
        if blocks:  # then Q: one step of each block's scale on the innovations' likelihood
            current, moved = fit_blocks(model, now, noise(), blocks, current, judged, floored)
        converged = _within_band(current.nis, _below_band_at_floor(current.nis, scale)) and moved < CAL_Q_TOLERANCE
    # a group still below the band at the R floor: no noise_std brings it to 1 (most of its S is
    # H P H^T; PX4's own attitude estimate as a measurement, smoother than any sensor). Its R at
    # the floor would alarm on every small deviation: it keeps the profile's, and says so.
    at_floor = {name: current.nis[name][0] for name in _below_band_at_floor(current.nis, scale)}
    if at_floor:
        for name in at_floor:
            scale[name] = 1.0
        current = evaluate(model, scaled(), noise(), q_scale(), judged)
    document = {
        "method": "noise variance scaled to mean NIS per output 1",
        "iterations": iterations,
        "groups": _group_entries(base, scale, before.nis, current.nis, at_floor, _logged_noise(runs)),
    }
    if process_noise:
        document.update(_process_noise_entries(model, blocks, before, current, converged))
    document["failures"] = _failures(document, converged, iterations)
    return document


def _failures(document: dict, converged: bool, iterations: int) -> list[str]:
    """Why a calibration failed (empty: it worked): not converged, a block's Q scale or a group's
    noise_std at its bound (the likelihood or the NIS still pulling past it)."""
    out = [] if converged else [f"not converged in {iterations} iteration(s)"]
    for name, entry in (document.get("process_noise_blocks") or {}).items():
        if entry["identified"] and not Q_SCALE_MIN * 1.0001 < entry["scale"] < Q_SCALE_MAX / 1.0001:
            out.append(f"the process noise of {name} ran to its bound (Q x {entry['scale']:.3g})")
    for name, entry in document["groups"].items():
        if entry["calibrated"] and entry["noise_factor"] ** 2 >= CAL_CEILING / 1.0001:
            out.append(f"the noise of {name} ran to its ceiling (noise_std x {entry['noise_factor']:.3g})")
    return out


def calibration_failures(calibration: dict | None) -> list[str]:
    """Why the tables' calibration failed (`calibrate`'s ``failures``; empty: it worked or there is none)."""
    return [str(reason) for reason in (calibration or {}).get("failures") or []]


def suspended_policy(profile, run, filter_from: float | None = None):
    """``profile``'s [alarms] policy suspended for ``run`` (`AlarmPolicy.suspend`: its ground channel,
    a window's ground around it, ``filter_from``: where a window's filter started), as the detectors
    judge it; the policy as it is when it suspends nothing, None without one."""
    policy = getattr(profile, "alarm_policy", None)
    if policy is None or not policy.suspends:
        return policy
    return policy.suspend(run.t, run.ground, filter_from, run.ground_around)


def judged_steps(profile, run, filter_from: float | None = None) -> np.ndarray | None:
    """The steps of ``run`` the detectors judge under ``profile``'s [alarms] policy: not on the
    ground, not in the take-off or touchdown transients, not in the filter's first seconds (None:
    every step; ``filter_from``: see `suspended_policy`).
    Calibration uses the same steps: a vehicle standing still (a real flight's ground time, a SITL
    log's exact GNSS at rest) tells little of the noise the detectors will judge in flight."""
    policy = suspended_policy(profile, run, filter_from)
    suspended = None if policy is None else policy.suspended
    return None if suspended is None else ~suspended


def _at_floor(scale: float) -> bool:
    """Whether a group's variance scale has reached the floor (within rounding)."""
    return scale <= CAL_FLOOR * 1.0001


def _below_band_at_floor(nis: dict[str, tuple[float, int]], scale: dict[str, float]) -> list[str]:
    """The calibrated groups whose noise is at the floor with their mean NIS per output still under
    the band."""
    low = CAL_NIS_BAND[0]
    return [
        name
        for name, (ratio, count) in nis.items()
        if count >= CAL_MIN_UPDATES and _at_floor(scale.get(name, 1.0)) and ratio < low
    ]


def _logged_noise(runs: Sequence) -> set[str]:
    """The groups whose noise std is logged per sample (noise_channels) in any of ``runs``."""
    return {name for run in runs for name, g in run.groups.items() if g.noise_std_series is not None}


def _group_entries(
    base, scale, before, after, at_floor: dict[str, float] | None = None, logged: set[str] = frozenset()
) -> dict:
    """Each group's entry of the calibration document (``at_floor``: the groups no noise_std could
    calibrate, with their mean NIS per output at the floor; they keep the profile's)."""
    at_floor = at_floor or {}
    groups = {}
    for name in base:
        ratio0, count = before.get(name, (np.nan, 0))
        ratio1 = after.get(name, (np.nan, 0))[0]
        calibrated = count >= CAL_MIN_UPDATES and name not in at_floor
        groups[name] = {
            "noise_std": [float(v) for v in (base[name] * np.sqrt(scale[name]) if calibrated else base[name])],
            # the std's factor, for the logged per-sample std (noise_channels) too
            "noise_factor": float(np.sqrt(scale[name])) if calibrated else 1.0,
            "profile_noise_std": [float(v) for v in base[name]],
            "updates": int(count),
            "mean_nis_per_output_before": float(ratio0),
            "mean_nis_per_output_after": float(ratio1) if calibrated or name in at_floor else float(ratio0),
            "calibrated": bool(calibrated),
            "nis_at_floor": float(at_floor[name]) if name in at_floor else None,
            "logged_noise": name in logged,  # the filter takes the logged std: noise_factor scales it
            "at_floor": bool(calibrated and _at_floor(scale[name])),
        }
    return groups


def _process_noise_entries(model, blocks: dict[str, BlockFit], before, after, converged: bool) -> dict:
    """The process-noise part of the calibration document: the scale of each state's Q (what
    `logscan analyze --tables` applies), each block's, and the innovations' cost per output before
    and after (`logscan.training.process_noise.Evaluation.cost` over its outputs: lower is likelier)."""
    names = model.state_names
    scales = {name: float(np.exp(fit.log_scale)) if fit.identified else 1.0 for name, fit in blocks.items()}
    return {
        "method": "noise variance scaled to mean NIS per output 1; process noise Q scaled per block of "
        "states to the least -2 log-likelihood of the innovations",
        "converged": bool(converged),
        "nis_band": list(CAL_NIS_BAND),
        "process_noise_scale": {names[i]: scales[name] for name, fit in blocks.items() for i in fit.states},
        "process_noise_blocks": {
            name: {"states": [names[i] for i in fit.states], "scale": scales[name], "identified": fit.identified}
            for name, fit in blocks.items()
        },
        "innovation_cost_per_output_before": before.cost / max(before.samples, 1),
        "innovation_cost_per_output_after": after.cost / max(after.samples, 1),
    }


def with_noise_factors(runs: Sequence, factors: dict[str, float]) -> list:
    """``runs`` with each group's logged per-sample noise std (``noise_channels``) times its factor;
    a run with none to scale is returned as it is."""
    out = []
    for run in runs:
        groups = dict(run.groups)
        scaled = [
            name
            for name, f in factors.items()
            if f != 1.0 and getattr(groups.get(name), "noise_std_series", None) is not None
        ]
        for name in scaled:
            groups[name] = replace(groups[name], noise_std_series=groups[name].noise_std_series * factors[name])
        out.append(replace(run, groups=groups) if scaled else run)
    return out


def calibrated_runs(runs: Sequence, calibration: dict) -> list:
    """``runs`` with each calibrated group's noise std replaced, and its logged per-sample std
    scaled (the filter then uses them)."""
    entries = {name: e for name, e in calibration.get("groups", {}).items() if e.get("calibrated")}
    out = []
    for run in with_noise_factors(runs, {name: _factor(e) for name, e in entries.items()}):
        groups = dict(run.groups)
        for name, entry in entries.items():
            if name in groups:
                groups[name] = replace(groups[name], noise_std=np.asarray(entry["noise_std"], dtype=np.float64))
        out.append(replace(run, groups=groups))
    return out


def _factor(entry: dict) -> float:
    """A calibrated group's std factor (tables written before it was stored: from its noise_std)."""
    if "noise_factor" in entry:
        return float(entry["noise_factor"])
    return float(np.asarray(entry["noise_std"])[0] / np.asarray(entry["profile_noise_std"])[0])


def apply_calibration(profile, calibration: dict | None) -> list[str]:
    """Set each calibrated group's noise_std in ``profile`` (in place); one line per group changed."""
    lines = []
    for name, entry in (calibration or {}).get("groups", {}).items():
        spec = profile.measurements.get(name)
        if spec is None or not entry.get("calibrated"):
            continue
        spec.noise_std = [float(v) for v in entry["noise_std"]]
        if spec.noise_channels:  # the logged per-sample std is what the filter takes: scale it alike
            spec.noise_channels_scale = _factor(entry)
        lines.append(
            f"calibrated noise_std of {name}: {', '.join(f'{v:.3g}' for v in spec.noise_std)} "
            f"(mean NIS per output on the training logs {entry['mean_nis_per_output_after']:.2f})"
        )
    return lines


def uncalibrable_groups(calibration: dict | None) -> frozenset[str]:
    """The groups a calibration found no noise_std for (still under the band at the floor)."""
    groups = (calibration or {}).get("groups", {})
    return frozenset(name for name, entry in groups.items() if entry.get("nis_at_floor") is not None)


def process_noise_scale(calibration: dict | None) -> dict[str, float] | None:
    """The calibration's Q scale per state ({state name: scale}), None when it calibrated R alone."""
    scales = (calibration or {}).get("process_noise_scale")
    return {str(name): float(value) for name, value in scales.items()} if scales else None


def calibrate_command(profile) -> str:
    """The command that calibrates ``profile``'s noise on healthy flights of its vehicle (its file
    passed with --profile; a built-in or embedded profile comes from each log)."""
    import shlex

    source = profile.source_file()
    chosen = f" --profile {shlex.quote(source)}" if source else ""
    return f"logscan train HEALTHY_LOG...{chosen} --calibrate -o tables.json"


def calibration_lines(calibration: dict | None) -> list[str]:
    """Human-readable lines of a calibration (the train command's summary)."""
    failures = calibration_failures(calibration)
    lines = [f"  FAILED: {'; '.join(failures)}: `logscan analyze --tables` refuses it"] if failures else []
    for name, entry in (calibration or {}).get("groups", {}).items():
        if entry.get("nis_at_floor") is not None:
            lines.append(
                f"  {name}: not calibrated: at the floor (noise_std / 1000) its mean NIS per output was still "
                f"{entry['nis_at_floor']:.3g} (most of its S is the filter's own uncertainty); the profile's "
                f"noise_std kept (mean NIS per output {entry['mean_nis_per_output_after']:.3g})"
            )
            continue
        if not entry.get("calibrated"):
            lines.append(f"  {name}: not calibrated ({entry['updates']} updates, {CAL_MIN_UPDATES} needed)")
            continue
        before = ", ".join(f"{v:.3g}" for v in entry["profile_noise_std"])
        after = ", ".join(f"{v:.3g}" for v in entry["noise_std"])
        note = " (at the floor: the process noise may be too large for it)" if entry["at_floor"] else ""
        if entry.get("logged_noise"):
            note += f" (its logged per-sample std x {entry['noise_factor']:.3g}: noise_channels_scale)"
        lines.append(
            f"  {name}: noise_std {before} -> {after}; mean NIS per output "
            f"{entry['mean_nis_per_output_before']:.3g} -> {entry['mean_nis_per_output_after']:.3g}{note}"
        )
    return lines + process_noise_lines(calibration)


def process_noise_lines(calibration: dict | None) -> list[str]:
    """The Q scale of each block of states, and the iterations used (empty when R alone)."""
    blocks = (calibration or {}).get("process_noise_blocks") or {}
    if not blocks:
        return []
    state = "converged" if calibration.get("converged") else "not converged"
    lines = [f"  process noise Q x scale per block of states ({calibration.get('iterations')} iteration(s), {state}):"]
    for name, entry in blocks.items():
        shown = f"{entry['scale']:.3g}" if entry.get("identified") else "1 (not identifiable from these logs)"
        lines.append(f"    {name} ({', '.join(entry['states'])}): {shown}")
    return lines
