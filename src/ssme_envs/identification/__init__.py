"""Identification pipeline: alpha-canonical engine models (NASA TM-104422)."""

from ssme_envs.identification.alpha_canonical import (
    Identification,
    StructureSearch,
    check_record,
    estimate_indices,
    identify,
)
from ssme_envs.identification.metrics import filter_prediction, fit_percent, model_prediction, see, validate

__all__ = [
    "Identification",
    "StructureSearch",
    "check_record",
    "estimate_indices",
    "filter_prediction",
    "fit_percent",
    "identify",
    "model_prediction",
    "see",
    "validate",
]
