"""Filters shared by every model-based detector: the numba EKF core and its trace."""

from logscan.filters.ekf import run_ekf
from logscan.traces import DivergenceEpisode, EkfTrace

__all__ = ["DivergenceEpisode", "EkfTrace", "run_ekf"]
