"""Training: fit detectors on prepared healthy runs, and their trained state as versioned tables JSON.

    detectors = trainable_detectors(loaded)                     # those with something to learn
    prepared = [prepare(p, loaded, needs_of(detectors)) for p in healthy_logs]
    fit_detectors(detectors, prepared)
    write_tables("vehicle.tables.json", tables_document(detectors, logs, loaded.profile))

Training never runs a detector over a log: it prepares each healthy log (read, align, filters) and
hands the runs and traces to each detector's `fit`. The tables file it writes, and how analysis
reads and checks it, is `logscan.training.tables`'s.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from logscan import __version__
from logscan.artifacts import write_json
from logscan.detectors.registry import default_registry
from logscan.errors import InputError, ProfileError, UsageError
from logscan.fleet import run_many
from logscan.needs import Needs
from logscan.pipeline import load_profile_for, prepare
from logscan.pipeline.stages import FILTERS, create_detectors, fit_context, needs_of, refuse_embedded_plugins
from logscan.readers import read_embedded
from logscan.training.calibration import calibrate, calibrated_runs, judged_steps, process_noise_scale
from logscan.training.tables import TABLES_FORMAT, TABLES_VERSION, profile_fingerprint, profile_rates
from logscan.training.tuning import tune as tune_multipliers


def file_sha256(path: str | os.PathLike) -> str:
    """SHA-256 of a log file; of a log that is a directory (per-topic CSVs), of its files' names
    and contents in name order."""
    digest = hashlib.sha256()
    for file in _log_files(path):
        if Path(path).is_dir():
            digest.update(os.path.basename(file).encode() + b"\0")
        with open(file, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                digest.update(block)
    return digest.hexdigest()


def _log_bytes(path: str | os.PathLike) -> int:
    return sum(os.path.getsize(file) for file in _log_files(path))


def _log_files(path: str | os.PathLike) -> list[str]:
    """The files of a log: itself, or a directory's regular files in name order."""
    if not Path(path).is_dir():
        return [str(path)]
    return sorted(str(p) for p in Path(path).iterdir() if p.is_file())


def trainable_detectors(loaded, names: Sequence[str] | None = None) -> list:
    """The detectors training fits: those the profile runs (or ``names``) that learn something in
    their configuration, and those whose tables the profile asks for (`Detector.asked_for_by`)."""
    registry = default_registry()
    chosen = list(names or loaded.profile.enabled_detectors() or registry.default_names())
    if not names:
        if loaded.source == "embedded":  # a log's profile runs no plugin (`stages.refuse_embedded_plugins`)
            refuse_embedded_plugins(
                chosen, registry.builtin_names(), registry.plugin_entry_names(), loaded.profile.source
            )
        # the built-ins a profile asks for without enabling them (plugins run only when named)
        asked = [
            n for n in registry.builtin_names() if n not in chosen and registry.get(n).asked_for_by(loaded.profile)
        ]
        chosen += asked
    # none may learn: `logscan train --calibrate` still calibrates the filter (logscan.training.calibration)
    return [d for d in create_detectors(loaded, chosen) if d.learns()]


def fit_detectors(detectors: Sequence, prepared: Sequence) -> list:
    """Fit every detector on the prepared healthy runs (`logscan.pipeline.stages.Prepared`), with the
    model and the filters it probes with (`fit_context`); returns them."""
    if not prepared:
        raise UsageError("training needs at least one healthy log")
    runs = [p.run for p in prepared]
    traces = [p.trace for p in prepared]
    for detector in detectors:
        detector.fit(runs, traces, **fit_context(detector, prepared[0].model, runs[0]))
    return list(detectors)


def tables_document(
    detectors: Sequence,
    logs: Sequence[str] = (),
    profile=None,
    calibration: dict | None = None,
    window: tuple[float | None, float | None] = (None, None),
) -> dict[str, Any]:
    """The tables JSON: format, version, what it was trained on (the logs, and the ``window`` of
    each, seconds since its start), the filter's calibrated measurement noise
    (`logscan.training.calibration`) and each detector's trained state."""
    return {
        "format": TABLES_FORMAT,
        "schema_version": TABLES_VERSION,
        "logscan_version": __version__,
        "profile_fingerprint": profile_fingerprint(profile) if profile is not None else None,
        "profile_rates": profile_rates(profile) if profile is not None else None,
        "profile_path": profile.source_file() if profile is not None else None,
        "profile_name": getattr(profile, "name", "") if profile is not None else "",
        "training_logs": [
            {"name": os.path.basename(p), "path": str(p), "bytes": _log_bytes(p), "sha256": file_sha256(p)}
            for p in logs
        ],
        "training_window": {"start_s": window[0], "end_s": window[1]} if window != (None, None) else None,
        "calibration": calibration,
        "detectors": [d.to_state() for d in detectors if d.trained_attributes],
    }


