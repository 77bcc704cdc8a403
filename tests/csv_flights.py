"""Simulated fixed-wing flights as wide CSVs, the way a real flight folder looks (docs/csv-logs.md).

Rows at 20 Hz (``time_s``); airspeed, altitude (and a barometric copy of it), roll, pitch, throttle
new on every row; the accelerometer (``acc_x``, ``acc_y``, ``acc_z``) sampled at about 2.6 Hz and
forward-filled onto every row; a text column (``mode``) and a constant one (``gps_fix``). The
dynamics are smooth and correlated (turns bank the aircraft and load the accelerometer, climbs
pitch it up), each sensor with its own white noise. Faulty flights carry ground truth in a
``<flight>.truth.json`` sidecar: a sensor bias step or a stuck value on one column.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

ROW_HZ = 20.0
IMU_HZ = 2.6
G = 9.81
# (name, seed, [(kind, column, onset s, duration s, size)])
FLIGHTS = (
    ("healthy_1", 101, []),
    ("healthy_2", 102, []),
    ("healthy_3", 103, []),
    ("healthy_4", 104, []),
    ("healthy_5", 105, []),
    ("healthy_6", 106, []),
    ("fault_airspeed_bias", 201, [("bias", "airspeed", 120.0, 20.0, 2.0)]),
    ("fault_altitude_stuck", 202, [("stuck", "altitude", 150.0, 8.0, 0.0)]),
    ("fault_acc_z_bias", 203, [("bias", "acc_z", 100.0, 20.0, 3.0)]),
    ("fault_roll_stuck", 204, [("stuck", "roll", 180.0, 6.0, 0.0)]),
    ("fault_pitch_bias", 205, [("bias", "pitch", 90.0, 15.0, 2.0)]),
    ("fault_altitude_bias", 206, [("bias", "altitude", 200.0, 20.0, 3.0)]),
)
TRAIN = ("healthy_1", "healthy_2", "healthy_3")


def smooth(rng: np.random.Generator, n: int, tau_s: float, std: float) -> np.ndarray:
    """A smooth random signal: white noise through two first-order lags of time constant tau_s,
    scaled to ``std``."""
    a = np.exp(-1.0 / (ROW_HZ * tau_s))
    x = rng.standard_normal(n)
    for _ in range(2):
        y = np.empty(n)
        acc = 0.0
        for i in range(n):  # a test fixture of a few thousand rows
            acc = a * acc + (1 - a) * x[i]
            y[i] = acc
        x = y
    return std * x / (x.std() or 1.0)


def fly(seed: int, duration_s: float) -> dict[str, np.ndarray]:
    """True signals of one flight on the 20 Hz rows."""
    rng = np.random.default_rng(seed)
    n = int(duration_s * ROW_HZ)
    t = np.arange(n) / ROW_HZ
    roll = smooth(rng, n, 4.0, 12.0)  # deg: turns
    climb = smooth(rng, n, 6.0, 1.5)  # m/s
    airspeed = 18.0 + smooth(rng, n, 10.0, 1.2) - 0.3 * climb
    altitude = 120.0 + np.cumsum(climb) / ROW_HZ
    pitch = 2.0 + 2.5 * climb + smooth(rng, n, 3.0, 0.8)  # deg
    throttle = 0.55 + 0.08 * climb + 0.05 * smooth(rng, n, 5.0, 1.0)
    acc_x = np.gradient(airspeed, 1 / ROW_HZ) + G * np.sin(np.radians(pitch))
    acc_y = 0.4 * smooth(rng, n, 2.0, 1.0)
    acc_z = -G / np.cos(np.radians(roll))
    return {
        "t": t,
        "airspeed": airspeed,
        "altitude": altitude,
        "roll": roll,
        "pitch": pitch,
        "throttle": throttle,
        "acc_x": acc_x,
        "acc_y": acc_y,
        "acc_z": acc_z,
    }


NOISE = {
    "airspeed": 0.25,
    "altitude": 0.3,
    "roll": 0.3,
    "pitch": 0.3,
    "throttle": 0.005,
    "acc_x": 0.35,
    "acc_y": 0.35,
    "acc_z": 0.35,
}
IMU = ("acc_x", "acc_y", "acc_z")


def measured(truth: dict[str, np.ndarray], seed: int, faults) -> dict[str, np.ndarray]:
    """The logged columns: noise, faults, the accelerometer forward-filled from ~2.6 Hz."""
    rng = np.random.default_rng(seed + 7919)
    t = truth["t"]
    out = {name: truth[name] + NOISE[name] * rng.standard_normal(t.size) for name in NOISE}
    for kind, column, onset, duration, size in faults:
        inside = (t >= onset) & (t < onset + duration)
        if kind == "bias":
            out[column][inside] += size
        else:  # stuck: the last value before the onset, repeated
            out[column][inside] = out[column][np.flatnonzero(t < onset)[-1]]
    # the IMU samples at ~2.6 Hz (a jittered clock); each row repeats the latest sample
    imu_t = np.cumsum(rng.uniform(0.9, 1.1, int(t[-1] * IMU_HZ) + 2) / IMU_HZ)
    row_of_sample = np.searchsorted(t, imu_t)
    latest = np.searchsorted(imu_t, t, side="right") - 1
    for name in IMU:
        sampled = out[name][np.minimum(row_of_sample, t.size - 1)]
        out[name] = np.where(latest >= 0, sampled[np.maximum(latest, 0)], sampled[0])
    return out


def write_flight(folder: Path, name: str, seed: int, faults, duration_s: float) -> Path:
    truth = fly(seed, duration_s)
    columns = measured(truth, seed, faults)
    t = truth["t"]
    mode = np.where((t // 60) % 2 == 0, "AUTO", "LOITER")
    path = folder / f"{name}.csv"
    header = "time_s,airspeed,altitude,alt_baro,roll,pitch,throttle,acc_x,acc_y,acc_z,mode,gps_fix"
    rows = [header]
    for i in range(t.size):
        c = {k: v[i] for k, v in columns.items()}
        rows.append(
            f"{t[i]:.2f},{c['airspeed']:.3f},{c['altitude']:.2f},{c['altitude']:.2f},{c['roll']:.2f},"
            f"{c['pitch']:.2f},{c['throttle']:.4f},{c['acc_x']:.3f},{c['acc_y']:.3f},{c['acc_z']:.3f},"
            f"{mode[i]},3"
        )
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    if faults:
        events = [
            {"kind": f"{kind}", "target": column, "start": onset, "end": onset + duration}
            for kind, column, onset, duration, _ in faults
        ]
        doc = {"schema": "logscan.truth/1", "generator": "tests/csv_flights.py", "events": events}
        (folder / f"{name}.truth.json").write_text(json.dumps(doc, indent=1), encoding="utf-8")
    return path


def write_flights(folder: Path, duration_s: float = 300.0) -> list[Path]:
    """Every flight of FLIGHTS into ``folder``: the training flights into ``folder/healthy``, the
    others into ``folder/new`` (created); the paths written."""
    written = []
    for name, seed, faults in FLIGHTS:
        where = folder / ("healthy" if name in TRAIN else "new")
        where.mkdir(parents=True, exist_ok=True)
        written.append(write_flight(where, name, seed, faults, duration_s))
    return written


if __name__ == "__main__":
    import sys

    for written in write_flights(Path(sys.argv[1] if len(sys.argv) > 1 else "flights")):
        print(written)
