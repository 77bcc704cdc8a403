"""The `--json` summary of `logscan analyze` against its published JSON Schema
(docs/schema/analyze-summary.schema.json): every sample log's output validates, a missing file's
error entry too, and the schema can fail."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

SCHEMA = Path(__file__).resolve().parents[1] / "docs" / "schema" / "analyze-summary.schema.json"


@pytest.fixture(scope="module")
def validator():
    import jsonschema

    schema = json.loads(SCHEMA.read_text(encoding="utf-8"))
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def test_every_sample_logs_summary_validates(validator, tmp_path):
    from conftest import SAMPLES

    from logscan.cli.analyze_cmd import SUMMARY_SCHEMA_VERSION
    from logscan.cli.main import main

    logs = sorted(str(p) for p in SAMPLES.iterdir() if p.suffix in (".mcap", ".csv"))
    if not logs:
        pytest.skip("sample logs missing")
    out = tmp_path / "summary.json"
    with pytest.raises(SystemExit):
        main(["analyze", *logs, str(tmp_path / "missing.mcap"), "--no-report", "-q", "--json", str(out)])
    document = json.loads(out.read_text())
    errors = sorted(validator.iter_errors(document), key=str)
    assert errors == [], errors[0].message if errors else ""
    assert document["schema_version"] == SUMMARY_SCHEMA_VERSION
    assert len(document["logs"]) == len(logs) and len(document["errors"]) == 1
    broken = {**document, "logs": [{**document["logs"][0], "n_alarms": "three"}]}
    assert list(validator.iter_errors(broken))  # the schema can fail
