"""Profiles: schema validation with precise messages, model binding, channel checks, TOML round trip."""

from __future__ import annotations

import copy
import datetime
import re
from pathlib import Path

import numpy as np
import pytest

from logscan.errors import ProfileError
from logscan.log import Channel, Log, SourceInfo
from logscan.models.base import GroupSpec
from logscan.profiles import (
    GROUP_STALE_PERIODS,
    channels_under,
    dumps_toml,
    load_profile,
    parse_profile,
    resolve_profile,
    validate,
)

REPO = Path(__file__).resolve().parents[1]

QUAD = {
    "vehicle": {"model": "quadcopter", "rate_hz": 100},
    "inputs": {"thrust": "/cmd/thrust", "tau": ["/cmd/tau.x", "/cmd/tau.y", "/cmd/tau.z"]},
    "measurements": {
        "accel": {
            "channels": ["/imu/accel/x", "/imu/accel/y", "/imu/accel/z"],
            "rate_hz": 100,
            "stale_s": 0.05,
            "noise_std": 0.1,
        },
        "position": {
            "channels": ["/gps/position/x", "/gps/position/y", "/gps/position/z"],
            "rate_hz": 10,
        },
    },
}


class FakeModel:
    """The smallest object validation reads: input, state and group names."""

    input_names = ("force", "w1", "w2")
    state_names = ("pos", "vel")
    groups = {
        "speed": GroupSpec("speed", 0, ("v",), (0.1,), (-10.0,), (10.0,)),
        "pair": GroupSpec("pair", 1, ("a", "b"), (0.1, 0.1), (-1.0, -1.0), (1.0, 1.0)),
    }


FAKE_TOML = """
[vehicle]
model = "fake"
rate_hz = 50

[inputs]
force = "/u/force"
w = ["/u/w1", "/u/w2"]

[measurements.pair]
channels = ["/s/a", "/s/b"]
rate_hz = 10
"""


def problems_of(data: dict, **kw) -> list[str]:
    with pytest.raises(ProfileError) as info:
        parse_profile(dumps_toml(data), source="p.toml", **kw)
    return info.value.problems


def mutated(path: str, value, base=QUAD) -> dict:
    """A deep copy of ``base`` with the dotted ``path`` set to ``value`` (``...`` deletes it)."""
    data = copy.deepcopy(base)
    *parents, last = path.split(".")
    node = data
    for key in parents:
        node = node[key]
    if value is ...:
        del node[last]
    else:
        node[last] = value
    return data


# ------------------------------------------------------------------------------------------------
# A valid profile
# ------------------------------------------------------------------------------------------------


def test_valid_profile_binds_inputs_in_model_order_and_fills_defaults():
    p = parse_profile(dumps_toml(QUAD))
    assert p.inputs.names == ["thrust", "tau_x", "tau_y", "tau_z"]
    assert p.inputs.channels == ["/cmd/thrust", "/cmd/tau.x", "/cmd/tau.y", "/cmd/tau.z"]
    assert p.inputs.stale_s == pytest.approx(2 / 100)
    assert p.measurements["accel"].noise_std == [0.1, 0.1, 0.1]
    assert p.measurements["position"].stale_s == pytest.approx(GROUP_STALE_PERIODS / 10)
    assert p.measurements["position"].noise_std is None
    assert p.model_facts.state_names[:3] == ("x", "y", "z")


def test_motor_inputs_bind_a_list_to_numbered_inputs():
    data = mutated("inputs", {"w": ["/m/1", "/m/2", "/m/3", "/m/4"]})
    data["vehicle"]["params"] = {"inputs": "motors"}
    p = parse_profile(dumps_toml(data))
    assert p.inputs.names == ["w1", "w2", "w3", "w4"]
    assert p.inputs.channels == ["/m/1", "/m/2", "/m/3", "/m/4"]


