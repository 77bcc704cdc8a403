"""Where the peak memory of one `logscan analyze` is: the peak RSS of each step of the pipeline.

Runs what `logscan analyze LOG -o REPORT --json SUMMARY` runs, in this process (`analyze_log` with
the series freed as they go and the report's innovations kept, the summary, the report), while a
thread samples the process's RSS (/proc/self/status) every 10 ms and books it to the step the
pipeline last announced (its progress messages: reading, aligning, filtering, each detector; the
observability verdict runs under "filtering", before the first detector). Prints one line per step,
in MiB (2**20 bytes), and the arrays still held by the analysis when the detectors are done.

    python bench/memory_phases.py LOG [LOG2]     # two lengths of one log: also the growth per log-hour
    python bench/memory_phases.py --blocks LOG   # block mode, as `logscan analyze LOG --no-report`
                                                 # runs it: the steps of every block booked together,
                                                 # and each block's peak

Each log is analysed in a forked child process, so that both start from the same memory.
"""

from __future__ import annotations

import sys
import tempfile
import threading
import time
from pathlib import Path

from logscan.memory import reuse_freed_arrays


def rss_mib() -> float:
    with open("/proc/self/status", encoding="ascii") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


class PhasePeaks:
    """The peak RSS booked to each announced step, in the order the steps came."""

    def __init__(self) -> None:
        self.phase = "start-up"
        self.peaks: dict[str, float] = {}
        self.done = False
        self.thread = threading.Thread(target=self._sample, daemon=True)
        self.thread.start()

    def step(self, message: str) -> None:
        self._book()
        self.phase = message

    def stop(self) -> None:
        self._book()
        self.done = True
        self.thread.join()

    def _book(self) -> None:
        self.peaks[self.phase] = max(self.peaks.get(self.phase, 0.0), rss_mib())

    def _sample(self) -> None:
        while not self.done:
            self._book()
            time.sleep(0.01)


def held_arrays(analysis) -> list[tuple[float, str]]:
    """(MiB, where) of the numpy arrays the analysis still holds, each buffer counted once."""
    import numpy as np

    seen: set[int] = set()
    found: list[tuple[float, str]] = []

    def walk(obj, where: str, depth: int) -> None:
        if id(obj) in seen or depth > 8 or isinstance(obj, type):
            return
        seen.add(id(obj))
        if isinstance(obj, np.ndarray):
            base = obj
            while isinstance(base.base, np.ndarray):
                base = base.base
            if id(base) not in seen or base is obj:
                seen.add(id(base))
                found.append((base.nbytes / 2**20, where))
            return
        items = obj.items() if isinstance(obj, dict) else enumerate(obj) if isinstance(obj, list | tuple) else ()
        for key, value in items:
            walk(value, f"{where}[{key!r}]", depth + 1)
        for key, value in getattr(obj, "__dict__", {}).items():
            walk(value, f"{where}.{key}", depth + 1)

    walk(analysis, "analysis", 0)
    return sorted(found, reverse=True)


def profile(path: str) -> tuple[dict[str, float], list[tuple[float, str]], float]:
    """The peak RSS per step of analysing ``path``, the arrays held after the detectors, the log's hours."""
    from logscan.pipeline import analyze_log

    reuse_freed_arrays()  # as the CLI does
    peaks = PhasePeaks()
    analysis = analyze_log(path, free_series=True, sensor_views=True, progress=peaks.step)
    held = held_arrays(analysis)
    peaks.step("summary")
    analysis.summary()
    peaks.step("release")
    analysis.prepared.release_series()
    from logscan.report.page import stage_report

    peaks.step("report")
    with tempfile.TemporaryDirectory() as tmp:
        stage_report(analysis.report_input(), str(Path(tmp) / "report.html"), plotlyjs="embed", token="bench")
        peaks.stop()
    return peaks.peaks, held, analysis.duration_s / 3600.0


def profile_blocks(path: str) -> tuple[dict[str, float], dict[str, float]]:
    """The peak RSS per step of analysing ``path`` in blocks (`analyze_blocked`, as `logscan
    analyze --no-report` does), each step's over every block, and each block's peak."""
    from logscan.pipeline.blocks import analyze_blocked

    reuse_freed_arrays()
    steps, blocks = PhasePeaks(), PhasePeaks()

    def step(message: str) -> None:
        block, _, what = message.partition(": ") if message.startswith("block ") else ("", "", message)
        steps.step(what)
        if block and block != blocks.phase:
            blocks.step(block)

    analysis = analyze_blocked(path, free_series=True, progress=step)
    steps.step("summary")
    blocks.step("summary")
    analysis.summary()
    steps.stop()
    blocks.stop()
    return steps.peaks, blocks.peaks


def in_child(path: str):
    """`profile` of ``path`` in a forked child process, so that each log starts from the same memory."""
    import multiprocessing

    with multiprocessing.get_context("fork").Pool(1) as pool:
        return pool.apply(profile, (path,))


def main(argv: list[str]) -> int:
    if argv[:1] == ["--blocks"] and len(argv) == 2:
        import multiprocessing

        with multiprocessing.get_context("fork").Pool(1) as pool:
            steps, blocks = pool.apply(profile_blocks, (argv[1],))
        print(f"{'step (every block)':<24}{'peak MiB':>10}")
        for name, mib in steps.items():
            print(f"{name:<24}{mib:10.0f}")
        print(f"\n{'block':<24}{'peak MiB':>10}")
        for name, mib in blocks.items():
            print(f"{name:<24}{mib:10.0f}")
        return 0
    if not 1 <= len(argv) <= 2:
        print(__doc__)
        return 2
    runs = [in_child(path) for path in argv]
    hours = [h for _, _, h in runs]
    print(
        f"{'step':<24}"
        + "".join(f"{f'{h:.2f} h, MiB':>16}" for h in hours)
        + ("  per log-hour" if len(runs) == 2 else "")
    )
    for step in runs[0][0]:
        values = [peaks.get(step, float("nan")) for peaks, _, _ in runs]
        slope = f"  {(values[1] - values[0]) / (hours[1] - hours[0]):12.0f}" if len(runs) == 2 else ""
        print(f"{step:<24}" + "".join(f"{v:16.0f}" for v in values) + slope)
    print(f"\narrays held after the detectors ({hours[-1]:.2f} h), over 1 MiB:")
    for mib, where in runs[-1][1]:
        if mib >= 1.0:
            print(f"  {mib:8.1f}  {where}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
