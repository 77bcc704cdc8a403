"""`logscan inspect`: what a log holds (topics, types, counts, rates, time span, fields)."""

from __future__ import annotations

import click
import numpy as np

from logscan.cli.options import header_stamp_option, json_option
from logscan.cli.render_inspect import render_inspect
from logscan.log import Log
from logscan.readers import read_log


@click.command(
    epilog="Examples:\n\n"
    "  logscan inspect sample_logs/quad_healthy.mcap\n\n"
    "  logscan inspect flight.ulg --channels\n\n"
    "  logscan inspect flight.ulg --topic vehicle_imu_0 --full\n\n"
    "  logscan inspect drive.bag --channels\n\n"
    "  logscan inspect csv_dir/ --json facts.json"
)
@click.argument("log_path", metavar="LOG", type=click.Path(path_type=str))
@click.option(
    "--channels", "show_channels", is_flag=True, help="List every numeric channel with samples, rate, NaNs and range."
)
@click.option(
    "--topic",
    "-t",
    "topics",
    multiple=True,
    metavar="NAME",
    help="Read only this topic or channel (repeatable). Default: all.",
)
@click.option("--full", is_flag=True, help="Do not truncate field lists, skips and warnings.")
@json_option
@header_stamp_option
def inspect(
    log_path: str,
    show_channels: bool,
    topics: tuple[str, ...],
    full: bool,
    json_path: str | None,
    use_header_stamp: bool,
) -> None:
    """Show the topics, message types, counts, rates, time span and fields of LOG.

    LOG is an MCAP file, a PX4 ULog file, a ROS 1 bag, a rosbag2 .db3 file or directory, a CSV file
    or a directory of per-topic CSV files. Names
    from the log are shown with control characters escaped (e.g. ESC as \\x1b).
    """
    from logscan.fleet import refuse_clobbering

    refuse_clobbering([("--json", json_path)], [log_path])  # the facts never replace the log
    facts = read_facts(log_path, topics or None, use_header_stamp)
    if json_path:
        from logscan.artifacts import write_json

        write_json(json_path, facts)
        if json_path == "-":
            return
    click.echo(render_inspect(facts, show_channels, full=full))


def read_facts(path: str, topics: tuple[str, ...] | None, use_header_stamp: bool) -> dict:
    """The facts of one log. An MCAP file (also the one file of a rosbag2 directory with MCAP
    storage) is read in memory bounded by a few chunks (its channels' statistics folded as it is
    decoded); ULog, other ROS bags and CSV logs are read whole."""
    from pathlib import Path

    from logscan.readers import detect_format

    fmt = detect_format(path)
    mcap_file = path if fmt == "mcap" else None
    if fmt == "rosbag2":
        from logscan.readers.rosbag import single_mcap

        mcap_file = single_mcap(Path(path))
    if mcap_file is not None:
        from logscan.readers.mcap import inspect_mcap

        wanted = None if topics is None else set(topics)
        log, stats = inspect_mcap(mcap_file, wanted, use_header_stamp=use_header_stamp)
        log.source.path, log.source.format = str(path), fmt
        facts = log.summary()
        facts.setdefault("metadata", {k: dict(v) for k, v in log.source.metadata.items()})
        for name, info in facts["channels"].items():
            info.update(stats[name])
        return facts
    return inspect_facts(read_log(path, topics, use_header_stamp=use_header_stamp))


def inspect_facts(log: Log) -> dict:
    """``Log.summary()`` plus the source metadata and per-channel statistics (JSON-ready)."""
    facts = log.summary()
    facts.setdefault("metadata", {k: dict(v) for k, v in log.source.metadata.items()})
    for name, info in facts["channels"].items():
        info.update(_channel_stats(log.channels[name]))
    return facts


def _channel_stats(channel) -> dict:
    t, values = channel.t, channel.values
    finite = np.isfinite(values)
    n = int(t.size)
    span = (int(t.max()) - int(t.min())) / 1e9 if n else 0.0
    return {
        "rate_hz": round((n - 1) / span, 6) if n > 1 and span > 0 else 0.0,
        "nonfinite": int(n - finite.sum()),
        "min": float(values[finite].min()) if finite.any() else None,
        "max": float(values[finite].max()) if finite.any() else None,
    }
