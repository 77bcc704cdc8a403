"""Raw samples released as alignment goes: each channel's once it is held for the last time, the
same aligned run as with the log kept whole, the log's counts and span kept, and what is read
after alignment (the report's context, the ground truth's states) kept until then."""

from __future__ import annotations

import numpy as np
import pytest
from test_align import BASE, FakeModel, force_100hz, make_log

from logscan.align import align
from logscan.align.aligner import _Aligner
from logscan.errors import InternalError
from logscan.needs import Needs
from logscan.pipeline import load_profile_for, prepare
from logscan.profiles import parse_profile
from logscan.readers import read_log
from logscan.report.run_context import run_context

PROFILE = """
[measurements.speed]
channels = ["/speed"]
rate_hz = 10

[mode]
channel = "/speed"
stale_s = inf

[onboard]
state = ["/est/pos", "/est/vel"]
stale_s = 0.05
"""


def channels() -> dict[str, tuple]:
    t = np.arange(0, 1001, 100)
    est = np.arange(0, 1001, 20)
    return {
        "/force": force_100hz(),
        "/speed": (t, np.arange(11.0)),  # held twice: a measurement and the mode
        "/est/pos": (est, est * 1.0),
        "/est/vel": (est, est * 2.0),
        "/other": (t, -np.arange(11.0)),  # aligned by nothing
    }


def test_released_channels_align_as_the_whole_log_and_keep_their_counts():
    profile = parse_profile(BASE + PROFILE, model=FakeModel())
    whole, log = make_log(channels()), make_log(channels())
    before = log.summary()
    kept = align(whole, profile)
    released = align(log, profile, release=lambda name: name != "/force")
    for name in ("u", "u_fresh", "mode", "t"):
        np.testing.assert_array_equal(getattr(released, name), getattr(kept, name))
    np.testing.assert_array_equal(released.groups["speed"].z, kept.groups["speed"].z)
    np.testing.assert_array_equal(np.asarray(released.onboard_state), np.asarray(kept.onboard_state))
    assert (released.warnings, released.gaps, released.channel_stats) == (kept.warnings, kept.gaps, kept.channel_stats)
    # what the profile holds is gone but for the one the test keeps; the rest is as read
    assert {name for name, channel in log.channels.items() if len(channel) == 0} == {"/speed", "/est/pos", "/est/vel"}
    assert len(log.channels["/force"]) == 101 and len(log.channels["/other"]) == 11
    assert log.summary() == before and log.start_ns == whole.start_ns and log.end_ns == whole.end_ns
    log.release_samples()  # the rest, as `prepare` does after the report's context
    assert all(len(channel) == 0 for channel in log.channels.values()) and log.summary() == before


def test_a_channel_is_not_read_after_its_release():
    log = make_log(channels())
    aligner = _Aligner(log, parse_profile(BASE + PROFILE, model=FakeModel()))
    assert aligner.clean("/speed").t.size == 11
    aligner.release(["/speed"])
    assert aligner.cache["/speed"].samples == 11 and aligner.cache["/speed"].t.size == 0
    with pytest.raises(InternalError, match="/speed"):
        aligner.clean("/speed")


def test_prepare_keeps_the_ground_truth_states_for_the_report(sample):
    """The simulated log's true states (a topic the profile does not hold) reach the report's
    context as from the log kept whole; the profile's own channels are released by then."""
    path = sample("hover_healthy.mcap")  # the UBIKF's page draws them (a model with intervals)
    prepared = prepare(path, load_profile_for(path, None), Needs.of(ubikf=()))
    truth = prepared.log.truth
    assert truth is not None and truth.get("true_state_topic")
    whole = read_log(path, topics=prepared.profile.topics() | {truth["true_state_topic"].strip("/")})
    whole.truth = truth
    expected = run_context(align(whole, prepared.profile), prepared.model, whole).true_states
    got = prepared.context.true_states
    assert got and got.keys() == expected.keys()
    for name in expected:
        np.testing.assert_array_equal(got[name], expected[name])


def test_what_is_read_after_alignment_is_not_released():
    """The report's context (the autopilot's states, a ULog's GNSS time), the ground truth's state
    topic and a detector's raw topics are read after alignment; a profile with further loops
    aligns the log again, so nothing goes."""
    from logscan.pipeline.preparation import _released_once_held

    log = make_log(channels())
    log.truth = {"true_state_topic": "/truth/state"}
    profile = parse_profile(BASE + PROFILE, model=FakeModel())
    releasable = _released_once_held(log, profile, frozenset({"battery_status"}))
    assert releasable is not None
    for name in ("/vehicle_status_0/arming_state", "/truth/state/x", "/battery_status/voltage_v"):
        assert not releasable(name), name
    assert not releasable("/vehicle_gps_position_0/time_utc_usec")
    for name in ("/speed", "/est/pos", "/truth/stateful", "/vehicle_status_1/arming_state"):
        assert releasable(name), name
    profile.loops = {"inner": profile}
    assert _released_once_held(log, profile, frozenset()) is None
