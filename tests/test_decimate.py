"""Report trace decimation: point bound, exact bucket extremes, alarm edges and NaN gaps kept."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from logscan.report.decimate import bucket_width, decimate, decimate_indices, edge_indices, sorted_unique


def _check_buckets(y: np.ndarray, idx: np.ndarray, max_points: int, n_keep: int) -> None:
    """Every bucket's min, max (NaN ignored) and, if it has one, a NaN appear among y[idx]."""
    width = bucket_width(y.size, max_points, n_keep, bool(np.isnan(y).any()))
    which = idx // width
    for b, start in enumerate(range(0, y.size, width)):
        block = y[start : start + width]
        kept = y[idx[which == b]]
        if np.isnan(block).any():
            assert np.isnan(kept).any(), f"bucket {b} lost its NaN gap"
        finite = block[~np.isnan(block)]
        if finite.size:
            assert np.nanmax(kept) == finite.max(), f"bucket {b} lost its maximum"
            assert np.nanmin(kept) == finite.min(), f"bucket {b} lost its minimum"


def test_short_series_is_returned_whole():
    y = np.arange(100.0)
    assert np.array_equal(decimate_indices(y, 5000), np.arange(100))


def test_long_series_is_bounded_and_keeps_every_bucket_extreme():
    rng = np.random.default_rng(1)
    y = np.cumsum(rng.normal(size=360_000))
    idx = decimate_indices(y, 5000)
    assert idx.size <= 5000
    assert idx.size > 4000  # the budget is used, not wasted
    assert np.all(np.diff(idx) > 0)  # time order, no duplicates
    assert idx[0] == 0 and idx[-1] == y.size - 1
    _check_buckets(y, idx, 5000, 0)


def test_spike_survives_decimation():
    y = np.zeros(1_000_000)
    y[123_457] = 1e20  # a bit-flipped float
    y[700_001] = -3.0
    t, v = decimate(np.arange(y.size) * 0.01, y, 5000)
    assert v.max() == 1e20 and v.min() == -3.0
    assert t.size <= 5000


def test_alarm_edges_are_kept():
    rng = np.random.default_rng(2)
    t = np.arange(360_000) * 0.01
    y = rng.normal(size=t.size)
    spans = [(100.004, 100.5), (1234.56, 1300.0), (3599.0, 3600.0)]
    edges = edge_indices(t, spans)
    assert np.array_equal(edges, np.searchsorted(t, np.ravel(spans)).clip(0, t.size - 1))
    idx = decimate_indices(y, 5000, keep=edges)
    assert idx.size <= 5000
    assert np.isin(edges, idx).all()
    _check_buckets(y, idx, 5000, edges.size)


def test_nan_gap_breaks_the_line_after_decimation():
    y = np.sin(np.arange(200_000) * 1e-3)
    y[50_000:50_003] = np.nan  # a short gap, far smaller than a bucket
    y[150_000:160_000] = np.nan  # a long gap, whole buckets
    idx = decimate_indices(y, 3000)
    kept = y[idx]
    assert idx.size <= 3000
    near_short = (idx >= 49_000) & (idx <= 51_000)
    assert np.isnan(kept[near_short]).any()
    assert np.isnan(kept[(idx >= 150_000) & (idx < 160_000)]).any()
    # finite values on both sides of the short gap are still drawn
    assert np.isfinite(kept[(idx < 50_000) & (idx >= 49_000)]).any()
    assert np.isfinite(kept[(idx > 50_003) & (idx <= 51_000)]).any()


def test_flat_runs_collapse_without_changing_the_polyline():
    y = np.full(360_000, 7.5)
    y[200_000:] = 9.0
    t, v = decimate(np.arange(y.size) * 0.01, y, 5000, simplify_flat=True)
    assert t.size == 4  # two flat segments: their end points
    assert list(v) == [7.5, 7.5, 9.0, 9.0]
    assert t[0] == 0.0 and t[-1] == pytest.approx(3599.99)