def test_fake_model_through_the_validation_hook():
    p = parse_profile(FAKE_TOML, model=FakeModel())
    assert p.inputs.names == ["force", "w1", "w2"]
    assert p.model_facts.group_sizes == {"speed": 1, "pair": 2}
    with pytest.raises(ProfileError) as info:
        parse_profile(FAKE_TOML.replace('w = ["/u/w1", "/u/w2"]', 'w = ["/u/w1"]'), model=FakeModel())
    assert info.value.problems == ["[inputs] w: 1 channel but model 'fake' has 2 inputs starting with 'w' (w1, w2)"]
    # the structure alone, without any model
    p = parse_profile(FAKE_TOML, check_model=False)
    assert p.inputs.names == ["force", "w[0]", "w[1]"]
    assert validate(p, model=FakeModel()).inputs.names == ["force", "w1", "w2"]


# ------------------------------------------------------------------------------------------------
# Broken profiles: each gives one precise problem
# ------------------------------------------------------------------------------------------------

BROKEN = [
    (
        mutated("vehicle.model", "quadrotor"),
        "[vehicle] model: unknown model 'quadrotor' (did you mean 'quadcopter'?) "
        "(known models: dc_motor, hover_uav, ins, linear, quadcopter, steer_by_wire, unicycle, wheeled)",
    ),
    (mutated("vehicle.model", ...), "[vehicle]: missing required key 'model'"),
    (mutated("vehicle.rate_hz", 0), "[vehicle] rate_hz: must be > 0, got 0"),
    (mutated("vehicle.rate_hz", -5.5), "[vehicle] rate_hz: must be > 0, got -5.5"),
    (mutated("vehicle.rate_hz", "100"), "[vehicle] rate_hz: expected a number, got string '100'"),
    (mutated("vehicle.rate_hz", True), "[vehicle] rate_hz: expected a number, got boolean true"),
    (mutated("vehicle.params", [1, 2]), "[vehicle] params: expected a table, got an array"),
    (
        mutated("vehicle.params", {"mass": -1.0}),
        "[vehicle] params: model 'quadcopter' cannot be built: quadcopter: parameter mass must be > 0 (got -1.0)",
    ),
    (mutated("vehicle.ratehz", 5), "[vehicle]: unknown key 'ratehz' (did you mean 'rate_hz'?)"),
    (
        mutated("vehicle.colour", "red"),
        "[vehicle]: unknown key 'colour' (valid keys: model, rate_hz, params, loop, id)",
    ),
    (mutated("measurment", {}), "unknown key 'measurment' (did you mean 'measurements'?)"),
    (mutated("measurements.accel.stale_s", -0.1), "[measurements.accel] stale_s: must be > 0, got -0.1"),
    (mutated("measurements.accel.noise_std", 0), "[measurements.accel] noise_std: must be > 0 and finite, got 0"),
    (
        mutated("measurements.accel.noise_std", [0.1, -0.2, 0.1]),
        "[measurements.accel] noise_std: must be > 0 and finite, got -0.2",
    ),
    (
        mutated("measurements.accel.noise_std", [0.1, 0.2]),
        "[measurements.accel] noise_std: 2 values for 3 channels (give one number or 3)",
    ),
    (mutated("measurements.accel.rate_hz", 0), "[measurements.accel] rate_hz: must be > 0, got 0"),
    (mutated("measurements.accel.rate_hz", ...), "[measurements.accel]: missing required key 'rate_hz'"),
    (
        mutated("measurements.accel.channels", "/imu/accel"),
        "[measurements.accel] channels: expected a non-empty array of channel names, got string '/imu/accel'",
    ),
    (
        mutated("measurements.accel.channels", ["/a", "/a", "/b"]),
        "[measurements.accel] channels: channel '/a' listed twice",
    ),
    (
        mutated("measurements.accel.channels", ["/a", "/b"]),
        "[measurements.accel] channels: 2 channels but model 'quadcopter' group 'accel' has 3 outputs (ax, ay, az)",
    ),
    (
        mutated("measurements.accel.noise", 0.1),
        "[measurements.accel]: unknown key 'noise' (did you mean 'noise_std'?)",
    ),
    (
        mutated("measurements.accel", {**QUAD["measurements"]["accel"], "range_lo": [0, 0, 5], "range_hi": 4}),
        "[measurements.accel]: range_lo must be < range_hi, got 5 >= 4 for '/imu/accel/z'",
    ),
    (
        mutated("measurements.gyroscope", {"channels": ["/g/x", "/g/y", "/g/z"], "rate_hz": 100}),
        "[measurements.gyroscope]: model 'quadcopter' has no measurement group 'gyroscope' "
        "(did you mean 'gyro'?) (groups: accel, gyro, position, attitude)",
    ),
    (
        mutated("measurements.acel", {"channels": ["/g/x", "/g/y", "/g/z"], "rate_hz": 100}),
        "[measurements.acel]: model 'quadcopter' has no measurement group 'acel' "
        "(did you mean 'accel'?) (groups: accel, gyro, position, attitude)",
    ),
    (mutated("measurements", {}), "[measurements]: no measurement group: add at least one [measurements.<group>]"),
    (
        mutated("inputs", ...),
        "[inputs]: model 'quadcopter' inputs 'thrust', 'tau_x', 'tau_y', 'tau_z' have no channel "
        "(inputs: thrust, tau_x, tau_y, tau_z)",
    ),
    (mutated("vehicle", ...), "missing required key 'vehicle'"),
    (
        mutated("inputs.thrust", ...),
        "[inputs]: model 'quadcopter' input 'thrust' has no channel (inputs: thrust, tau_x, tau_y, tau_z)",
    ),
    (
        mutated("inputs", {"thrst": "/cmd/t", "tau": QUAD["inputs"]["tau"]}),
        "[inputs] thrst: model 'quadcopter' has no input 'thrst' (did you mean 'thrust'?) "
        "(inputs: thrust, tau_x, tau_y, tau_z)",
    ),
    (
        mutated("inputs.tau", ["/a", "/b"]),
        "[inputs] tau: 2 channels but model 'quadcopter' has 3 inputs starting with 'tau' (tau_x, tau_y, tau_z)",
    ),
    (
        mutated("inputs.thrust", 3),
        ("[inputs] thrust: expected a channel name, an array of them or a table { channels = [...] }, got number 3"),
    ),
    (mutated("inputs.stale_s", -1), "[inputs] stale_s: must be > 0, got -1"),
    (mutated("mode", {"chanel": "/m"}), "[mode]: unknown key 'chanel' (did you mean 'channel'?)"),
    (mutated("mode", {"channel": "/m", "stale_s": -2}), "[mode] stale_s: must be > 0, got -2"),
    (
        mutated("redundant", {"speed": {"sensors": {"left": "/l"}}}),
        "[redundant.speed] sensors: a redundant group needs at least 2 sensors, got 1",
    ),
    (
        mutated("redundant", {"speed": {"sensors": {"left": "/l", "gps": {"channel": "/g", "poly": "x"}}}}),
        "[redundant.speed] sensors.gps poly: expected a number or an array of numbers, got string 'x'",
    ),
    (
        mutated("onboard", {"state": ["/e/0", "/e/1"]}),
        "[onboard] state: 2 channels but model 'quadcopter' has 12 states "
        "(x, y, z, vx, vy, vz, roll, pitch, yaw, p, q, r)",
    ),
    (
        mutated("onboard", {"state": {"xx": "/e/x"}}),
        "[onboard] state: model 'quadcopter' has no state 'xx' (did you mean 'x'?) "
        "(states: x, y, z, vx, vy, vz, roll, pitch, yaw, p, q, r)",
    ),
    (
        mutated("onboard", {"stale_s": 1.0}),
        "[onboard]: give 'state' and/or 'variance' (a channel prefix, an array or a table)",
    ),
    (
        mutated("detectors", {"nis": {"enabled": "yes"}}),
        "[detectors.nis] enabled: expected true or false, got string 'yes'",
    ),
    (mutated("detectors", {"nis": 3}), "[detectors.nis]: expected a table, got number 3"),
    # values that would hide faults
    (mutated("measurements.accel.stale_s", 0), "[measurements.accel] stale_s: must be > 0, got 0"),
    (
        mutated("measurements.accel.noise_std", 1e300),
        "[measurements.accel] noise_std: 1e+300 would hide every fault of the group (at most 1e+150)",
    ),
    (
        mutated("measurements.accel.noise_std", [0.1, 1e-200, 0.1]),
        "[measurements.accel] noise_std: 1e-200 is too small: its square underflows (at least 1e-150)",
    ),
    (
        mutated("measurements.accel.noise_std", [0.1, 400.0, 0.1]),
        "[measurements.accel] noise_std: 400 ('/imu/accel/y') exceeds the group's range span 320 "
        "(range_lo -160 to range_hi 160): the filter would ignore the group and hide its faults; "
        "give the sensor's real noise",
    ),
    (
        mutated("measurements.accel", {**QUAD["measurements"]["accel"], "range_lo": -0.01, "range_hi": 0.01}),
        "[measurements.accel] noise_std: 0.1 ('/imu/accel/x') exceeds the group's range span 0.02 "
        "(range_lo -0.01 to range_hi 0.01): the filter would ignore the group and hide its faults; "
        "give the sensor's real noise",
    ),
    (
        mutated("measurements.position", {**QUAD["measurements"]["position"], "range_lo": -0.2, "range_hi": 0.2}),
        "[measurements.position] noise_std: 0.5 (the model's default for 'position', '/gps/position/x') exceeds "
        "the group's range span 0.4 (range_lo -0.2 to range_hi 0.2): the filter would ignore the group "
        "and hide its faults; give the sensor's real noise",
    ),
    (mutated("measurements.accel.range_lo", float("-inf")), "[measurements.accel] range_lo: must be finite, got -inf"),
    (mutated("measurements.accel.range_hi", float("nan")), "[measurements.accel] range_hi: must be finite, got nan"),
    (
        mutated("redundant", {"alt": {"sensors": {"a": "/a", "b": {"channel": "/b", "poly": [0.0, float("inf")]}}}}),
        "[redundant.alt] sensors.b poly: must be finite, got inf",
    ),
    (
        mutated("vehicle.params", {"q_accel": -0.2}),
        "[vehicle] params: model 'quadcopter' cannot be built: quadcopter: parameter q_accel must be >= 0 (got -0.2)",
    ),
    (
        mutated("vehicle.params", {"q_accel": 1e200}),
        "[vehicle] params: model 'quadcopter': process noise Q at dt = 0.01 s has non-finite entries",
    ),
    (mutated("alarms", {"n_persist": 0}), "[alarms] n_persist: must be between 1 and 1000, got 0"),
    (mutated("alarms", {"n_persist": 2.0}), "[alarms] n_persist: expected an integer, got number 2.0"),
    (mutated("alarms", {"min_duration_s": -0.1}), "[alarms] min_duration_s: must be >= 0, got -0.1"),
    (mutated("alarms", {"min_duration_s": 3600}), "[alarms] min_duration_s: must be <= 10, got 3600"),
    (mutated("alarms", {"persist": 3}), "[alarms]: unknown key 'persist' (did you mean 'n_persist'?)"),
    (mutated("alarms", 3), "[alarms]: expected a table, got number 3"),
]


