"""What the report draws of recovery (`logscan.report.recovery_figures`), kept before the filters'
series are released: per loop, the states that were recovered, with the measurement that reads each
state directly (when one does), the shared EKF's estimate, the recovered estimate and its bounds,
and the anomaly records. Small: a loop's grid and a few columns."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from logscan.readers import read_log

MAX_POINTS = 20_000  # per series: longer loops are drawn at a stride (recovered spans are short)


@dataclass
class StateView:
    loop: str
    state: str
    t: np.ndarray  # (N,) seconds since the log's time zero
    ekf: np.ndarray  # (N,) the shared EKF's posterior
    recovered: np.ndarray  # (N,) NaN outside recovered spans
    bound: np.ndarray  # (N,) k-sigma
    worst_case: np.ndarray  # (N,) Proposition 5.1
    measured: np.ndarray | None = None  # (N,) a group output that reads this state, as held
    measured_name: str = ""
    truth: np.ndarray | None = None  # (N,) the true state (a simulated log's truth names its channel)


@dataclass
class RecoveryView:
    states: list[StateView] = field(default_factory=list)
    anomalies: list = field(default_factory=list)  # logscan.recovery.AnomalyRecord
    k_sigma: float = 3.0


def _measurement_of(loop, state: int) -> tuple[np.ndarray | None, str]:
    """The first group output that reads ``state`` directly (its held values), else None."""
    for name, group in loop.run.groups.items():
        states, gains = loop.model.group(name).direct_map()  # output o reads gains[o] * x[states[o]]
        for o, s in enumerate(states.tolist()):
            if s == state and gains[o] != 0:
                return group.z[:, o] / gains[o], group.channels[o]
    return None, ""


def true_states(path: str, truth: dict | None, loops) -> dict[str, np.ndarray]:
    """Loop name -> (N, n) true states on that loop's grid, for the loops whose channels the log's
    ground truth names (``loops.<name>.true_state_channels``, as `logscan simulate` writes them),
    read again from the log (only those channels), held at each grid time."""
    named = {
        loop.name: ((truth or {}).get("loops") or {}).get(loop.name, {}).get("true_state_channels") for loop in loops
    }
    named = {name: list(channels) for name, channels in named.items() if channels}
    if not named:
        return {}
    log = read_log(path, [ch for channels in named.values() for ch in channels])
    out = {}
    for loop in loops:
        if loop.name not in named or not all(ch in log.channels for ch in named[loop.name]):
            continue
        grid_ns = loop.run.start_ns + np.round(np.asarray(loop.run.t) * 1e9).astype(np.int64)
        columns = []
        for name in named[loop.name]:
            channel = log.channels[name]
            i = np.searchsorted(channel.t, grid_ns, side="right") - 1  # the latest sample at each step
            columns.append(np.where(i >= 0, np.asarray(channel.values)[np.clip(i, 0, None)], np.nan))
        out[loop.name] = np.column_stack(columns)
    return out


def recovery_view(loops, recovery, k_sigma: float, truths: dict | None = None) -> RecoveryView:
    """The report's view of ``recovery`` (`logscan.recovery.Recovery`) over ``loops`` (LoopRun),
    with the loops' true states where ``truths`` has them (`true_states`)."""
    view = RecoveryView(anomalies=list(recovery.anomalies), k_sigma=k_sigma)
    truths = truths or {}
    for loop in loops:
        rec = recovery.loops[loop.name]
        stride = max(1, -(-rec.t.size // MAX_POINTS))
        for i, state in enumerate(rec.state_names):
            if not np.isfinite(rec.x_recovered[:, i]).any():
                continue
            measured, channel = _measurement_of(loop, i)
            view.states.append(
                StateView(
                    loop=loop.name,
                    state=state,
                    t=rec.t[::stride],
                    ekf=loop.trace.x_post[::stride, i],
                    recovered=rec.x_recovered[::stride, i],
                    bound=rec.bound[::stride, i],
                    worst_case=rec.worst_case[::stride, i],
                    measured=None if measured is None else measured[::stride],
                    measured_name=channel,
                    truth=truths[loop.name][::stride, i] if loop.name in truths else None,
                )
            )
    return view
