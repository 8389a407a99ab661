"""The nozzle envs' joints: the plant presets, the model each is designed on, and the RK4
substeps an env step takes on them."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

from ssme_envs.envs.task import shown
from ssme_envs.models.nozzle import (
    DEFAULT_TORQUE_LIMIT,
    NOZZLE_DT,
    NozzleModel,
    NozzleParameters,
    identified_nozzle,
    integration_substeps,
    published_nozzle,
    strong_nozzle,
)

# RK4 substeps per sample by h * rate <= 0.25 (models.nozzle.recommended_substeps): 3 for Table 1,
# within 3e-4 of the motion on the PRBS test of experiments/results/nozzle_integration_accuracy.md
# and within half the default sensor noise (1e-4 rad) on 3 deg motions under any torque, ten
# seeded joints drawn around it within the sensor noise; the linear and the strong joints within 3e-4
# (tests/test_nozzle_integration_references.py, against scipy's solve_ivp). The Bouc-Wen law's
# kink at velocity reversals, which the rate (the natural frequency) does not count, sets the
# error of the hysteretic joints: 4 substeps are not better on every torque.
# models.nozzle.integration_substeps adds RK4's stability rule (stiffness, damping and hysteresis
# rates at h * rate <= 1.3, half the stability limit) and refuses plants that need more than
# MAX_SUBSTEPS; the accuracy rule sets the count of Table 1's and the identified joints.
ENV_STEP_RATE = 0.25


def strong_linear_nozzle() -> NozzleParameters:
    """The strong-hysteresis nozzle's small-signal linear joint (same J, b, stiffness at rest)."""
    strong = strong_nozzle()
    return NozzleParameters.linear(strong.J, strong.b, strong.small_signal_stiffness)


# plant presets -> (the joint, the packaged identified model the controllers design on)
PLANTS: dict[str, tuple[Callable[[], NozzleParameters], str]] = {
    "bouc_wen": (lambda: published_nozzle("bouc_wen"), "table1"),
    "linear": (lambda: published_nozzle("linear"), "table1"),
    "identified": (lambda: identified_nozzle("table1").plant(), "table1"),
    "strong": (strong_nozzle, "strong"),
    "strong_linear": (strong_linear_nozzle, "strong"),
    "strong_identified": (lambda: identified_nozzle("strong").plant(), "strong"),
}


def resolve_nozzle(plant: str | Path | NozzleParameters | NozzleModel) -> tuple[NozzleParameters, str]:
    """The joint behind the env and the bench test whose identified model designs for it.

    ``plant``: a preset of :data:`PLANTS` (``"bouc_wen"``: Table 1's hysteretic joint, the
    truth; ``"linear"``: its linear row; ``"identified"``: the packaged model identified from its
    bench test; ``"strong"``, ``"strong_linear"``, ``"strong_identified"``: the same for the
    strong-hysteresis nozzle), a nozzle model.json path, or a parameter/model object (designed
    for with Table 1's identified model).
    """
    if isinstance(plant, NozzleParameters):
        return plant, "table1"
    if isinstance(plant, NozzleModel):
        return plant.plant(), "table1"
    if isinstance(plant, str) and plant in PLANTS:
        joint, design = PLANTS[plant]
        return joint(), design
    if isinstance(plant, str | Path) and str(plant).endswith(".json"):
        return NozzleModel.load(plant).plant(), "table1"
    raise ValueError(
        f"plant must be one of {', '.join(PLANTS)}, a nozzle model.json path or a model, got {shown(plant)}"
    )


def rule_substeps(joints: Sequence[NozzleParameters], envelope: float) -> int:
    """RK4 substeps per env step for the worst of ``joints`` (the env's rule, see NozzleTVCEnv)."""
    return max(
        integration_substeps(joint, NOZZLE_DT, envelope, DEFAULT_TORQUE_LIMIT, ENV_STEP_RATE, sample="step")
        for joint in joints
    )


__all__ = ["ENV_STEP_RATE", "PLANTS", "resolve_nozzle", "rule_substeps", "strong_linear_nozzle"]
