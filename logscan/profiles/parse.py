"""Profile parsing: TOML text -> a validated Profile, every problem collected and reported at once."""

from __future__ import annotations

import os
import stat
import tomllib
from pathlib import Path

from logscan.input_files import SPECIAL_FILE_HINT, os_error_text, special_kind
from logscan.profiles.bind import bind_inputs_without_model, build_model, check_against_model
from logscan.profiles.check_sections import SectionChecker
from logscan.profiles.loops import PRIMARY_LOOP, parse_loops
from logscan.profiles.problems import DOCS_HINT, profile_error, single_error, type_name
from logscan.profiles.schema import (
    TOP_KEYS,
    Profile,
    VehicleSpec,
)

# A profile is a few KB of TOML; a larger one is the wrong file (or hostile), refused before parsing.
MAX_PROFILE_BYTES = 1 << 20
_SIZE_HINT = "a profile is a few KB of TOML: check that this is the right file"


def load_profile(path: str | os.PathLike, *, model=None) -> Profile:
    """Read and validate the profile file at ``path``."""
    p = Path(path)
    return parse_profile(_profile_text(p), source=str(p), model=model)


def _profile_text(p: Path) -> str:
    """The text of the profile file ``p``: a regular file of at most MAX_PROFILE_BYTES of UTF-8,
    checked with ``os.stat`` before it is opened (opening a FIFO blocks); else a ProfileError."""
    try:
        st = os.stat(p)
        kind = "a directory" if stat.S_ISDIR(st.st_mode) else special_kind(st.st_mode)
        if kind is not None:
            raise single_error(f"profile is {kind}, not a regular file", str(p), hint=SPECIAL_FILE_HINT)
        if st.st_size > MAX_PROFILE_BYTES:
            raise _too_large(st.st_size, str(p))
        with open(p, "rb") as fh:
            data = fh.read(MAX_PROFILE_BYTES + 1)  # the file may have grown since the stat
    except FileNotFoundError:
        raise single_error("no such profile file", str(p)) from None
    except OSError as exc:
        message, hint = os_error_text(exc)
        raise single_error(f"cannot read profile: {message}", str(p), hint=hint or DOCS_HINT) from None
    if len(data) > MAX_PROFILE_BYTES:
        raise _too_large(len(data), str(p))
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise single_error(
            f"profile is not UTF-8 text (bad byte at offset {exc.start})", str(p), hint="save it as UTF-8"
        ) from None


def _too_large(size: int, source: str):
    return single_error(
        f"profile is {size} bytes, more than the {MAX_PROFILE_BYTES} a profile may have", source, hint=_SIZE_HINT
    )


def resolve_profile(log, profile_path: str | os.PathLike | None = None, *, model=None) -> Profile:
    """The ``--profile`` file when given, else the profile embedded in the log, else an error."""
    if profile_path is not None:
        return load_profile(profile_path, model=model)
    text = getattr(log, "profile_text", None) if log is not None else None
    if text:
        return parse_profile(text, source=f"{log.source.path} (embedded logscan.profile)", model=model)
    where = log.source.path if log is not None else None
    raise single_error(
        "no profile: pass --profile or analyse a log that embeds one "
        "(MCAP metadata record 'logscan.profile', as `logscan simulate` writes)",
        where,
    )


def parse_profile(text: str, source: str = "<embedded>", *, model=None, check_model: bool = True) -> Profile:
    """Parse and validate profile TOML ``text``; ``source`` names it in messages.

    ``model``: a built Model to validate against (tests pass fakes); default: the registry's model
    named in ``[vehicle] model``. ``check_model=False`` checks only the structure.
    """
    if len(text) > MAX_PROFILE_BYTES:  # characters: at least as many bytes
        raise _too_large(len(text), source)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise single_error(f"invalid TOML: {exc}", source) from None
    except ValueError:  # not a TOMLDecodeError: Python's int() refuses integers of over 4300 digits
        raise single_error("invalid TOML: an integer has more than 4300 digits", source) from None
    except RecursionError:  # tomllib recurses once per level of nested arrays and inline tables
        raise single_error("invalid TOML: arrays, tables or keys nested too deeply", source) from None
    checker = _Checker(check_model and model is None)
    profile = checker.profile(data, source)
    if profile is not None and check_model and not checker.problems:
        check_against_model(profile, model, checker.problems)
    elif checker.vehicle_spec is not None and check_model and model is None:
        build_model(checker.vehicle_spec, checker.problems)  # its parameter problems too, all at once
    elif profile is not None and not checker.problems:
        bind_inputs_without_model(profile)
    if checker.problems:
        raise profile_error(checker.problems, source)
    return profile


def validate(profile: Profile, model=None) -> Profile:
    """Re-check ``profile`` against ``model`` (default: the registry's); raise ProfileError."""
    problems: list[str] = []
    check_against_model(profile, model, problems)
    if problems:
        raise profile_error(problems, profile.source)
    return profile


class _Checker(SectionChecker):
    """Walks the parsed TOML, building dataclasses and collecting problems (the value, group and
    section checks: `logscan.profiles.check_values`, `check_groups`, `check_sections`)."""

    def __init__(self, check_model: bool = True) -> None:
        self.check_model = check_model  # further loops are checked against their models here
        self.problems: list[str] = []
        self.vehicle_spec: VehicleSpec | None = None  # [vehicle], when it is valid

    def profile(self, data: dict, source: str) -> Profile | None:
        self.keys(data, "", TOP_KEYS, required=("vehicle", "measurements"))
        for key in ("name", "description", "tables"):
            if key in data and not isinstance(data[key], str):
                self.add(key, f"expected a string, got {type_name(data[key])}")
        notes = data.get("notes", [])
        if not (isinstance(notes, list) and all(isinstance(note, str) for note in notes)):
            self.add("notes", f"expected an array of strings, got {type_name(notes)}")
        vehicle = self.vehicle_spec = self.vehicle(data["vehicle"]) if "vehicle" in data else None
        inputs = self.inputs(data.get("inputs", {}), vehicle)
        measurements = self.measurements(data["measurements"]) if "measurements" in data else {}
        mode = self.mode(data["mode"]) if "mode" in data else None
        redundant = self.redundant(data["redundant"]) if "redundant" in data else {}
        onboard = self.onboard(data["onboard"]) if "onboard" in data else None
        detectors = self.detectors(data["detectors"]) if "detectors" in data else {}
        alarm_policy = self.alarms(data["alarms"]) if "alarms" in data else None
        check = check_against_model if self.check_model else None
        loops = parse_loops(self, data["loops"], source, check) if "loops" in data else {}
        primary = vehicle.loop if vehicle is not None and vehicle.loop else PRIMARY_LOOP
        if primary in loops:
            self.add(f"[loops.{primary}]", f"the top level is already the loop {primary!r}: rename one")
        recovery = self.recovery_table(data, {primary, *loops})
        if vehicle is None or inputs is None or self.problems:
            return None
        return Profile(
            loops=loops,
            recovery=recovery,
            vehicle=vehicle,
            inputs=inputs,
            measurements=measurements,
            mode=mode,
            redundant=redundant,
            onboard=onboard,
            detectors=detectors,
            alarm_policy=alarm_policy,
            name=data.get("name", ""),
            description=data.get("description", ""),
            tables=data.get("tables", ""),
            notes=list(notes),
            source=source,
        )
