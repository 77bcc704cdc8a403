"""`logscan evaluate`: detection rate, precision/recall/F1, latency and false alarms against ground truth."""

from __future__ import annotations

import sys

import click

from logscan.cli.options import (
    GroupedCommand,
    check_parallelism,
    check_profile,
    detector_option,
    header_stamp_option,
    help_groups,
    jobs_option,
    json_option,
    plotlyjs_option,
    profile_option,
    quiet_option,
    scheduler_option,
    show_progress,
    tables_option,
    window_option,
)
from logscan.cli.render import printable, render_evaluation
from logscan.errors import ExitCode, InputError
from logscan.verdict.scoring import DEFAULT_GRACE_S, DEFAULT_RECOVERY_S


@help_groups(
    {
        "Input": ("profile_path", "tables_path", "start_s", "end_s", "use_header_stamp"),
        "Detectors": ("detector_names",),
        "Scoring": ("grace_s", "recovery_s"),
        "Outputs": ("json_path", "page_path", "plotlyjs_dir", "quiet"),
        "Parallel": ("jobs", "scheduler"),
    }
)
@click.command(
    cls=GroupedCommand,
    epilog="Examples:\n\n"
    "  logscan evaluate sample_logs/\n\n"
    "  logscan evaluate runs/*.mcap --detector nis --json eval.json\n\n"
    "  logscan evaluate sample_logs/ --grace 0.5 --recovery 10",
)
@click.argument("log_paths", metavar="LOG_OR_DIR...", nargs=-1, required=True, type=click.Path(path_type=str))
@json_option
@click.option(
    "--output",
    "-o",
    "page_path",
    type=click.Path(dir_okay=False, path_type=str),
    default=None,
    help="Write the evaluation as an HTML page: the scores per detector and check with the latency "
    "distribution, and the detection matrix per fault kind.",
)
@plotlyjs_option("Write plotly.min.js once into DIR and link it from the --output page; default 'embed': inside it.")
@click.option(
    "--grace",
    "grace_s",
    type=click.FloatRange(min=0.0),
    default=DEFAULT_GRACE_S,
    show_default=True,
    help="Seconds after a fault's end during which an alarm that starts still counts as detecting it.",
)
@click.option(
    "--recovery",
    "recovery_s",
    type=click.FloatRange(min=0.0),
    default=DEFAULT_RECOVERY_S,
    show_default=True,
    help="Seconds after the grace period of a detected fault during which an alarm that starts is "
    "counted as recovery (the filter settling), neither a detection nor a false alarm.",
)
@detector_option("Evaluate only this detector (repeatable). Default: those each log's profile enables.")
@profile_option
@tables_option
@window_option
@header_stamp_option
@jobs_option
@scheduler_option
@quiet_option
def evaluate(
    log_paths: tuple[str, ...],
    json_path: str | None,
    page_path: str | None,
    plotlyjs_dir: str | None,
    grace_s: float,
    recovery_s: float,
    detector_names: tuple[str, ...],
    profile_path: str | None,
    tables_path: str | None,
    start_s: float | None,
    end_s: float | None,
    use_header_stamp: bool,
    jobs: int,
    scheduler: str | None,
    quiet: bool,
) -> None:
    """Score the detectors against the ground truth of each LOG (how: algorithms.md, section 7).

    Runs the analysis on every log that carries ground truth (logs written by `logscan simulate`
    do; others are skipped and listed), matches alarms to fault events, and prints per detector
    and per check (encoded e_x with the rejected-sample checks, e_v, NIS per sensor group and
    overall): TP/FN/FP, events with an alarm already on at their onset (not detections), alarms
    in the recovery window after a detected fault and alarms on the truth's healthy transients
    (neither counted as false alarms), precision, recall, F1, mean/max latency and false alarms
    per hour on the healthy logs (those without fault events), then the detection rate and
    latency per fault kind.
    A log that cannot be analysed is reported as one line. Exit code: 0, or 2 when a log could not
    be analysed or none has ground truth.
    """
    from logscan.align import check_window
    from logscan.fleet import expand_logs, refuse_clobbering
    from logscan.tasks import evaluate_logs

    check_window(start_s, end_s)
    check_parallelism(jobs, scheduler)
    check_profile(profile_path, tuple(detector_names) or None)
    logs = expand_logs(log_paths)
    refuse_clobbering([("--json", json_path), ("--output", page_path)], logs, profile_path)  # before any log
    evaluation = evaluate_logs(
        logs, profile_path=profile_path, detector_names=list(detector_names) or None, grace_s=grace_s,
        recovery_s=recovery_s, use_header_stamp=use_header_stamp, jobs=jobs, scheduler=scheduler,
        progress=show_progress(quiet), start_s=start_s, end_s=end_s, tables_path=tables_path,
    )  # fmt: skip
    _write_outputs(evaluation, json_path, page_path, plotlyjs_dir)
    if json_path != "-":
        click.echo(render_evaluation(evaluation))
    for failure in evaluation.failures:
        click.echo(f"logscan: error: {printable(failure.message)}", err=True)
    if not evaluation.logs and not evaluation.failures:
        raise InputError(
            f"none of the {len(logs)} log(s) has ground truth",
            hint="evaluate logs written by `logscan simulate` (fault events embedded) or with <log>.truth.json beside",
        )
    sys.exit(ExitCode.BAD_INPUT if evaluation.failures else ExitCode.OK)


def _write_outputs(evaluation, json_path: str | None, page_path: str | None, plotlyjs: str | None = None) -> None:
    """--json (the evaluation's document) and --output (its HTML page, when a log was evaluated;
    with --plotlyjs DIR, plotly.min.js beside it, written with it)."""
    if json_path:
        from logscan import __version__
        from logscan.artifacts import write_json

        write_json(json_path, {"logscan_version": __version__, **evaluation.to_dict()})
    if page_path and evaluation.logs:
        from logscan.artifacts import commit, new_token, stage
        from logscan.report.evaluation_page import render_evaluation_html
        from logscan.report.plotly_script import shared_plotly_js

        token = new_token()
        src, js = shared_plotly_js(page_path, plotlyjs, token)
        page = stage(page_path, render_evaluation_html(evaluation, plotlyjs_src=src), token=token)
        commit([js, page] if js is not None else [page])
