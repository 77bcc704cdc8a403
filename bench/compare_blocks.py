"""How a log's block-mode analysis differs from its analysis at once (docs/algorithms.md section 8.1b).

    logscan analyze LOG --block-s 0 --no-report --json whole.json
    logscan analyze LOG --block-s 900 --no-report --json blocks.json
    python bench/compare_blocks.py whole.json blocks.json --block-s 900

Prints both verdicts and exit codes, the incidents of each, and every alarm (detector, statistic,
start, end) found by one run only or with other times, each marked with its distance to the nearest
block border (a multiple of --block-s). Exits 1 when an alarm differs further than --near seconds
(default 10 s: the longest detector window plus the lead-in's settling) from every border.
"""

from __future__ import annotations

import argparse
import json
import sys


def _alarms(log: dict) -> dict[tuple[str, str], list[tuple[float, float]]]:
    out: dict[tuple[str, str], list[tuple[float, float]]] = {}
    for result in log["detectors"]:
        for alarm in result["alarms"]:
            out.setdefault((result["detector"], alarm["signal"]), []).append((alarm["start"], alarm["end"]))
    return out


def _to_border(t: float, block_s: float) -> float:
    return abs(t - round(t / block_s) * block_s)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("whole")
    parser.add_argument("blocks")
    parser.add_argument("--block-s", type=float, required=True)
    parser.add_argument("--near", type=float, default=10.0)
    args = parser.parse_args()
    whole, blocks = (json.load(open(p))["logs"][0] for p in (args.whole, args.blocks))
    for name, log in (("whole", whole), ("blocks", blocks)):
        print(f"{name}: {log['verdict']} (exit {log['exit_code']})")
        for incident in log["incidents"]:
            print(f"  {incident['start']:.2f}-{incident['end']:.2f} {incident['headline']}")
    a, b = _alarms(whole), _alarms(blocks)
    far = 0
    for key in sorted(set(a) | set(b)):
        mine, theirs = a.get(key, []), b.get(key, [])
        if mine == theirs:
            continue
        for label, spans in (
            ("whole only", [s for s in mine if s not in theirs]),
            ("blocks only", [s for s in theirs if s not in mine]),
        ):
            for start, end in spans:
                distance = _to_border(start, args.block_s)
                far += distance > args.near
                print(f"  {label}: {key[0]} {key[1]} {start:.2f}-{end:.2f} ({distance:.1f} s from a border)")
    print(f"alarms differing further than {args.near:g} s from a border: {far}")
    return 1 if far else 0


if __name__ == "__main__":
    sys.exit(main())
