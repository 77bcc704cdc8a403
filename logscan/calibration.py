"""Calibration of the measurement noise from healthy logs' innovations (`logscan train`).

On a healthy log a consistent filter's NIS per measurement group averages the group's size:
E[y^T S^-1 y] = m with S = H P H^T + R. A profile's guessed noise_std is rarely that: on real PX4
logs the mean NIS per output ran from 0.001 to 2 with PX4's own EKF2 noise values. Training scales
each group's noise variance by the ratio of its mean NIS per output to 1, re-filters every training
log with the new R, and repeats (CAL_ITERATIONS): the update is exact for a group whose innovation
covariance is all R, and converges in a few steps when H P H^T is a part of S. The result is one
noise_std per output of each group (the profile's per-output proportions kept), written in the
tables as ``calibration`` and applied by `logscan analyze --tables` before the filter runs, so the
detectors trained in the same run are fitted on the calibrated filter.

Simplified: only R is calibrated. The process noise Q stays the model's (its IMU noise parameters
for `ins`); a group whose NIS stays low with R at its floor (CAL_FLOOR of the profile's variance)
says that Q is too large for it, and the tables report the NIS reached.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from logscan.errors import InputError

CAL_ITERATIONS = 6
CAL_FLOOR = 1e-6  # the smallest calibrated variance, relative to the profile's (std / 1000)
CAL_CEILING = 1e6  # the largest (std x 1000)
CAL_MIN_UPDATES = 20  # updates of a group over the training logs to calibrate it


def base_noise_std(model, run) -> dict[str, np.ndarray]:
    """Each group's noise std as the filter takes it (`logscan.filters.ekf.pack_run`: the
    profile's, else the model's default R), from the diagonal of its block of R."""
    from logscan.filters.ekf import pack_run

    packed = pack_run(model, run)
    diagonal = np.sqrt(np.diag(packed.R_all))
    return {
        name: diagonal[o : o + m].copy()
        for name, o, m in zip(packed.group_names, packed.group_offsets.tolist(), packed.group_sizes.tolist())
    }


def mean_nis_per_output(model, runs: Sequence, noise_std: dict[str, np.ndarray]) -> dict[str, tuple[float, int]]:
    """(mean NIS per output, updates) of each group over ``runs`` filtered with ``noise_std``."""
    from logscan.filters.ekf import run_ekf

    sums: dict[str, float] = {}
    counts: dict[str, int] = {}
    for run in runs:
        trace = run_ekf(model, run, R=noise_std, store_gain=False, store_S=False, store_innovations=False)
        for g, name in enumerate(trace.group_names):
            used = trace.updated[:, g] & np.isfinite(trace.nis_group[:, g])
            sums[name] = sums.get(name, 0.0) + float(trace.nis_group[used, g].sum())
            counts[name] = counts.get(name, 0) + int(used.sum())
    sizes = {name: model.group(name).size for name in sums}
    return {
        name: (sums[name] / (sizes[name] * counts[name]) if counts[name] else np.nan, counts[name]) for name in sums
    }


def calibrate(model, runs: Sequence) -> dict:
    """The calibration document: per group the calibrated noise std, the profile's, and the mean NIS
    per output before and after (see the module docstring)."""
    if not runs:
        raise InputError("calibration needs at least one healthy log")
    base = base_noise_std(model, runs[0])
    scale = {name: 1.0 for name in base}
    before = mean_nis_per_output(model, runs, base)
    current = before
    for _ in range(CAL_ITERATIONS):
        for name, (ratio, count) in current.items():
            if count >= CAL_MIN_UPDATES and np.isfinite(ratio) and ratio > 0:
                scale[name] = float(np.clip(scale[name] * ratio, CAL_FLOOR, CAL_CEILING))
        std = {name: base[name] * np.sqrt(scale[name]) for name in base}
        current = mean_nis_per_output(model, runs, std)
    groups = {}
    for name in base:
        ratio0, count = before.get(name, (np.nan, 0))
        ratio1 = current.get(name, (np.nan, 0))[0]
        calibrated = count >= CAL_MIN_UPDATES
        groups[name] = {
            "noise_std": [float(v) for v in (base[name] * np.sqrt(scale[name]) if calibrated else base[name])],
            "profile_noise_std": [float(v) for v in base[name]],
            "updates": int(count),
            "mean_nis_per_output_before": float(ratio0),
            "mean_nis_per_output_after": float(ratio1) if calibrated else float(ratio0),
            "calibrated": bool(calibrated),
            "at_floor": bool(calibrated and scale[name] <= CAL_FLOOR * 1.0001),
        }
    return {"method": "noise variance scaled to mean NIS per output 1", "iterations": CAL_ITERATIONS, "groups": groups}


def calibrated_runs(runs: Sequence, calibration: dict) -> list:
    """``runs`` with each calibrated group's noise std replaced (the filter then uses it)."""
    out = []
    for run in runs:
        groups = dict(run.groups)
        for name, entry in calibration.get("groups", {}).items():
            if name in groups and entry.get("calibrated"):
                groups[name] = replace(groups[name], noise_std=np.asarray(entry["noise_std"], dtype=np.float64))
        out.append(replace(run, groups=groups))
    return out


def apply_calibration(profile, calibration: dict | None) -> list[str]:
    """Set each calibrated group's noise_std in ``profile`` (in place); one line per group changed."""
    lines = []
    for name, entry in (calibration or {}).get("groups", {}).items():
        spec = profile.measurements.get(name)
        if spec is None or not entry.get("calibrated"):
            continue
        spec.noise_std = [float(v) for v in entry["noise_std"]]
        lines.append(
            f"calibrated noise_std of {name}: {', '.join(f'{v:.3g}' for v in spec.noise_std)} "
            f"(mean NIS per output on the training logs {entry['mean_nis_per_output_after']:.2f})"
        )
    return lines


def calibration_lines(calibration: dict | None) -> list[str]:
    """Human-readable lines of a calibration (the train command's summary)."""
    lines = []
    for name, entry in (calibration or {}).get("groups", {}).items():
        if not entry.get("calibrated"):
            lines.append(f"  {name}: not calibrated ({entry['updates']} updates, {CAL_MIN_UPDATES} needed)")
            continue
        before = ", ".join(f"{v:.3g}" for v in entry["profile_noise_std"])
        after = ", ".join(f"{v:.3g}" for v in entry["noise_std"])
        note = " (at the floor: the process noise may be too large for it)" if entry["at_floor"] else ""
        lines.append(
            f"  {name}: noise_std {before} -> {after}; mean NIS per output "
            f"{entry['mean_nis_per_output_before']:.3g} -> {entry['mean_nis_per_output_after']:.3g}{note}"
        )
    return lines
