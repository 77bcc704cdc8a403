"""Are the analyses of every sample log the same with the EKF's K and S held for the whole log and
with them filtered again block by block as they are read (`logscan.pipeline.refilter`)?

Runs `analyze_log` as `logscan analyze LOG -o REPORT --json SUMMARY` does (the series freed as they
go, the report's pack of innovations) twice per log in this process, once with the trace holding
the whole run's K and S (`run_ekf`, as before) and once as the pipeline does now, and compares the
JSON summaries. Prints one line per log; exits 1 when any differs.

    python bench/refilter_identity.py [LOG ...]     # default: every sample log
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import logscan.pipeline.stages as stages
from logscan.filters.ekf import run_ekf
from logscan.pipeline import analyze_log
from logscan.pipeline.refilter import run_ekf_parts

SAMPLES = Path(__file__).resolve().parent.parent / "sample_logs"


def held_whole(model, run, parts: frozenset[str], x0=None, P0=None, steps_done=None):
    """The trace as the pipeline filtered it before: K and S, when asked, held for the whole log."""
    return run_ekf(
        model,
        run,
        x0=x0,
        P0=P0,
        store_gain="K" in parts,
        store_S="S" in parts,
        full_P="P" in parts,
        store_innovations="y" in parts,
        steps_done=steps_done,
    )


def summary(path: str, filter_ekf) -> str:
    before = stages.FILTERS["ekf"]
    stages.FILTERS["ekf"] = filter_ekf
    try:
        analysis = analyze_log(path, free_series=True, sensor_views=True)
        return json.dumps(analysis.summary(), sort_keys=True, default=str)
    finally:
        stages.FILTERS["ekf"] = before


def main(argv: list[str]) -> int:
    logs = argv or [str(p) for p in sorted(SAMPLES.glob("*.mcap"))] + [
        str(SAMPLES / "quad_healthy.csv"),
        str(SAMPLES / "husky_drive.bag"),
    ]
    differ = 0
    for path in logs:
        same = summary(path, held_whole) == summary(path, run_ekf_parts)
        differ += not same
        print(f"{'same' if same else 'DIFFERS'}  {Path(path).name}", flush=True)
    print(f"{len(logs) - differ} of {len(logs)} summaries identical")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
