"""`[measurements.<group>] fresh = "on_change"`: a forward-filled column is fresh only where its
value changes; without the key (or with "on_sample") the fresh masks are as before."""

from __future__ import annotations

import numpy as np
import pytest
from test_align import MS, FakeModel  # the same stand-in model and time unit

from logscan.align import align, changed_steps
from logscan.errors import ProfileError
from logscan.log import Channel, Log, SourceInfo
from logscan.profiles import parse_profile

BASE = """
[vehicle]
model = "fake"
rate_hz = 20

[inputs]
force = "/force"
"""


def filled_log() -> Log:
    """20 Hz rows for 2 s: /force new on every row; /speed a 4 Hz sensor forward-filled onto every
    row (each value repeated 5 times); /a, /b a pair filled the same way, changing at different rows."""
    t = np.arange(0, 2000, 50)
    slow = np.repeat(np.arange(8, dtype=float) * 0.1, 5)
    b = np.repeat(np.arange(9, dtype=float) * 0.1, 5)[2:42]
    chans = {
        "/force": (t, t / 1000.0),
        "/speed": (t, slow),
        "/a": (t, slow),
        "/b": (t, b),
    }
    channels = {
        n: Channel(n, np.asarray(tt, dtype=np.int64) * MS, np.asarray(v, dtype=float)) for n, (tt, v) in chans.items()
    }
    return Log(channels, SourceInfo("filled.csv", "csv"))


def group_toml(fresh: str | None) -> str:
    key = f'fresh = "{fresh}"\n' if fresh else ""
    return (
        f'[measurements.speed]\nchannels = ["/speed"]\nrate_hz = 20\n{key}'
        f'[measurements.pair]\nchannels = ["/a", "/b"]\nrate_hz = 20\n{key}'
    )


def run(fresh: str | None):
    return align(filled_log(), parse_profile(BASE + group_toml(fresh), model=FakeModel()))


def test_a_forward_filled_column_is_fresh_only_where_its_value_changes():
    aligned = run("on_change")
    speed = aligned.groups["speed"]
    # the value changes every 5th row (0.25 s); the first step holds the first value
    assert np.flatnonzero(speed.fresh).tolist() == [0, 5, 10, 15, 20, 25, 30, 35]
    # the held values are those of every row, as without the key
    np.testing.assert_array_equal(speed.z, run(None).groups["speed"].z)
    # channel_fresh still marks every sample's arrival (the frozen check reads the fill from it)
    assert speed.channel_fresh[:, 0].all()


def test_a_group_is_fresh_where_any_of_its_channels_changes():
    pair = run("on_change").groups["pair"]
    # /a changes at rows 5, 10, ...; /b (shifted by 2 rows) at rows 3, 8, 13, ...
    expected = sorted({0, *range(5, 40, 5), *range(3, 40, 5)})
    assert np.flatnonzero(pair.fresh).tolist() == expected


@pytest.mark.parametrize("fresh", [None, "on_sample"])
def test_without_on_change_every_sample_is_fresh(fresh):
    aligned = run(fresh)
    assert aligned.groups["speed"].fresh.all()
    assert aligned.groups["pair"].fresh.all()


def test_the_default_is_on_sample_and_is_not_written_back():
    profile = parse_profile(BASE + group_toml(None), model=FakeModel())
    assert profile.measurements["speed"].fresh == "on_sample"
    assert "fresh" not in profile.to_toml()
    changed = parse_profile(BASE + group_toml("on_change"), model=FakeModel())
    assert changed.measurements["speed"].fresh == "on_change"
    assert parse_profile(changed.to_toml(), model=FakeModel()) == changed


def test_an_unknown_fresh_value_is_a_profile_error_naming_the_choices():
    with pytest.raises(ProfileError, match=r"fresh: expected 'on_sample' or 'on_change', got string 'always'"):
        parse_profile(BASE + group_toml("always"), model=FakeModel())


def test_changed_steps_counts_a_value_back_after_a_gap_and_ignores_nan():
    z = np.array([[1.0], [1.0], [np.nan], [1.0], [1.0], [2.0]])
    assert changed_steps(z).tolist() == [True, False, False, True, False, True]
    assert changed_steps(np.empty((0, 2))).tolist() == []
