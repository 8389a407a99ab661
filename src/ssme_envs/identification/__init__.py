"""Identification: alpha-canonical engine models (NASA TM-104422); nozzle DSR_e and Bouc-Wen (VLS paper)."""

from ssme_envs.identification.alpha_canonical import (
    Identification,
    StructureSearch,
    check_record,
    estimate_indices,
    identify,
)
from ssme_envs.identification.bouc_wen import BoucWenFit, fit_bouc_wen
from ssme_envs.identification.metrics import filter_prediction, fit_percent, model_prediction, see, validate
from ssme_envs.identification.subspace import (
    InnovationsModel,
    SubspaceResult,
    dsr_e,
    second_order_parameters,
    to_continuous,
)

__all__ = [
    "BoucWenFit",
    "Identification",
    "InnovationsModel",
    "StructureSearch",
    "SubspaceResult",
    "check_record",
    "dsr_e",
    "estimate_indices",
    "filter_prediction",
    "fit_bouc_wen",
    "fit_percent",
    "identify",
    "model_prediction",
    "second_order_parameters",
    "see",
    "to_continuous",
    "validate",
]
