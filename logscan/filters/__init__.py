"""Filters shared by every model-based detector: the numba EKF core and its trace."""

from logscan.filters.ekf import DivergenceEpisode, EkfTrace, run_ekf

__all__ = ["DivergenceEpisode", "EkfTrace", "run_ekf"]
