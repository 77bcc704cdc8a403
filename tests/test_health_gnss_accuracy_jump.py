"""The GNSS accuracy-jump check (detectors/accuracy_jump.py, docs/algorithms.md section 3c): its
reference median is every 3D-fixed report before, armed or not; only the judging waits for arming.
A jump within a second of arming is found on a real log edited as a receiver would report it."""

from __future__ import annotations

import json

import hypothesis.strategies as st
import numpy as np
import pytest
from conftest import need_testdata
from hypothesis import given, settings
from ulog_edit import edit_ulog

from logscan.detectors import accuracy_jump as accuracy_jump_module
from logscan.detectors.accuracy_jump import accuracy_jump

EVENTS = "px4-ulog/sample_px4_events.ulg"  # SITL quadcopter: first 3D fix 9.18 s, armed 14.94 s
GPS = "vehicle_gps_position"


def test_the_reference_takes_the_reports_not_judged_and_only_judged_samples_get_a_ratio():
    t = (np.arange(100) * 0.2e9).astype(np.int64)  # 5 Hz for 20 s
    eph = np.where(t >= 10.2e9, 4.0, 1.0)  # 4 times worse from 10.2 s
    armed = t >= 10e9  # armed one sample before the jump
    ratio = accuracy_jump(t, eph, 10.0, judged=armed)
    assert np.isnan(ratio[~armed]).all()  # not judged before arming
    assert ratio[50] == pytest.approx(1.0) and ratio[51] == pytest.approx(4.0)  # against the level before
    assert ratio[56] == pytest.approx(4.0)  # and for the second it must persist to alarm
    # a reference of judged reports alone: within 0.4 s it holds only the jumped ones
    alone = accuracy_jump(t, np.where(armed, eph, np.nan), 10.0)
    assert alone[51] == pytest.approx(4.0) and alone[52] == pytest.approx(1.6) and alone[53] == 1.0


@pytest.mark.testdata("px4-ulog")
def test_a_jump_half_a_second_after_arming_alarms(cli, tmp_path):
    """eph / epv steady at 0.3 / 0.4 m from the first 3D fix, 4 times worse from 15.5 s (armed at
    14.94 s): both jump checks alarm once it has lasted min_duration_s (1 s)."""
    from pyulog import ULog

    source = need_testdata(EVENTS)
    start_us = ULog(str(source), [GPS]).start_timestamp
    onset_s = 15.5

    def worse(data) -> None:
        t = (data["timestamp"].astype(np.int64) - start_us) / 1e6
        fixed = data["fix_type"] >= 3
        for field, level in (("eph", 0.3), ("epv", 0.4)):
            data[field][fixed] = np.where(t[fixed] >= onset_s, 4.0 * level, level)

    path = edit_ulog(source, tmp_path / "jump_after_arming.ulg", {GPS: worse})
    out = tmp_path / "summary.json"
    cli("analyze", str(path), "--no-report", "--json", str(out))
    log = json.loads(out.read_text())["logs"][0]
    health = next(d for d in log["detectors"] if d["detector"] == "health")
    jumps = {a["signal"]: a for a in health["alarms"] if a["signal"].startswith("health.gnss_accuracy_jump.")}
    assert set(jumps) == {"health.gnss_accuracy_jump.eph", "health.gnss_accuracy_jump.epv"}, health["alarms"]
    assert all(onset_s - 0.2 <= a["first_exceed"] and a["start"] <= onset_s + 1.5 for a in jumps.values()), jumps


@settings(max_examples=60, deadline=None)
@given(
    steps=st.lists(st.integers(1, 400), min_size=0, max_size=120),
    values=st.lists(st.one_of(st.floats(-1.0, 50.0), st.just(float("nan"))), min_size=120, max_size=120),
    judged=st.lists(st.booleans(), min_size=120, max_size=120),
    window_s=st.floats(0.05, 30.0),
    entries=st.integers(1, 64),
)
def test_the_rows_a_slice_at_a_time_give_the_whole_matrix_medians(steps, values, judged, window_s, entries):
    """Taken `WINDOW_ENTRIES` at a time, bit for bit the ratios of the whole matrix at once (one
    slice holding every row)."""
    t = (np.cumsum([0, *steps]) * 1e7).astype(np.int64)  # 10 ms to 4 s apart, irregular
    v, gate = np.asarray(values[: t.size]), np.asarray(judged[: t.size])
    ratios = {}
    for size in (entries, 2**62):
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(accuracy_jump_module, "WINDOW_ENTRIES", size)
            ratios[size] = accuracy_jump(t, v, window_s, judged=gate)
    np.testing.assert_array_equal(ratios[entries], ratios[2**62])
    # and the definition row by row: the median of the valid values among the k samples before
    # (k: the window at the median period) that lie within window_s
    steps_apart = np.diff(t)
    period = float(np.median(steps_apart)) if np.any(steps_apart > 0) else 0.0
    k = int(np.clip(np.ceil(window_s * 1e9 / period), 1, t.size)) if period > 0 else 1
    expected = np.full(t.size, np.nan)
    for i in range(t.size if t.size >= 2 else 0):
        before, times = v[max(0, i - k) : i], t[max(0, i - k) : i]
        valid = before[(times >= t[i] - int(window_s * 1e9)) & np.isfinite(before) & (before > 0)]
        if valid.size and gate[i] and np.isfinite(v[i]) and v[i] > 0:
            expected[i] = v[i] / np.median(valid)
    np.testing.assert_allclose(ratios[entries], expected, rtol=1e-12)


@settings(max_examples=200, deadline=None)
@given(
    rows=st.integers(1, 30),
    k=st.integers(1, 12),
    data=st.data(),
)
def test_the_row_medians_are_numpys_nanmedian_bit_for_bit(rows, k, data):
    """The one-sort median of rows of finite values and NaN, each row holding a finite one."""
    cells = st.one_of(st.floats(1e-3, 1e6, allow_nan=False), st.just(float("nan")))
    x = np.asarray(data.draw(st.lists(cells, min_size=rows * k, max_size=rows * k)), dtype=np.float64).reshape(rows, k)
    x[np.isnan(x).all(axis=1), 0] = 1.0
    expected = np.nanmedian(x, axis=1)
    assert accuracy_jump_module._row_nanmedians(x).tobytes() == expected.tobytes()
