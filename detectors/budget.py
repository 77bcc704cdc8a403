"""The false-alarm budget as a demonstration: the rate a detector designs for so that a healthy run
of ``proof_hours`` hours shows its budget met (used by `nis` and `cusum`; docs/algorithms.md 1b)."""

from __future__ import annotations

from logscan.errors import ProfileError

# A demonstration of the budget: the exact (two-sided) Poisson interval's confidence, whose upper end
# must be within the budget, and the probability that a detector running at its design rate passes
# (the consumer's and the producer's risk of a fixed-length demonstration test, as in MIL-HDBK-781's
# plans: 2.5 % and 10 %).
PROOF_CONFIDENCE = 0.95
PROOF_PASS_PROBABILITY = 0.9


def design_rate(budget_per_hour: float, proof_hours: float | None) -> float:
    """False alarms per hour to design for, so that ``proof_hours`` healthy hours show the upper end
    of the rate's exact 95 % Poisson interval at or below ``budget_per_hour`` with probability 0.9.

    c = the most alarms whose upper end chi2.ppf(0.975, 2c + 2) / (2 T) stays within the budget;
    rate = chi2.ppf(0.1, 2c + 2) / (2 T), the rate at which P(at most c alarms in T hours) = 0.9.
    T = 100 h, budget 0.1/h: c = 3, rate 0.0174/h. None: the budget itself. A demonstration too
    short to ever show the budget (budget x T < 3.69, the upper end with no alarm) is refused when
    the detector is created (`check_proof`)."""
    from scipy.special import chdtri  # chdtri(d, q) = chi2.ppf(1 - q, d)

    if proof_hours is None:
        return float(budget_per_hour)
    hours = float(proof_hours)
    # the upper end of c alarms in T hours, against the budget (a relative 1e-12: at exactly
    # proof_shortest_hours the two sides differ by rounding)
    upper = lambda c: chdtri(2 * c + 2, (1.0 - PROOF_CONFIDENCE) / 2.0) / (2.0 * hours) / (1.0 + 1e-12)  # noqa: E731
    if upper(0) > budget_per_hour:
        raise ValueError(f"{hours:g} h cannot show a budget of {budget_per_hour:g} per hour")
    c = 0
    while upper(c + 1) <= budget_per_hour:  # a few steps: c grows like budget x T
        c += 1
    return float(chdtri(2 * c + 2, PROOF_PASS_PROBABILITY)) / (2.0 * hours)


def proof_shortest_hours(budget_per_hour: float) -> float:
    """The shortest demonstration that can show ``budget_per_hour``: no alarm, upper end = budget."""
    from scipy.special import chdtri

    return float(chdtri(2, (1.0 - PROOF_CONFIDENCE) / 2.0)) / (2.0 * budget_per_hour)


def check_proof(detector) -> None:
    """Refuse, at creation, a ``proof_hours`` too short to ever show the detector's budget."""
    if detector.proof_hours is None:
        return
    try:
        design_rate(float(detector.budget_per_hour), detector.proof_hours)
    except ValueError as exc:
        shortest = proof_shortest_hours(float(detector.budget_per_hour))
        raise ProfileError(
            f"detector {detector.name!r}: proof_hours: {exc}", hint=f"use at least {shortest:.4g} h, or null"
        ) from None
