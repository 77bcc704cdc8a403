"""Per-sample measurement noise (`[measurements.<group>] noise_channels`: a receiver's own accuracy,
PX4's eph / epv): the EKF kernel takes each sample's std in place of the group's noise_std, as the
numpy reference does, and the NIS follows the noise the samples really have."""

from __future__ import annotations

import numpy as np
from test_ekf import simulate

from logscan.filters import run_ekf
from logscan.filters.ekf import pack_run
from logscan.filters.reference import reference_ekf
from logscan.profiles import parse_profile


def test_kernel_matches_the_reference_with_per_sample_noise():
    model, run, _ = simulate("quadcopter", N=300, seed=5)
    group = run.groups["position"]
    rng = np.random.default_rng(2)
    std = np.where(rng.random(300) < 0.5, 0.2, 3.0)[:, None] * np.ones((1, 3))
    std[::7] = np.nan  # no accuracy logged: the group's noise_std
    group.noise_std_series = std
    trace = run_ekf(model, run, full_P=True)
    ref = reference_ekf(model, pack_run(model, run))
    assert np.max(np.abs(trace.x_post - ref["x_post"])) < 1e-9
    assert np.max(np.abs(trace.P_post - ref["P_post"])) < 1e-9
    np.testing.assert_allclose(trace.nis, ref["nis"], rtol=1e-7, atol=1e-9)
    group.noise_std_series = None
    plain = run_ekf(model, run, full_P=True)
    assert np.max(np.abs(plain.x_post - trace.x_post)) > 1e-3  # the per-sample noise was used


def test_nis_follows_the_noise_the_samples_have():
    """Position noise 10x larger in the second half: with the accuracy per sample the group's mean
    NIS stays near 3; with one noise_std (the first half's) it explodes."""
    model, run, _ = simulate("quadcopter", N=2000, seed=8)
    group = run.groups["position"]
    rng = np.random.default_rng(4)
    sigma = np.where(np.arange(2000) < 1000, 0.5, 5.0)
    noisy = group.fresh & (np.arange(2000) >= 1000)
    group.z[noisy] += rng.normal(size=(int(noisy.sum()), 3)) * 4.5  # sqrt(5^2 - 0.5^2) ~ 4.97; ~4.5 is close
    g = list(run.groups).index("position")
    fixed = run_ekf(model, run)
    group.noise_std_series = np.repeat(sigma[:, None], 3, axis=1)
    per_sample = run_ekf(model, run)
    late = fixed.updated[:, g] & (np.arange(2000) >= 1000)
    assert np.nanmean(fixed.nis_group[late, g]) > 30
    assert 1.0 < np.nanmean(per_sample.nis_group[late, g]) < 5.0


def test_noise_channels_in_a_profile():
    text = """
[vehicle]
model = "ins"
rate_hz = 200
[inputs]
gyro = ["/imu/g.x", "/imu/g.y", "/imu/g.z"]
accel = ["/imu/a.x", "/imu/a.y", "/imu/a.z"]
[measurements.gnss_position]
channels = ["/gps/lat", "/gps/lon", "/gps/alt"]
from = "geodetic"
rate_hz = 5
noise_channels = ["/gps/eph", "/gps/eph", "/gps/epv"]
"""
    profile = parse_profile(text)
    assert profile.measurements["gnss_position"].noise_channels == ["/gps/eph", "/gps/eph", "/gps/epv"]
    assert parse_profile(profile.to_toml()) == profile
    assert ("[measurements.gnss_position] noise_channels", "/gps/epv") in profile.channel_refs()
    from logscan.errors import ProfileError

    try:
        parse_profile(text.replace('"/gps/eph", "/gps/eph", "/gps/epv"', '"/gps/eph"'))
    except ProfileError as exc:
        assert "one noise std channel per output" in str(exc)
    else:
        raise AssertionError("a wrong count of noise_channels must be refused")
