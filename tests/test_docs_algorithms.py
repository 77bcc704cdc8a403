"""docs/algorithms.md agrees with the code: detector defaults, model sections, section references.

- Every parameter of every built-in detector appears in that detector's parameter table with its
  default value (a table whose header row starts with "| parameter | default" and whose
  introducing line names the profile table `[detectors.<name>]`), and no table documents a
  parameter the detector does not have.
- Every registered vehicle model has a heading of its own.
- Every reference of the form "docs/algorithms.md section N" (also "algorithms.md section N",
  e.g. from inside docs/) in the repository's tracked .py and .md files names a numbered heading
  that exists ("## 1b. ...", "## 7. ...", "### 6.3 ..."). References in any other form are not
  checked.
"""

from __future__ import annotations

import json
import math
import re
import subprocess
from pathlib import Path

import pytest

from logscan.detectors.registry import BUILTIN, default_registry
from logscan.models import MODEL_NAMES

ROOT = Path(__file__).resolve().parents[1]
DOC_PATH = ROOT / "docs" / "algorithms.md"
DOC = DOC_PATH.read_text(encoding="utf-8")

# The top-level sections the code and docs rely on.
REQUIRED_SECTIONS = ("1", "1b", "1c", "1d", "2", "3", "4", "5", "6", "7", "8")

# "## 1b. Title", "## 7. Title", "### 6.3 Title", "### 6.3. Title"
HEADING = re.compile(r"^(#{2,4})[ \t]+(\d+[a-z]?(?:\.\d+)*)\.?[ \t]+(\S.*?)[ \t]*$")
# "docs/algorithms.md section 7", "algorithms.md, section 1b", "[docs/algorithms.md](...) section 6.3";
# case-sensitive, so an upper-case file name (another document) is not taken for this one.
REFERENCE = re.compile(
    r"(?<![\w.-])(?:docs/)?algorithms\.md(?:\]\([^)]*\))?[\s,\"'`*#>)\]]*"
    r"(?:sections?|§|s\.)[ \t]*(\d+[a-z]?(?:\.\d+)*)"
)
PARAMETER_TABLE = re.compile(r"^\|\s*parameter\s*\|\s*default\s*\|", re.I)
DETECTOR_TABLE_NAME = re.compile(r"\[detectors\.([A-Za-z0-9_.-]+)\]")


def doc_lines_outside_code() -> list[tuple[int, str]]:
    """(line number, text) of the document's lines that are not inside a fenced code block."""
    out, fenced = [], False
    for number, line in enumerate(DOC.splitlines(), start=1):
        if line.lstrip().startswith("```"):
            fenced = not fenced
            continue
        if not fenced:
            out.append((number, line))
    return out


def headings() -> list[tuple[str, str, int]]:
    """(section id, title, line number) of every numbered heading."""
    found = []
    for number, line in doc_lines_outside_code():
        match = HEADING.match(line)
        if match:
            found.append((match.group(2), match.group(3), number))
    return found


def section_ids() -> set[str]:
    return {section for section, _, _ in headings()}


def _cells(row: str) -> list[str]:
    return [cell.strip() for cell in re.split(r"(?<!\\)\|", row.strip().strip("|"))]


def parameter_tables() -> dict[str, dict[str, str]]:
    """detector name -> {parameter: default cell} from the document's parameter tables."""
    lines = doc_lines_outside_code()
    tables: dict[str, dict[str, str]] = {}
    for i, (_, line) in enumerate(lines):
        if not PARAMETER_TABLE.match(line):
            continue
        intro = next((text for _, text in reversed(lines[:i]) if text.strip()), "")
        owner = DETECTOR_TABLE_NAME.search(intro)
        if owner is None:
            continue  # a model's parameter table
        rows = tables.setdefault(owner.group(1), {})
        for _, row in lines[i + 2 :]:  # skip the header and its |---| separator
            if not row.lstrip().startswith("|"):
                break
            cells = _cells(row)
            if len(cells) < 2:
                continue
            for name in re.findall(r"`([^`]+)`", cells[0]) or [cells[0]]:
                rows[name] = cells[1]
    return tables


def parse_default(cell: str):
    """The value written in a default cell: the first `code` span, else the whole cell."""
    match = re.search(r"`([^`]*)`", cell)
    text = (match.group(1) if match else cell).strip()
    lowered = text.lower()
    if lowered in ("null", "none"):
        return None
    if lowered in ("true", "false"):
        return lowered == "true"
    if len(text) >= 2 and text[0] == text[-1] and text[0] in "\"'":
        return text[1:-1]
    if text[:1] in "[{":
        try:
            return json.loads(text)
        except ValueError:
            return text
    try:
        return float(text)
    except ValueError:
        return text


