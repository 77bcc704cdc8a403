"""Profile binding: channels to the vehicle model's inputs, measurement groups and states, checked."""

from __future__ import annotations

from logscan.models import MODEL_NAMES, get_model
from logscan.profiles.problems import is_number, plural, suggest
from logscan.profiles.schema import (
    MeasurementSpec,
    ModelFacts,
    Profile,
    VehicleSpec,
    input_channels,
    input_transform,
)


def build_model(vehicle: VehicleSpec, problems: list[str]):
    """The registry's model named in ``[vehicle]`` built from its params, or None with problems
    (every problem the model found in its parameters)."""
    names = tuple(MODEL_NAMES)
    name = vehicle.model
    if name not in names:
        problems.append(
            f"[vehicle] model: unknown model {name!r}{suggest(name, names)} (known models: {', '.join(sorted(names))})"
        )
        return None
    try:
        return get_model(name, vehicle.params)
    except Exception as exc:  # noqa: BLE001 - any failure to build is a profile problem
        found = getattr(exc, "problems", None) or [getattr(exc, "message", None) or str(exc)]
        problems.extend(f"[vehicle] params: model {name!r} cannot be built: {msg}" for msg in found)
        return None


def check_against_model(profile: Profile, model, problems: list[str]) -> None:
    """Bind inputs and check group names, sizes and noise against the model; append problems."""
    if model is None:
        model = build_model(profile.vehicle, problems)
        if model is None:
            return
    label = f"model {profile.vehicle.model!r}"
    params = profile.vehicle.params
    if params.get("continuous") is False and is_number(params.get("dt")) and params["dt"] > 0:
        # discrete matrices step once per grid period: the grid must run at 1 / dt
        if abs(params["dt"] * profile.vehicle.rate_hz - 1.0) > 1e-9:
            problems.append(
                f"[vehicle] params.dt: discrete matrices of period {params['dt']:g} s need "
                f"rate_hz = {1.0 / params['dt']:g}, got {profile.vehicle.rate_hz:g}"
            )
    input_names = tuple(model.input_names)
    _bind_inputs(profile, input_names, label, problems)
    groups = dict(model.groups)
    for g in profile.measurements.values():
        where = f"[measurements.{g.name}]"
        spec = groups.get(g.name)
        if spec is None:
            problems.append(
                f"{where}: {label} has no measurement group {g.name!r}"
                f"{suggest(g.name, groups)} (groups: {', '.join(groups)})"
            )
        elif g.width != spec.size:
            converted = (
                f' (from = "{g.source}" gives {plural(g.width, "value")}: {", ".join(g.output_names())})'
                if g.source is not None
                else ""
            )
            problems.append(
                f"{where} channels: {plural(len(g.channels), 'channel')}{converted} but {label} group {g.name!r} has "
                f"{spec.size} outputs ({', '.join(spec.outputs)})"
            )
        else:
            _check_noise_in_range(g, spec, problems)
    if not problems and hasattr(model, "covariance_problems"):
        problems.extend(f"[vehicle] params: {p}" for p in model.covariance_problems(1.0 / profile.vehicle.rate_hz))
    if not problems:
        profile.model_facts = ModelFacts(
            input_names=input_names,
            state_names=tuple(model.state_names),
            group_sizes={name: spec.size for name, spec in groups.items()},
        )
        _check_onboard_sizes(profile, problems)


def _check_noise_in_range(group: MeasurementSpec, spec, problems: list[str]) -> None:
    """A group's noise std (the profile's, else the model's) must not exceed its range span (the
    profile's range, else the model's): noise wider than every possible value makes the filter
    ignore the group, so no fault of it could be seen."""
    noise = group.noise_std if group.noise_std is not None else spec.noise_std
    lo = group.range_lo if group.range_lo is not None else spec.range_lo
    hi = group.range_hi if group.range_hi is not None else spec.range_hi
    for i, channel in enumerate(group.output_names() or group.channels):
        span = hi[i] - lo[i]
        if noise[i] > span:
            whose = "" if group.noise_std is not None else f"the model's default for {group.name!r}, "
            problems.append(
                f"[measurements.{group.name}] noise_std: {noise[i]:g} ({whose}{channel!r}) exceeds the group's "
                f"range span {span:g} (range_lo {lo[i]:g} to range_hi {hi[i]:g}): the filter would ignore the group "
                "and hide its faults; give the sensor's real noise"
            )
            return


