"""An input fault told from a fault of the sensor that alarmed first: rule 6 of the incidents
(docs/algorithms.md 9.1).

Under a model whose input is a sensor that the prediction integrates (`ins`: the IMU's specific
force, integrated to a velocity and again to a position), an accelerometer fault moves the
prediction, and the aiding sensor that measures the first integral (the GNSS velocity) disagrees
with it first: rule 3 then names that healthy sensor. The sensors that measure the motion twice
over (`Model.kinematic_pairs`: the GNSS velocity and the GNSS position on each axis, the GNSS
velocity down and the barometer) tell the two apart by the signs of their innovations
(measured - predicted):

- an input fault moves the predicted velocity and, integrated, the predicted position the same
  way; the healthy sensors both measure the true motion, so both innovations of a pair leave zero
  with the same sign;
- a fault of one of them (a GNSS velocity spoof) pulls the filter's velocity towards it, and the
  position it integrates leaves the healthy position sensor the other way: opposite signs (and a
  position fault pulls the velocity against it likewise).

Each innovation is taken as its normalised mean over the alarm the headline quotes, z = mean x
sqrt(M) for M samples (N(0, 1) for the filter's white innovations), and counts when |z| reaches
z(1 - alpha / 2), alpha the false-alarm budget (0.1 per hour) spent over the alarm's span. The
input is suspect when a pair agrees and none disagrees; otherwise rule 3 stands.

Limits: a spoofer that moves the GNSS position and velocity together, coherently, agrees with
itself as the true motion would; on the down axis the barometer is a second, independent witness
(its pair with the GNSS velocity then disagrees), but horizontally only the one receiver measures
the motion: the words then say that such a spoof looks alike (`KinematicEvidence.independent`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.special import ndtri  # not scipy.stats (46 MB to import)

from logscan.alarms import AlarmInterval
from logscan.detectors.words import group_words
from logscan.verdict.deviation import significant

BUDGET_PER_HOUR = 0.1  # logscan's false-alarm budget (docs/algorithms.md 1b), here of wrong renames


@dataclass
class KinematicEvidence:
    """Per step, the normalised innovations of each pair of `Model.kinematic_pairs` (NaN where the
    output was not tested), and the words and channels of the input a pair's agreement blames."""

    t: np.ndarray  # (N,)
    names: list[tuple[str, str]]  # per pair: ("GNSS velocity v_down", "barometer altitude")
    rate: np.ndarray  # (N, P) float32: the rate output's normalised innovation
    level: np.ndarray  # (N, P) float32: the level output's, times the pair's sign
    groups: frozenset[str]  # the groups the pairs read: an incident headed by another is not judged
    what: str  # "accelerometer (the model's input)"
    channels: str  # its log channels, joined
    dt: float  # the grid step, s
    # per pair: whether its level is measured by a sensor of its own (the barometer), not by the
    # rate's (the GNSS position from the receiver that gives the velocity); empty: none is
    independent: tuple[bool, ...] = ()

    def within(self, alarms: list[AlarmInterval]) -> KinematicEvidence:
        """Only the steps within ``alarms`` (what a later call reads: the alarms a suppression
        leaves are among them), so that a kept analysis does not hold the whole log's."""
        keep = np.zeros(self.t.size, dtype=bool)
        for alarm in alarms:
            a, b = np.searchsorted(self.t, [alarm.start - 1e-9, alarm.end + 1e-9], side="left")
            keep[a : b + 1] = True
        return replace(self, t=self.t[keep], rate=self.rate[keep], level=self.level[keep])


