"""Detectors of logscan (installed as ``logscan.detectors``): the contract, the registry, the built-ins.

The contract lives in ``logscan.detectors.base`` (Detector, DetectorResult, Band), the registry in
``logscan.detectors.registry`` (Registry, default_registry, BUILTIN_DETECTORS); one module per
built-in detector.
"""

from logscan.detectors.base import Band, Detector, DetectorResult

__all__ = ["Band", "Detector", "DetectorResult"]
