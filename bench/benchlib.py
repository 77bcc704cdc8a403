"""What several benchmark scripts share: timing the best of n runs, and rewriting a marked block of
a documentation page with a regenerated table."""

from __future__ import annotations

import time


def best_of(n: int, run) -> float:
    """The shortest of ``n`` wall times of ``run()``, seconds."""
    times = []
    for _ in range(n):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return min(times)


def write_doc_block(path: str, begin: str, end: str, text: str) -> None:
    """Replace what lies between the ``begin`` and ``end`` markers of the page at ``path``."""
    with open(path, encoding="utf-8") as fh:
        doc = fh.read()
    if begin not in doc or end not in doc:
        raise SystemExit(f"{path} has no {begin} ... {end} block")
    head, rest = doc.split(begin, 1)
    _, tail = rest.split(end, 1)
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(head + begin + "\n" + text + "\n" + end + tail)
