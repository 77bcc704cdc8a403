"""The health checks of logged events: IMU clipping, estimator faults, the autopilot's own errors,
topics that stopped arriving."""

from __future__ import annotations

import numpy as np

from logscan.detectors.health_checks import (
    COMBINED,
    ESTIMATOR,
    EVENT_TOPICS,
    FLAG,
    IMU,
    LEVELS,
    MAX_LOGGED_ERRORS,
    PREFIX,
    HealthChecks,
    _suffix,
)
from logscan.detectors.raw_topics import grid_steps, on_grid
from logscan.detectors.topic_clock import clock_period, lost_time
from logscan.log import logged_messages


class EventChecks(HealthChecks):
    """Clipping, estimator flags, logged errors, timeouts."""

    # --- 4. IMU clipping, 5. estimator faults ----------------------------------------------------
    def _flag_check(self, topics, topic: str, field: str, name_of) -> bool:
        ran = False
        for (t_name, instance), fields in sorted(topics.items()):
            if t_name != topic:
                continue
            channel = fields.get(field)
            name = name_of(instance)
            if channel is None:
                self._skipped[name] = f"{topic}_{instance} has no {field}"
                continue
            values = np.where(np.isfinite(channel.values), np.where(channel.values != 0, FLAG, 0.0), np.nan)
            ran |= self._add(name, f"{topic}_{instance}", channel.t, values, limit={field: "!= 0"})
        return ran

    def _clipping(self, topics) -> None:
        if not any(t in (COMBINED, IMU) for t, _ in topics):
            self._skipped["imu_clipping"] = f"no {COMBINED} or {IMU} topic"
            return
        self._flag_check(topics, COMBINED, "accelerometer_clipping", lambda i: f"{PREFIX}.imu_clipping{_suffix(i)}")
        self._flag_check(topics, IMU, "delta_velocity_clipping", lambda i: f"{PREFIX}.imu_clipping.imu{i}")

    def _estimator(self, topics) -> None:
        if not any(t == ESTIMATOR for t, _ in topics):
            self._skipped["estimator_fault"] = f"no {ESTIMATOR} topic"
            return
        self._flag_check(topics, ESTIMATOR, "filter_fault_flags", lambda i: f"{PREFIX}.estimator_fault{_suffix(i)}")
        failed = {}
        for (topic, instance), fields in sorted(topics.items()):
            channel = fields.get("gps_check_fail_flags") if topic == ESTIMATOR else None
            if channel is not None and channel.values.size:
                bits = np.bitwise_or.reduce(np.nan_to_num(channel.values).astype(np.int64))
                failed[f"{topic}_{instance}"] = {
                    "bits_ever_set": int(bits),
                    "share_of_samples": float(np.mean(channel.values != 0)),
                }
        if failed:
            self._result.info["gps_check_fail_flags"] = failed

    # --- 6. logged errors ------------------------------------------------------------------------
    def _logged_errors(self, metadata) -> None:
        messages = metadata.get("ulog.messages")
        name = f"{PREFIX}.logged_error"
        if messages is None:
            self._skipped[name] = "the log carries no logged messages (not a ULog)"
            return
        run = self._grid
        found = logged_messages(metadata, run.start_ns, LEVELS, limit=None)
        t_ns = np.array([m.t_ns for m in found], dtype=np.int64)
        statistic = np.nan_to_num(on_grid(run, t_ns, np.full(t_ns.size, FLAG)))
        landed = grid_steps(run, t_ns)[1] if found else np.zeros(0, bool)
        errors = [
            {"time": m.t, "level": m.level, "text": m.text, "on_grid": bool(on)}
            for m, on in zip(found[:MAX_LOGGED_ERRORS], landed.tolist())
        ]
        if run.n_steps:
            run_result = self._result
            run_result.add_statistic(run.t, name, statistic, upper=1.0, valid=np.ones(run.n_steps, bool), n_persist=1)
            self._checks[name] = {"source": "ulog.messages", "limit": {"levels": list(LEVELS)}, "n_persist": 1}
        self._result.info["logged_errors"] = errors

    # --- 7. sensor timeouts ----------------------------------------------------------------------
    def _silence(self, t_ns: np.ndarray, limit_ns: float, lost_ns: np.ndarray) -> np.ndarray:
        """At each grid step, the age of the topic's newest sample over ``limit_ns`` (over 1: a
        timeout, from the moment it began to the next sample, or to the end of the log for a
        topic that never reports again); NaN until its second sample: the first interval is not
        judged (PX4's logger writes a topic's latest sample when it subscribes, which can be
        older than the topic's rate says). ``lost_ns`` (per sample, NaN for none): the time the gap
        after that sample lost (`topic_clock.lost_time`); a gap that lost no more than the limit
        is a jitter, not a stop: its age is held at the lost time."""
        run = self._grid
        grid_ns = run.start_ns + np.round(np.asarray(run.t, dtype=np.float64) * 1e9)
        newest = np.searchsorted(t_ns, grid_ns, side="right") - 1
        age = grid_ns - t_ns[np.maximum(newest, 0)].astype(np.float64)
        lost = lost_ns[np.maximum(newest, 0)]
        jitter = lost <= limit_ns  # False where NaN: no gap judged there
        ratio = np.where(jitter, np.minimum(age, np.maximum(lost, 0.0)), age) / limit_ns
        ratio[newest < 1] = np.nan
        return ratio

    def _lost(self, t: np.ndarray, limit_ns: float, where: str) -> np.ndarray:
        """Per sample, the time the gap after it lost if that gap is over ``limit_ns`` (NaN
        elsewhere); a warning names the topic when such gaps lost no more than the limit (jitter)."""
        lost = np.full(t.size, np.nan)
        gaps = np.flatnonzero(np.diff(t) > limit_ns)
        lost[gaps] = lost_time(t, gaps, clock_period(t))
        jittered = gaps[lost[gaps] <= limit_ns]
        if jittered.size:
            longest = float(np.max(t[jittered + 1] - t[jittered])) / 1e9
            self._result.warnings.append(
                f"health: {where}'s timestamps jitter: {jittered.size} gap(s) over the timeout's "
                f"{limit_ns / 1e9:.3g} s (the longest {longest:.3g} s) lost no samples (the count after "
                "each caught up), so they are not timeouts"
            )
        return lost

    def _timeouts(self, topics, metadata) -> None:
        periods = float(self.timeout_periods)
        for (topic, instance), fields in sorted(topics.items()):
            if topic in EVENT_TOPICS:
                continue
            where = f"{topic}_{instance}"
            name = f"{PREFIX}.timeout.{where}"
            t = next(iter(fields.values())).t
            if t.size < 4:
                self._skipped[name] = f"{where}: fewer than 4 samples"
                continue
            t = np.sort(t)  # a jittered sensor's timestamps can go back in the log's order
            period = float(np.median(np.diff(t)))
            if not period > 0:
                self._skipped[name] = f"{where}: no sample period"
                continue
            limit = {"gap_s": periods * period / 1e9, "median_period_s": period / 1e9}
            lost = self._lost(t, periods * period, where)
            self._add_on_grid(name, where, self._silence(t, periods * period, lost), limit=limit, n_persist=1)
        dropouts = (metadata.get("ulog.log") or {}).get("dropouts")
        if dropouts not in (None, "0"):
            self._result.info["logging_dropouts"] = (
                f"{dropouts} logging dropout(s) in the log: a timeout may be data the logger lost, not a sensor"
            )
