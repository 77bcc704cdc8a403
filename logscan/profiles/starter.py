"""A starter profile for a CSV log that has none: one mean-reverting state per numeric column.

The `linear` model with, per kept column i, a first-order Gauss-Markov state (a random walk that
reverts to the column's median): x_i' = -x_i / tau_i + w_i, E[w_i w_i] = q_i (continuous), measured
directly, z_i = x_i + v_i, E[v_i^2] = r_i^2, the column held with ``offset = -median``. Nothing
couples the columns: the filter predicts each column from its own past, so a sensor that jumps,
drifts or sticks stands out against its own history (docs/csv-logs.md).

Every number comes from the column's own fresh samples v_1..v_M (every row, or, for a column whose
rows repeat, the rows where its value changed: ``fresh = "on_change"``), s(.) being the robust
scatter 1.4826 * median |x - median x|:

 - r = s(second differences) / sqrt(6): white noise of std r gives second differences (1, -2, 1)
   of std sqrt(6) r, and a smooth motion adds little to them; a column quantised so coarsely that
   they are mostly 0 gets its step / sqrt(12) (the noise of rounding to that step);
 - q = (s(first differences)^2 - 2 r^2) / dt, dt the median spacing of the fresh samples: a random
   walk plus white noise has first differences of variance q dt + 2 r^2; at least a tenth of
   s(first differences)^2 / dt (increments that look all noise: the filter can still follow);
 - tau = 2 s(v - median)^2 / q: the Gauss-Markov state's stationary variance q tau / 2 is the
   column's own spread, clipped to [10 dt, the log's span].

Dropped columns are listed with why: the time column, text, constant, an exact copy of another
column, a few distinct values (a mode or flag: a `[mode]` candidate, not a state), a constant step
(a counter or clock), too few fresh samples. A column whose consecutive rows repeat exactly on at
least FILLED_REPEAT_SHARE of them is taken as forward-filled (a sensor with noise never repeats a
float exactly); its mean repeat run and rate are written beside it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from logscan.docs import doc_url
from logscan.log import Log
from logscan.profiles.toml_writer import _string

# The formats `logscan init-profile` writes a starter profile for when a log has no profile: their
# channels are numeric columns or message fields that name no vehicle (a bag's ROS topics do).
STARTER_FORMATS = frozenset({"csv", "csv-dir", "mcap"})
MIN_FRESH = 30  # fewer fresh samples than this: too few to read a column's noise from
FILLED_REPEAT_SHARE = 0.5  # exact repeats on at least half the rows: forward-filled (or held)
MAX_DISCRETE_VALUES = 16  # a column with this few distinct values is a mode, a flag or a state number
MAD_TO_STD = 1.4826  # s = 1.4826 median |x - median x| estimates a normal std
Q_FLOOR_SHARE = 0.1  # q is at least this share of the first differences' scatter (per second)
TAU_MIN_PERIODS = 10.0  # tau at least 10 fresh periods: slower than the sampling


@dataclass
class Column:
    """One kept column: its state's numbers and how they were read."""

    channel: str
    group: str
    fresh: str  # "on_sample" or "on_change"
    rate_hz: float  # fresh samples per second
    center: float  # the median: offset = -center
    noise_std: float  # r
    q: float  # continuous process noise spectral density (unit^2 / s)
    tau_s: float
    repeat_share: float
    notes: list[str] = field(default_factory=list)


@dataclass
class StarterProfile:
    """The profile text (TOML with comments), the notes to show, the columns kept and dropped."""

    text: str
    notes: list[str]
    kept: list[Column]
    dropped: list[tuple[str, str]]  # (column, why)


def scatter(x: np.ndarray) -> float:
    """Robust std: 1.4826 * median |x - median x| (0 for an empty array)."""
    return float(MAD_TO_STD * np.median(np.abs(x - np.median(x)))) if x.size else 0.0


def _group_name(channel: str, taken: set[str]) -> str:
    base = re.sub(r"[^A-Za-z0-9_]+", "_", channel).strip("_") or "column"
    base = base if base[0].isalpha() else f"c_{base}"
    name, i = base, 2
    while name in taken:
        name, i = f"{base}_{i}", i + 1
    taken.add(name)
    return name


def _fresh_samples(t: np.ndarray, v: np.ndarray) -> tuple[str, float, np.ndarray, np.ndarray]:
    """(fresh mode, repeat share, fresh times, fresh values): the rows where the value changed when
    at least FILLED_REPEAT_SHARE of the rows repeat the one before exactly, else every row."""
    repeats = v[1:] == v[:-1]
    share = float(repeats.mean()) if repeats.size else 0.0
    if share < FILLED_REPEAT_SHARE:
        return "on_sample", share, t, v
    new = np.concatenate(([True], ~repeats))
    return "on_change", share, t[new], v[new]


