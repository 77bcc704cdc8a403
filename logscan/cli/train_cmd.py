"""`logscan train`: fit the profile's trainable detectors on healthy logs into a tables JSON (+ report)."""

from __future__ import annotations

import os

import click

from logscan.cli.options import (
    GroupedCommand,
    check_parallelism,
    echo_notice,
    help_groups,
    jobs_option,
    plotlyjs_option,
    profile_option,
    quiet_option,
    scheduler_option,
    show_progress,
    window_options,
)


@help_groups(
    {
        "Input": ("profile_path", "start_s", "end_s", "allow_faulty"),
        "Training": ("calibrate", "tune"),
        "Outputs": ("output_path", "report_path", "no_report", "plotlyjs_dir", "quiet"),
        "Parallel": ("jobs", "scheduler"),
    }
)
@click.command(
    cls=GroupedCommand,
    short_help="Train the detectors' tables and thresholds (and the filter's noise) on healthy logs.",
    epilog="Examples:\n\n"
    "  logscan train sample_logs/jackal_train_1.mcap sample_logs/jackal_train_2.mcap -o jackal.tables.json\n\n"
    "  logscan analyze sample_logs/jackal_gps_bias.mcap --tables jackal.tables.json -d atfm",
)
@click.argument("log_paths", metavar="LOG_OR_DIR...", nargs=-1, required=True, type=click.Path(path_type=str))
@profile_option
@click.option(
    "--output", "-o", "output_path", required=True, type=click.Path(dir_okay=False, path_type=str),
    help="The tables JSON to write (its training report goes beside it as <name>.html).",
)  # fmt: skip
@click.option(
    "--report", "report_path", type=click.Path(dir_okay=False, path_type=str), default=None,
    help="Write the training report here instead of beside the tables.",
)  # fmt: skip
@click.option("--no-report", is_flag=True, default=False, help="Write no training report.")
@plotlyjs_option("Write plotly.min.js once into DIR and link it from the training report; default 'embed': inside it.")
@click.option(
    "--allow-faulty", is_flag=True, default=False,
    help="Train on logs whose ground truth lists faults (refused by default: a table trained on a fault "
    "tolerates it).",
)  # fmt: skip
@click.option(
    "--calibrate",
    is_flag=True,
    default=False,
    help="Also calibrate the filter's noise: each group's noise_std (its mean NIS per output on these logs "
    "-> 1) and the process noise Q, one scale per block of like states fitted to the innovations' "
    "likelihood (for real logs whose noise the profile only guesses); the detectors are then fitted on "
    "the calibrated filter.",
)
@window_options("Train on", "each log", "e.g. to leave out the ground time and take-off of a real flight")
@jobs_option
@scheduler_option
@click.option(
    "--tune",
    is_flag=True,
    default=False,
    help="Also choose the threshold multipliers (encoded_ekf's rho, rho_v, rho_s): the smallest with no "
    "false alarm on the healthy logs plus a margin of 1, F1 on labelled logs (ground truth with faults, "
    "accepted with --tune) breaking ties; `logscan analyze --tables` then runs with them.",
)
@quiet_option
def train(
    log_paths: tuple[str, ...],
    profile_path: str | None,
    output_path: str,
    report_path: str | None,
    no_report: bool,
    plotlyjs_dir: str | None,
    allow_faulty: bool,
    calibrate: bool,
    start_s: float | None,
    end_s: float | None,
    jobs: int,
    scheduler: str | None,
    tune: bool,
    quiet: bool,
) -> None:
    """Train the lookup tables and thresholds of the profile's detectors on healthy logs (and, with
    --calibrate, the filter's measurement and process noise).

    LOG_OR_DIR are healthy logs (or directories of them) of one vehicle and profile. With
    --calibrate the filter's noise is calibrated first: each group's noise_std is scaled until its
    mean NIS per output on these logs is 1, alternating with one scale of the process noise Q per
    block of like states, fitted to the innovations' likelihood (`logscan analyze --tables` then
    filters with both). Every detector that learns from healthy logs is fitted (on the calibrated
    filter with --calibrate): the A-TFM table of each [redundant] group
    (eps and e per sensor and mode value), and the thresholds of the detectors the profile runs in a
    trained variant. Writes one versioned JSON (the training logs' names and SHA-256, the profile's
    fingerprint) for `logscan analyze --tables`, and a training report. Exit 0, or 2 on bad input
    or a calibration that failed (not converged, or a noise at its bound: written, marked failed).
    """
    from logscan.errors import InputError
    from logscan.fleet import expand_logs, refuse_clobbering
    from logscan.timebase.time_sanity import check_window
    from logscan.training.calibration import calibration_failures
    from logscan.training.train import train_logs

    check_parallelism(jobs, scheduler)
    check_window(start_s, end_s)
    logs = expand_logs(log_paths)
    report = None if no_report else (report_path or _beside(output_path))
    refuse_clobbering([("--output", output_path), ("--report", report)], logs, profile_path)
    document = train_logs(
        logs, profile_path, allow_faulty=allow_faulty, calibrate=calibrate, tune=tune,
        progress=_echo_step if show_progress(quiet) else None, notice=None if quiet else echo_notice,
        jobs=jobs, scheduler=scheduler, start_s=start_s, end_s=end_s,
    )  # fmt: skip
    _write(output_path, report, document, plotlyjs_dir)
    if not quiet:
        for line in _summary_lines(document, output_path, report):
            click.echo(line)
    failures = calibration_failures(document.get("calibration"))
    if failures:  # written, marked failed (the report shows why); analyze refuses them
        raise InputError(
            f"the calibration failed: {'; '.join(failures)} (marked so in the tables; `logscan analyze` refuses them)",
            path=output_path,
            hint="calibrate on more or longer healthy flights, or train without --calibrate",
        )


