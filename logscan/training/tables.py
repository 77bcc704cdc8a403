"""The trained tables file (`logscan train` writes it, `logscan.training.train`): reading it, checking it
against a profile and applying it to the detectors (`apply_tables`), below the pipeline that
applies it (`logscan.pipeline.analyze_log`) and the training that writes it.

The tables file holds one trained state per detector (`Detector.to_state`: detector name, its
schema version, parameters, trained attributes), the training logs (name, size, SHA-256) and the
fingerprint of the profile's vehicle, inputs, measurements, mode and redundant sections:
`logscan analyze --tables` refuses tables trained for another profile (`apply_tables`). The
fingerprint is what identifies the vehicle and its profile (model, channels, transforms,
parameters), not the numbers a built-in profile measures from each log (`MEASURED_KEYS`: two
flights of one vehicle log its IMU at 198 and 200 Hz): the rates are held to within
RATE_TOLERANCE of the tables' instead (``profile_rates``), and the noise is the calibration's or
each flight's own.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from logscan.detectors.registry import default_registry
from logscan.errors import InputError, ProfileError
from logscan.input_files import MAX_TABLES_BYTES, inside_log_folder, read_input_text
from logscan.training.calibration import apply_calibration, calibration_failures
from logscan.training.tuning import tuned_params

TABLES_FORMAT = "logscan-tables"
TABLES_VERSION = 3  # 3: the fingerprint leaves out measured values, the rates are held apart
# the profile sections a trained table depends on (detector settings and alarm floors do not)
TRAINED_SECTIONS = ("vehicle", "inputs", "measurements", "mode", "redundant")
# the keys whose values a built-in profile measures from each log (a rate, the staleness that
# follows from it, a noise; an input's "scale" is the per-second scale of an IMU's increments, one
# over their measured period): not the vehicle's identity, left out of its fingerprint
MEASURED_KEYS = frozenset({"rate_hz", "stale_s", "noise_std", "noise_channels_scale"})
RATE_TOLERANCE = 0.1  # a rate (or an input's scale) may differ this much (relative) from the tables'


def profile_fingerprint(profile) -> str:
    """SHA-256 of what identifies the profile in the sections a trained table depends on
    (canonical JSON, without the measured values: `MEASURED_KEYS`, the inputs' scales)."""
    data = profile.to_dict()
    trained = {key: _identity(data.get(key), key) for key in TRAINED_SECTIONS}
    return hashlib.sha256(json.dumps(trained, sort_keys=True, default=str).encode()).hexdigest()


def _identity(value, section: str):
    """``value`` without the measured values of `MEASURED_KEYS` (and the inputs' scales)."""
    if isinstance(value, dict):
        return {
            key: _identity(item, section)
            for key, item in value.items()
            if key not in MEASURED_KEYS and not (section == "inputs" and key == "scale")
        }
    if isinstance(value, list):
        return [_identity(item, section) for item in value]
    return value


def profile_rates(profile) -> dict[str, float]:
    """The rates a trained table assumes: the grid's and each group's rate_hz, and each input's
    scale (an IMU's increments per second), by their place in the profile ("vehicle.rate_hz")."""
    data = profile.to_dict()
    rates: dict[str, float] = {}
    for section in TRAINED_SECTIONS:
        _collect_rates(data.get(section), section, rates)
    return rates


def _collect_rates(value, where: str, out: dict[str, float]) -> None:
    if not isinstance(value, dict):
        return
    for key, item in value.items():
        place = f"{where}.{key}"
        scale = where.startswith("inputs") and key == "scale"
        if (key == "rate_hz" or scale) and item is not None:
            numbers = [float(v) for v in (item if isinstance(item, list) else [item])]
            if numbers and all(n > 0 and n != float("inf") for n in numbers):
                out[place] = numbers[0]
        else:
            _collect_rates(item, place, out)


def _rate_mismatches(trained: dict, profile) -> list[str]:
    """The rates of ``profile`` more than RATE_TOLERANCE from the tables' (``trained``)."""
    own = profile_rates(profile)
    return [
        f"{place} {own[place]:.4g} (the tables': {value:.4g})"
        for place, value in sorted(trained.items())
        if place in own and abs(own[place] - value) > RATE_TOLERANCE * abs(value)
    ]


def retrain_command(document: dict, tables: str | os.PathLike, profile, *, same_logs: bool = True) -> str:
    """The `logscan train` command that writes ``tables`` again for ``profile`` (None: the profile
    file the tables were trained with, if any): the tables' own training logs that are still there
    (``same_logs``; else, or when none is, HEALTHY_LOG...: logs of the vehicle to analyse), with
    their options (--calibrate, --tune, --start/--end), and --profile only for a profile file (a
    built-in or embedded profile comes from each log)."""
    import shlex

    source = profile.source_file() if profile is not None else document.get("profile_path")
    logs = [str(entry.get("path", "")) for entry in document.get("training_logs") or [] if isinstance(entry, dict)]
    logs = [path for path in logs if path and os.path.exists(path)] if same_logs else []
    words = ["logscan", "train", *(shlex.quote(path) for path in logs or ["HEALTHY_LOG..."])]
    if source and Path(source).is_file():
        words += ["--profile", shlex.quote(str(source))]
    if document.get("calibration"):
        words.append("--calibrate")
    if document.get("tuning"):
        words.append("--tune")
    window = document.get("training_window") or {}
    words += [f"--{edge} {window[f'{edge}_s']:g}" for edge in ("start", "end") if window.get(f"{edge}_s") is not None]
    return " ".join([*words, "-o", shlex.quote(str(tables))])


def read_tables_document(path: str | os.PathLike) -> dict[str, Any]:
    """The tables JSON (InputError on anything but a tables file of this schema)."""
    text = read_input_text(path, what="the tables file", limit=MAX_TABLES_BYTES)
    try:
        document = json.loads(text)
    except RecursionError:
        raise InputError("the tables file is nested too deeply to be tables JSON", path=str(path)) from None
    except ValueError as exc:  # a JSONDecodeError: where, not the decoder's words
        where = f" (line {exc.lineno}, column {exc.colno})" if isinstance(exc, json.JSONDecodeError) else ""
        raise InputError(
            f"not a tables file: not JSON{where}", path=str(path), hint="give the tables JSON `logscan train -o` wrote"
        ) from None
    if not isinstance(document, dict) or document.get("format") != TABLES_FORMAT:
        raise InputError("not a logscan tables file", path=str(path), hint="use a file written by `logscan train`")
    if document.get("schema_version") != TABLES_VERSION:
        raise InputError(
            f"tables schema version {document.get('schema_version')!r}, this logscan reads {TABLES_VERSION}",
            path=str(path),
            hint=f"retrain with `{retrain_command(document, path, None)}`",
        )
    return document


def read_tables(path: str | os.PathLike) -> dict[str, Any]:
    """Trained detectors by name from a tables file (InputError on anything but a tables file)."""
    document = read_tables_document(path)
    registry = default_registry()
    trained = {}
    for state in document.get("detectors") or []:
        name = state.get("detector") if isinstance(state, dict) else None
        trained[name] = registry.get(str(name)).from_state(state, path=str(path))
    return trained


def tables_path(option: str | None, profile, log: str | os.PathLike | None = None) -> str | None:
    """The tables to use: ``--tables``, else the profile's ``tables`` key: relative to the profile's
    file, or, for the profile embedded in the log ``log`` (or any profile that is no file of the
    user's), a file in the log's folder (the current directory without ``log``) and never outside
    it (`logscan.input_files.inside_log_folder`)."""
    if option is not None:
        return option
    if not profile.tables:
        return None
    source = Path(profile.source)
    if source.is_file():  # the user's own profile file
        return str(source.parent / profile.tables)
    beside = log if log is not None else os.path.join(os.getcwd(), "log")
    return inside_log_folder(str(profile.tables), beside, key="tables", source=str(profile.source))


def apply_tables(detectors: Sequence, path: str | os.PathLike, profile) -> list:
    """``detectors`` with the trained state of ``path`` (trained for this profile, else exit 2):
    each detector the tables hold is replaced by its trained self, its run-time parameters taken
    from the profile; the others are kept. The tables' calibrated measurement noise is set in
    ``profile`` (`logscan.training.calibration.apply_calibration`): the filter then runs as in training."""
    document = read_tables_document(path)
    fingerprint = document.get("profile_fingerprint")
    if fingerprint != profile_fingerprint(profile):
        # a profile file: its tables from the same logs; a built-in or embedded one: other logs
        command = retrain_command(document, path, profile, same_logs=bool(profile.source_file()))
        raise ProfileError(
            "the tables were trained for another profile (its vehicle, inputs, measurements, mode or "
            "redundant sections differ)",
            path=str(path),
            hint=f"train tables for it: `{command}`",
        )
    rates = _rate_mismatches(document.get("profile_rates") or {}, profile)
    if rates:
        raise ProfileError(
            f"the tables were trained at other rates: {', '.join(rates)}; more than {RATE_TOLERANCE:.0%} apart",
            path=str(path),
            hint=f"train tables at these rates: `{retrain_command(document, path, profile, same_logs=False)}`",
        )
    failures = calibration_failures(document.get("calibration"))
    if failures:
        raise InputError(
            f"the tables' calibration failed ({'; '.join(failures)}): its noise would misjudge every log",
            path=str(path),
            hint="calibrate on more or longer healthy flights "
            f"(`{retrain_command(document, path, profile, same_logs=False)}`), or train without --calibrate",
        )
    trained = read_tables(path)
    # after the profile check: the calibrated noise changes the profile it fingerprints
    apply_calibration(profile, document.get("calibration"))

    out = []
    for detector in detectors:
        tuned = tuned_params(document.get("tuning"), detector.name)
        if tuned:  # `logscan train --tune`: the multipliers chosen on the training logs
            detector = detector.with_params(**tuned)
        fitted = trained.get(detector.name)
        if fitted is None:
            out.append(detector)
            continue
        fitted.params.update({k: v for k, v in detector.params.items() if k not in fitted.fit_params})
        fitted.check_params()
        out.append(fitted)
    return out
