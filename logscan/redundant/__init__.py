"""Redundant sensors: the adaptive transient fault model (tfm: training into speed lookup tables,
weak and strong inconsistency) and the fusion of redundant readings."""