def write_tables(path: str | os.PathLike, document: dict) -> None:
    """Write the tables JSON atomically."""
    write_json(path, document)


def train_logs(
    logs: Sequence[str],
    profile_path: str | None,
    *,
    allow_faulty: bool = False,
    calibrate: bool = False,
    tune: bool = False,
    progress=None,
    notice=None,
    jobs: int = 1,
    scheduler: str | None = None,
    start_s: float | None = None,
    end_s: float | None = None,
) -> dict[str, Any]:
    """`logscan train`: prepare each healthy log (its ``start_s``..``end_s`` window, seconds since
    its start, when given), with ``calibrate`` calibrate the filter's
    measurement noise on them (the detectors are then fitted on the calibrated filter), fit the
    trainable detectors, return the tables document. Without ``profile_path`` every log's own
    profile (embedded or built-in) must match the first's. The logs are prepared (`PrepareTask`)
    in ``jobs`` local processes or on the Dask ``scheduler`` (`logscan.fleet.run_many`), and fitted
    here: the same tables whichever runs them."""

    step = progress or (lambda message: None)
    if not logs:
        raise UsageError("training needs at least one healthy log")
    loaded = load_profile_for(logs[0], profile_path)
    detectors = trainable_detectors(loaded)
    fingerprint = profile_fingerprint(loaded.profile)
    tuned = tunable_detectors(loaded) if tune else []
    _refuse_nothing_to_train(detectors, tuned, calibrate, tune)
    # the first log, when its profile is built in, was read to build it: its task reads it again
    # (a task travels to worker processes without a log in it)
    loaded = dataclasses.replace(loaded, log=None)
    task = PrepareTask(
        loaded, logs[0], profile_path, fingerprint, allow_faulty or tune, calibrate, notice, tune, start_s, end_s
    )
    prepared = _prepare_logs(task, logs, jobs, scheduler, step)
    needs = task.needs()
    # --tune takes labelled logs too (ground truth with faults): they only score the multipliers
    labelled = [p for p in prepared if ((p.log.truth or {}).get("events") or [])] if tune else []
    healthy = [p for p in prepared if all(p is not q for q in labelled)]
    if not healthy:
        raise UsageError("training needs at least one healthy log (one whose ground truth lists no fault)")
    calibration = None
    if calibrate:
        step("calibrating the measurement noise")
        calibration = calibrate_prepared(healthy, needs)
    if detectors:
        step("fitting " + ", ".join(d.name for d in detectors))
        fit_detectors(detectors, healthy)
    tuning = None
    if tune:
        step(f"tuning {', '.join(d.name for d in tuned)} on {len(healthy)} healthy and {len(labelled)} labelled log(s)")
        tuning = tune_multipliers(tuned, healthy, labelled)
    document = tables_document(detectors, logs, loaded.profile, calibration, (start_s, end_s))
    document["tuning"] = tuning
    return document


def _refuse_nothing_to_train(detectors: list, tuned: list, calibrate: bool, tune: bool) -> None:
    """A UsageError when --tune finds no detector to tune, or when nothing would be trained."""
    if tune and not tuned:
        raise UsageError(
            "--tune: no detector of this profile has threshold multipliers to tune",
            hint="enable [detectors.encoded_ekf] (its rho, rho_v and rho_s are tuned)",
        )
    if not detectors and not calibrate and not tune:
        raise UsageError(
            "nothing to train: no detector of this profile learns from healthy logs",
            hint="pass --calibrate to calibrate the filter's measurement noise, add a [redundant.<name>] "
            "group (A-TFM) or [detectors.encoded_ekf] variant = 'baseline'",
        )


