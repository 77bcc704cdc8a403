"""`logscan analyze`: run the profile's detectors on logs, write report + JSON, exit 0/1/2/3."""

from __future__ import annotations

import gc
import sys
from dataclasses import dataclass, replace

import click

from logscan.cli.options import (
    GroupedCommand,
    block_option,
    check_parallelism,
    check_profile,
    detector_option,
    echo_notice,
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
from logscan.cli.progress import coloured_verdict, echo_fraction, echo_step, end_steps, plan_steps, use_colour
from logscan.cli.render import printable, render_summary
from logscan.errors import ExitCode, UsageError

_HELP = """Run the model-based detectors on each LOG and report the incidents and alarms.

LOG is an MCAP, ULog or CSV file, a directory of per-topic CSVs, or a directory of logs. The
profile comes from --profile or from the log itself (logs written by `logscan simulate` embed
theirs). Exit code: 0 no alarm and everything checked; 1 alarms (0 with --exit-zero); 2 bad
input, or a log that could not be fully checked (read in part, a sensor without valid samples,
a diverged filter; 0 or 1 with --allow-partial); 3 a detector or logscan failed. The report is
written in every case and says what could not be checked.
"""

SUMMARY_SCHEMA_VERSION = 1  # of the --json document; a removed or retyped field changes it


def _print_profiles(logs, profile_path: str | None, err: bool) -> None:
    """--print-profile: each log's profile as TOML, headed by where it comes from."""
    from logscan.pipeline import load_profile_for

    for log in logs:
        loaded = load_profile_for(log, profile_path)
        click.echo(f"# profile for {log} ({loaded.source})", err=err)
        for note in loaded.notes:
            click.echo(f"# {note}", err=err)
        click.echo(loaded.text.rstrip("\n") + "\n", err=err)


@dataclass(frozen=True)
class _Run:
    """The options of one `logscan analyze` run, as click parsed them (the command's parameters)."""

    log_paths: tuple[str, ...]
    profile_path: str | None
    tables_path: str | None
    output_path: str | None
    json_path: str | None
    no_report: bool
    plotlyjs_dir: str | None
    detector_names: tuple[str, ...]
    exit_zero: bool
    allow_partial: bool
    fail_on: str
    suppressions_path: str | None
    baseline_path: str | None
    junit_path: str | None
    markdown_path: str | None
    github_annotations: bool
    truth_path: str | None
    print_profile: bool
    start_s: float | None
    end_s: float | None
    block_s: float | None
    use_header_stamp: bool
    jobs: int
    scheduler: str | None
    quiet: bool

    @property
    def err(self) -> bool:
        """With --json - the JSON owns stdout: the summaries and other lines go to stderr."""
        return self.json_path == "-"


@help_groups(
    {
        "Input": (
            "profile_path",
            "tables_path",
            "truth_path",
            "start_s",
            "end_s",
            "block_s",
            "use_header_stamp",
            "print_profile",
        ),
        "Detectors": ("detector_names", "suppressions_path"),
        "Outputs": ("output_path", "json_path", "no_report", "plotlyjs_dir", "quiet"),
        "CI": (
            "exit_zero",
            "fail_on",
            "allow_partial",
            "baseline_path",
            "junit_path",
            "markdown_path",
            "github_annotations",
        ),
        "Parallel": ("jobs", "scheduler"),
    }
)
@click.command(
    cls=GroupedCommand,
    help=_HELP,
    epilog="Examples:\n\n"
    "  logscan analyze sample_logs/quad_imu_bias.mcap\n\n"
    "  logscan analyze flight.mcap --profile quad.toml -o flight.html --json flight.json\n\n"
    "  logscan analyze sample_logs/ -o reports/ --plotlyjs reports/ --exit-zero",
)
@click.argument("log_paths", metavar="LOG...", nargs=-1, required=True, type=click.Path(path_type=str))
@profile_option
@tables_option
@click.option(
    "--output",
    "-o",
    "output_path",
    type=click.Path(path_type=str),
    default=None,
    help="HTML report file (one log) or directory (several logs: an existing one, or a name ending in / to create). "
    "Default: <log name>.report.html in the current directory.",
)
@json_option
@click.option("--no-report", is_flag=True, default=False, help="Write no HTML report.")
@plotlyjs_option(
    "Write plotly.min.js once into DIR and reference it from the reports (small reports for fleets); "
    "'embed' puts it into each report (self-contained files). Default: embed for one log; for several, one "
    "copy beside the reports (in --output's directory)."
)
@detector_option("Run only this detector (repeatable). Default: those the profile enables.")
@click.option("--exit-zero", is_flag=True, default=False, help="Exit 0 even when there are alarms.")
@click.option(
    "--allow-partial",
    is_flag=True,
    default=False,
    help="A log that could not be fully checked (read in part, a sensor without valid samples, a "
    "diverged filter) exits 0 or 1 by its alarms instead of 2; the verdict still says what was not checked.",
)
@click.option(
    "--fail-on",
    "fail_on",
    type=click.Choice(["alarm", "warning", "new", "never"]),
    default="alarm",
    show_default=True,
    help="Exit 1 on alarms; 'warning': also on 'possible fault' warnings (a level below alarms that a "
    "detector may raise); 'new': only on alarms the --baseline does not have; 'never': exit 0 whatever "
    "the alarms (as --exit-zero).",
)
@click.option(
    "--suppressions",
    "suppressions_path",
    type=click.Path(dir_okay=False, path_type=str),
    default=None,
    help="A TOML file of accepted alarms ([[suppress]]: detector, check, log glob, start/end, reason, "
    "expires): they leave the verdict and exit code and are listed with their reason everywhere; an entry "
    "that matched no alarm is a warning.",
)
@click.option(
    "--baseline",
    "baseline_path",
    type=click.Path(dir_okay=False, path_type=str),
    default=None,
    help="A previous run's --json summary: every alarm is marked new or unchanged (same log name, "
    "detector and statistic, overlapping in time), the previous ones no longer raised are listed as gone, "
    "and its logs this run did not analyse as not analysed.",
)
@click.option(
    "--junit",
    "junit_path",
    type=click.Path(dir_okay=False, path_type=str),
    default=None,
    help="Write a JUnit XML report: a testsuite per log (its time: the log's analysis time), a testcase per "
    "detector and statistic (failed when it alarmed), for CI servers' test views.",
)
@click.option(
    "--markdown",
    "markdown_path",
    type=click.Path(dir_okay=False, path_type=str),
    default=None,
    help="Write a Markdown summary (verdict and alarm tables, links to the reports relative to the file) for a "
    "CI job summary page (e.g. >> $GITHUB_STEP_SUMMARY).",
)
@click.option(
    "--github-annotations",
    is_flag=True,
    default=False,
    help="Print one GitHub Actions '::error' line per incident and '::warning' per possible fault or "
    "unchecked part (at most 10 of each per log, then a '::notice' of how many more), shown on the workflow run.",
)
@click.option(
    "--truth",
    "truth_path",
    type=click.Path(exists=True, dir_okay=False, path_type=str),
    default=None,
    help="Ground truth (JSON: events with kind, target and start/end in seconds since the log's start, or "
    "start_utc/end_utc) to score the alarms against. Default: the log's own, or <log>.truth.json beside it.",
)
@click.option(
    "--print-profile",
    is_flag=True,
    default=False,
    help="Print the profile each log is analysed with (the file given, the log's embedded one, or the "
    "built-in one a PX4 log gets), as TOML, before analysing it.",
)
@window_option
@block_option
@header_stamp_option
@jobs_option
@scheduler_option
@quiet_option
def analyze(**options) -> None:
    """`logscan analyze` (its help: ``_HELP``); click passes the options of `_Run`."""
    from logscan.artifacts import cleanup, discard, new_token
    from logscan.fleet import expand_logs
    from logscan.tasks import LogOutcome

    run = _Run(**options)
    names, rules, previous = _check_arguments(run)  # before any log is read
    logs = expand_logs(run.log_paths)
    if run.print_profile:
        _print_profiles(logs, run.profile_path, err=run.err)
    run = _shared_plotly_js(run, len(logs))
    reports, index, written = _output_paths(run, logs)
    if run.plotlyjs_dir is not None and options["plotlyjs_dir"] is None and not run.quiet:
        shared = _plotly_js_path(run.plotlyjs_dir)  # the default for several logs: say so
        echo_notice(f"plotly.js: one copy for the {len(logs)} reports, {shared} (--plotlyjs embed: one in each)")
    token = new_token()  # tags this run's temporary files, wherever a worker wrote them
    progress = show_progress(run.quiet)
    task = _task(run, names, rules, token, steps=progress and len(logs) == 1)
    plan_steps(report=not run.no_report)  # the ETA of one log's steps leaves out a report not written
    staged: list = []
    try:
        outcomes = _run_logs(list(zip(logs, reports)), task, run.jobs, progress, run.scheduler)
        staged += [o.staged for o in outcomes if isinstance(o, LogOutcome) and o.staged is not None]
        code = _finish(run, outcomes, previous, staged, index, token, rules)
    except BaseException:
        # an error or Ctrl-C: no output is replaced, and no temporary file stays
        discard(staged)
        cleanup(written, token)
        raise
    sys.exit(code)


def _shared_plotly_js(run: _Run, n_logs: int) -> _Run:
    """--plotlyjs resolved: ``embed`` (or no report) is None, plotly.js inside each report; not
    given, for several logs, the reports' directory: one shared copy of plotly.js (~4.6 MB)
    instead of one in each report."""
    if run.no_report or run.plotlyjs_dir == "embed":
        return replace(run, plotlyjs_dir=None)
    if run.plotlyjs_dir is None and n_logs > 1:
        return replace(run, plotlyjs_dir=run.output_path or ".")
    return run


def _check_arguments(run: _Run) -> tuple[tuple[str, ...] | None, tuple, dict | None]:
    """Every argument checked before any log is read (exit 2): the window, parallelism, one
    profile's detector settings, --fail-on new's baseline; the detectors asked for, the
    suppression rules and the baseline's document."""
    from logscan.align import check_window

    check_window(run.start_s, run.end_s)
    check_parallelism(run.jobs, run.scheduler)
    names = tuple(run.detector_names) or None
    check_profile(run.profile_path, names)
    if run.fail_on == "new" and run.baseline_path is None:
        raise UsageError("--fail-on new needs --baseline PREVIOUS.json (the run whose alarms are known)")
    rules: tuple = ()
    if run.suppressions_path is not None:  # no reason or an expired entry is exit 2
        from logscan.verdict.suppressions import read_suppressions

        rules = tuple(read_suppressions(run.suppressions_path))
    previous = None
    if run.baseline_path is not None:  # a bad baseline stops the run at once
        from logscan.verdict.baseline import read_baseline

        previous = read_baseline(run.baseline_path)
    return names, rules, previous


def _output_paths(run: _Run, logs: list) -> tuple[list, str | None, list[str]]:
    """(each log's report or None, the index page of several reports, every file written), checked
    before any log is read: no output may replace an input or another output; the temporary files
    a killed run left beside them are removed."""
    from logscan.artifacts import remove_orphans
    from logscan.fleet import output_paths, refuse_clobbering
    from logscan.report.index_page import index_path

    reports = output_paths(logs, run.output_path) if not run.no_report else [None] * len(logs)
    plotly_js = _plotly_js_path(None if run.no_report else run.plotlyjs_dir)
    report_option = "--output" if run.output_path else "report"
    artifacts = {"--json": run.json_path, "--plotlyjs": plotly_js, "--junit": run.junit_path}
    refuse_clobbering(
        [*((report_option, r) for r in reports), *artifacts.items(), ("--markdown", run.markdown_path)],
        logs,
        run.profile_path,
    )
    index = index_path(reports) if run.output_path is not None else None  # several reports: their index page
    given = (*reports, run.json_path, plotly_js, run.junit_path, run.markdown_path, index)
    written = [p for p in given if p and p != "-"]
    remove_orphans(written)
    return reports, index, written


def _task(run: _Run, names, rules: tuple, token: str, steps: bool):
    """The per-log task (`logscan.tasks.AnalyzeTask`) of this run."""
    from logscan.tasks import AnalyzeTask

    return AnalyzeTask(
        run.profile_path,
        names,
        run.use_header_stamp,
        None if run.no_report else run.plotlyjs_dir,
        run.allow_partial,
        render=render_summary,
        step=echo_step if steps else None,
        fraction=echo_fraction if steps else None,
        notice=echo_notice if not run.quiet else None,
        token=token,
        start_s=run.start_s,
        end_s=run.end_s,
        tables_path=run.tables_path,
        truth_path=run.truth_path,
        fail_on_warning=run.fail_on == "warning",
        suppressions=rules,
        block_s=run.block_s,
    )


def _finish(run: _Run, outcomes: list, previous: dict | None, staged: list, index: str | None, token: str, rules=()):
    """The summaries, the unused suppressions, the baseline's comparison and the annotations
    printed, then every output written at once (`_write_outputs`); the run's exit code."""
    from logscan.tasks import LogOutcome

    exit_zero = run.exit_zero or run.fail_on == "never"
    code, document = _report_outcomes(outcomes, exit_zero, err=run.err)
    if run.suppressions_path is not None:
        _warn_unused_suppressions(document, list(rules), run.suppressions_path)
    if previous is not None:
        code = _compare_with_baseline(document, previous, code, run.fail_on, exit_zero, err=run.err)
    if run.github_annotations:
        from logscan.report.ci_annotations import github_annotations as annotations
        from logscan.report.ci_annotations import summary_words

        for line in annotations(document, summary_words(run.markdown_path, run.json_path)):
            click.echo(line, err=run.err)
    if index is not None:
        from logscan.artifacts import stage
        from logscan.report.index_page import render_index_html

        staged.append(stage(index, render_index_html(document, index), token=token))
    plotlyjs_dir = None if run.no_report else run.plotlyjs_dir
    times = [o.seconds for o in outcomes if isinstance(o, LogOutcome)]  # JUnit's, in the order of the logs
    _write_outputs(staged, run.json_path, document, plotlyjs_dir, token, run.junit_path, run.markdown_path, times)
    return code


def _warn_unused_suppressions(document: dict, rules: list, path: str) -> None:
    """List the suppression entries that matched no alarm in the document and warn of each on
    stderr (as ruff's unused ``noqa``); the exit code stays (docs/ci.md says why)."""
    from logscan.report.ci_artifacts import unused_line
    from logscan.verdict.suppressions import mark_unused

    for entry in mark_unused(document, rules, path):
        click.echo(f"logscan: warning: {printable(path)}: {printable(unused_line(entry))}", err=True)


def _run_logs(items: list, task, jobs: int, progress: bool, scheduler: str | None) -> list:
    """Each (log, report) through ``task`` (`logscan.fleet.run_many`); one log's step line ended
    (its last step's time printed) before anything else is."""
    from logscan.fleet import run_many

    # what the imports made lives to the end: the collector stops walking it while logs are analysed
    # (0.1 s of a 1-hour log), and forked workers keep sharing its pages
    gc.freeze()
    try:
        return run_many(
            items, task, jobs=jobs, progress=progress, label="analysing", isolate=len(items) > 1, scheduler=scheduler
        )
    finally:
        gc.unfreeze()
        end_steps()


def _compare_with_baseline(document: dict, previous: dict, code, fail_on: str, exit_zero: bool, err: bool):
    """Mark the alarms new / unchanged / gone (in the document), print the counts, and with
    ``--fail-on new`` let only new alarms fail the run; returns the exit code."""
    from logscan.verdict.baseline import compare, exit_code_on_new

    totals = compare(document, previous)
    click.echo(
        f"baseline: {totals['new']} new, {totals['unchanged']} unchanged, {totals['gone']} gone alarm(s)", err=err
    )
    missing = document["baseline"]["not_analysed"]
    if missing:
        names = ", ".join(printable(name) for name in missing)
        click.echo(f"baseline: {len(missing)} log(s) not analysed in this run: {names}", err=err)
    if fail_on == "new" and not exit_zero:
        code = ExitCode(exit_code_on_new(document))
        document["exit_code"] = int(code)
    return code


def _plotly_js_path(plotlyjs_dir: str | None) -> str | None:
    """Where --plotlyjs DIR puts plotly.js (DIR is created here, before any log is read)."""
    from logscan.report.page_assets import plotly_js_target

    return None if plotlyjs_dir is None else str(plotly_js_target(plotlyjs_dir))


def _report_outcomes(outcomes: list, exit_zero: bool, err: bool) -> tuple[ExitCode, dict]:
    """Print each log's summary (stderr when ``err``) or error line; the run's exit code and JSON."""
    from logscan import __version__
    from logscan.fleet import LogFailure

    summaries, failures, codes = [], [], []
    for outcome in outcomes:
        if isinstance(outcome, LogFailure):
            click.echo(f"logscan: error: {printable(outcome.message)}", err=True)
            failures.append({"file": outcome.path, "error": outcome.message, "exit_code": outcome.exit_code})
            codes.append(ExitCode(outcome.exit_code))
            continue
        summaries.append(outcome.summary)
        codes.append(ExitCode(outcome.summary["exit_code"]))
        # with --json - the JSON owns stdout; the human summary goes to stderr
        colour = use_colour(err)
        text = coloured_verdict(outcome.text, outcome.summary["verdict"], outcome.summary["exit_code"])
        click.echo(text if colour else outcome.text, err=err, color=colour)

    # the worst log decides: a failure (3) over bad or unchecked input (2) over alarms (1)
    code = max(codes, default=ExitCode.OK)
    if exit_zero and code == ExitCode.ALARMS:
        code = ExitCode.OK
    # docs/schema/analyze-summary.schema.json describes it (a test validates every sample's)
    document = {
        "schema_version": SUMMARY_SCHEMA_VERSION,
        "logscan_version": __version__,
        "exit_code": int(code),
        "logs": summaries,
        "errors": failures,
    }
    return code, document


def _write_outputs(
    staged: list,
    json_path: str | None,
    document: dict,
    plotlyjs_dir: str | None,
    token: str,
    junit_path: str | None = None,
    markdown_path: str | None = None,
    times: list[float] | None = None,
) -> None:
    """The run's outputs all at once: the reports (already staged by the tasks), plotly.js and the
    JSON staged beside their targets, then renamed in a row (`logscan.artifacts.commit`: the JSON
    last, signals held), so an interrupted run leaves all previous outputs or all new ones."""
    from logscan.artifacts import commit, stage, stage_json, write_json_into

    if plotlyjs_dir is not None:
        from logscan.report.page_assets import stage_plotly_js

        js = stage_plotly_js(plotlyjs_dir, token)
        if js is not None:
            staged.insert(0, js)
    if junit_path or markdown_path:
        from logscan.report.ci_artifacts import junit_xml, markdown_summary

        if junit_path:  # each log's analysis time, which the JSON leaves out
            staged.append(stage(junit_path, junit_xml(document, times), token=token))
        if markdown_path:  # the report links relative to its folder
            staged.append(stage(markdown_path, markdown_summary(document, markdown_path), token=token))
    if json_path and json_path != "-":
        staged.append(stage_json(json_path, document, token=token))
    commit(staged)
    staged.clear()
    if json_path == "-":
        write_json_into(sys.stdout, document)
