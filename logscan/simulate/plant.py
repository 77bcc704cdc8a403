"""An off-nominal plant for `logscan simulate --plant-draw`: the truth flies a vehicle whose interval
parameters are drawn inside their intervals, while the log's profile (and the on-board estimator)
keep the nominal ones, as a real vehicle differs from its model (docs/algorithms.md section 6.6).
"""

from __future__ import annotations

import numpy as np

from logscan.errors import UsageError
from logscan.models import get_model
from logscan.models.base import Model


def check_plant_draw(model_name: str, plant_draw: bool) -> None:
    """UsageError when --plant-draw is asked of a model without interval parameters."""
    if plant_draw and model_name != "hover_uav":
        raise UsageError(
            f"--plant-draw needs a model with interval parameters; {model_name} has none",
            hint="simulate hover_uav, or drop --plant-draw",
        )


def draw_plant(model: Model, seed: int) -> tuple[Model, dict[str, float]]:
    """(the plant model, the drawn values): every parameter of ``model.parameter_box()`` drawn
    uniformly inside its interval from the stream ``[seed, 4]`` (the simulator's other streams are
    0 .. 3), the others the model's."""
    box = model.parameter_box()  # type: ignore[attr-defined]  # models with intervals have one
    rng = np.random.default_rng([seed, 4])
    drawn = {name: float(rng.uniform(lo, hi)) for name, (lo, hi) in box.items()}
    return get_model(model.name, {**model.params, **drawn}), drawn
