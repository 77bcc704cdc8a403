"""The px4 profile's measurement noise, from the scatter PX4's own EKF2 logged for each sensor.

Specified in docs/algorithms.md section 6.7a. PX4's noise parameters (EKF2_GPS_P_NOISE,
EKF2_GPS_V_NOISE, EKF2_BARO_NOISE) are conservative floors, and a receiver's reported accuracy
(eph, epv, s_variance_m_s) is the sensor vouching for itself: on real flights either left the
filter 10^2-10^5 times looser than the data. What PX4 logged of each fused sensor says how far
the sensor actually strayed from PX4's one-step prediction: its innovations (``estimator_innovations``,
PX4 v1.12+; ``ekf2_innovations`` v1.6-1.8; ``estimator_aid_src_*`` v1.14+, its samples PX4
fused). Per output:

    std = clip(sigma_hat, FLOOR, PX4's configured std)

- ``sigma_hat``: the root mean square of the innovations PX4 accepted (within its gate,
  y^2 <= gate^2 S, finite, non-zero): the covariance-matching estimate of the innovation variance
  (Mehra 1972), whose H P H' + R bounds the sensor's noise R from above; taken at its one-sided
  95 % upper confidence bound for n samples (``n s^2 / chi2_(0.05, n)``), so a short log errs to
  loose rather than to false alarms. Only PX4's accepted samples count: a fault PX4 rejected does
  not widen it, one it accepted widens it at most to the ceiling.
- ``FLOOR``: the resolution PX4 logs a GNSS position with (1e-7 deg, 1.1 cm), the same number for
  velocity (m/s) and height (m): it guards against a zero scatter (a simulator's exact GNSS), below
  which the logged values cannot tell noise apart.
- the ceiling: PX4's own configured std (EKF2_*_NOISE; 1.5 times vertically for GNSS, as
  before): never looser than PX4 flew.

Fewer than MIN_SAMPLES accepted innovations, or none logged: PX4's configured std.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

INNOVATIONS = "estimator_innovations_0"
VARIANCES = "estimator_innovation_variances_0"
LEGACY = "ekf2_innovations_0"
# PX4 v1.14+ per aiding source: innovation, innovation_variance and fused in one message (gps_* in
# early v1.14, gnss_* since)
AID = "estimator_aid_src_{}_0"
AID_SOURCES = ("gnss_pos", "gps_pos", "gnss_hgt", "gps_hgt", "gnss_vel", "gps_vel", "baro_hgt")
NOISE_TOPICS = (INNOVATIONS, VARIANCES, LEGACY, *(AID.format(source) for source in AID_SOURCES))
CONFIDENCE = 0.95  # sigma_hat at its upper confidence bound of this level
MIN_SAMPLES = 10  # fewer accepted innovations: PX4's configured std
FLOOR = 0.011  # m (and m/s): the 1e-7 deg resolution of a logged GNSS latitude / longitude
PAIR_NS = 20_000_000  # an innovation and its variance from one EKF2 cycle: within 20 ms (PX4 runs at 100+ Hz)
DEFAULT_GATE = 5.0  # PX4's default innovation gates (EKF2_GPS_P_GATE, _V_GATE, EKF2_BARO_GATE)

# group -> per output: (estimator_innovations field, ekf2_innovations index or None, gate parameter,
# estimator_aid_src_* sources (the new name first) and the output's element of theirs, None: scalar)
SOURCES = {
    "gnss_position": (
        ("gps_hpos[0]", 3, "EKF2_GPS_P_GATE", ("gnss_pos", "gps_pos"), 0),
        ("gps_hpos[1]", 4, "EKF2_GPS_P_GATE", ("gnss_pos", "gps_pos"), 1),
        ("gps_vpos", None, "EKF2_GPS_P_GATE", ("gnss_hgt", "gps_hgt"), None),
    ),
    "gnss_velocity": (
        ("gps_hvel[0]", 0, "EKF2_GPS_V_GATE", ("gnss_vel", "gps_vel"), 0),
        ("gps_hvel[1]", 1, "EKF2_GPS_V_GATE", ("gnss_vel", "gps_vel"), 1),
        ("gps_vvel", 2, "EKF2_GPS_V_GATE", ("gnss_vel", "gps_vel"), 2),
    ),
    "baro": (("baro_vpos", 5, "EKF2_BARO_GATE", ("baro_hgt",), None),),
}


@dataclass(frozen=True)
class Noise:
    """One group's noise std per output, the innovations each was estimated from (None: PX4's
    configured std) and the parameter named as that configured std."""

    std: tuple[float, ...]
    samples: tuple[int | None, ...]
    parameter: str

    def comment(self) -> str:
        """Where the values came from, for the profile's comment."""
        n = [k for k in self.samples if k is not None]
        if not n:
            return f"{self.parameter}: PX4 logged no innovations of it"
        where = f"from PX4's own innovations (n={min(n)}-{max(n)}, RMS at its 95 % upper bound"
        where = where.replace(f"n={min(n)}-{max(n)}", f"n={n[0]}") if min(n) == max(n) else where
        configured = "" if len(n) == len(self.samples) else f"; {self.parameter} where none"
        return f"{where}) within [{FLOOR:g}, {self.parameter}]{configured}"


