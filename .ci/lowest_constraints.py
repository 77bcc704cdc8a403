"""Print a pip constraints file that pins each direct dependency of pyproject.toml to its declared
lower bound (`name>=X` -> `name==X`), so that an install under it tests the floors users may get.

Usage: python3 .ci/lowest_constraints.py [pyproject.toml] > lowest-constraints.txt
A dependency without a `>=` bound is an error: every floor must be one the suite has run with.
"""

from __future__ import annotations

import re
import sys
import tomllib
from pathlib import Path

REQUIREMENT = re.compile(r"^\s*([A-Za-z0-9][A-Za-z0-9._-]*)(\[[^\]]*\])?\s*(.*?)\s*(;.*)?$")


def lowest_pins(dependencies: list[str]) -> list[str]:
    """`name==floor` for each requirement string; ValueError naming one without a `>=` floor."""
    pins = []
    for requirement in dependencies:
        match = REQUIREMENT.match(requirement)
        floors = re.findall(r">=\s*([^,\s]+)", match.group(3)) if match else []
        if len(floors) != 1:
            raise ValueError(f"{requirement!r}: needs exactly one '>=' lower bound")
        pins.append(f"{match.group(1)}=={floors[0]}")
    return pins


def main(argv: list[str]) -> int:
    path = Path(argv[1] if len(argv) > 1 else Path(__file__).resolve().parents[1] / "pyproject.toml")
    project = tomllib.loads(path.read_text(encoding="utf-8"))["project"]
    try:
        pins = lowest_pins(project["dependencies"])
    except ValueError as exc:
        print(f"{path}: {exc}", file=sys.stderr)
        return 2
    print(f"# generated from {path.name} by .ci/lowest_constraints.py: each direct dependency at its floor")
    print("\n".join(pins))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