def _echo_step(message: str) -> None:
    """A step of the training (a log read, a table fitted), on stderr."""
    click.echo(f"logscan: {message}", err=True)


def _beside(output_path: str) -> str:
    root, ext = os.path.splitext(output_path)
    return (root if ext.lower() == ".json" else output_path) + ".html"


def _write(output_path: str, report: str | None, document: dict, plotlyjs: str | None = None) -> None:
    """The tables and the report (with --plotlyjs DIR, plotly.min.js there too), all or none
    (staged, then renamed in a row)."""
    from logscan.artifacts import commit, new_token, stage, stage_json

    token = new_token()
    staged = [stage_json(output_path, document, token=token)]
    if report is not None:
        from logscan.report.plotly_script import shared_plotly_js
        from logscan.report.training_page import render_training_html

        src, js = shared_plotly_js(report, plotlyjs, token)
        staged.insert(0, stage(report, render_training_html(document, plotlyjs_src=src), token=token))
        if js is not None:
            staged.insert(0, js)
    commit(staged)


def _summary_lines(document: dict, output_path: str, report: str | None) -> list[str]:
    from logscan.detectors.registry import default_registry

    registry = default_registry()
    from logscan.report.training_page import window_text
    from logscan.training.calibration import calibration_lines

    window = window_text(document.get("training_window"))
    each = f" ({window} of each)" if window else ""
    lines = [f"trained on {len(document['training_logs'])} log(s){each}: {output_path}"]
    if document.get("calibration"):
        lines.append("  filter noise calibrated (mean NIS per output -> 1; process noise Q per block):")
        lines.extend("  " + line for line in calibration_lines(document["calibration"]))
    if document.get("tuning"):
        from logscan.training.tuning import tuning_lines

        lines.append("  threshold multipliers tuned:")
        lines.extend("  " + line for line in tuning_lines(document["tuning"]))
    for state in document["detectors"]:
        lines.extend(registry.get(state["detector"]).state_lines(state))
    if report is not None:
        lines.append(f"  report: {report}")
    return lines
