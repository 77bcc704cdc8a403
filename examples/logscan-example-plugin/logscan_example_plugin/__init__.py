"""Example logscan plugin: `range_check`, a physical-range check on measurement channels.

It shows the whole detector API a plugin needs: parameters with defaults, optional training
(trailing-underscore attributes, JSON state), running on an aligned run, and the shared alarm
logic through `DetectorResult.add_statistic`.
"""

from __future__ import annotations

import numpy as np

from logscan.detectors.base import Detector, DetectorResult
from logscan.detectors.params import Boolean, Interval
from logscan.errors import NotTrainedError, ProfileError

__all__ = ["RangeCheckDetector"]


class RangeCheckDetector(Detector):
    """Flags measurement samples outside their allowed range (configured, trained or the model's)."""

    name = "range_check"
    defaults = {
        "limits": {},  # channel -> [low, high]; wins over trained and model ranges
        "margin": 0.5,  # training: widen the healthy [min, max] by this fraction of its span
        "use_model_ranges": True,  # fall back to the model's physical sensor ranges
        "n_persist": 1,
        "hold_off_s": 0.0,
    }
    # types and ranges, checked when the detector is created (before any log is read)
    parameter_constraints = {
        "margin": [Interval(float, 0, None)],
        "use_model_ranges": [Boolean()],
        "n_persist": [Interval(int, 1, None)],
        "hold_off_s": [Interval(float, 0, None)],
    }
    trained_attributes = ("limits_",)

    def check_params(self) -> None:
        # the declared constraints first, then what relates values to each other
        super().check_params()
        if not isinstance(self.limits, dict):
            raise ProfileError("range_check: limits must be a table of channel = [low, high]")
        for channel, pair in self.limits.items():
            if not (isinstance(pair, (list, tuple)) and len(pair) == 2 and pair[0] <= pair[1]):
                raise ProfileError(f"range_check: limits[{channel!r}] must be [low, high] with low <= high")

    def _fit(self, runs, traces, **context) -> None:
        # healthy [min, max] per channel over every fresh sample of every run, widened by margin
        lows: dict[str, float] = {}
        highs: dict[str, float] = {}
        for run in runs:
            for group in run.groups.values():
                z = group.z[group.fresh]
                for j, channel in enumerate(group.channels):
                    values = z[:, j][np.isfinite(z[:, j])]
                    if values.size:
                        lows[channel] = min(lows.get(channel, np.inf), float(values.min()))
                        highs[channel] = max(highs.get(channel, -np.inf), float(values.max()))
        self.limits_ = {}
        for channel in lows:
            pad = self.margin * (highs[channel] - lows[channel])
            self.limits_[channel] = [lows[channel] - pad, highs[channel] + pad]

    def _limits_for(self, group, model) -> list[tuple[float, float] | None]:
        spec = None
        if self.use_model_ranges and model is not None:
            spec = getattr(model, "groups", {}).get(group.name)
            if spec is not None and len(spec.range_lo) != len(group.channels):
                spec = None
        out = []
        for j, channel in enumerate(group.channels):
            if channel in self.limits:
                out.append(tuple(self.limits[channel]))
            elif channel in getattr(self, "limits_", {}):
                out.append(tuple(self.limits_[channel]))
            elif spec is not None:
                out.append((spec.range_lo[j], spec.range_hi[j]))
            else:
                out.append(None)
        return out

    def _run(self, run, trace, **context) -> DetectorResult:
        result = self.new_result()
        checked, unchecked = 0, []
        for group in run.groups.values():
            for j, limits in enumerate(self._limits_for(group, context.get("model"))):
                channel = group.channels[j]
                if limits is None:
                    unchecked.append(channel)
                    continue
                result.add_statistic(
                    run.t,
                    channel,
                    group.z[:, j],
                    upper=limits[1],
                    lower=limits[0],
                    valid=group.fresh,
                    n_persist=self.n_persist,
                    hold_off_s=self.hold_off_s,
                )
                checked += 1
        if checked == 0:
            raise NotTrainedError(
                "range_check has no range for any channel",
                hint="set `limits`, run `logscan train` on healthy logs, or use a model with sensor ranges",
            )
        if unchecked:
            result.warnings.append(f"range_check: no range for {len(unchecked)} channel(s): {', '.join(unchecked)}")
        result.info.update(checked_channels=checked, unchecked_channels=unchecked)
        return result
