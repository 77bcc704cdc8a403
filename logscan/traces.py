"""The shared EKF's per-step trace (what every model-based detector reads) and its summary.

`EkfTrace` holds the filter's output arrays; `divergence_episodes` groups the diverged steps;
`EkfTrace.summary` gives the JSON-ready counts.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from logscan.errors import ModelError


@dataclass
class DivergenceEpisode:
    """Diverged steps up to the next successful update (first step, last step, count)."""

    start_step: int
    end_step: int
    n_steps: int
    t_start: float
    t_end: float


@dataclass
class EkfTrace:
    """Per-step output of the shared EKF (N grid steps, n states, G groups, m_total = sum m_g).

    Group g's measurement columns are `group_offsets[g] : group_offsets[g] + group_sizes[g]`
    (`group_slice(name)`). Arrays with NaN mean "not updated at this step".
    """

    model_name: str
    state_names: list[str]
    group_names: list[str]
    group_offsets: np.ndarray  # (G,) int
    group_sizes: np.ndarray  # (G,) int
    t: np.ndarray  # (N,)
    dt: float
    x_prior: np.ndarray  # (N, n)
    x_post: np.ndarray  # (N, n)
    P_prior_diag: np.ndarray  # (N, n) float32
    P_post_diag: np.ndarray  # (N, n) float32
    # (N, m_total) float32 innovation z - h(x_prior), NaN where not tested (`tested`; None: not kept)
    y: np.ndarray | None
    S_diag: np.ndarray | None  # (N, m_total) float32 diagonal of S, NaN where not tested (None: not kept)
    nis: np.ndarray  # (N,) y^T S^-1 y over the stacked update, NaN without update
    nis_group: np.ndarray  # (N, G) y_g^T S_gg^-1 y_g per group, NaN where not tested
    m_k: np.ndarray  # (N,) int, measurements in the update (0: none)
    gain_norm: np.ndarray  # (N,) Frobenius norm of K, NaN without update
    updated: np.ndarray  # (N, G) bool, group used in the update
    rejected: np.ndarray  # (N, G) bool, fresh sample non-finite or outside the physical range
    seeded: np.ndarray  # (N, G) bool, sample used to (re-)seed directly observed states
    diverged: np.ndarray  # (N,) bool, divergence detected at this step (filter restarted)
    input_held: np.ndarray  # (N,) bool, non-finite input replaced by the last finite one
    Q: np.ndarray  # (n, n) process noise used
    R: np.ndarray  # (m_total, m_total) block-diagonal measurement noise used
    P_prior: np.ndarray | None = None  # (N, n, n) when full_P
    P_post: np.ndarray | None = None  # (N, n, n) when full_P
    S: np.ndarray | None = None  # (N, m_total, m_total) padded with NaN, when store_S
    K: np.ndarray | None = None  # (N, n, m_total) padded with NaN, when store_gain
    # (N,) the encoded check's predicted variance CV K S K^T CV^T, 0 where not updated, when asked
    # (`logscan.needs.CodedVariance`)
    ex_variance: np.ndarray | None = None
    divergence_episodes: list[DivergenceEpisode] = field(default_factory=list)

    @property
    def n_steps(self) -> int:
        return int(self.t.size)

    @property
    def tested(self) -> np.ndarray:
        """(N, G) bool: the group's sample was tested against the prediction: used in the update, or
        left out by the group's outlier gate, its innovation and NIS kept (docs/algorithms.md 8.4)."""
        return self.updated | np.isfinite(self.nis_group)

    def group_index(self, name: str) -> int:
        try:
            return self.group_names.index(name)
        except ValueError:
            raise ModelError(
                f"the trace has no group {name!r}", hint="groups: " + ", ".join(self.group_names)
            ) from None

    def group_slice(self, name: str) -> slice:
        g = self.group_index(name)
        o = int(self.group_offsets[g])
        return slice(o, o + int(self.group_sizes[g]))

    def summary(self, first: int = 0) -> dict:
        """JSON-ready counts: updates, rejections and seeds per group, divergence, mean NIS; of the
        steps from ``first`` on (a block's own, after its lead-in)."""
        rows = slice(int(first), self.n_steps)
        nis, updated = self.nis_group[rows], self.updated[rows]
        # NIS near float's maximum (a value of 1e308 let through) add up beyond it: the mean is inf
        with np.errstate(invalid="ignore", over="ignore"):
            mean_nis = {
                g: float(np.nanmean(np.where(updated[:, i], nis[:, i], np.nan))) if updated[:, i].any() else None
                for i, g in enumerate(self.group_names)
            }
        return {
            "steps": self.n_steps - rows.start,
            "updates": dict(zip(self.group_names, updated.sum(axis=0).tolist())),
            "rejected": dict(zip(self.group_names, self.rejected[rows].sum(axis=0).tolist())),
            "seeded": dict(zip(self.group_names, self.seeded[rows].sum(axis=0).tolist())),
            "inputs_held": int(self.input_held[rows].sum()),
            "divergence_episodes": sum(1 for e in self.divergence_episodes if e.end_step >= rows.start),
            "diverged_steps": int(self.diverged[rows].sum()),
            "mean_nis": mean_nis,
        }


def divergence_episodes(t: np.ndarray, diverged: np.ndarray, m_k: np.ndarray) -> list[DivergenceEpisode]:
    """Group diverged steps into episodes: an episode ends at the next successful update."""
    steps = np.flatnonzero(diverged)
    if steps.size == 0:
        return []
    successes = np.cumsum((m_k > 0) & ~diverged)
    new = np.ones(steps.size, dtype=bool)
    new[1:] = successes[steps[1:]] > successes[steps[:-1]]
    starts = np.flatnonzero(new)
    ends = np.append(starts[1:], steps.size) - 1
    return [
        DivergenceEpisode(int(steps[a]), int(steps[b]), int(b - a + 1), float(t[steps[a]]), float(t[steps[b]]))
        for a, b in zip(starts, ends)
    ]