def _prepare_logs(task: PrepareTask, logs: Sequence[str], jobs: int, scheduler: str | None, step) -> list:
    """Each log prepared by ``task`` (`PrepareTask`), in order: here one by one (``step`` says which),
    or in ``jobs`` local processes or on the Dask ``scheduler`` (`logscan.fleet.run_many`)."""
    items = [(path, number) for number, path in enumerate(logs, 1)]
    if jobs <= 1 and scheduler is None:
        prepared = []
        for path, number in items:
            step(f"reading {path} ({number}/{len(logs)})")
            prepared.append(task((path, number)))
        return prepared
    step(f"reading {len(logs)} log(s) on " + (f"the scheduler {scheduler}" if scheduler else f"{jobs} processes"))
    return run_many(items, task, jobs=jobs, scheduler=scheduler, isolate=False)


def tunable_detectors(loaded) -> list:
    """The profile's detectors (those it runs, else the defaults) that declare multipliers to tune."""
    chosen = list(loaded.profile.enabled_detectors() or default_registry().default_names())
    return [d for d in create_detectors(loaded, chosen) if getattr(d, "tunable", None)]


@dataclass(frozen=True)
class PrepareTask:
    """Check and prepare one healthy training log, an item (path, its number from 1): the per-log
    work of `train_logs`, picklable for local processes and Dask workers. Returns its
    `logscan.pipeline.stages.Prepared` (read, aligned, filtered), which the fit and calibration read."""

    loaded: Any  # logscan.pipeline.stages.LoadedProfile: the first log's (or --profile's)
    first_log: str
    profile_path: str | None
    fingerprint: str
    allow_faulty: bool = False
    calibrate: bool = False
    notice: Any = None  # a module-level function (picklable), or None
    tune: bool = False  # the tuned detectors' needs too (logscan.training.tuning)
    start_s: float | None = None  # --start/--end: the window of each log trained on
    end_s: float | None = None

    def needs(self):

        detectors = trainable_detectors(self.loaded) + (tunable_detectors(self.loaded) if self.tune else [])
        needs = needs_of(detectors)
        return _with_ekf(needs) if self.calibrate else needs

    def __call__(self, item: tuple[str, int]):
        path, number = item
        _, truth = read_embedded(path)  # one metadata read: the truth
        faults = ((truth or {}).get("events")) or []
        if faults and not self.allow_faulty:
            raise InputError(
                f"its ground truth lists {len(faults)} fault(s): a table trained on it would tolerate them",
                path=path,
                hint="train on healthy logs only, or pass --allow-faulty",
            )
        loaded, own = self.loaded, self.loaded.profile
        if self.profile_path is None and number > 1:
            theirs = load_profile_for(path, None)  # embedded, or built-in (a PX4 log: read once here)
            own = theirs.profile
            loaded = dataclasses.replace(loaded, log=theirs.log, log_extra_topics=theirs.log_extra_topics)
        if profile_fingerprint(own) != self.fingerprint:
            raise ProfileError(
                f"its embedded profile differs from {self.first_log}'s "
                "(vehicle, inputs, measurements, mode or redundant)",
                path=path,
                hint="train logs of one profile together, or pass --profile",
            )
        one = prepare(path, loaded, self.needs(), notice=self.notice, start_s=self.start_s, end_s=self.end_s)
        if one.log.source.partial:
            raise InputError(
                f"read in part ({one.log.source.partial_reason})", path=path, hint="train on complete logs"
            )
        return one


def _with_ekf(needs):
    """``needs`` plus the EKF's default trace (calibration filters every training log)."""
    return lambda run: needs(run) | Needs.of(ekf=())


def calibrate_prepared(prepared: Sequence, needs) -> dict:
    """Calibrate the measurement and process noise on the prepared healthy logs
    (`logscan.training.calibration`), then put the calibrated noise in their runs and models and re-run their
    filters, so the detectors are fitted on the filter `logscan analyze --tables` runs."""
    judged = [judged_steps(p.profile, p.run, p.filter_from) for p in prepared]
    calibration = calibrate(prepared[0].model, [p.run for p in prepared], judged=judged)
    for one, run in zip(prepared, calibrated_runs([p.run for p in prepared], calibration)):
        one.run = run
        one.model.process_noise_scale = process_noise_scale(calibration)  # as `prepare` sets it from tables
        # a window's EKF from its lead-in's start (taken with the noise before calibration)
        start = {"ekf": one.lead_in.arguments()} if one.lead_in is not None else {}
        one.traces = {
            name: FILTERS[name](one.model, run, frozenset(parts), **start.get(name, {}))
            for name, parts in needs(run).filters.items()
        }
        one._filter_summary = None
    return calibration