def kinematic_evidence(model, trace, run) -> KinematicEvidence | None:
    """The evidence of a prepared log's EKF trace (its innovations y and S's diagonal, before they
    are freed); None when the model names no pairs or the trace kept no innovations."""
    pairs = tuple(getattr(model, "kinematic_pairs", ()))
    y, s = getattr(trace, "y", None), getattr(trace, "S_diag", None)
    if not pairs or y is None or s is None:
        return None
    names, rate, level, groups, independent = [], [], [], set(), []
    witnesses = frozenset(getattr(model, "kinematic_witnesses", ()))
    for rate_group, i, level_group, j, sign in pairs:
        if rate_group not in trace.group_names or level_group not in trace.group_names:
            continue
        a, b = trace.group_slice(rate_group).start + i, trace.group_slice(level_group).start + j
        with np.errstate(invalid="ignore", divide="ignore"):
            rate.append(y[:, a] / np.sqrt(s[:, a]))
            level.append(sign * y[:, b] / np.sqrt(s[:, b]))
        names.append((_output(model, rate_group, i), _output(model, level_group, j)))
        groups |= {rate_group, level_group}
        independent.append(level_group in witnesses)
    if not names:
        return None
    inputs = tuple(getattr(model, "kinematic_inputs", ()))
    channels = list(getattr(run, "input_channels", ()))
    named = [channels[k] if k < len(channels) else model.input_names[k] for k in inputs]
    what = f"{getattr(model, 'kinematic_input_words', 'model input')} (the model's input)"  # then " suspect: ..."
    stack = np.column_stack
    return KinematicEvidence(
        trace.t, names, stack(rate).astype(np.float32), stack(level).astype(np.float32), frozenset(groups), what,
        ", ".join(named), float(trace.dt), tuple(independent),
    )  # fmt: skip


def _output(model, group: str, index: int) -> str:
    spec = model.groups.get(group)
    output = spec.outputs[index] if spec is not None and index < len(spec.outputs) else str(index)
    return f"{group_words(group)} {output}"


def _z(values: np.ndarray) -> float:
    """mean x sqrt(M) of the finite values (0 without any)."""
    finite = values[np.isfinite(values)]
    return float(np.mean(finite, dtype=np.float64) * np.sqrt(finite.size)) if finite.size else 0.0


def input_suspect(evidence: KinematicEvidence | None, group: str | None, alarm: AlarmInterval) -> str | None:
    """The words of rule 6 when the pairs say the input is at fault during ``alarm`` (quoted for
    ``group``): "GNSS velocity v_down, GNSS position down and barometer altitude agree against its
    prediction (-35σ, -15σ, -16σ)" (the level's z times its pair's sign); None when rule 3 stands."""
    if evidence is None or group not in evidence.groups:
        return None
    rows = (evidence.t >= alarm.start - 1e-9) & (evidence.t <= alarm.end + 1e-9)
    span_s = max(float(alarm.end - alarm.start), evidence.dt)
    z_min = -float(ndtri(BUDGET_PER_HOUR * span_s / 3600.0 / 2.0))
    agree: dict[str, float] = {}  # each sensor's z, in the pairs' order
    confirmed = False  # by a pair whose level has a sensor of its own
    for p, (rate_name, level_name) in enumerate(evidence.names):
        zr, zl = _z(evidence.rate[rows, p]), _z(evidence.level[rows, p])
        if abs(zr) < z_min or abs(zl) < z_min:
            continue
        if np.sign(zr) != np.sign(zl):
            return None  # a fault of one of the pair's sensors
        agree.setdefault(rate_name, zr)
        agree.setdefault(level_name, zl)
        confirmed |= p < len(evidence.independent) and evidence.independent[p]
    if not agree:
        return None
    names = list(agree)
    sigmas = ", ".join(f"{significant(z)}σ" for z in agree.values())
    words = f"{', '.join(names[:-1])} and {names[-1]} agree against its prediction ({sigmas})"
    # one sensor measuring both (a GNSS receiver's velocity and position) agrees with itself when it
    # is wrong coherently, as a spoofer makes it: said, as nothing here tells the two apart
    return (
        words
        if confirmed
        else f"{words}; they come from one sensor, and its fault moving both together (a spoof) looks alike"
    )