def same_value(default, documented) -> bool:
    if default is None or isinstance(default, bool):
        return documented is default
    if isinstance(default, (int, float)):
        return (
            isinstance(documented, float)
            and not isinstance(documented, bool)
            and math.isclose(documented, float(default), rel_tol=1e-12, abs_tol=0.0)
        )
    return documented == default


def builtin_detectors() -> dict[str, dict]:
    registry = default_registry()
    return {
        entry.name: dict(registry.get(entry.name).defaults)
        for entry in registry.entries()
        if entry.origin == BUILTIN and entry.ok
    }


BUILTINS = builtin_detectors()


def test_there_are_builtin_detectors_to_check():
    assert BUILTINS, "no built-in detector loaded: the parameter check would check nothing"


@pytest.mark.parametrize("name", sorted(BUILTINS))
def test_every_parameter_of_a_builtin_detector_is_documented_with_its_default(name):
    tables = parameter_tables()
    assert name in tables, (
        f"docs/algorithms.md has no parameter table for detector {name!r}: add a table whose "
        f"header starts with '| parameter | default |', introduced by a line naming "
        f"`[detectors.{name}]`"
    )
    documented = tables[name]
    defaults = BUILTINS[name]
    missing = sorted(set(defaults) - set(documented))
    unknown = sorted(set(documented) - set(defaults))
    wrong = [
        f"{key}: code {defaults[key]!r}, document {documented[key]!r}"
        for key in sorted(set(defaults) & set(documented))
        if not same_value(defaults[key], parse_default(documented[key]))
    ]
    assert not missing, f"{name}: parameters missing from docs/algorithms.md: {missing}"
    assert not unknown, f"{name}: docs/algorithms.md documents parameters the detector lacks: {unknown}"
    assert not wrong, f"{name}: defaults differ from docs/algorithms.md: " + "; ".join(wrong)


@pytest.mark.parametrize("model", MODEL_NAMES)
def test_every_model_has_a_section(model):
    pattern = re.compile(rf"(?<![\w]){re.escape(model)}(?![\w])")
    titles = [title for _, title, _ in headings()]
    assert any(pattern.search(title) for title in titles), (
        f"docs/algorithms.md has no heading for the model {model!r} (section 6)"
    )


def test_required_sections_exist_once():
    ids = [section for section, _, _ in headings()]
    duplicates = sorted({s for s in ids if ids.count(s) > 1})
    assert not duplicates, f"section numbers used by more than one heading: {duplicates}"
    missing = [s for s in REQUIRED_SECTIONS if s not in ids]
    assert not missing, f"docs/algorithms.md lacks the sections {missing}"


def tracked_files() -> list[Path]:
    try:
        out = subprocess.run(
            ["git", "ls-files", "-z", "--", "*.py", "*.md"], cwd=ROOT, capture_output=True, check=True, timeout=60
        ).stdout
    except (OSError, subprocess.SubprocessError):
        pytest.skip("git is not available (or this is not a git checkout)")
    return [ROOT / name for name in out.decode("utf-8", "replace").split("\0") if name]


def test_reference_parser_reads_the_accepted_forms():
    text = (
        "see docs/algorithms.md section 1b, docs/algorithms.md, section 7; "
        "[docs/algorithms.md](../docs/algorithms.md) section 6.3. algorithms.md section 8\n"
        "docs/algorithms.md\n# section 1c; " + "algorithms.md".upper() + " section 0; "
        "docs/algorithms.md section N"
    )
    assert [m.group(1) for m in REFERENCE.finditer(text)] == ["1b", "7", "6.3", "8", "1c"]


def test_every_section_reference_in_the_repository_exists():
    ids = section_ids()
    bad = []
    for path in tracked_files():
        if not path.is_file():
            continue  # deleted in the working tree but still in the index
        text = path.read_text(encoding="utf-8", errors="replace")
        for match in REFERENCE.finditer(text):
            if match.group(1) not in ids:
                line = text.count("\n", 0, match.start()) + 1
                bad.append(f"{path.relative_to(ROOT)}:{line}: section {match.group(1)}")
    assert not bad, (
        "references to sections that docs/algorithms.md does not have (its sections: "
        + ", ".join(sorted(ids))
        + "):\n"
        + "\n".join(bad)
    )