def _why_dropped(v: np.ndarray, vf: np.ndarray) -> str | None:
    """Why a column is no state (None: keep it)."""
    if v.size == 0:
        return "no numeric sample"
    if np.all(v == v[0]):
        return f"constant ({v[0]:g})"
    distinct = np.unique(v)
    if distinct.size <= MAX_DISCRETE_VALUES:
        return (
            f"{distinct.size} distinct values: a mode, flag or state number, not a sensor "
            "(undecided: if it is the flight mode, set it as [mode] channel)"
        )
    if vf.size < MIN_FRESH:
        return f"too few samples ({vf.size} fresh, at least {MIN_FRESH} needed to read its noise)"
    steps = np.diff(vf)
    if np.all(steps == steps[0]) or scatter(steps) == 0.0 and np.all(steps > 0):
        return "changes by a constant step: a counter or a clock, not a sensor"
    return None


def _column(channel: str, group: str, t_ns: np.ndarray, v: np.ndarray, span_s: float) -> Column | str:
    """The Column of one channel's finite samples, or why it is dropped."""
    fresh, share, tf, vf = _fresh_samples(t_ns, v)
    why = _why_dropped(v, vf)
    if why is not None:
        return why
    dt = float(np.median(np.diff(tf))) / 1e9
    d1, d2 = np.diff(vf), np.diff(vf, 2)
    notes = []
    r = scatter(d2) / np.sqrt(6.0)
    if r == 0.0:
        step = float(np.min(np.abs(d1[d1 != 0])))
        r = step / np.sqrt(12.0)
        notes.append(f"quantised: second differences mostly 0, noise from its step {step:g} / sqrt(12)")
    s1 = scatter(d1) if scatter(d1) > 0 else float(np.std(d1))
    q = max(s1**2 - 2 * r**2, Q_FLOOR_SHARE * s1**2) / dt
    if s1**2 - 2 * r**2 < Q_FLOOR_SHARE * s1**2:
        notes.append("undecided: its increments look all noise; Q kept at a tenth of their scatter")
    spread = scatter(v - np.median(v)) or float(np.std(v))
    tau = float(np.clip(2 * spread**2 / q, TAU_MIN_PERIODS * dt, max(span_s, TAU_MIN_PERIODS * dt)))
    if fresh == "on_change":
        notes.append(
            f"forward-filled: {share:.0%} of its rows repeat the one before; fresh only where it changes "
            f"(~{1 / dt:.3g} Hz)"
        )
    return Column(channel, group, fresh, 1.0 / dt, float(np.median(v)), r, q, tau, share, notes)


def _copies(log: Log) -> dict[str, str]:
    """channel -> the earlier channel it is an exact copy of (same times, same values)."""
    seen: dict[tuple, str] = {}
    out = {}
    for name, ch in log.channels.items():
        key = (ch.t.tobytes(), np.nan_to_num(ch.values, nan=np.pi).tobytes())
        if key in seen:
            out[name] = seen[key]
        else:
            seen[key] = name
    return out


def _source_drops(log: Log) -> list[tuple[str, str]]:
    """The time column(s) and the text columns the reader skipped."""
    out = []
    for label, what in log.source.metadata.get("csv.time_columns", {}).items():
        out.append((what.split(" in ", 1)[0].strip("'\""), f"the time column of {label}"))
    for item in log.source.skipped:
        found = re.match(r"text column '(.*)' of ", item.what)
        if found:
            out.append((found.group(1), "text, not numeric"))
    return out


def row_rate_hz(log: Log) -> float:
    """The analysis grid: the rate of the channel with the most samples (the log's rows)."""
    busiest = max(log.channels.values(), key=len)
    steps = np.diff(np.unique(busiest.t))
    return float(1e9 / np.median(steps)) if steps.size else 1.0


def starter_profile(log: Log) -> StarterProfile:
    """The starter profile of ``log`` (a CSV log): see the module docstring for every rule."""
    span_s = max(log.duration_s, 1e-9) if log.channels else 1e-9
    copies = _copies(log)
    kept: list[Column] = []
    dropped = _source_drops(log)
    taken: set[str] = set()
    for name, ch in log.channels.items():
        if name in copies:
            dropped.append((name, f"an exact copy of {copies[name]}"))
            continue
        finite = np.isfinite(ch.values)
        order = np.argsort(ch.t[finite], kind="stable")
        found = _column(name, "", ch.t[finite][order], ch.values[finite][order], span_s)
        if isinstance(found, str):
            dropped.append((name, found))
        else:
            found.group = _group_name(name, taken)
            kept.append(found)
    notes = [f"starter profile from {log.source.path}: {len(kept)} column(s) kept, {len(dropped)} dropped"]
    if not kept:
        notes.append("no column varies enough to be a state: the profile has none and will not parse")
    text = render(log, kept, dropped, row_rate_hz(log) if log.channels else 1.0)
    return StarterProfile(text, notes, kept, dropped)


