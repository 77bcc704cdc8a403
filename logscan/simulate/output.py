"""Writing a simulated log: MCAP (JSON or ROS 2) with embedded truth and profile, or CSV + sidecars.

 - MCAP: one topic per `Simulation.series()` entry; metadata `logscan.truth` (key `json`: the
   ground-truth document) and `logscan.profile` (key `toml`: the matching profile).
 - CSV: one wide file `<log>.csv` (column `time_ns`, then one column per channel, empty where a
   channel has no sample at that time), sidecars `<log>.truth.json` and `<log>.profile.toml`.
Logged values are rounded to 7 significant digits (a float32 sensor's precision; it keeps sample
logs small); the grid starts at t = 0 ns. Equal inputs give equal bytes.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from logscan.artifacts import commit, discard, stage
from logscan.errors import UsageError
from logscan.readers.mcap.writer import TopicData, write_mcap
from logscan.simulate.simulation import Simulation

FORMATS = ("mcap-json", "mcap-ros2", "csv")
SIGNIFICANT_DIGITS = 7


def round_significant(values: np.ndarray, digits: int = SIGNIFICANT_DIGITS) -> np.ndarray:
    """``values`` rounded to ``digits`` significant digits (NaN, inf and 0 unchanged)."""
    v = np.asarray(values, dtype=np.float64)
    finite = np.isfinite(v) & (v != 0.0)
    exponent = np.zeros(v.shape, dtype=np.int64)
    exponent[finite] = np.floor(np.log10(np.abs(v[finite]))).astype(np.int64)
    shift = digits - 1 - exponent
    out = v.copy()
    # divide or multiply by an exact power of ten so the result is the double nearest the decimal
    up = finite & (shift >= 0) & (shift <= 22)
    down = finite & (shift < 0) & (shift >= -22)
    out[up] = np.round(v[up] * 10.0 ** shift[up]) / 10.0 ** shift[up]
    out[down] = np.round(v[down] / 10.0 ** (-shift[down])) * 10.0 ** (-shift[down])
    return out


def grid_ns(sim: Simulation) -> np.ndarray:
    """Timestamps (int64 ns) of the grid steps: k * dt."""
    dt_ns = int(round(sim.dt * 1e9))
    return np.arange(sim.n_steps, dtype=np.int64) * dt_ns


def sidecar_paths(path: str | Path) -> tuple[Path, Path]:
    """(truth JSON, profile TOML) beside a CSV log: `<log>.truth.json`, `<log>.profile.toml`."""
    p = Path(path)
    return p.with_suffix(".truth.json"), p.with_suffix(".profile.toml")


def write_simulation(sim: Simulation, path: str | Path, fmt: str = "mcap-json") -> list[Path]:
    """Write ``sim`` to ``path`` in ``fmt``; returns the files written."""
    if fmt not in FORMATS:
        raise UsageError(f"unknown format {fmt!r}", hint="choose one of " + ", ".join(FORMATS))
    truth_text = json.dumps(sim.truth(), indent=2) + "\n"
    profile_text = sim.profile_toml()
    if fmt == "csv":
        return _write_csv(sim, Path(path), truth_text, profile_text)

    t_ns = grid_ns(sim)
    topics = {
        s.topic: TopicData(s.schema, t_ns[s.steps], {k: round_significant(v) for k, v in s.fields.items()})
        for s in sim.series()
    }
    write_mcap(
        path,
        topics,
        encoding="ros2" if fmt == "mcap-ros2" else "json",
        metadata={"logscan.truth": {"json": truth_text}, "logscan.profile": {"toml": profile_text}},
    )
    return [Path(path)]


def _write_csv(sim: Simulation, path: Path, truth_text: str, profile_text: str) -> list[Path]:
    import pandas as pd

    columns: dict[str, np.ndarray] = {"time_ns": grid_ns(sim)}
    for s in sim.series():
        for name, values in s.fields.items():
            col = np.full(sim.n_steps, np.nan)
            col[s.steps] = round_significant(values)
            columns[f"{s.topic}/{name}"] = col
    frame = pd.DataFrame(columns)
    text = frame.to_csv(index=False, na_rep="", float_format=f"%.{SIGNIFICANT_DIGITS}g", lineterminator="\n")
    truth_path, profile_path = sidecar_paths(path)
    # the log and its two sidecars replace the previous ones together (or none of them does)
    staged = []
    try:
        for target, content in ((path, text), (truth_path, truth_text), (profile_path, profile_text)):
            staged.append(stage(target, content))
    except BaseException:
        discard(staged)
        raise
    commit(staged)
    return [path, truth_path, profile_path]
