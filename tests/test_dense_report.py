"""A report of a log alarming all day (2,015 incidents, 1,728 truth events): `merge_spans` (the
shaded spans of a figure) stays within MAX_SPANS and covers every span given, also when asked to
merge nothing (no width, no gap: the ground-truth events), which once looped for ever; the verdict
names only the first incidents."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from logscan.report.figures import MAX_SPANS, merge_spans

SPAN = st.tuples(st.floats(0, 1e5), st.floats(0, 100)).map(lambda s: (s[0], s[0] + s[1]))


def test_a_thousand_disjoint_events_with_no_gap_asked_are_merged_within_the_bound():
    """1,728 faults of 4 s, every 50 s in 24 flights of an hour, 400 s apart: one span per flight."""
    spans = [(4000.0 * (k // 72) + 50.0 * (k % 72), 4000.0 * (k // 72) + 50.0 * (k % 72) + 4.0) for k in range(1728)]
    merged = merge_spans(spans, 0.0, 0.0)
    assert merged == [(4000.0 * f, 4000.0 * f + 50.0 * 71 + 4.0) for f in range(24)]


@settings(max_examples=200, deadline=None)
@given(st.lists(SPAN, max_size=400), st.sampled_from([0.0, 0.5]), st.sampled_from([0.0, 1.0]))
def test_merged_spans_cover_every_span_and_stay_within_the_bound(spans, min_width, min_gap):
    merged = merge_spans(spans, min_width, min_gap)
    assert len(merged) <= MAX_SPANS
    starts = np.array([m[0] for m in merged])
    for start, end in spans:
        i = np.searchsorted(starts, start, side="right") - 1
        assert i >= 0 and merged[i][0] <= start and end <= merged[i][1]


def test_the_verdict_names_the_first_incidents_and_counts_the_rest():
    """A day of 2,015 incidents filled the report's first screen with its verdict list: it names
    the first VERDICT_INCIDENTS and says how many more the Incidents table holds."""
    from types import SimpleNamespace

    from logscan.report.page_rows import VERDICT_INCIDENTS, verdict_lines

    heads = [SimpleNamespace(line=lambda clock, k=k: f"incident {k}") for k in range(2015)]
    report = SimpleNamespace(clock=None, results=[])
    lines = verdict_lines(report, heads, [])
    assert lines[:VERDICT_INCIDENTS] == [f"incident {k}" for k in range(VERDICT_INCIDENTS)]
    assert lines[VERDICT_INCIDENTS:] == [f"... and {2015 - VERDICT_INCIDENTS} more incidents: see the Incidents table"]
    assert verdict_lines(report, heads[:3], []) == ["incident 0", "incident 1", "incident 2"]
