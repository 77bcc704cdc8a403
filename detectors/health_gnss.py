"""The health checks of the GNSS receiver: fix, accuracy against PX4's own limits, accuracy jumps,
jamming."""

from __future__ import annotations

import numpy as np

from logscan.detectors.accuracy_jump import accuracy_jump
from logscan.detectors.health_checks import (
    ESTIMATOR,
    FLAG,
    GNSS_CHECKS_FAILING_S,
    GPS,
    PREFIX,
    REQ_EPH_M,
    REQ_EPV_M,
    SENSOR_GPS,
    HealthChecks,
    _suffix,
)
from logscan.detectors.raw_topics import in_span
from logscan.detectors.raw_topics import log_parameter as _parameter


def _px4_gnss_passing(topics, t_ns: np.ndarray) -> np.ndarray | None:
    """At each time: whether PX4's own GNSS checks (``estimator_status_0.gps_check_fail_flags``
    all clear) passed within the last GNSS_CHECKS_FAILING_S, so PX4 did not call them failing;
    None when the log lacks the flags. PX4 judges its own receiver values, with its own filtering:
    where it saw a pass, a reading over the limit in ``vehicle_gps_position`` is not a fault."""
    channel = topics.get((ESTIMATOR, 0), {}).get("gps_check_fail_flags")
    if channel is None or not channel.values.size:
        return None
    t = np.asarray(channel.t)
    # failing is 5 s of failures seen: the log's first flags count as the latest pass (PX4's timer
    # before the log started is unknown), and before them nothing is known to fail
    pass_t = np.union1d(t[:1], t[np.nan_to_num(channel.values) == 0])
    latest = np.searchsorted(pass_t, t_ns, side="right") - 1
    last_pass = pass_t[np.maximum(latest, 0)]
    return (latest < 0) | ((np.asarray(t_ns) - last_pass) < GNSS_CHECKS_FAILING_S * 1e9)