@pytest.mark.parametrize("data, expected", BROKEN, ids=[e[:50] for _, e in BROKEN])
def test_broken_profile_gives_a_precise_first_problem(data, expected):
    problems = problems_of(data)
    assert problems[0] == expected


def test_all_problems_are_collected_in_one_error():
    data = mutated("vehicle.rate_hz", 0)
    data["measurements"]["accel"]["stale_s"] = -1
    data["measurements"]["accel"]["noise_std"] = 0
    with pytest.raises(ProfileError) as info:
        parse_profile(dumps_toml(data), source="flight.toml")
    err = info.value
    assert err.problems == [
        "[vehicle] rate_hz: must be > 0, got 0",
        "[measurements.accel] stale_s: must be > 0, got -1",
        "[measurements.accel] noise_std: must be > 0 and finite, got 0",
    ]
    line = err.one_line()
    assert line.startswith(
        "flight.toml: invalid profile: 3 problems: [vehicle] rate_hz: must be > 0, got 0; "
        "[measurements.accel] stale_s: must be > 0, got -1; "
        "[measurements.accel] noise_std: must be > 0 and finite, got 0"
    )
    assert "\n" not in line


def test_model_parameter_problems_come_with_the_structure_problems():
    data = mutated("measurements.accel.stale_s", -1)
    data["vehicle"]["params"] = {"mass": -1.0, "q_angacc": -1.0, "inputs": "wrench"}
    assert problems_of(data) == [
        "[measurements.accel] stale_s: must be > 0, got -1",
        "[vehicle] params: model 'quadcopter' cannot be built: quadcopter: parameter mass must be > 0 (got -1.0)",
        "[vehicle] params: model 'quadcopter' cannot be built: quadcopter: parameter q_angacc must be >= 0 (got -1.0)",
    ]


