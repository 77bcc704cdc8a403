"""logscan: offline model-based fault and attack detection for drone and ground-vehicle logs."""

__version__ = "0.1.0"
