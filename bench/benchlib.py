"""What several benchmark scripts share: simulating a log, timing the best of n runs, and printing a
regenerated table (and rewriting its marked block of a documentation page)."""

from __future__ import annotations

import os
import time


def best_of(n: int, run, clock=time.perf_counter) -> float:
    """The shortest of ``n`` times of ``run()`` on ``clock`` (wall time; `time.process_time`: this
    process's CPU time), seconds."""
    times = []
    for _ in range(n):
        start = clock()
        run()
        times.append(clock() - start)
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


def simulate_log(model: str, path: str, *args: str) -> str:
    """``logscan simulate MODEL ARGS -q -o PATH`` in this process; RuntimeError when it fails."""
    from logscan.cli.main import main

    try:
        main(["simulate", model, *args, "-q", "-o", path])
    except SystemExit as exc:
        if exc.code not in (0, None):
            raise RuntimeError(f"logscan simulate {model} {' '.join(args)} exited {exc.code}") from None
    return path


def publish(text: str, write_docs: bool, path: str, begin: str, end: str) -> None:
    """Print a benchmark's table; with ``write_docs``, also put it between its page's markers."""
    print(text)
    if write_docs:
        write_doc_block(path, begin, end, text)


def installed_environment(**extra: str) -> dict[str, str]:
    """The environment of a CLI run as an installed logscan sees it: Python's bytecode cache on
    (pip compiles it at install; a sandbox's PYTHONDONTWRITEBYTECODE=1 would add 0.3 s of source
    compiling to every run), plus ``extra``."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    return env | extra