def test_every_problem_of_a_linear_model_is_listed():
    data = {
        "vehicle": {
            "model": "linear",
            "rate_hz": 100,
            "params": {
                "A": [[0.0, 1.0], [0.0, 0.0]],
                "B": [[0.0], [1.0]],
                "C": {"pos": [[1.0, 0.0]]},
                "Q": [[1.0, 0.0], [0.0, -1.0]],
                "R": {"pos": [[-1.0]], "vel": [0.1]},
                "states": ["p", "p"],
            },
        },
        "inputs": {"u0": "/u"},
        "measurements": {"pos": {"channels": ["/pos"], "rate_hz": 50}},
    }
    prefix = "[vehicle] params: model 'linear' cannot be built: linear model: "
    assert problems_of(data) == [
        prefix + "Q is not positive semi-definite (smallest eigenvalue -1)",
        prefix + "states names 'p' twice",
        prefix + "R given for group 'vel' but C has no such group (groups: pos)",
        prefix + "R[pos] is not positive definite (smallest eigenvalue -1)",
    ]


def test_alarms_table_becomes_the_alarm_policy_and_round_trips():
    from logscan.results import AlarmPolicy

    assert parse_profile(dumps_toml(QUAD)).alarm_policy is None
    p = parse_profile(dumps_toml(mutated("alarms", {"n_persist": 3, "min_duration_s": 0.05})))
    assert p.alarm_policy == AlarmPolicy(n_persist=3, min_duration_s=0.05)
    assert "\n[alarms]\nn_persist = 3\nmin_duration_s = 0.05\n" in p.to_toml()
    assert parse_profile(p.to_toml()) == p
    only_duration = parse_profile(dumps_toml(mutated("alarms", {"min_duration_s": 1})))
    assert only_duration.alarm_policy == AlarmPolicy(n_persist=1, min_duration_s=1.0)
    assert parse_profile(dumps_toml(mutated("alarms", {}))).alarm_policy == AlarmPolicy()