def innovation_std(y: np.ndarray, S: np.ndarray, gate: float) -> tuple[float, int] | None:
    """(sigma_hat at its upper confidence bound, n) of the innovations ``y`` with variances ``S``
    that PX4 accepted (y^2 <= gate^2 S, finite, non-zero); None with fewer than MIN_SAMPLES."""
    from scipy.special import chdtri  # chi-square quantiles without scipy.stats (46 MB to import)

    y = np.asarray(y, dtype=np.float64)
    S = np.asarray(S, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        accepted = np.isfinite(y) & np.isfinite(S) & (S > 0) & (y != 0) & (y * y <= gate * gate * S)
    n = int(accepted.sum())
    if n < MIN_SAMPLES:
        return None
    variance = float(np.mean(y[accepted] ** 2))
    return float(np.sqrt(variance * n / chdtri(n, CONFIDENCE))), n


def paired(t_y, y, t_s, s) -> tuple[np.ndarray, np.ndarray] | None:
    """Each innovation ``y`` (times ``t_y``, ns) with the variance ``s`` published for it: the two
    topics are written in the same EKF2 cycle, stamped a little apart, so each y takes the
    variance nearest in time within PAIR_NS; None when none pairs."""
    if t_y.size == 0 or t_s.size == 0:
        return None
    right = np.clip(np.searchsorted(t_s, t_y), 1, t_s.size - 1) if t_s.size > 1 else np.zeros(t_y.size, int)
    left = np.maximum(right - 1, 0)
    nearest = np.where(np.abs(t_s[left] - t_y) <= np.abs(t_s[right] - t_y), left, right)
    close = np.abs(t_s[nearest] - t_y) <= PAIR_NS
    return (y[close], s[nearest[close]]) if close.any() else None


def _pairs(channels, has, legacy_height: bool):
    """{group: [(y, S) or None per output]} from the log's PX4 innovation topics."""

    def series(topic_y: str, field_y: str, topic_s: str, field_s: str):
        y_name, s_name = f"/{topic_y}/{field_y}", f"/{topic_s}/{field_s}"
        if not (has(y_name) and has(s_name)):
            return None
        y, s = channels[y_name], channels[s_name]
        # float64: a log read to be held keeps float32 values (`read_log`'s ``held``)
        return paired(
            np.asarray(y.t), np.asarray(y.values, np.float64), np.asarray(s.t), np.asarray(s.values, np.float64)
        )

    def aid(sources: tuple[str, ...], element: int | None):
        """(y, S) of the first estimator_aid_src_* source logged, its samples PX4 fused only."""
        suffix = "" if element is None else f"[{element}]"
        for source in sources:
            topic = AID.format(source)
            fused = f"/{topic}/fused"
            found = series(topic, f"innovation{suffix}", topic, f"innovation_variance{suffix}")
            if found is not None and has(fused) and channels[fused].values.shape == found[0].shape:
                keep = np.asarray(channels[fused].values) != 0
                return found[0][keep], found[1][keep]
        return None

    out = {}
    for group, outputs in SOURCES.items():
        row = []
        for field, index, _, sources, element in outputs:
            found = series(INNOVATIONS, field, VARIANCES, field)
            if found is None and index is not None and (index != 5 or legacy_height):
                found = series(LEGACY, f"vel_pos_innov[{index}]", LEGACY, f"vel_pos_innov_var[{index}]")
            row.append(found if found is not None else aid(sources, element))
        out[group] = row
    return out


def px4_noise(
    channels, param: Callable[[str, float], float], configured: dict[str, tuple[tuple[float, ...], str]]
) -> dict[str, Noise]:
    """Each group's noise (see the module docstring) of a PX4 log's ``channels`` (read with
    NOISE_TOPICS); ``param(name, default)``: the log's parameter; ``configured``: group -> (PX4's
    configured std per output: the ceiling, and the value without innovations; the parameter's
    name, for the comment)."""
    has = lambda name: name in channels and len(channels[name]) > 0  # noqa: E731
    # ekf2_innovations' height innovation is the baro's only when it is the height source (mode 0)
    legacy_baro = param("EKF2_HGT_MODE", -1.0) in (-1.0, 0.0)
    pairs = _pairs(channels, has, legacy_baro)
    out = {}
    for group, (ceiling, parameter) in configured.items():
        stds: list[float] = []
        samples: list[int | None] = []
        for k, limit in enumerate(ceiling):
            source = SOURCES[group][k] if k < len(SOURCES.get(group, ())) else None
            found = pairs[group][k] if source is not None else None
            estimate = None if found is None else innovation_std(*found, param(source[2], DEFAULT_GATE))
            if estimate is None:
                stds.append(float(limit))
                samples.append(None)
            else:
                stds.append(float(min(max(estimate[0], FLOOR), limit)))
                samples.append(estimate[1])
        out[group] = Noise(tuple(stds), tuple(samples), parameter)
    return out
