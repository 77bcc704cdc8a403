"""`merge_spans` (the shaded spans of a figure): at most MAX_SPANS, covering every span given, also
when asked to merge nothing (no width, no gap: the page's ground-truth events), which once looped
for ever on a log of more than MAX_SPANS faults."""

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
