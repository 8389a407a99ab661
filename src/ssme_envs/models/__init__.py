"""Plants: one batched dynamics core per plant, and the model types they run."""

from ssme_envs.models.engine import (
    ENGINE_DT,
    POWER_LEVELS,
    EngineCore,
    TruthConfig,
    identified_model,
    published_model,
    simulate,
)
from ssme_envs.models.engine_nonlinear import NonlinearEngine, flow_characteristic, simulate_nonlinear
from ssme_envs.models.statespace import AlphaCanonicalModel, AlphaStructure, asymmetric_gain

__all__ = [
    "ENGINE_DT",
    "POWER_LEVELS",
    "AlphaCanonicalModel",
    "AlphaStructure",
    "EngineCore",
    "NonlinearEngine",
    "TruthConfig",
    "asymmetric_gain",
    "flow_characteristic",
    "identified_model",
    "published_model",
    "simulate",
    "simulate_nonlinear",
]
