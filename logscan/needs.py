"""What a detector asks of the pipeline: which filters to run and which parts of their traces to keep.

A detector declares its needs (`Detector.needs`); the pipeline takes the union over the detectors it
runs and runs each needed filter exactly once, keeping only the trace parts someone asked for
(the EKF's gain K and innovation covariance S are large: (N, n, m) and (N, m, m)).

Detectors ask, the pipeline filters: no detector runs a filter itself. One that must filter runs of
its own making while it trains (KGN's blindness probe re-filters a healthy run with a fault added)
declares those filters as ``probes``; training then passes its `fit` the context keyword
``refilter``, ``refilter(filter name, aligned run) -> trace``: that filter run by the pipeline on the
given run, with the model and trace parts it uses for the log (`logscan.pipeline.stages.refilter_for`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field


@dataclass(frozen=True)
class CodedVariance:
    """An EKF trace part: the predicted variance of the encoded state check e_x = CV_k (x_prior_k -
    x_post_k) at every update, CV_k K_k S_k K_k^T CV_k^T (docs/algorithms.md section 1.2). The
    filter computes it at each step from that step's K and S, so neither is kept nor filtered
    again; the coding vector CV_k is the detector's (Lemma 1 with the sum bound: 1 / max(sigma_i,
    sigma_floor * state scale_i), scaled down so that its sum stays within r_max)."""

    sigma_floor: float
    r_max: float


Part = str | CodedVariance  # a trace part a detector may ask a filter for


@dataclass(frozen=True)
class Needs:
    """filters: filter name -> the optional trace parts to keep (empty: the filter's default trace).
    The EKF's optional parts: "K" (gain), "S" (full innovation covariance), "P" (full covariance),
    "y" (the innovations y and the diagonal of S per step), and a `CodedVariance` (the encoded
    check's predicted variance per step, computed inside the filter)."""

    filters: Mapping[str, frozenset[Part]] = field(default_factory=dict)
    # the filters `fit` re-runs on runs it makes (`refilter`, see the module docstring)
    probes: frozenset[str] = frozenset()

    @classmethod
    def of(cls, *, probes: Iterable[str] = (), **filters: Iterable[Part]) -> Needs:
        """``Needs.of(ekf=("K", "S"))``: the EKF with its gain and innovation covariance;
        ``Needs.of(ekf=("K",), probes=("ekf",))``: and the EKF again, with its gain, on runs `fit` makes."""
        return cls({name: frozenset(parts) for name, parts in filters.items()}, frozenset(probes))

    def __or__(self, other: Needs) -> Needs:
        merged = {name: frozenset(parts) for name, parts in self.filters.items()}
        for name, parts in other.filters.items():
            merged[name] = merged.get(name, frozenset()) | frozenset(parts)
        return Needs(merged, self.probes | other.probes)

    def parts(self, filter_name: str) -> frozenset[Part]:
        return frozenset(self.filters.get(filter_name, ()))

    def wants(self, filter_name: str) -> bool:
        return filter_name in self.filters


def union(needs: Iterable[Needs]) -> Needs:
    total = Needs()
    for item in needs:
        total = total | item
    return total
