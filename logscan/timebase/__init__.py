"""A log's time base: its clock (UTC from GNSS where it has one) and the sanity of its timestamps."""
