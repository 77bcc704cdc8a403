"""One log's analysis, end to end: read -> profile -> align -> shared filter pass -> detectors -> scoring.

The filter runs once per log; every detector the profile enables reads the same trace. Pure: no
output files and no printing here (the CLI and the report module do that).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any, Callable

from logscan import __version__
from logscan.errors import LogscanError, ProfileError

# Default detector settings when a profile enables none: both checks of issue 4.
DEFAULT_DETECTORS = ("encoded_ekf", "nis")


@dataclass
class Analysis:
    """Everything one analysed log produced."""

    path: str
    log: Any  # logscan.log.Log
    profile: Any  # logscan.profile.Profile
    profile_text: str
    profile_source: str
    model: Any
    run: Any  # logscan.align.AlignedRun
    trace: Any  # logscan.filters.ekf.EkfTrace
    results: list = field(default_factory=list)  # DetectorResult per detector
    events: list = field(default_factory=list)  # logscan.scoring.FaultEvent from ground truth
    scores: dict = field(default_factory=dict)  # detector -> Score (when the log has truth)
    warnings: list[str] = field(default_factory=list)

    @property
    def alarms(self) -> list:
        return [alarm for result in self.results for alarm in result.alarms]

    @property
    def partial(self) -> bool:
        return bool(self.log.source.partial)

    def verdict(self) -> str:
        n = len(self.alarms)
        if n:
            return f"{n} alarm{'s' if n != 1 else ''}"
        return "partial input" if self.partial else "no alarms"

    def summary(self) -> dict[str, Any]:
        """JSON-ready summary of this log (the `--json` artifact's per-log entry)."""
        return {
            "file": self.path,
            "verdict": self.verdict(),
            "n_alarms": len(self.alarms),
            "logscan_version": __version__,
            "profile_source": self.profile_source,
            "model": self.model.name,
            "log": self.log.summary() | {"channels": len(self.log.channels)},
            "filter": self.trace.summary(),
            "detectors": [result.to_dict() for result in self.results],
            "truth_events": [
                {"kind": e.kind, "target": e.target, "start": e.t_start, "end": e.t_end} for e in self.events
            ],
            "scores": {name: score.to_dict() for name, score in self.scores.items()},
            "warnings": list(self.warnings),
        }


def load_log_and_profile(path: str, profile_path: str | None, *, use_header_stamp: bool = False):
    """Read only what the profile needs: the profile first (file, or the log's embedded one)."""
    from logscan.profile import load_profile, parse_profile
    from logscan.readers import read_embedded_profile, read_log

    if profile_path is not None:
        profile = load_profile(profile_path)
        profile_text, source = profile.to_toml(), str(profile_path)
    else:
        embedded = read_embedded_profile(path)
        if not embedded:
            raise ProfileError(
                "no profile: the log embeds none",
                path=str(path),
                hint="pass --profile PROFILE.toml (see docs/profiles.md)",
            )
        profile = parse_profile(embedded, source=f"{path} (embedded profile)")
        profile_text, source = embedded, "embedded"
    log = read_log(path, topics=profile.topics(), use_header_stamp=use_header_stamp)
    profile.check_channels(log)
    return log, profile, profile_text, source


def analyze_log(
    path: str | os.PathLike,
    profile_path: str | None = None,
    *,
    use_header_stamp: bool = False,
    detector_names: list[str] | None = None,
    grace_s: float = 1.0,
    progress: Callable[[str], None] | None = None,
) -> Analysis:
    """Analyse one log; raises LogscanError subclasses for bad input."""
    from logscan.align import align
    from logscan.detectors.registry import default_registry
    from logscan.filters.ekf import run_ekf
    from logscan.models import get_model
    from logscan.results import events_from_truth
    from logscan.scoring import score_by_detector

    step = progress or (lambda message: None)
    path = str(path)
    step("reading")
    log, profile, profile_text, source = load_log_and_profile(path, profile_path, use_header_stamp=use_header_stamp)
    model = get_model(profile.vehicle.model, profile.vehicle.params)
    step("aligning")
    run = align(log, profile)
    if run.n_steps < 2:
        raise LogscanError(
            "too few samples on the analysis grid to filter", path=path,
            hint="check the profile's channels and rate_hz against `logscan inspect`",
        )

    registry = default_registry()
    names = detector_names or profile.enabled_detectors() or list(DEFAULT_DETECTORS)
    detectors = []
    for name in names:
        spec = profile.detectors.get(name)
        detectors.append(registry.create(name, dict(spec.settings) if spec else {}))

    step("filtering")
    needs_gain = any(getattr(d, "variance_check", None) == "observed" for d in detectors) or (
        run.onboard_variance is None and any(d.name == "encoded_ekf" for d in detectors)
    )
    # R from each group's profile noise_std, else the model's default (pack_run)
    trace = run_ekf(model, run, store_gain=needs_gain, store_S=needs_gain)

    analysis = Analysis(
        path=path, log=log, profile=profile, profile_text=profile_text, profile_source=source,
        model=model, run=run, trace=trace,
    )
    analysis.warnings.extend(log.source.warnings)
    analysis.warnings.extend(run.warnings)
    if log.source.partial:
        analysis.warnings.append(f"partial read: {log.source.partial_reason}")
    for episode in trace.divergence_episodes:
        analysis.warnings.append(f"filter diverged: {episode}")

    for detector in detectors:
        step(f"detector {detector.name}")
        analysis.results.append(detector.run(run, trace, model=model, log_name=path))

    if log.truth is not None:
        analysis.events = events_from_truth(log.truth.get("events", []), path=path)
        analysis.scores = score_by_detector(
            analysis.events, analysis.alarms, duration_s=float(run.t[-1] - run.t[0]),
            grace_s=grace_s, detectors=[d.name for d in detectors], log=path,
        )
    return analysis
