"""Training: fit detectors on prepared healthy runs, and their trained state as versioned tables JSON.

    detectors = create_detectors(loaded)                            # logscan.pipeline
    prepared = [prepare(p, loaded, needs_of(detectors)) for p in healthy_logs]
    fit_detectors(detectors, prepared)
    write_tables("vehicle.tables.json", detectors)

Training never runs a detector over a log: it prepares each healthy log (read, align, filters) and
hands the runs and traces to each detector's `fit`. The tables file holds one trained state per
detector (`Detector.to_state`: detector name, its schema version, parameters, trained attributes).
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from typing import Any

from logscan.errors import InputError, UsageError

TABLES_FORMAT = "logscan-tables"
TABLES_VERSION = 1


def fit_detectors(detectors: Sequence, prepared: Sequence) -> list:
    """Fit every detector on the prepared healthy runs (`logscan.pipeline.Prepared`); returns them."""
    if not prepared:
        raise UsageError("training needs at least one healthy log")
    runs = [p.run for p in prepared]
    traces = [p.trace for p in prepared]
    for detector in detectors:
        detector.fit(runs, traces, model=prepared[0].model)
    return list(detectors)


def tables_document(detectors: Sequence) -> dict[str, Any]:
    """The tables JSON: format, version and the trained state of each detector that learns something."""
    from logscan import __version__

    return {
        "format": TABLES_FORMAT,
        "schema_version": TABLES_VERSION,
        "logscan_version": __version__,
        "detectors": [d.to_state() for d in detectors if d.trained_attributes],
    }


def write_tables(path: str | os.PathLike, detectors: Sequence) -> None:
    """Write the tables JSON atomically."""
    from logscan.artifacts import write_json

    write_json(path, tables_document(detectors))


def read_tables(path: str | os.PathLike) -> dict[str, Any]:
    """Trained detectors by name from a tables file (InputError on anything but a tables file)."""
    from logscan.detectors.registry import default_registry

    try:
        with open(path, encoding="utf-8") as fh:
            document = json.load(fh)
    except (OSError, ValueError) as exc:
        raise InputError(f"cannot read the tables file: {exc}", path=str(path)) from None
    if not isinstance(document, dict) or document.get("format") != TABLES_FORMAT:
        raise InputError("not a logscan tables file", path=str(path), hint="use a file written by `logscan train`")
    if document.get("schema_version") != TABLES_VERSION:
        raise InputError(
            f"tables schema version {document.get('schema_version')!r}, this logscan reads {TABLES_VERSION}",
            path=str(path),
            hint="retrain with `logscan train`",
        )
    registry = default_registry()
    trained = {}
    for state in document.get("detectors") or []:
        name = state.get("detector") if isinstance(state, dict) else None
        trained[name] = registry.get(str(name)).from_state(state, path=str(path))
    return trained
