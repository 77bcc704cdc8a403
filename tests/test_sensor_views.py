"""The sensor beside the statistic (logscan.report.sensor_views, logscan.report.sensor_figures): every
group's prediction, innovation and sigma packed right after the filter, unpacked for the groups an
alarm names, drawn per channel with the log's channel names."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from logscan.needs import Needs
from logscan.pipeline import analyze_log, create_detectors, detect, load_profile_for, needs_of, prepare
from logscan.report import render_html
from logscan.report.sensor_views import PACKED, pack_innovations


def analysed(path, **kwargs):
    return analyze_log(path, free_series=True, sensor_views=True, **kwargs)


def test_the_pack_takes_as_much_as_a_float64_sample():
    assert PACKED.itemsize == np.dtype(np.float64).itemsize


def synthetic(sigmas: list[float], n: int = 500, seed: int = 0):
    """A one-group run and trace with the given per-channel sigma (any unit)."""
    rng = np.random.default_rng(seed)
    m = len(sigmas)
    sigma = np.asarray(sigmas)
    z = 1e3 + rng.normal(size=(n, m)) * sigma  # values far from zero: the prediction keeps its digits
    y = rng.normal(size=(n, m)) * sigma
    y[::7] = np.nan  # steps without an update
    S = np.where(np.isnan(y), np.nan, sigma**2)
    group = SimpleNamespace(z=z, channels=[f"/c{j}" for j in range(m)])
    run = SimpleNamespace(groups={"g": group})
    trace = SimpleNamespace(
        y=y.astype(np.float32), S_diag=S.astype(np.float32), group_names=["g"],
        group_offsets=np.array([0]), group_sizes=np.array([m]),
    )  # fmt: skip
    return run, trace, z, y, sigma


@pytest.mark.parametrize("sigmas", [[1e-6, 1.0, 3e4], [2e-9, 5e-3]])
def test_unpacked_values_match_the_filter_in_any_unit(sigmas):
    run, trace, z, y, sigma = synthetic(sigmas)
    view = pack_innovations(run, trace).view("g")
    updated = ~np.isnan(y)
    assert view.channels == [f"/c{j}" for j in range(len(sigmas))]
    for arr in (view.measured, view.predicted, view.sigma, view.normalised):
        np.testing.assert_array_equal(np.isnan(arr), ~updated)
    y32 = trace.y.astype(np.float64)  # what the filter kept
    np.testing.assert_allclose(view.predicted[updated], (z - y32)[updated], rtol=1e-6)
    # measured = prediction + float16 innovation: within a thousandth of sigma of the sample, or
    # float32's rounding of it (what the page draws)
    error = np.abs(view.measured - z) - 2.0**-23 * np.abs(z)
    assert np.nanmax(error / sigma) < 2e-3
    np.testing.assert_allclose(view.sigma[updated], np.broadcast_to(sigma, y.shape)[updated], rtol=1e-3)
    np.testing.assert_allclose(view.normalised[updated], (y / sigma)[updated], rtol=2e-3, atol=2e-3)


def test_the_pack_can_reuse_the_samples_buffer():
    run, trace, z, y, _ = synthetic([0.1, 2.0])
    samples = np.ascontiguousarray(z.copy())
    in_place = pack_innovations(run, trace, samples)
    assert np.shares_memory(in_place.packed, samples)
    apart = pack_innovations(run, trace)
    for field in PACKED.names:
        np.testing.assert_array_equal(in_place.packed[field], apart.packed[field])


def test_the_accelerometer_bias_shows_on_its_axis(sample):
    analysis = analysed(sample("quad_imu_bias.mcap"))
    view = analysis.prepared.innovations.view("accel")
    assert view.channels == ["/imu/accel.x", "/imu/accel.y", "/imu/accel.z"]
    t = analysis.run.t
    before, during = (t > 5) & (t < 29), (t > 31) & (t < 40)  # the truth: +1 m/s^2 on x, 30-40 s
    x = view.normalised[:, 0]
    assert np.nanmedian(x[during]) > 3 and abs(np.nanmedian(x[before])) < 0.5
    # the measured value sits above the prediction while the +1 m/s^2 bias lasts (the filter's
    # state absorbs part of it), and on it before
    offset = (view.measured - view.predicted)[:, 0]
    assert 0.3 < np.nanmedian(offset[during]) < 1.2 and abs(np.nanmedian(offset[before])) < 0.05
    assert abs(np.nanmedian(view.normalised[during, 1])) < 1  # y is untouched


def test_the_pack_reuses_the_samples_and_leaves_them_alone_otherwise(sample):
    path = sample("quad_imu_bias.mcap")
    loaded = load_profile_for(path, None)
    # the frozen-sensor check reads the samples: it runs first, then the pack takes their buffer
    detectors = create_detectors(loaded, ["encoded_ekf", "nis", "frozen"])
    wanted = lambda run: needs_of(detectors)(run) | Needs.of(ekf=("y",))  # noqa: E731
    kept = prepare(path, loaded, wanted)
    z_before = kept.run.groups["accel"].z.copy()
    detect(kept, detectors, sensor_views=True)  # the samples stay readable
    np.testing.assert_array_equal(kept.run.groups["accel"].z, z_before)
    assert not np.shares_memory(kept.innovations.packed, kept.run.groups["accel"].z)
    freed = prepare(path, loaded, wanted)
    samples = freed.run.groups["accel"].z
    detect(freed, detectors, free_series=True, sensor_views=True)
    assert np.shares_memory(freed.innovations.packed, samples)  # no new buffer through the detectors
    assert all(group.z is None for group in freed.run.groups.values())
    assert freed.trace.y is None and freed.trace.S_diag is None  # no detector here reads them
    assert [r.detector for r in detect(prepare(path, loaded, wanted), detectors).results] == [
        "encoded_ekf",
        "nis",
        "frozen",
    ]  # results in the given order, whatever order they ran in
    for field in PACKED.names:
        np.testing.assert_array_equal(freed.innovations.packed[field], kept.innovations.packed[field])


def test_without_the_report_nothing_is_kept(sample):
    analysis = analyze_log(sample("quad_imu_bias.mcap"), free_series=True)
    assert analysis.prepared.innovations is None


def test_the_report_draws_the_groups_alarms_name_beside_their_statistic(sample):
    analysis = analysed(sample("quad_imu_bias.mcap"))
    analysis.prepared.release_series()
    page = render_html(analysis.report_input())
    named = {a.signal.split(".")[1] for r in analysis.results for a in r.alarms if a.signal.startswith("nis.")}
    assert "accel" in named and "gyro" not in named
    for group in named - {"all"}:
        assert f"{group}: normalised innovation per channel" in page
    assert page.count("measured vs predicted") >= 3
    assert "accel: /imu/accel.x measured vs predicted" in page
    assert "gyro: /imu/gyro.x measured vs predicted" not in page
    # beside the statistic: the NIS section's first figure, then the accelerometer's
    nis = page.index("nis: statistic / threshold")
    assert nis < page.index("accel: /imu/accel.x measured vs predicted") < page.index("nis: per_dof")


def test_a_healthy_report_draws_no_sensor_figure(sample):
    analysis = analysed(sample("quad_healthy.mcap"))
    assert analysis.alarms == []
    page = render_html(analysis.report_input())
    assert "measured vs predicted" not in page


def hour_innovations(n: int) -> Innovations:  # noqa: F821 - the type is logscan.report.sensor_views.Innovations
    """Packed innovations of three 3-channel groups over ``n`` steps (gps at 10 Hz)."""
    rng = np.random.default_rng(1)
    names, groups, ys, Ss = ["accel", "gyro", "gps"], {}, [], []
    for name, sigma in zip(names, (0.1, 0.01, 0.5)):
        updated = np.ones(n, dtype=bool) if name != "gps" else (np.arange(n) % 10 == 0)
        y = np.where(updated[:, None], rng.normal(size=(n, 3)) * sigma, np.nan)
        ys.append(y)
        Ss.append(np.where(np.isnan(y), np.nan, sigma**2))
        z = np.cumsum(rng.normal(size=(n, 3)), axis=0) * sigma
        groups[name] = SimpleNamespace(z=z, channels=[f"/{name}/{axis}" for axis in "xyz"])
    trace = SimpleNamespace(
        y=np.hstack(ys).astype(np.float32), S_diag=np.hstack(Ss).astype(np.float32), group_names=names,
        group_offsets=np.array([0, 3, 6]), group_sizes=np.array([3, 3, 3]),
    )  # fmt: skip
    return pack_innovations(SimpleNamespace(groups=groups), trace)


def test_an_hour_with_three_alarming_groups_stays_under_the_size_limits(tmp_path):
    from test_report import make_report

    from logscan.report import render_report
    from logscan.results import DetectorResult

    report = make_report(hostile=False)
    n = report.t.size
    more = DetectorResult("more")  # alarms naming the other two groups, as a fault seen by several
    for name in ("gyro", "gps"):
        statistic = np.zeros(n)
        statistic[250_000:250_300] = 10.0
        more.add_statistic(report.t, f"more.{name}", statistic, upper=1.0, n_persist=3)
    report.results.append(more)
    report.innovations = hour_innovations(n)
    sizes = {}
    for mode, option in (("embed", "embed"), ("directory", tmp_path / "js")):
        page = tmp_path / f"{mode}.html"
        render_report(report, page, plotlyjs=option)
        text = page.read_text(encoding="utf-8")
        assert text.count("measured vs predicted") >= 9 and text.count("normalised innovation per channel") >= 3
        sizes[mode] = len(text.encode("utf-8"))
    assert sizes["embed"] <= 6_000_000 and sizes["directory"] <= 300_000, sizes


@pytest.mark.parametrize("sigmas", [[1e-6, 1.0, 3e4], [2e-9, 5e-3], [1e-30, 1e18]])
def test_the_pack_is_the_float64_formula_rounded_once(sigmas):
    # innovations divided in float32 (exact for a power-of-two scale) pack as float64's quotient
    # does, at the edges of float16 and float32 too: tiny, huge, subnormal, inf, NaN
    run, trace, z, y, sigma = synthetic(sigmas)
    edges = np.array([1e-45, -1e-40, 3e-8, 6e-8, 7e4, -1e30, 3e38, np.inf, -np.inf, np.nan], dtype=np.float32)
    trace.y[1 : 1 + edges.size, 0] = edges
    with np.errstate(over="ignore"):
        trace.y[20 : 20 + edges.size, -1] = edges * np.float32(sigmas[-1])
    pack = pack_innovations(run, trace)
    y64, S64 = trace.y.astype(np.float64), trace.S_diag.astype(np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        expected = {
            "predicted": (z - y64 - pack.offset).astype(np.float32),
            "innovation": (y64 / pack.scale).astype(np.float16),
            "sigma": (np.sqrt(S64) / pack.scale).astype(np.float16),
        }
    for field, values in expected.items():
        bits = np.dtype(f"u{values.dtype.itemsize}")  # bit for bit: NaN's and zero's sign too
        np.testing.assert_array_equal(np.ascontiguousarray(pack.packed[field]).view(bits), values.view(bits))


def test_the_normalised_innovations_and_predictions_alone_are_the_views():
    run, trace, *_ = synthetic([1e-6, 1.0, 3e4])
    innovations = pack_innovations(run, trace)
    view = innovations.view("g")
    np.testing.assert_array_equal(innovations.normalised("g"), view.normalised)  # NaN where not updated, too
    np.testing.assert_array_equal(innovations.predicted("g", (2, 0)), view.predicted[:, [2, 0]])
    assert innovations.normalised("nope") is None and innovations.predicted("nope", (0,)) is None


@pytest.mark.parametrize("scale", [2.0**-110, 2.0**-20, 1.0, 2.0**40, 2.0**110])
def test_a_view_is_the_pack_unpacked_in_float64_at_any_scale(scale):
    from logscan.report.sensor_views import Innovations

    rng = np.random.default_rng(3)
    packed = np.empty((300, 2), dtype=PACKED)
    packed["predicted"] = rng.normal(size=(300, 2)).astype(np.float32)
    packed["innovation"] = rng.normal(size=(300, 2)).astype(np.float16)
    packed["sigma"] = rng.uniform(0.5, 2.0, size=(300, 2)).astype(np.float16)
    packed["innovation"][::7] = np.nan  # steps without an update
    offset, scales = np.array([1e3, -5.0]), np.array([scale, 1.0])
    innovations = Innovations(["g"], np.array([0]), np.array([2]), {"g": ["/a", "/b"]}, packed, scales, offset)
    view = innovations.view("g")
    # as the pack was first unpacked: every product and sum in float64, rounded once to float32
    predicted = packed["predicted"] + offset
    y = packed["innovation"] * scales
    np.testing.assert_array_equal(view.predicted, predicted.astype(np.float32))
    np.testing.assert_array_equal(view.measured, (predicted + y).astype(np.float32))
    np.testing.assert_array_equal(view.sigma, (packed["sigma"] * scales).astype(np.float32))
    with np.errstate(invalid="ignore"):
        np.testing.assert_array_equal(
            view.normalised, np.divide(packed["innovation"], packed["sigma"], dtype=np.float32)
        )


def test_a_page_makes_each_groups_view_once():
    from logscan.report.sensor_views import PageViews

    run, trace, *_ = synthetic([0.1, 2.0])
    innovations = pack_innovations(run, trace)
    made = []
    innovations.view = lambda group, view=innovations.view: made.append(group) or view(group)
    views = PageViews(innovations)
    headline = views.view("g")  # the headline's, kept for the group's sensor figures
    assert views.view("g") is headline and views.take("g") is headline and made == ["g"]
    assert views.take("g") is not headline and made == ["g", "g"]  # taken: no longer kept