def _check_onboard_sizes(profile: Profile, problems: list[str]) -> None:
    if profile.onboard is None or profile.model_facts is None:
        return
    states = profile.model_facts.state_names
    for key in ("state", "variance"):
        value = getattr(profile.onboard, key)
        if isinstance(value, list) and len(value) != len(states):
            problems.append(
                f"[onboard] {key}: {plural(len(value), 'channel')} but model {profile.vehicle.model!r} has "
                f"{len(states)} states ({', '.join(states)})"
            )
        elif isinstance(value, dict):
            for s in value:
                if s not in states:
                    problems.append(
                        f"[onboard] {key}: model {profile.vehicle.model!r} has no state {s!r}"
                        f"{suggest(s, states)} (states: {', '.join(states)})"
                    )


def _members(key: str, input_names: tuple[str, ...]) -> list[str]:
    """Model inputs a list-valued key binds: ``key`` + ``_ . [`` or a digit + anything."""
    return [
        n
        for n in input_names
        if n.startswith(key) and len(n) > len(key) and (n[len(key)] in "_.[" or n[len(key)].isdigit())
    ]


def _bind_inputs(profile: Profile, input_names: tuple[str, ...], label: str, problems: list[str]) -> None:
    bound: dict[str, str] = {}
    transform: dict[str, tuple[float, float]] = {}
    reported: set[str] = set()
    for key, value in profile.inputs.mapping.items():
        where = f"[inputs] {key}"
        channels = input_channels(value)
        factors, offsets = input_transform(value)
        if isinstance(value, str) or (key in input_names and len(channels) == 1):
            if key not in input_names:
                problems.append(
                    f"{where}: {label} has no input {key!r}{suggest(key, input_names)} "
                    f"(inputs: {', '.join(input_names)})"
                )
                continue
            targets, chans = [key], channels[:1]
        else:
            targets, chans = _members(key, input_names), channels
            if not targets:
                problems.append(
                    f"{where}: {label} has no inputs named {key!r} or {key}_*{suggest(key, input_names)} "
                    f"(inputs: {', '.join(input_names)})"
                )
                continue
            if len(targets) != len(chans):
                problems.append(
                    f"{where}: {plural(len(chans), 'channel')} but {label} has {len(targets)} inputs "
                    f"starting with {key!r} ({', '.join(targets)})"
                )
                reported.update(targets)  # not "missing" as well
                continue
        for name, ch, factor, offset in zip(targets, chans, factors, offsets):
            if name in bound:
                problems.append(f"{where}: input {name!r} is bound twice")
            bound[name] = ch
            transform[name] = (factor, offset)
    missing = [n for n in input_names if n not in bound and n not in reported]
    if missing:
        problems.append(
            f"[inputs]: {label} input{'s' if len(missing) > 1 else ''} "
            f"{', '.join(repr(m) for m in missing)} {'have' if len(missing) > 1 else 'has'} no channel "
            f"(inputs: {', '.join(input_names)})"
        )
    profile.inputs.names = [n for n in input_names if n in bound]
    profile.inputs.channels = [bound[n] for n in profile.inputs.names]
    profile.inputs.factors = [transform[n][0] for n in profile.inputs.names]
    profile.inputs.offsets = [transform[n][1] for n in profile.inputs.names]


def bind_inputs_without_model(profile: Profile) -> None:
    names, chans, factors, offsets = [], [], [], []
    for key, value in profile.inputs.mapping.items():
        channels = input_channels(value)
        if isinstance(value, str):
            names.append(key)
        else:
            names.extend(f"{key}[{i}]" for i in range(len(channels)))
        chans.extend(channels)
        f, o = input_transform(value)
        factors.extend(f)
        offsets.extend(o)
    profile.inputs.names, profile.inputs.channels = names, chans
    profile.inputs.factors, profile.inputs.offsets = factors, offsets
