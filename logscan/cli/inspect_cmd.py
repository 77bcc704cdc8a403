"""`logscan inspect`: what a log holds (topics, types, counts, rates, time span, fields)."""

from __future__ import annotations

import click

from logscan.cli.options import header_stamp_option, json_option
from logscan.readers import read_log


@click.command(
    epilog="Examples:\n\n"
    "  logscan inspect sample_logs/quad_healthy.mcap\n\n"
    "  logscan inspect flight.ulg --channels\n\n"
    "  logscan inspect csv_dir/ --json facts.json"
)
@click.argument("log_path", metavar="LOG", type=click.Path(path_type=str))
@click.option("--channels", "show_channels", is_flag=True, help="List every numeric channel.")
@json_option
@header_stamp_option
def inspect(log_path: str, show_channels: bool, json_path: str | None, use_header_stamp: bool) -> None:
    """Show the topics, message types, counts, rates, time span and fields of LOG.

    LOG is an MCAP file, a PX4 ULog file, a CSV file or a directory of per-topic CSV files.
    """
    log = read_log(log_path, use_header_stamp=use_header_stamp)
    facts = log.summary()
    if json_path:
        from logscan.artifacts import write_json

        write_json(json_path, facts)
        if json_path == "-":
            return
    click.echo(render_inspect(facts, show_channels))


def render_inspect(facts: dict, show_channels: bool) -> str:
    """Plain-text view of ``Log.summary()`` for the terminal."""
    lines = [
        f"file:      {facts['file']}",
        f"format:    {facts['format']}  (time from {facts['time_source']}, source unit {facts['time_unit']})",
    ]
    if facts["start_ns"] is not None:
        lines.append(
            f"time span: {facts['start_ns'] / 1e9:.6f} s .. {facts['end_ns'] / 1e9:.6f} s "
            f"({facts['duration_s']:.3f} s)"
        )
    else:
        lines.append("time span: (no messages)")
    if facts["partial"]:
        lines.append(f"PARTIAL:   {facts['partial_reason']}")
    lines.append(f"extras:    ground truth: {'yes' if facts['has_truth'] else 'no'}, "
                 f"embedded profile: {'yes' if facts['has_profile'] else 'no'}")
    topics = facts["topics"]
    lines.append("")
    lines.append(f"{len(topics)} topic(s):")
    if topics:
        width = max(len(name) for name in topics)
        lines.append(f"  {'topic':<{width}}  {'messages':>9}  {'rate Hz':>9}  encoding / schema")
        for name, info in topics.items():
            kind = " / ".join(x for x in (info["encoding"], info["schema"]) if x)
            lines.append(
                f"  {name:<{width}}  {info['message_count']:>9}  {info['rate_hz']:>9.3f}  {kind}"
            )
            if info["fields"]:
                lines.append(f"  {'':<{width}}  fields: {', '.join(info['fields'])}")
    channels = facts["channels"]
    lines.append("")
    lines.append(f"{len(channels)} numeric channel(s)")
    if show_channels:
        for name, info in channels.items():
            lines.append(f"  {name}  ({info['samples']} samples)")
    if facts["skipped"]:
        lines.append("")
        lines.append("skipped:")
        for item in facts["skipped"]:
            lines.append(f"  {item['what']}: {item['why']} (x{item['count']})")
    for warning in facts["warnings"]:
        lines.append(f"warning: {warning}")
    return "\n".join(lines)