class GnssChecks(HealthChecks):
    """GNSS."""

    # --- 2. GNSS ---------------------------------------------------------------------------------
    def _gnss(self, topics, parameters, armed) -> None:
        topic = GPS if any(t == GPS for t, _ in topics) else SENSOR_GPS
        found = sorted(i for t, i in topics if t == topic)
        if not found:
            self._skipped["gnss"] = f"no {GPS} or {SENSOR_GPS} topic"
            return
        eph_limit, eph_from = _parameter(parameters, "EKF2_REQ_EPH") or (REQ_EPH_M, "default")
        epv_limit, epv_from = _parameter(parameters, "EKF2_REQ_EPV") or (REQ_EPV_M, "default")
        accuracy = (("eph", eph_limit, eph_from), ("epv", epv_limit, epv_from))
        for instance in found:
            self._one_gnss(topics, topic, instance, accuracy, armed)

    def _one_gnss(self, topics, topic: str, instance: int, accuracy, armed) -> None:
        """The checks of one receiver: its fix, its accuracy (``accuracy``: (field, limit in m, where
        the limit comes from) for eph and epv) and accuracy jumps while 3D-fixed, its jamming."""
        fields = topics[(topic, instance)]
        where = f"{topic}_{instance}"
        sfx = _suffix(instance)
        any_channel = next(iter(fields.values()))
        t = any_channel.t
        px4_passing = _px4_gnss_passing(topics, t)
        gate = np.ones(t.size, bool) if armed is None else armed[1](t)
        while_ = "armed" if armed is not None else "always (arming state unknown)"
        fixed = self._gnss_fix(fields, where, sfx, t, gate, while_)
        for field, limit, source in accuracy:
            name = f"{PREFIX}.gnss_{field}{sfx}"
            if not fixed.any():  # judged while 3D-fixed only: the line above says it
                continue
            channel = fields.get(field)
            if channel is None or not np.array_equal(channel.t, t):
                self._skipped[name] = f"{where} has no {field}"
                continue
            values = np.where(gate & fixed, channel.values / limit, np.nan)
            if px4_passing is not None:  # PX4's own checks passed within 5 s: not failing
                values = np.where(px4_passing, np.minimum(values, 1.0), values)
            self._add(
                name,
                where,
                t,
                values,
                limit={"m": limit, "from": source, "while": f"{while_}, 3D fix", "for_s": GNSS_CHECKS_FAILING_S},
                why=f" ({while_}, 3D fix)",
                # PX4's own pass/fail timer, when logged, already waited the 5 s
                min_duration_s=None if px4_passing is not None else GNSS_CHECKS_FAILING_S,
            )
        if fixed.any():  # judged while 3D-fixed only, as eph / epv
            self._accuracy_jumps(fields, where, sfx, fixed, gate, f"{while_}, 3D fix")
        jam = fields.get("jamming_indicator")
        name = f"{PREFIX}.gnss_jamming{sfx}"
        if jam is None or not np.array_equal(jam.t, t):
            self._skipped[name] = f"{where} has no jamming_indicator"
        else:
            values = np.where(gate, jam.values / float(self.jamming_limit), np.nan)
            limit = {"indicator": float(self.jamming_limit), "while": while_}
            self._add(name, where, t, values, limit=limit, why=f" ({while_})")

    def _gnss_fix(self, fields, where: str, sfx: str, t, gate, while_: str) -> np.ndarray:
        """Whether the receiver is 3D-fixed at each of its times ``t`` (all when fix_type is absent),
        and ``health.gnss_fix``: a fix below 3D, judged where ``gate`` after the first 3D fix."""
        fixed = np.ones(t.size, bool)  # 3D-fixed now (all when fix_type is absent)
        fix = fields.get("fix_type")
        if fix is not None and np.array_equal(fix.t, t):
            three_d = fix.values >= 3
            first = np.flatnonzero(three_d)
            inside = in_span(self._grid, t)
            if inside.any() and not three_d[inside].any():
                self._unmonitored.append(self._no_fix_reason(where, fix.values[inside]))
                fixed = np.zeros(t.size, bool)
            elif first.size == 0:
                self._skipped[f"{PREFIX}.gnss_fix{sfx}"] = f"{where}: no 3D fix in the log"
                fixed = three_d
            else:
                after = np.arange(t.size) >= first[0]
                flag = np.where(three_d, 0.0, FLAG)
                self._add(
                    f"{PREFIX}.gnss_fix{sfx}",
                    where,
                    t,
                    np.where(after & gate, flag, np.nan),
                    limit={
                        "fix_type_below": 3,
                        "after_s": (t[first[0]] - self._grid.start_ns) / 1e9,
                        "while": while_,
                    },
                    why=f" ({while_}, after the first 3D fix)",
                )
                fixed = three_d
        else:
            self._skipped[f"{PREFIX}.gnss_fix{sfx}"] = f"{where} has no fix_type"
        return fixed

    def _no_fix_reason(self, where: str, judged_fix: np.ndarray) -> str:
        """Why the GNSS is not checked: no 3D fix in ``judged_fix`` (its fix_type where judged). The
        best fix is the judged samples' own: a window before the first 3D fix must not quote a fix
        the log only reaches later."""
        best = f"at most {int(np.nanmax(judged_fix))}" if np.isfinite(judged_fix).any() else "never set"
        if self._grid.window is None:
            return f"GNSS: no 3D fix all flight ({where}.fix_type {best})"
        # a window's checks are led in before it (logscan/pipeline/raw_lead.py): judged there too
        return f"GNSS: no 3D fix over the window ({where}.fix_type {best} while judged)"

    def _accuracy_jumps(self, fields, where: str, sfx: str, fixed, gate, while_: str) -> None:
        """``health.gnss_accuracy_jump.<field>``: each reported accuracy over ``accuracy_jump``
        times its median over the 3D-fixed reports before it (detectors/accuracy_jump.py), judged
        where ``gate`` and ``fixed``. The median takes the reports before arming too: a jump just
        after arming is judged against the level the receiver had then."""
        for field in ("eph", "epv", "s_variance_m_s"):
            channel = fields.get(field)
            name = f"{PREFIX}.gnss_accuracy_jump.{field}{sfx}"
            if channel is None or channel.t.shape != fixed.shape:
                self._skipped[name] = f"{where} has no {field}"
                continue
            valid = np.where(fixed, channel.values, np.nan)  # a report without a 3D fix is no level
            ratio = accuracy_jump(channel.t, valid, float(self.accuracy_window_s), judged=gate & fixed)
            limit = {"times_recent_median": float(self.accuracy_jump), "window_s": float(self.accuracy_window_s)}
            limit["while"] = while_
            self._add(name, where, channel.t, ratio / float(self.accuracy_jump), limit=limit, why=f" ({while_})")