def test_invalid_toml_names_the_file_and_line(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text('[vehicle]\nmodel = "quadcopter\n')
    with pytest.raises(ProfileError) as info:
        load_profile(path)
    assert info.value.path == str(path)
    assert "invalid TOML" in info.value.message and "line 2" in info.value.message
    assert info.value.problems == [info.value.message]


def test_missing_profile_file_is_a_profile_error(tmp_path):
    with pytest.raises(ProfileError, match="no such profile file"):
        load_profile(tmp_path / "nope.toml")


# ------------------------------------------------------------------------------------------------
# Channels against a log
# ------------------------------------------------------------------------------------------------


def make_log(names, path="flight.mcap", profile_text=None) -> Log:
    t = np.arange(5, dtype=np.int64) * 10_000_000
    channels = {n: Channel(n, t, np.zeros(5)) for n in names}
    return Log(channels, SourceInfo(path, "mcap"), profile_text=profile_text)


QUAD_CHANNELS = [
    "/cmd/thrust",
    "/cmd/tau.x",
    "/cmd/tau.y",
    "/cmd/tau.z",
    "/imu/accel/x",
    "/imu/accel/y",
    "/imu/accel/z",
    "/gps/position/x",
    "/gps/position/y",
    "/gps/position/z",
]


def test_check_channels_passes_when_all_exist():
    parse_profile(dumps_toml(QUAD)).check_channels(make_log(QUAD_CHANNELS))


def test_unknown_channel_suggests_the_closest_existing_names():
    log = make_log([c.replace("/imu/accel/", "/imu/acc/") for c in QUAD_CHANNELS])
    profile = parse_profile(dumps_toml(QUAD), source="q.toml")
    with pytest.raises(ProfileError) as info:
        profile.check_channels(log)
    err = info.value
    assert len(err.problems) == 3
    assert err.problems[0] == (
        "[measurements.accel] channels: no channel '/imu/accel/x' in the log "
        "(did you mean '/imu/acc/x', '/imu/acc/z', '/imu/acc/y'?)"
    )
    assert err.one_line().startswith("q.toml: invalid profile: 3 problems: [measurements.accel] channels: no channel")
    assert "3 problems: " in err.one_line() and all(p in err.one_line() for p in err.problems)
    assert "flight.mcap" in err.one_line()


def test_onboard_prefix_must_match_some_channel():
    data = mutated("onboard", {"state": "/ekf/state"})
    profile = parse_profile(dumps_toml(data))
    with pytest.raises(ProfileError) as info:
        profile.check_channels(make_log(QUAD_CHANNELS + ["/ekf/states[0]"]))
    assert info.value.problems == [
        "[onboard] state: no channel starts with '/ekf/state' in the log (did you mean '/ekf/states[0]'?)"
    ]
    profile.check_channels(make_log(QUAD_CHANNELS + ["/ekf/state[0]"]))


def test_topics_lists_every_channel_and_prefix_the_readers_need():
    data = mutated("onboard", {"state": "/ekf/state", "variance": [f"/v/{i}" for i in range(12)]})
    data["mode"] = {"channel": "/flight_mode/mode"}
    data["redundant"] = {"alt": {"sensors": {"baro": "/baro/alt", "gps": {"channel": "/gps/alt", "poly": [0, 1]}}}}
    topics = parse_profile(dumps_toml(data)).topics()
    assert topics == set(QUAD_CHANNELS) | {
        "/ekf/state",
        "/flight_mode/mode",
        "/baro/alt",
        "/gps/alt",
        *(f"/v/{i}" for i in range(12)),
    }


def test_channels_under_a_prefix_need_a_separator_after_it():
    names = ["/ekf/state", "/ekf/state.x", "/ekf/states", "/ekf/state[0]", "/ekf/state_y", "/ekf/state/z"]
    assert channels_under("/ekf/state", names) == ["/ekf/state.x", "/ekf/state[0]", "/ekf/state_y", "/ekf/state/z"]


def test_enabled_detectors():
    data = mutated("detectors", {"nis": {"alpha": 0.001}, "encoded_ekf": {"enabled": False}})
    profile = parse_profile(dumps_toml(data))
    assert profile.enabled_detectors() == ["nis"]
    assert profile.detectors["nis"].settings == {"alpha": 0.001}


# ------------------------------------------------------------------------------------------------
# TOML round trip and resolution
# ------------------------------------------------------------------------------------------------


def rich_profile_dict() -> dict:
    data = copy.deepcopy(QUAD)
    data["name"] = 'test "quad" \\ with\ttabs'
    data["description"] = "line one\nline two, ünïcode"
    data["vehicle"]["params"] = {"mass": 1.25, "drag": 0.3}
    data["inputs"]["stale_s"] = float("inf")
    data["measurements"]["accel"]["range_lo"] = [-50.0, -50.0, -80.0]
    data["measurements"]["accel"]["range_hi"] = 50.0
    data["mode"] = {"channel": "/flight mode/mode", "stale_s": float("inf")}
    data["redundant"] = {
        "alt": {
            "sensors": {"baro": "/baro/alt", "gps": {"channel": "/gps/alt", "poly": [0.5, 1.0, -1e-3]}},
            "rate_hz": 5,
        }
    }
    data["onboard"] = {"state": {"x": "/ekf/x", "y": "/ekf/y"}, "variance": "/ekf/var", "stale_s": 0.2}
    data["alarms"] = {"n_persist": 2, "min_duration_s": 0.03}
    data["detectors"] = {
        "encoded_ekf": {"rho": 4.1, "window_s": 2.0, "variant": "adaptive"},
        "atfm": {"enabled": False, "group": {"left": "/l", "right": "/r"}, "windows": [25, 50]},
        "weird key.name": {"nested": {"deep": {"deeper": [1, {"a": True}]}}},
        "dated": {"since": datetime.date(2026, 1, 2), "at": datetime.datetime(2026, 1, 2, 3, 4, 5)},
    }
    return data


def test_to_toml_round_trips_to_an_equal_profile():
    p = parse_profile(dumps_toml(rich_profile_dict()))
    text = p.to_toml()
    q = parse_profile(text)
    assert q == p
    assert q.to_toml() == text
    assert q.detectors["weird key.name"].settings == {"nested": {"deep": {"deeper": [1, {"a": True}]}}}
    assert q.name == 'test "quad" \\ with\ttabs'


def test_linear_model_matrices_round_trip():
    data = {
        "vehicle": {
            "model": "linear",
            "rate_hz": 100,
            "params": {"A": [[0.0, 1.0], [0.0, -0.5]], "B": [[0.0], [1.0]], "C": {"pos": [[1.0, 0.0]]}},
        },
        "inputs": {"u0": "/u"},
        "measurements": {"pos": {"channels": ["/pos"], "rate_hz": 50}},
    }
    model_inputs = parse_profile(dumps_toml(data), check_model=False)
    p = parse_profile(model_inputs.to_toml())
    assert p.vehicle.params["A"] == [[0.0, 1.0], [0.0, -0.5]]
    assert parse_profile(p.to_toml()) == p


def test_resolve_profile_prefers_the_file_then_the_embedded_text(tmp_path):
    file_data = mutated("vehicle.rate_hz", 50)
    path = tmp_path / "p.toml"
    path.write_text(dumps_toml(file_data))
    log = make_log(QUAD_CHANNELS, profile_text=dumps_toml(QUAD))
    assert resolve_profile(log, path).vehicle.rate_hz == 50
    embedded = resolve_profile(log, None)
    assert embedded.vehicle.rate_hz == 100
    assert embedded.source == "flight.mcap (embedded logscan.profile)"
    with pytest.raises(ProfileError) as info:
        resolve_profile(make_log(QUAD_CHANNELS), None)
    assert info.value.one_line().startswith("flight.mcap: no profile: pass --profile or")


def test_embedded_profile_errors_name_the_log():
    log = make_log(QUAD_CHANNELS, profile_text=dumps_toml(mutated("vehicle.rate_hz", 0)))
    with pytest.raises(ProfileError) as info:
        resolve_profile(log)
    assert info.value.one_line().startswith("flight.mcap (embedded logscan.profile): invalid profile:")


# ------------------------------------------------------------------------------------------------
# The documentation's examples are valid profiles
# ------------------------------------------------------------------------------------------------


def doc_examples() -> list[str]:
    text = (REPO / "docs" / "profiles.md").read_text(encoding="utf-8")
    return re.findall(r"```toml\n(.*?)```", text, flags=re.S)


def test_docs_have_an_example_per_model():
    from logscan.models import MODEL_NAMES

    models = {parse_profile(t).vehicle.model for t in doc_examples()}
    assert models == set(MODEL_NAMES)


@pytest.mark.parametrize("index", range(len(doc_examples())))
def test_docs_example_validates_and_round_trips(index):
    text = doc_examples()[index]
    p = parse_profile(text, source=f"docs/profiles.md example {index + 1}")
    assert parse_profile(p.to_toml()) == p


def test_discrete_linear_model_period_must_match_the_grid():
    data = {
        "vehicle": {
            "model": "linear",
            "rate_hz": 100,
            "params": {"A": [[1.0]], "B": [[0.1]], "C": {"y": [[1.0]]}, "continuous": False, "dt": 0.02},
        },
        "inputs": {"u0": "/u"},
        "measurements": {"y": {"channels": ["/y"], "rate_hz": 50}},
    }
    assert problems_of(data) == ["[vehicle] params.dt: discrete matrices of period 0.02 s need rate_hz = 50, got 100"]
    data["vehicle"]["rate_hz"] = 50
    assert parse_profile(dumps_toml(data)).vehicle.params["dt"] == 0.02