def test_flat_simplification_keeps_requested_edges():
    y = np.zeros(10_000)
    idx = decimate_indices(y, 500, keep=np.array([4321]), simplify_flat=True)
    assert 4321 in idx and idx.size == 3


def test_all_nan_series_stays_a_gap():
    idx = decimate_indices(np.full(50_000, np.nan), 1000)
    assert 0 < idx.size <= 1000


def test_bad_arguments_raise():
    with pytest.raises(ValueError):
        decimate_indices(np.zeros((3, 3)), 100)
    with pytest.raises(ValueError):
        decimate_indices(np.zeros(100), 8)
    with pytest.raises(ValueError):
        decimate(np.zeros(3), np.zeros(4))


_values = st.one_of(
    st.floats(allow_nan=False, width=64, min_value=-1e30, max_value=1e30),
    st.sampled_from([np.nan, np.inf, -np.inf]),
)


@settings(max_examples=150, deadline=None)
@given(
    y=hnp.arrays(np.float64, st.integers(0, 3000), elements=_values),
    max_points=st.integers(16, 400),
    keep=st.lists(st.integers(-5, 3100), max_size=40),
)
def test_property_bound_extremes_edges_gaps(y, max_points, keep):
    keep_arr = np.array(keep, dtype=np.int64)
    idx = decimate_indices(y, max_points, keep=keep_arr)
    assert idx.size <= max(max_points, y.size if y.size <= max_points else 0)
    assert np.all(np.diff(idx) > 0)
    if y.size == 0:
        return
    valid_keep = np.unique(keep_arr[(keep_arr >= 0) & (keep_arr < y.size)])
    if valid_keep.size <= max_points // 2:
        assert np.isin(valid_keep, idx).all()
    if y.size > max_points:
        n_keep = min(valid_keep.size, max(max_points // 2, 1))
        _check_buckets(y, idx, max_points, n_keep)


def _first_extremes(y: np.ndarray, width: int) -> set[int]:
    """Per bucket, the index of its first minimum and first maximum (NaN ignored), one at a time."""
    out = set()
    for start in range(0, y.size, width):
        block = y[start : start + width]
        finite = ~np.isnan(block)
        if finite.any():
            values = np.where(finite, block, np.nan)
            out |= {start + int(np.nanargmin(values)), start + int(np.nanargmax(values))}
    return out


@pytest.mark.parametrize("with_nan", [False, True])
def test_each_bucket_gives_its_first_extremes_also_from_a_strided_float32_view(with_nan):
    rng = np.random.default_rng(5)
    base = np.round(rng.normal(size=2 * 10_007), 1).astype(np.float32)  # ties: the first one counts
    y = base[::2]  # a strided view: the buckets are reshaped from it, not from a padded copy
    if with_nan:
        y = y.copy()
        y[rng.random(y.size) < 0.05] = np.nan
    idx = decimate_indices(y, 500)
    width = bucket_width(y.size, 500, 0, with_nan)
    assert y.size % width  # the last bucket is shorter
    assert _first_extremes(y, width) <= set(idx.tolist())


@settings(max_examples=100, deadline=None)
@given(st.lists(st.lists(st.integers(-50, 50), max_size=30), min_size=1, max_size=4))
def test_sorted_unique_is_the_union_of_the_arrays(arrays):
    arrays = [np.array(a, dtype=np.int64) for a in arrays]
    got = sorted_unique(*arrays)
    np.testing.assert_array_equal(got, np.unique(np.concatenate(arrays)))
    assert got.dtype == np.int64


@pytest.mark.parametrize("value", [2.5, np.nan])
@pytest.mark.parametrize("simplify_flat", [False, True])
def test_a_broadcast_constant_is_decimated_as_its_samples_are(value, simplify_flat):
    constant = np.broadcast_to(np.float32(value), (100_003,))  # as results keep a constant threshold
    keep = np.array([5, 77_000])
    expected = decimate_indices(constant.copy(), 1_000, keep=keep, simplify_flat=simplify_flat)
    np.testing.assert_array_equal(decimate_indices(constant, 1_000, keep=keep, simplify_flat=simplify_flat), expected)
