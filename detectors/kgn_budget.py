"""KGN's threshold rho sized for the false-alarm budget (docs/algorithms.md section 3, "rho from the
budget").

An alarm starts where ``n_persist`` consecutive judged windows all exceed rho, on any group: the
alarm statistic of judged window w is h(w) = min over the n_persist judged windows from w of g,
g = the largest group statistic (max over the groups of max over their columns of d_j). Its tail beyond the
training's reach is modelled, not taken from the training maximum (which new data exceeds):

- Tail model: peaks over a threshold, the generalised Pareto law with shape 0 (exponential
  excesses). u = the (1 - ``TAIL_SHARE``) quantile of the training h; the excesses over u have
  scale sigma. Shape 0 because a shape estimated from a few dozen excesses is too uncertain to use,
  and it bounds the tail of a Gaussian-like statistic from above.
- Margins for the estimates, as `detectors.atfm_budget`: the exceedance probability p_u is the upper
  end of the exact 95 % Poisson interval of the k excesses among n windows
  (chi2.ppf(0.975, 2k + 2) / (2 n)), the scale the upper end of its 95 % interval (the sum of k
  exponential excesses is Gamma(k, sigma): sigma_up = 2 sum / chi2.ppf(0.025, 2k)).
- The budget, as `nis`: per window, P(h > rho) <= alpha = rate_design / (3600 / window_s)
  (`detectors.budget.design_rate`), so rho = u + sigma_up ln(p_u / alpha); never below the
  training's largest h (the budget is not a reason to alarm on training data).
"""

from __future__ import annotations

import math

import numpy as np

TAIL_SHARE = 0.1  # the share of training windows whose excesses fit the tail
CONFIDENCE = 0.95
MIN_EXCESSES = 5  # fewer: no tail fit; rho is the training maximum + 1 (the prototype's rule), said so


def alarm_statistic(g: np.ndarray, n_persist: int) -> np.ndarray:
    """h = min(g[i], ..., g[i + n_persist - 1]) over the judged windows of one run (the finite
    entries of ``g``, NaN: not judged) taken in order: the shared alarm logic skips samples it does
    not judge, so they neither raise nor break a run of exceedances (`logscan.alarms`)."""
    g = np.asarray(g, dtype=np.float64)
    g = g[np.isfinite(g)]
    n = max(int(n_persist), 1)
    if g.size < n:
        return np.zeros(0)
    return np.min(np.stack([g[i : g.size - n + 1 + i] for i in range(n)]), axis=0)


def budget_rho(h: np.ndarray, alpha: float) -> dict:
    """rho for the training alarm statistics ``h`` (finite values) and the per-window probability
    ``alpha``, with the fit's figures (see the module docstring)."""
    from scipy.special import chdtri  # chdtri(d, q) = chi2.ppf(1 - q, d)

    h = np.sort(np.asarray(h, dtype=np.float64)[np.isfinite(h)])
    n = int(h.size)
    worst = float(h[-1]) if n else 0.0
    u = float(np.quantile(h, 1.0 - TAIL_SHARE)) if n else 0.0
    excess = h[h > u] - u
    k = int(excess.size)
    if k < MIN_EXCESSES:
        return {"rho": worst + 1.0, "rule": "training maximum + 1 (too few windows for a tail fit)", "windows": n}
    p_up = float(chdtri(2 * k + 2, (1.0 - CONFIDENCE) / 2.0)) / (2.0 * n)
    sigma_up = 2.0 * float(excess.sum()) / float(chdtri(2 * k, (1.0 + CONFIDENCE) / 2.0))
    rho = u + sigma_up * math.log(max(p_up / alpha, 1.0))
    return {
        "rho": max(rho, worst),
        "rule": "budget (exponential tail)",
        "windows": n,
        "u": u,
        "p_u": p_up,
        "sigma": sigma_up,
        "alpha": alpha,
        "training_max": worst,
    }
