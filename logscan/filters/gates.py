"""The outlier gates of the shared EKF's measurement groups (docs/algorithms.md 8.4, "The outlier
gate"): the NIS above which a gated group's sample is kept for the detectors, not the update."""

from __future__ import annotations

import numpy as np

# An outlier gate lets a consistent group's sample through but once in this many hours of its
# samples: the false-alarm budget's demonstration length (`nis` proof_hours, docs/algorithms.md 1b)
GATE_HOURS = 100.0


def outlier_gates(specs, rates: list[float | None], fresh: np.ndarray, dt: float) -> np.ndarray:
    """(G,) each group's outlier gate (docs/algorithms.md 8.4): for a `GroupSpec.gated` group the
    NIS a consistent group's sample exceeds with probability 1 / (its samples in GATE_HOURS), its
    chi-square point with the group's size as degrees of freedom; inf for the others. A group's
    rate is the profile's (``rates``: the whole log's, so a block of a long log gets the log's
    gate), else its fresh samples' over the run."""
    from scipy.special import chdtri  # chdtri(d, q) = chi2.ppf(1 - q, d)

    gates = np.full(len(specs), np.inf)
    duration = max(fresh.shape[0] * float(dt), float(dt))
    for g, spec in enumerate(specs):
        rate = rates[g] or np.count_nonzero(fresh[:, g]) / duration
        if spec.gated and rate > 0:
            gates[g] = float(chdtri(spec.size, 1.0 / (rate * 3600.0 * GATE_HOURS)))
    return gates
