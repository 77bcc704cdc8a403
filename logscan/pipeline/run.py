"""One log end to end (`analyze_log`): the only function that composes the pipeline's steps:
profile, detectors (checked before the log is read), `prepare`, `detect`."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from logscan.errors import ModelError
from logscan.filters.warmup import kernel_compilers, load_kernels
from logscan.models import get_model, model_class
from logscan.needs import Needs
from logscan.pipeline.detection import detect
from logscan.pipeline.preparation import Fraction, Progress, filter_free, load_profile_for, prepare, raw_topics_of
from logscan.pipeline.stages import LoadedProfile, create_detectors, needs_of
from logscan.readers import read_embedded_profile
from logscan.training.calibration import process_noise_scale, uncalibrable_groups
from logscan.training.tables import apply_tables, read_tables_document, tables_path

if TYPE_CHECKING:
    from logscan.align import AlignedRun


def analyze_log(
    path: str | os.PathLike,
    profile_path: str | os.PathLike | None = None,
    *,
    use_header_stamp: bool = False,
    detector_names: Sequence[str] | None = None,
    grace_s: float = 1.0,
    progress: Progress | None = None,
    notice: Progress | None = None,
    start_s: float | None = None,
    end_s: float | None = None,
    free_series: bool = False,
    sensor_views: bool = False,
    tables: str | os.PathLike | None = None,
    truth: str | os.PathLike | None = None,
    fraction: Fraction | None = None,
    loaded: LoadedProfile | None = None,
    judged_from_s: float | None = None,
    read_plans: dict | None = None,
):
    """One log end to end: profile, detectors (checked before the log is read), prepare, detect;
    ``tables``: trained tables (`logscan train`; default: the profile's ``tables`` key);
    ``start_s``/``end_s``: a window of the log (seconds since its start); ``free_series``: see
    `detect`; ``sensor_views``: keep the EKF's innovations for the report's measured-vs-predicted
    figures (`logscan.report.sensor_views`), when a detector runs the EKF; ``truth``: a ground-truth JSON
    to score against (default: the log's own, or `<log>.truth.json` beside it); ``fraction``: the
    bytes read of the log, a block at a time (`prepare`); ``loaded``: the profile already loaded
    from ``profile_path`` (block mode loads it once for every block), else loaded here;
    ``judged_from_s``: see `detect`; ``read_plans``: what a window's read learns of the file, kept
    for the next (block mode's)."""
    loaded = loaded if loaded is not None else load_profile_for(path, profile_path)
    detectors = filter_free(create_detectors(loaded, detector_names), loaded, path)
    trained = tables_path(None if tables is None else str(tables), loaded.profile, log=path)
    if trained is not None:  # the trained detectors, and the filter's calibrated noise in the profile
        detectors = apply_tables(detectors, trained, loaded.profile)
        calibration = read_tables_document(trained).get("calibration")
        loaded.process_noise_scale = process_noise_scale(calibration)
        loaded.uncalibrated = uncalibrable_groups(calibration)
    options: dict[str, Any] = {"use_header_stamp": use_header_stamp, "start_s": start_s, "end_s": end_s}
    # the innovations also for a model whose sensors measure the motion twice over (incidents' rule 6)
    kinematic = _kinematic(loaded)
    needs = _with_innovations(needs_of(detectors)) if sensor_views or kinematic else needs_of(detectors)
    prepared = prepare(
        path,
        loaded,
        needs,
        progress=progress,
        notice=notice,
        raw_topics=raw_topics_of(detectors),
        truth_path=truth,
        fraction=fraction,
        ahead=kernel_compilers(detectors),
        read_plans=read_plans,
        judged_from_s=judged_from_s,
        **options,
    )
    views = {"free_series": free_series, "sensor_views": sensor_views}
    return detect(prepared, detectors, grace_s=grace_s, progress=progress, judged_from_s=judged_from_s, **views)


def _kinematic(loaded: LoadedProfile) -> bool:
    """Whether the profile's model names sensors that measure the motion twice over (rule 6 of
    `logscan.verdict.incidents` reads their innovations)."""
    try:
        return bool(getattr(model_class(str(loaded.profile.vehicle.model)), "kinematic_pairs", ()))
    except ModelError:  # a model the registry does not know: its profile's own error, said elsewhere
        return False


def load_kernels_for(
    path: str | os.PathLike,
    profile_path: str | os.PathLike | None = None,
    *,
    detector_names: Sequence[str] | None = None,
    notice: Progress | None = None,
) -> None:
    """Load the kernels the analysis of the log at ``path`` calls (its model's EKF, its detectors':
    `logscan.filters.warmup.load_kernels`), and import what its profile, reader and detectors
    import, without reading its samples: `--jobs` calls it for the fleet's first log in the parent
    before forking (`logscan.tasks.AnalyzeTask.warm_up`). Never raises: a log whose profile or
    detectors fail here meets the error again in its own analysis, which says so. A log with a
    built-in profile (a PX4 ULog, a ROS log) is left to its worker: that profile is made by reading
    the log, which would take the parent a whole read of it, alone, to save each worker ~0.1 s."""
    try:
        embedded = None if profile_path is not None else read_embedded_profile(path)
        if profile_path is None and not embedded:
            return
        loaded = load_profile_for(path, profile_path, embedded)
        detectors = filter_free(create_detectors(loaded, detector_names), loaded, path)
        vehicle = loaded.profile.vehicle
        model = None if loaded.model_not_run else get_model(vehicle.model, vehicle.params)
    except Exception:  # noqa: BLE001 - see the docstring
        return
    load_kernels(model, detectors, notice)


def _with_innovations(needs: Callable[[AlignedRun], Needs]) -> Callable[[AlignedRun], Needs]:
    """``needs`` plus the EKF's innovations, when the EKF runs at all."""

    def wanted(run) -> Needs:
        base = needs(run)
        return base | Needs.of(ekf=("y",)) if base.wants("ekf") else base

    return wanted
