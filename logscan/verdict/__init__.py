"""What a log is judged to be: its incidents, what was checked (coverage), suppressions and
baselines, what a fault could not show (observability), and scores against ground truth."""
