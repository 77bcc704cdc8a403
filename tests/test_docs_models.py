"""docs/models.md agrees with the models: state, input, group and output names in the model's
order, and each group's unit, default noise standard deviation and range."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from logscan.models import MODEL_NAMES, get_model

DOC = (Path(__file__).resolve().parents[1] / "docs" / "models.md").read_text(encoding="utf-8")
TABLED = ("quadcopter", "steer_by_wire", "dc_motor", "ins")


def section(model: str) -> str:
    return DOC.split(f"\n## {model}\n", 1)[1].split("\n## ", 1)[0]


def table(text: str, first_header: str) -> list[list[str]]:
    """Rows (cells) of the table whose header row starts with ``| first_header |``."""
    lines = text.split(f"| {first_header} |", 1)[1].splitlines()[2:]
    rows = []
    for line in lines:
        if not line.startswith("|"):
            break
        rows.append([cell.strip() for cell in line.strip().strip("|").split("|")])
    return rows


def names(cell: str) -> list[str]:
    return re.findall(r"`([^`]+)`", cell)


def numbers(cell: str) -> list[float]:
    return [float(n) for n in re.findall(r"[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?", cell.replace("+-", ""))]


def test_every_model_has_a_section():
    assert set(re.findall(r"^## (\w+)$", DOC, re.M)) == set(MODEL_NAMES)


@pytest.mark.parametrize("model", TABLED)
def test_states_in_the_models_order(model):
    assert [names(row[0])[0] for row in table(section(model), "state")] == list(get_model(model).state_names)


@pytest.mark.parametrize("model", TABLED)
def test_inputs_in_the_models_order(model):
    documented = [name for row in table(section(model), "input") for name in names(row[0])]
    expected = list(get_model(model).input_names)
    if model == "quadcopter":  # the wrench inputs, then the motor speeds `w1` .. `w4`
        motors = get_model(model, {"inputs": "motors"}).input_names
        expected += [motors[0], motors[-1]]
    assert documented == expected


@pytest.mark.parametrize("model", TABLED)
def test_groups_outputs_units_noise_and_ranges(model):
    groups = get_model(model).groups
    rows = table(section(model), "group")
    assert [names(row[0])[0] for row in rows] == list(groups)
    for group_cell, outputs, unit, noise, span, _ in rows:
        spec = groups[names(group_cell)[0]]
        assert names(outputs) == list(spec.outputs), spec.name
        assert {unit} == set(spec.units), spec.name
        assert numbers(noise) * spec.size == list(spec.noise_std) or numbers(noise) == list(spec.noise_std)
        highs = numbers(span)
        assert highs == list(spec.range_hi) or highs * spec.size == list(spec.range_hi), spec.name
        assert [-h for h in spec.range_hi] == list(spec.range_lo), spec.name


def test_linear_default_names():
    model = get_model("linear", {"A": [[0.0, 1.0], [0.0, -0.5]], "B": [[0.0], [1.0]], "C": [[1.0, 0.0]]})
    text = section("linear")
    assert model.state_names[:2] == ("x0", "x1") and "`x0, x1, ...`" in text
    assert model.input_names[0] == "u0" and "`u0, u1, ...`" in text
    assert list(model.groups) == ["y"] and model.groups["y"].outputs == ("y0",) and "group `y`" in text
