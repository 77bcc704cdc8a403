"""Observability verdict: when could a fault of a kind on a sensor or actuator be seen at all?

Specified in docs/algorithms.md section 10. For each fault direction of the model (each actuator,
each measured output) the kernel (`logscan.verdict.observability_kernel`) propagates a unit fault through the
filter linearised along its own trajectory and sums the evidence it leaves in the innovations over
``window_s`` from every window start on a ``stride_s`` grid: lambda = sum r^T S^-1 r, the
non-centrality of the innovations. A fault of size m scales it by m^2 (an actuator offset of
m = -10 %: du = m u; a lost actuator: du = -u, m^2 = 1; a sensor bias of m units). The fault is
observable from a window start when

    sqrt(m^2 lambda) >= snr_min = z(1 - alpha) + z(0.9)     (5.63 standard deviations of evidence)

i.e. the matched test of that fault direction (the best any detector can do: it knows the fault's
signature), spending logscan's budget of 0.1 false alarms per hour over one test per window start
(alpha = 0.1 x 0.25 / 3600), would still see it with 90 % probability. Below it, no detector that
reads these sensors can promise to see that fault there: a steer-by-wire actuator offset during straight driving (the
commanded torque is nearly zero, so is the offset) is the case in point.

Kinds with a verdict: actuator-offset and lost-actuator on every actuator, bias on every measured
output. Other kinds (drift, stuck, noise, bit flips, estimator corruption) get none: their
signature does not depend on the excitation this way (a stuck sensor is seen by its vanished noise).
Actuators: the model's own (`Model.actuators`: names, mixer and operating point, the source the
simulator reads too, so the names match the ground truth of simulated logs).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np

from logscan.alarms import true_runs
from logscan.docs import doc_url
from logscan.models.dispatch import call_literal
from logscan.results import events_from_truth
from logscan.verdict.observability_kernel import (
    FaultDirections,
    FilterModel,
    FilterTrajectory,
    Windows,
    signature_evidence,
    workspace,
)

# kind -> reference size for the report's shading and the summary (the simulator's default sizes:
# `logscan simulate --help`); evaluate scales by each fault's own magnitude instead
REFERENCE_SIZE = {"actuator-offset": -0.10, "lost-actuator": 1.0, "bias": 1.0}
ACTUATOR_KINDS = ("actuator-offset", "lost-actuator")
SENSOR_KINDS = ("bias",)
WINDOW_S = 1.0  # a fault must show within 1 s of its onset (the detection target of issue 17)
STRIDE_S = 0.25  # window starts every 0.25 s: the resolution of the shading
# a span judged alone: its kernel starts this long before it, where its covariance, started from the
# trace's diagonal, has settled (evidence within 1e-4 of the whole run's on ins, 1e-9 on a quadcopter)
WARMUP_S = 30.0
BUDGET_PER_HOUR = 0.1  # the false alarms per hour every logscan detector may spend
POWER = 0.9  # the detection probability a fault "that can be seen" must reach


def snr_needed(budget_per_hour: float = BUDGET_PER_HOUR, stride_s: float = STRIDE_S, power: float = POWER) -> float:
    """sqrt(lambda) a fault needs: the matched test of its direction, one test per window start,
    at the false-alarm budget (alpha = budget * stride / 3600 per test), with probability ``power``:
    z(1 - alpha) + z(power) (0.1 / h every 0.25 s: 4.35 + 1.28 = 5.63)."""
    from scipy.special import ndtri

    alpha = budget_per_hour * stride_s / 3600.0
    return float(ndtri(1.0 - alpha) + ndtri(power))


SNR_MIN = 5.63  # snr_needed() at the defaults (a test checks it); computed per run from its stride

WORDS = {
    "actuator-offset": "an offset on {target} could not be seen here: {why}",
    "lost-actuator": "a loss of {target} could not be seen here: {why}",
    "bias": "a bias on {target} could not be seen here: {why}",
}
WHY = {
    "actuator": "it is barely commanded (straight driving, steady hover), so the fault gives the sensors no signature",
    "sensor": "within a second it stays small against the sensor's noise, and the filter absorbs part of it",
}


@dataclass(frozen=True)
class Direction:
    """One fault direction: an actuator, or one measured output (group column)."""

    target: str  # as the ground truth names it: steering_motor, motor1, yaw_rate, accel.x
    what: str  # "actuator" or "sensor"
    channel: str = ""  # a sensor's log channel (matches a truth event's channels)


@dataclass
class Observability:
    """Evidence of a unit fault per window start (rows, every ``stride_s``) and direction (columns)."""

    t_start: np.ndarray  # (W,) window start times (s)
    evidence: np.ndarray  # (W, D) lambda of a unit fault over [t, t + window_s)
    directions: list[Direction]
    window_s: float = WINDOW_S
    stride_s: float = STRIDE_S
    snr_min: float = SNR_MIN
    t_end: float = 0.0  # the log's last grid time
    notes: list[str] = field(default_factory=list)

    # --- verdicts -------------------------------------------------------------------------------
    def kinds_of(self, direction: Direction) -> tuple[str, ...]:
        return ACTUATOR_KINDS if direction.what == "actuator" else SENSOR_KINDS

    def observable(self, d: int, kind: str, magnitude: float | None = None) -> np.ndarray:
        """(W,) bool: a fault of ``kind`` and ``magnitude`` (None: the reference size) on direction
        ``d`` starting at each window start would leave sqrt(m^2 lambda) >= snr_min (NaN: False)."""
        return seen_rows(self.evidence[:, d], kind, magnitude, self.snr_min)

    def unobservable_intervals(self, d: int, kind: str, magnitude: float | None = None) -> list[tuple[float, float]]:
        """Merged [start, end) spans of window starts from which the fault would not be seen (windows
        without a verdict, NaN evidence, are neither seen nor unseen)."""
        blind = blind_rows(self.evidence[:, d], kind, magnitude, self.snr_min)
        return spans_of(blind, self.t_start, self.stride_s, self.t_end)

    def find(self, target: str, channels=()) -> int | None:
        """Index of the direction a fault event names (its log channel first, then its target)."""
        for i, direction in enumerate(self.directions):
            if direction.channel and direction.channel in channels:
                return i
        for i, direction in enumerate(self.directions):
            if direction.target == target:
                return i
        return None

    def event_verdict(self, event) -> bool | None:
        """Whether a truth event (`logscan.results.FaultEvent`) overlaps a period where it could be
        seen: True (observable), False (its whole span is unobservable), None (no verdict: a kind
        or target this module does not judge)."""
        d = self.find(event.target, event.channels or ())
        if d is None or event.kind not in self.kinds_of(self.directions[d]):
            return None
        magnitude = event.magnitude if event.kind != "lost-actuator" else 1.0
        seen = self.observable(d, event.kind, magnitude)
        inside = inside_rows(self.t_start, self.evidence[:, d], event, self)
        before = self.seen_before(event, magnitude)
        if not inside.any():
            return before
        return bool(seen[inside].any()) or bool(before)

    def seen_before(self, event, magnitude: float) -> bool | None:
        """The verdict of the windows a truth event fills among those no longer held in full (a
        long log's, `logscan.verdict.observability_folded`); None: none (every window is held)."""
        return None

    @property
    def t_first(self) -> float:
        """The first window's start (the report's time axis begins there)."""
        return self.t_start[0]

    # --- views ----------------------------------------------------------------------------------
    def blind_periods(self) -> list[dict]:
        """Every (direction, kind) at its reference size with an unobservable period: target, kind,
        plain words and the intervals (seconds since the log's time zero)."""
        out = []
        for d, direction in enumerate(self.directions):
            for kind in self.kinds_of(direction):
                spans = self.unobservable_intervals(d, kind)
                if not spans:
                    continue
                out.append(
                    {
                        "target": direction.target,
                        "kind": kind,
                        "size": REFERENCE_SIZE[kind],
                        "words": WORDS[kind].format(target=direction.target, why=WHY[direction.what]),
                        "intervals": [[a, b] for a, b in spans],
                        "unobservable_s": float(sum(b - a for a, b in spans)),
                    }
                )
        return out

    def to_dict(self) -> dict:
        """JSON-ready summary (the analyze summary's ``observability``)."""
        return {
            "window_s": self.window_s,
            "stride_s": self.stride_s,
            "snr_min": self.snr_min,
            "judged": [{"target": d.target, "kinds": list(self.kinds_of(d))} for d in self.directions],
            "unobservable": self.blind_periods(),
            "notes": list(self.notes),
        }


def fault_scale(kind: str, magnitude: float) -> float:
    """The factor a fault of ``kind`` and ``magnitude`` puts on the unit signature: the offset
    itself (du = m u), 1 for a lost actuator (du = -u), the bias itself."""
    return 1.0 if kind == "lost-actuator" else float(magnitude)


def seen_rows(evidence: np.ndarray, kind: str, magnitude: float | None, snr_min: float) -> np.ndarray:
    """Of one direction's ``evidence`` (rows), whether a fault of ``kind`` and ``magnitude`` (None:
    the reference size) starting there leaves sqrt(m^2 lambda) >= snr_min (NaN: False)."""
    size = fault_scale(kind, REFERENCE_SIZE[kind] if magnitude is None else magnitude)
    with np.errstate(invalid="ignore"):
        return size * size * evidence >= snr_min**2


def blind_rows(evidence: np.ndarray, kind: str, magnitude: float | None, snr_min: float) -> np.ndarray:
    """The rows of one direction's ``evidence`` with a verdict (finite) that the fault is not seen."""
    return np.isfinite(evidence) & ~seen_rows(evidence, kind, magnitude, snr_min)


def inside_rows(t_start: np.ndarray, evidence: np.ndarray, event, verdict) -> np.ndarray:
    """The rows (window starts ``t_start``, one direction's ``evidence``) with a verdict that a truth
    event fills: from the window in progress at its onset to the last that ends before the fault
    does (a fault ending a moment after the excitation began left no more than that moment's
    evidence); the onset's window always counts. ``verdict``: its window_s, stride_s and t_end."""
    end = min(event.end_or_inf, verdict.t_end)
    last = max(end - verdict.window_s, event.t_start)
    inside = (t_start + verdict.stride_s > event.t_start) & (t_start <= last + 1e-9)
    return inside & np.isfinite(evidence)


def spans_of(mask: np.ndarray, t_start: np.ndarray, stride_s: float, t_end: float) -> list[tuple[float, float]]:
    """[t_start[i], t_start[i] + stride) of the True entries of ``mask``, merged, clipped to t_end."""
    if not mask.any():
        return []
    first, stop = true_runs(mask)
    return spans_of_runs(t_start[first], t_start[stop - 1], stride_s, t_end)


def spans_of_runs(firsts: np.ndarray, lasts: np.ndarray, stride_s: float, t_end: float) -> list[tuple[float, float]]:
    """[first, last + stride) of each run of window starts (its first and last start), clipped to t_end."""
    return [(float(a), float(min(b + stride_s, t_end))) for a, b in zip(firsts, lasts) if a < t_end]


# --- building the verdict from a filtered run ------------------------------------------------------


def held_inputs(u: np.ndarray) -> np.ndarray:
    """u with every non-finite row replaced by the last finite one (zeros before the first), as
    the filter holds them."""
    u = np.asarray(u, dtype=np.float64)
    ok = np.all(np.isfinite(u), axis=1)
    if ok.all():  # the usual case: no copy (a 1-hour 100 Hz log's inputs are 12 MB a copy)
        return np.ascontiguousarray(u)
    last = np.maximum.accumulate(np.where(ok, np.arange(u.shape[0]), -1))
    held = np.where((last >= 0)[:, None], u[np.maximum(last, 0)], 0.0)
    return np.ascontiguousarray(held)


def _fault_directions(model, run, trace, u: np.ndarray):
    """(directions, FaultDirections): the model's actuators (a unit relative offset on each, at
    its values a = M^+ u + trim), then a unit bias on every measured output of the trace's groups."""
    actuators = model.actuators()
    names, M, trim = list(actuators.names), np.asarray(actuators.M, dtype=np.float64), actuators.trim
    # actuator values a = M^+ u (+ trim): the fault du = M[:, a] * m * value
    values = np.ascontiguousarray(u @ np.linalg.pinv(M).T) if names else np.zeros((u.shape[0], 0))
    values += trim if names else 0.0  # in place: no second (N, A) array
    directions = [Direction(name, "actuator") for name in names]
    cols = []
    for g, group in enumerate(trace.group_names):
        channels = list(run.groups[group].channels) if group in run.groups else []
        size = int(trace.group_sizes[g])
        for c in range(size):
            channel = channels[c] if c < len(channels) else ""
            # the simulator's target names: the group alone, or <group>.<field's last part> (accel.x)
            field_name = (channel or model.group(group).outputs[c]).rsplit("/", 1)[-1].rsplit(".", 1)[-1]
            target = group if size == 1 else f"{group}.{field_name}"
            directions.append(Direction(target, "sensor", channel))
            cols.append(int(trace.group_offsets[g]) + c)
    faults = FaultDirections(np.ascontiguousarray(M.T, dtype=np.float64), values, np.array(cols, dtype=np.int64))
    return directions, faults


def _kernel_ranges(judged: np.ndarray, stride: int, window: int, warmup: int, N: int) -> list[tuple[int, int]]:
    """The step ranges [k0, k1) the kernel runs over to judge the window starts ``judged`` (rows of
    the stride grid): each run of judged rows from ``warmup`` steps before its first start (on the
    grid) to the end of its last window; ranges that touch are merged."""
    edges = np.diff(np.concatenate(([0], judged.astype(np.int8), [0])))
    ranges: list[tuple[int, int]] = []
    for first, last in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1):
        k0 = max(int(first) * stride - -(-warmup // stride) * stride, 0)
        k1 = min(int(last) * stride + window + 1, N)
        if ranges and k0 <= ranges[-1][1]:
            ranges[-1] = (ranges[-1][0], k1)
        else:
            ranges.append((k0, k1))
    return ranges


def observability_of(
    model, run, trace, *, window_s=WINDOW_S, stride_s=STRIDE_S, snr_min=None, spans=None
) -> Observability:
    """The verdict of one filtered run (the EKF trace with its x_prior and x_post); ``snr_min`` None:
    `snr_needed` at the grid's stride. ``spans`` None judges every window start; else only those in
    the [t0, t1] spans given (the trace's time axis), the others get no verdict (NaN): the kernel
    runs over each span from WARMUP_S before it, its covariance started there from the trace's
    diagonal (`_kernel_ranges`)."""
    dt = float(trace.dt)
    stride = max(int(round(stride_s / dt)), 1)
    window = max(int(round(window_s / dt / stride)), 1) * stride
    u = held_inputs(run.u)
    directions, faults = _fault_directions(model, run, trace, u)
    t = np.asarray(trace.t, dtype=np.float64)
    N = t.size
    starts = t[0] + dt * stride * np.arange(N // stride + 1)
    judged = np.ones(starts.size, dtype=bool)
    if spans is not None:
        judged[:] = False
        for t0, t1 in spans:
            judged |= (starts >= t0 - 1e-9) & (starts <= t1 + 1e-9)
    evidence = np.full((starts.size, len(directions)), np.nan)
    windows = Windows(np.int64(window), np.int64(stride))
    for k0, k1 in _kernel_ranges(judged, stride, window, int(round(WARMUP_S / dt)), N):
        filter_model = FilterModel(
            p=model.param_vector(dt),
            dt=dt,
            Q=np.ascontiguousarray(trace.Q, dtype=np.float64),
            R=np.ascontiguousarray(trace.R, dtype=np.float64),
            P0=np.diag(np.nan_to_num(trace.P_post_diag[k0].astype(np.float64), nan=1.0)),
            group_ids=np.array([model.group(g).group_id for g in trace.group_names], dtype=np.int64),
            group_offsets=np.asarray(trace.group_offsets, dtype=np.int64),
            group_sizes=np.asarray(trace.group_sizes, dtype=np.int64),
        )
        trajectory = FilterTrajectory(
            x_prior=np.ascontiguousarray(trace.x_prior[k0:k1], dtype=np.float64),
            x_post=np.ascontiguousarray(trace.x_post[k0:k1], dtype=np.float64),
            u=u[k0:k1],
            updated=np.ascontiguousarray(trace.updated[k0:k1]),
        )
        span_faults = faults._replace(act_values=np.ascontiguousarray(faults.act_values[k0:k1]))
        work = workspace(filter_model, trajectory, span_faults, windows)
        local = call_literal(signature_evidence, model.model_id, filter_model, trajectory, span_faults, windows, work)
        rows = np.arange(local.shape[0]) + k0 // stride
        take = rows < starts.size
        rows, local = rows[take], local[take]
        evidence[rows[judged[rows]]] = local[judged[rows]]
    keep = starts <= t[-1]
    # a window the log's end cuts short is not judged (nothing could be seen in what is left of it)
    evidence[stride * np.arange(evidence.shape[0]) + window > N - 1] = np.nan
    return Observability(
        t_start=starts[keep],
        evidence=evidence[keep],
        directions=directions,
        window_s=window * dt,
        stride_s=stride * dt,
        snr_min=snr_needed(stride_s=stride * dt) if snr_min is None else float(snr_min),
        t_end=float(t[-1]),
    )


def compile_kernel(model, dt: float) -> None:
    """Compile (or load from the disk cache) the verdict's kernel for ``model``: `observability_of`
    on three steps of a stand-in EKF run of its first group (the kernel's signature depends on the
    model id, array ranks and dtypes only: the same as a real run's). The first run calls it while
    the EKF's kernel compiles in its own process (`logscan.filters.warmup`), not after it."""
    name, spec = next(iter(model.groups.items()))
    steps, n, size = 3, model.n_states, spec.size
    trace = SimpleNamespace(
        dt=dt,
        t=np.arange(steps) * dt,
        Q=np.eye(n),
        R=np.eye(size),
        P_post_diag=np.ones((steps, n), dtype=np.float32),
        group_names=[name],
        group_offsets=np.zeros(1, dtype=np.int64),
        group_sizes=np.full(1, size, dtype=np.int64),
        x_prior=np.zeros((steps, n)),
        x_post=np.zeros((steps, n)),
        updated=np.zeros((steps, 1), dtype=bool),
    )
    run = SimpleNamespace(u=np.zeros((steps, model.n_inputs)), groups={})
    observability_of(model, run, trace)


def fault_spans(events, window_s: float = WINDOW_S) -> list[tuple[float, float]]:
    """Where a verdict is needed: from a window before each fault event of a judged kind to its
    end (open-ended: the log's), the window starts `Observability.event_verdict` reads."""
    judged = set(ACTUATOR_KINDS) | set(SENSOR_KINDS)
    return [(e.t_start - window_s, e.end_or_inf) for e in events if e.kind in judged]


def observability_for(prepared) -> tuple[Observability | None, str | None]:
    """(the verdict of a prepared log's EKF run, None) or (None, why there is none): no EKF trace
    or its states freed, no ground truth with a fault of a judged kind (the verdict is judged only
    where one is needed: around those faults, `fault_spans`), or the verdict failed (a warning,
    never a failed analysis)."""
    trace = getattr(prepared, "trace", None)
    run = prepared.run
    if trace is None or getattr(trace, "x_prior", None) is None or trace.x_post is None or run.u is None:
        return None, None
    try:
        spans = judged_spans(prepared)
        if not spans:
            return None, None
        obs = observability_of(prepared.model, run, trace, spans=spans)
        obs.notes.append(f"judged around the ground truth's faults only ({doc_url('algorithms.md')}, section 10)")
        return obs, None
    except Exception as exc:  # noqa: BLE001 - the verdict is an aid; it must not cost the analysis
        return None, f"observability verdict not computed: {type(exc).__name__}: {exc}"


def judged_spans(prepared) -> list[tuple[float, float]]:
    """The spans of a prepared log the verdict judges (`fault_spans` of its ground truth's events):
    none without ground truth or without a fault of a judged kind."""
    truth = prepared.log.truth
    return fault_spans(events_from_truth(truth.get("events", []), path=prepared.path)) if truth else []


def describe(obs: Observability | None) -> str:
    """One line for a summary: how much of the log each judged fault could not be seen."""
    if obs is None:
        return ""
    parts = [
        f"{p['kind']} on {p['target']} unobservable {p['unobservable_s']:.1f} s"
        for p in obs.blind_periods()
        if not math.isclose(p["unobservable_s"], 0.0)
    ]
    return "; ".join(parts)
