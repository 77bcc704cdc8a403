"""The per-log work the fleet runs: analyse one log (`AnalyzeTask`), score one log against its ground
truth (`EvaluationTask`), and `evaluate_logs`, which runs the latter over many logs and pools the scores.

This is the layer that composes the others: the pipeline analyses, `logscan.verdict` scores and
suppresses, `logscan.report` writes the page, `logscan.fleet.run_many` runs a task per log (local
processes or Dask workers). A task is a frozen dataclass, picklable by its module path; what it shows
the user (the text summary, progress lines) comes from the CLI as module-level callables, so no task
imports the command line.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from logscan.artifacts import Staged
from logscan.fleet import LogFailure, run_many
from logscan.pipeline import analyze_log, rescore
from logscan.pipeline.analysis import Analysis
from logscan.pipeline.blocks import analyze_blocked
from logscan.pipeline.run import load_kernels_for
from logscan.readers import read_embedded
from logscan.verdict.evaluation import Evaluation, LogEvaluation, evaluate_analysis
from logscan.verdict.scoring import DEFAULT_GRACE_S, DEFAULT_RECOVERY_S
from logscan.verdict.suppressions import apply_suppressions
from logscan.verdict.truth import truth_beside


@dataclass
class LogOutcome:
    """What one analysed log sends back to the command: its JSON summary and its text."""

    summary: dict
    text: str
    staged: Staged | None = None  # the report in its temporary file, renamed by the command at the end
    seconds: float = 0.0  # the wall time of its analysis and report (JUnit's time; not in the JSON)


@dataclass(frozen=True)
class AnalyzeTask:
    """Analyse one (log, report path) pair and write its report (picklable for --jobs and Dask).

    ``render`` is the text summary of one analysis and its report path (`logscan.cli.render`);
    ``step`` receives ``<log>: <step>`` before each step, ``notice`` the one-off notes (the first
    run's compile); both None: silent. All three must be module-level functions (pickled by name)."""

    profile_path: str | None
    detector_names: tuple[str, ...] | None
    use_header_stamp: bool
    plotlyjs_dir: str | None
    allow_partial: bool = False  # a log not fully checked exits 0/1 instead of 2
    render: Callable[[Analysis, str | None], str] = field(kw_only=True)
    step: Callable[[str], None] | None = None
    notice: Callable[[str], None] | None = None
    fraction: Callable[[int, int], None] | None = None  # the bytes read of the log (with ``step``)
    token: str = ""  # tags the temporary files of the run (logscan.artifacts.cleanup)
    start_s: float | None = None  # --start/--end: the window analysed (s since the log's start)
    end_s: float | None = None
    tables_path: str | None = None  # --tables: trained tables (logscan train)
    truth_path: str | None = None  # --truth: ground truth to score against
    fail_on_warning: bool = False  # --fail-on warning: possible faults exit 1 too
    suppressions: tuple = ()  # --suppressions: logscan.verdict.suppressions.Suppression entries
    block_s: float | None = None  # --block-s: None a long indexed MCAP log in blocks, 0 never (logscan.pipeline.blocks)

    def __call__(self, item: tuple[str, str | None]) -> LogOutcome:
        log_path, report_path = item
        started = time.perf_counter()

        def step(message: str) -> None:
            if self.step is not None:
                self.step(f"{log_path}: {message}")

        analysis = analyze_blocked(
            log_path,
            self.profile_path,
            block_s=self.block_s,
            use_header_stamp=self.use_header_stamp,
            detector_names=self.detector_names,
            progress=step,
            notice=self.notice,
            start_s=self.start_s,
            end_s=self.end_s,
            free_series=True,  # nothing reads the filter's series after the detectors
            sensor_views=report_path is not None,
            tables=self.tables_path,
            truth=self.truth_path,
            fraction=self.fraction,
        )
        if self.suppressions and apply_suppressions(analysis, list(self.suppressions)) and analysis.events:
            rescore(analysis)  # the suppressed alarms leave the scores too
        summary = analysis.summary()
        summary["exit_code"] = int(analysis.exit_code(self.allow_partial, self.fail_on_warning))
        summary["report"] = report_path
        text = self.render(analysis, report_path)
        analysis.prepared.release_series()  # the report reads the results and the grid's times
        staged = None
        if report_path is not None:
            # imported only now: plotly and the report's modules are ~58 MB, not needed while detecting
            from logscan.report.page import stage_report

            step("writing report")
            staged = stage_report(
                analysis.report_input(), report_path, plotlyjs=self.plotlyjs_dir or "embed", token=self.token
            )
        return LogOutcome(summary, text, staged, seconds=time.perf_counter() - started)

    def warm_up(self, items: Sequence[tuple[str, str | None]]) -> None:
        """Before `run_many` forks its workers: load the kernels of the first log's analysis and
        import its reader's and detectors' modules (`logscan.pipeline.run.load_kernels_for`), once
        here instead of in every worker's first log."""
        if items:
            load_kernels_for(items[0][0], self.profile_path, detector_names=self.detector_names, notice=self.notice)


def has_truth(path: str) -> bool:
    """Whether the log has ground truth: its own (reads only its metadata, not its messages), or a
    `<log>.truth.json` beside it, as the analysis finds it (`logscan.verdict.truth.truth_beside`)."""
    return truth_beside(path) is not None or read_embedded(path)[1] is not None


@dataclass(frozen=True)
class EvaluationTask:
    """Score one log (the per-log task of `evaluate_logs`; picklable for local processes and Dask).
    Returns a LogEvaluation, or None for a log without ground truth."""

    profile_path: str | None = None
    detector_names: tuple[str, ...] | None = None
    grace_s: float = DEFAULT_GRACE_S
    use_header_stamp: bool = False
    recovery_s: float = DEFAULT_RECOVERY_S
    start_s: float | None = None  # the window analysed (s since each log's start), None: all of it
    end_s: float | None = None
    tables_path: str | None = None  # trained tables (logscan train); None: each profile's own key

    def __call__(self, path: str) -> LogEvaluation | None:
        if not has_truth(path):
            return None
        analysis = analyze_log(
            path,
            self.profile_path,
            use_header_stamp=self.use_header_stamp,
            detector_names=self.detector_names,
            grace_s=self.grace_s,
            start_s=self.start_s,
            end_s=self.end_s,
            free_series=True,  # nothing reads the filter's series after the detectors
            tables=self.tables_path,
        )
        return evaluate_analysis(analysis, grace_s=self.grace_s, recovery_s=self.recovery_s)

    def warm_up(self, paths: Sequence[str]) -> None:
        """Before `run_many` forks its workers: the first log's kernels, as `AnalyzeTask.warm_up`."""
        if paths:
            load_kernels_for(paths[0], self.profile_path, detector_names=self.detector_names)


def evaluate_logs(
    paths: Sequence[str],
    *,
    profile_path: str | None = None,
    detector_names: Sequence[str] | None = None,
    grace_s: float = DEFAULT_GRACE_S,
    recovery_s: float = DEFAULT_RECOVERY_S,
    use_header_stamp: bool = False,
    jobs: int = 1,
    progress: bool = False,
    start_s: float | None = None,
    end_s: float | None = None,
    tables_path: str | None = None,
    scheduler: str | None = None,
) -> Evaluation:
    """Analyse and score every log with ground truth (``jobs`` local processes, or the Dask
    ``scheduler``: `logscan.fleet.run_many`); skip the others; record failures as lines.
    ``start_s``/``end_s``: the window of each log analysed."""
    names = tuple(detector_names) if detector_names else None
    task = EvaluationTask(profile_path, names, grace_s, use_header_stamp, recovery_s, start_s, end_s, tables_path)
    evaluation = Evaluation(grace_s=grace_s, recovery_s=recovery_s)
    for path, outcome in zip(
        paths, run_many(paths, task, jobs=jobs, progress=progress, label="evaluating", scheduler=scheduler)
    ):
        if isinstance(outcome, LogFailure):
            evaluation.failures.append(outcome)
        elif outcome is None:
            evaluation.skipped.append(path)
        else:
            evaluation.logs.append(outcome)
    return evaluation