def _fmt(x: float) -> str:
    return f"{x:.6g}"


def _matrix(rows: list[list[float]]) -> str:
    return "[\n" + "".join(f"  [{', '.join(_fmt(v) for v in row)}],\n" for row in rows) + "]"


def _header(log: Log, kept: list[Column], dropped: list[tuple[str, str]]) -> list[str]:
    """The comment lines: the principle, the columns dropped and why, the numbers of those kept."""
    lines = [
        f"# Starter profile written by `logscan init-profile` for {log.source.path}.",
        "# One state per kept column: a random walk reverting to the column's median (first-order",
        "# Gauss-Markov, A = -1/tau), measured directly (C = 1). Its noise comes from the column's own",
        "# fresh samples: R from the scatter of second differences, Q from that of first differences,",
        "# tau from its spread. Calibrate both on healthy flights: logscan train --calibrate --tune",
        f"# ({doc_url('csv-logs.md')}).",
        "# Edit freely: drop a column by deleting its row and column of A and Q, its C and R entries",
        "# and its [measurements] table.",
        "#",
        "# columns not used:",
        *[f"#   {name}: {why}" for name, why in dropped],
        "#",
        "# columns kept (state: fresh samples per s, noise std r, Q, tau):",
    ]
    for c in kept:
        numbers = f"r {_fmt(c.noise_std)}, q {_fmt(c.q)}, tau {c.tau_s:.3g} s"
        lines.append(f"#   {c.group} ({c.channel}): {c.rate_hz:.3g} Hz, {numbers}")
        lines.extend(f"#     {note}" for note in c.notes)
    return lines


def render(log: Log, kept: list[Column], dropped: list[tuple[str, str]], rate_hz: float) -> str:
    """The profile's TOML text, every choice commented."""
    n = len(kept)
    lines = _header(log, kept, dropped) + [
        f"name = {_string('starter: ' + log.source.path.rsplit('/', 1)[-1])}",
        'description = "one mean-reverting state per CSV column (logscan init-profile)"',
        "",
        "[vehicle]",
        'model = "linear"',
        f"rate_hz = {_fmt(rate_hz)}  # the rows' rate",
        "",
        "[vehicle.params]",
        f"states = [{', '.join(_string(c.group) for c in kept)}]",
        f"A = {_matrix([[-1.0 / c.tau_s if i == j else 0.0 for j in range(n)] for i, c in enumerate(kept)])}",
        f"B = [{', '.join('[]' for _ in kept)}]  # no inputs: each column is predicted from its own past",
        f"Q = {_matrix([[c.q if i == j else 0.0 for j in range(n)] for i, c in enumerate(kept)])}",
        "C = { "
        + ", ".join(
            f"{c.group} = [[{', '.join('1' if j == i else '0' for j in range(n))}]]" for i, c in enumerate(kept)
        )
        + " }",
        "R = { " + ", ".join(f"{c.group} = [{_fmt(c.noise_std)}]" for c in kept) + " }",
    ]
    for c in kept:
        lines += [
            "",
            f"[measurements.{c.group}]",
            f"channels = [{_string(c.channel)}]",
            f"rate_hz = {_fmt(c.rate_hz)}",
            f"offset = {_fmt(-c.center)}  # the state is the column less its median",
            f"noise_std = {_fmt(c.noise_std)}",
        ]
        if c.fresh == "on_change":
            lines.append(f'fresh = "on_change"  # {c.repeat_share:.0%} of its rows repeat: forward-filled')
    return "\n".join(lines + DETECTORS) + "\n"


# The innovation tests a per-column random walk supports. CUSUM is off: it takes the innovations as
# white, and a random walk per column leaves a flight's smooth motion (a climb, a turn) in them as
# runs of one sign, which it accumulates into alarms (docs/csv-logs.md: 86 false alarms in 15 min
# of healthy simulated flights with it, none without).
DETECTORS = [
    "",
    "[detectors.nis]  # a column that jumps away from its own prediction (a bias step, a spike)",
    "enabled = true",
    "",
    "[detectors.frozen]  # a column whose samples stop changing (stuck), filled columns included",
    "enabled = true",
    "",
    "[detectors.encoded_ekf]  # its band factors are what `logscan train --tune` chooses",
    "enabled = true",
    "",
    "[detectors.cusum]  # off: the smooth motion a random walk leaves in the innovations looks like drift",
    "enabled = false",
]
