"""`logscan analyze`: run the profile's detectors on logs, write report + JSON, exit 0/1/2/3."""

from __future__ import annotations

import sys
from dataclasses import dataclass

import click

from logscan.cli.options import (
    echo_notice,
    header_stamp_option,
    jobs_option,
    json_option,
    profile_option,
    quiet_option,
    show_progress,
)
from logscan.cli.render import render_summary
from logscan.errors import ExitCode


@click.command(
    epilog="Examples:\n\n"
    "  logscan analyze sample_logs/quad_imu_bias.mcap\n\n"
    "  logscan analyze flight.mcap --profile quad.toml -o flight.html --json flight.json\n\n"
    "  logscan analyze sample_logs/ -o reports/ --plotlyjs reports/ --exit-zero"
)
@click.argument("log_paths", metavar="LOG...", nargs=-1, required=True, type=click.Path(path_type=str))
@profile_option
@click.option(
    "--output",
    "-o",
    "output_path",
    type=click.Path(path_type=str),
    default=None,
    help="HTML report file (one log) or directory (several logs). "
    "Default: <log name>.report.html in the current directory.",
)
@json_option
@click.option("--no-report", is_flag=True, default=False, help="Write no HTML report.")
@click.option(
    "--plotlyjs",
    "plotlyjs_dir",
    type=click.Path(file_okay=False, path_type=str),
    default=None,
    help="Write plotly.min.js once into this directory and reference it from the reports "
    "(small reports for fleets) instead of embedding it in each report.",
)
@click.option(
    "--detector",
    "-d",
    "detector_names",
    multiple=True,
    help="Run only this detector (repeatable). Default: those the profile enables.",
)
@click.option("--exit-zero", is_flag=True, default=False, help="Exit 0 even when there are alarms.")
@click.option(
    "--allow-partial",
    is_flag=True,
    default=False,
    help="A log that could not be fully checked (read in part, a sensor without valid samples, a "
    "diverged filter) exits 0 or 1 by its alarms instead of 2; the verdict still says what was not checked.",
)
@header_stamp_option
@jobs_option
@quiet_option
def analyze(
    log_paths: tuple[str, ...],
    profile_path: str | None,
    output_path: str | None,
    json_path: str | None,
    no_report: bool,
    plotlyjs_dir: str | None,
    detector_names: tuple[str, ...],
    exit_zero: bool,
    allow_partial: bool,
    use_header_stamp: bool,
    jobs: int,
    quiet: bool,
) -> None:
    """Run the model-based detectors on each LOG and report the incidents and alarms.

    LOG is an MCAP, ULog or CSV file, a directory of per-topic CSVs, or a directory of logs. The
    profile comes from --profile or from the log itself (logs written by `logscan simulate` embed
    theirs). Exit code: 0 no alarm and everything checked; 1 alarms (0 with --exit-zero); 2 bad
    input, or a log that could not be fully checked (read in part, a sensor without valid samples,
    a diverged filter; 0 or 1 with --allow-partial); 3 a detector or logscan failed. The report is
    written in every case and says what could not be checked.
    """
    from logscan.fleet import LogFailure, expand_logs, output_paths, run_many

    names = tuple(detector_names) or None
    if profile_path is not None:
        # one profile for every log: its detector settings are checked once, before any log is read
        from logscan.pipeline import create_detectors, load_profile_for

        create_detectors(load_profile_for(None, profile_path), names)
    logs = expand_logs(log_paths)
    reports = output_paths(logs, output_path) if not no_report else [None] * len(logs)
    progress = show_progress(quiet)
    task = AnalyzeTask(
        profile_path,
        names,
        use_header_stamp,
        plotlyjs_dir,
        allow_partial,
        steps=progress and len(logs) == 1,
        notices=not quiet,
    )
    outcomes = run_many(
        list(zip(logs, reports)), task, jobs=jobs, progress=progress, label="analysing", isolate=len(logs) > 1
    )
    summaries, failures, codes = [], [], []
    for outcome in outcomes:
        if isinstance(outcome, LogFailure):
            click.echo(f"logscan: error: {outcome.message}", err=True)
            failures.append({"file": outcome.path, "error": outcome.message, "exit_code": outcome.exit_code})
            codes.append(ExitCode(outcome.exit_code))
            continue
        summaries.append(outcome.summary)
        codes.append(ExitCode(outcome.summary["exit_code"]))
        # with --json - the JSON owns stdout; the human summary goes to stderr
        click.echo(outcome.text, err=json_path == "-")

    # the worst log decides: a failure (3) over bad or unchecked input (2) over alarms (1)
    code = max(codes, default=ExitCode.OK)
    if exit_zero and code == ExitCode.ALARMS:
        code = ExitCode.OK
    if json_path:
        from logscan import __version__
        from logscan.artifacts import write_json

        write_json(
            json_path,
            {
                "logscan_version": __version__,
                "exit_code": int(code),
                "logs": summaries,
                "errors": failures,
            },
        )
    sys.exit(code)


@dataclass
class LogOutcome:
    """What one analysed log sends back to the command: its JSON summary and its text."""

    summary: dict
    text: str


@dataclass(frozen=True)
class AnalyzeTask:
    """Analyse one (log, report path) pair and write its report (picklable for --jobs)."""

    profile_path: str | None
    detector_names: tuple[str, ...] | None
    use_header_stamp: bool
    plotlyjs_dir: str | None
    allow_partial: bool = False  # a log not fully checked exits 0/1 instead of 2
    steps: bool = False  # print each step on stderr (one log on a terminal)
    notices: bool = True  # print the one-off notes (the first run's compile) on stderr

    def __call__(self, item: tuple[str, str | None]) -> LogOutcome:
        from logscan.pipeline import analyze_log
        from logscan.report import render_report

        log_path, report_path = item

        def step(message: str) -> None:
            if self.steps:
                click.echo(f"logscan: {log_path}: {message}...", err=True)

        analysis = analyze_log(
            log_path,
            self.profile_path,
            use_header_stamp=self.use_header_stamp,
            detector_names=self.detector_names,
            progress=step,
            notice=echo_notice if self.notices else None,
        )
        if report_path is not None:
            step("writing report")
            render_report(analysis.report_input(), report_path, plotlyjs=self.plotlyjs_dir or "embed")
        summary = analysis.summary()
        summary["exit_code"] = int(analysis.exit_code(self.allow_partial))
        summary["report"] = report_path
        return LogOutcome(summary, render_summary(analysis, report_path))
