"""Detectors of logscan (installed as ``logscan.detectors``) and their registry."""
