"""`logscan analyze`: run the profile's detectors on logs, write report + JSON, exit 0/1/2/3."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from logscan.cli.options import header_stamp_option, json_option, profile_option, quiet_option, show_progress
from logscan.errors import LogscanError, UsageError

LOG_SUFFIXES = {".mcap", ".ulg", ".csv"}


@click.command(
    epilog="Examples:\n\n"
    "  logscan analyze sample_logs/quad_imu_bias.mcap\n\n"
    "  logscan analyze flight.mcap --profile quad.toml -o flight.html --json flight.json\n\n"
    "  logscan analyze sample_logs/ -o reports/ --plotlyjs reports/ --exit-zero"
)
@click.argument("log_paths", metavar="LOG...", nargs=-1, required=True, type=click.Path(path_type=str))
@profile_option
@click.option(
    "--output", "-o", "output_path", type=click.Path(path_type=str), default=None,
    help="HTML report file (one log) or directory (several logs). "
    "Default: <log name>.report.html in the current directory.",
)
@json_option
@click.option("--no-report", is_flag=True, default=False, help="Write no HTML report.")
@click.option(
    "--plotlyjs", "plotlyjs_dir", type=click.Path(file_okay=False, path_type=str), default=None,
    help="Write plotly.min.js once into this directory and reference it from the reports "
    "(small reports for fleets) instead of embedding it in each report.",
)
@click.option(
    "--detector", "-d", "detector_names", multiple=True,
    help="Run only this detector (repeatable). Default: those the profile enables.",
)
@click.option("--exit-zero", is_flag=True, default=False, help="Exit 0 even when there are alarms.")
@header_stamp_option
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
    use_header_stamp: bool,
    quiet: bool,
) -> None:
    """Run the model-based detectors on each LOG and report the alarms.

    LOG is an MCAP, ULog or CSV file, a directory of per-topic CSVs, or a directory of logs. The
    profile comes from --profile or from the log itself (logs written by `logscan simulate` embed
    theirs). Exit code: 0 no alarm, 1 alarms (0 with --exit-zero), 2 bad input, 3 internal error.
    """
    from logscan.analysis import analyze_log

    logs = expand_logs(log_paths)
    reports = report_paths(logs, output_path) if not no_report else [None] * len(logs)
    progress = show_progress(quiet)
    summaries, failures = [], []
    for log_path, report_path in zip(logs, reports):
        def step(message: str, _log=log_path) -> None:
            if progress:
                click.echo(f"logscan: {_log}: {message}...", err=True)

        try:
            analysis = analyze_log(
                log_path, profile_path, use_header_stamp=use_header_stamp,
                detector_names=list(detector_names) or None, progress=step,
            )
            if report_path is not None:
                step("writing report")
                write_report(analysis, report_path, plotlyjs_dir)
        except LogscanError as exc:
            if len(logs) == 1:
                raise
            click.echo(f"logscan: error: {exc.one_line()}", err=True)
            failures.append({"file": log_path, "error": exc.one_line(), "exit_code": exc.exit_code})
            continue
        summary = analysis.summary()
        summary["report"] = report_path
        summaries.append(summary)
        # with --json - the JSON owns stdout; the human summary goes to stderr
        click.echo(render_summary(analysis, report_path), err=json_path == "-")

    code = 2 if failures else (1 if any(s["n_alarms"] for s in summaries) else 0)
    if exit_zero and code == 1:
        code = 0
    if json_path:
        from logscan import __version__
        from logscan.artifacts import write_json

        write_json(json_path, {
            "logscan_version": __version__, "exit_code": code, "logs": summaries, "errors": failures,
        })
    sys.exit(code)


def expand_logs(paths: tuple[str, ...]) -> list[str]:
    """Files as given; a directory holding log files expands to them (sorted), a directory of
    per-topic CSVs stays one log."""
    logs: list[str] = []
    for raw in paths:
        path = Path(raw)
        if path.is_dir():
            inner = sorted(p for p in path.iterdir() if p.is_file() and p.suffix.lower() in {".mcap", ".ulg"})
            inner_dirs = sorted(p for p in path.iterdir() if p.is_dir() and any(p.glob("*.csv")))
            if inner or inner_dirs:
                logs.extend(str(p) for p in inner + inner_dirs)
                continue
        logs.append(raw)
    return logs


def report_paths(logs: list[str], output: str | None) -> list[str]:
    """Report file per log: -o FILE for one log, -o DIR/<name>.report.html for several."""
    names = [f"{Path(log.rstrip('/')).stem}.report.html" for log in logs]
    if len(set(names)) != len(names):
        names = [f"{Path(log.rstrip('/')).parent.name}_{n}" for log, n in zip(logs, names)]
    if output is None:
        return names
    if len(logs) == 1 and not Path(output).is_dir():
        return [output]
    directory = Path(output)
    if directory.exists() and not directory.is_dir():
        raise UsageError(f"--output {output} is a file, but {len(logs)} logs need a directory")
    directory.mkdir(parents=True, exist_ok=True)
    return [str(directory / name) for name in names]


def write_report(analysis, path: str, plotlyjs_dir: str | None) -> None:
    from logscan import __version__
    from logscan.report import ReportInput, render_report, report_matches

    events = analysis.events
    report = ReportInput(
        log_facts=analysis.log.summary(),
        profile_text=analysis.profile_text,
        profile_source=analysis.profile_source,
        model=analysis.model.describe(),
        logscan_version=__version__,
        t=analysis.run.t,
        results=analysis.results,
        truth_events=events,
        matches=report_matches(analysis.results, events) if events else None,
        verdict=analysis.verdict(),
        warnings=analysis.warnings,
    )
    render_report(report, path, plotlyjs=plotlyjs_dir or "embed")


def render_summary(analysis, report_path: str | None, max_rows: int = 12) -> str:
    """One screen per log: verdict, the first alarms, scores against ground truth."""
    lines = [f"{analysis.path}: {analysis.verdict()}  "
             f"({analysis.log.duration_s:.1f} s, model {analysis.model.name}, "
             f"detectors {', '.join(r.detector for r in analysis.results)})"]
    alarms = sorted(analysis.alarms, key=lambda a: a.start)
    if alarms:
        lines.append(f"  {'detector':<12} {'signal':<16} {'start s':>9} {'end s':>9} {'peak/thr':>9}")
        for alarm in alarms[:max_rows]:
            ratio = "-" if alarm.peak_ratio is None else f"{alarm.peak_ratio:.3g}"
            lines.append(f"  {alarm.detector:<12} {alarm.signal:<16} {alarm.start:>9.2f} {alarm.end:>9.2f} {ratio:>9}")
        if len(alarms) > max_rows:
            lines.append(f"  ... {len(alarms) - max_rows} more (see the report / --json)")
    for name, score in analysis.scores.items():
        latency = "-" if score.mean_latency_s is None else f"{score.mean_latency_s:.2f} s"
        lines.append(f"  truth: {name}: detected {score.tp}/{score.tp + score.fn} events, "
                     f"{score.fp} false alarm(s), mean latency {latency}")
    for warning in analysis.warnings[:5]:
        lines.append(f"  warning: {warning}")
    if report_path:
        lines.append(f"  report: {report_path}")
    return "\n".join(lines)
