"""The policies shipped in agents/policies/: one directory per (env, variant).

A directory is named after its env (``EngineTracking-v0``: trained on the env's full truth) or
the env and a variant (``EngineTracking-v0-identified``: trained on the identified model; the
others, such as ``-residual``, are the ``ppo:VARIANT`` specs of :mod:`agents`). This module is
light (no torch, no SB3): the controller catalogue reads the variants from here.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from ssme_envs.envs.catalogue import ENVS

SHIPPED = (
    "EngineTracking-v0",
    "EngineTracking-v0-identified",
    "EngineThrottle-v0",
    "NozzleTVC-v0",
    "NozzleTVC-v0-spread",  # trained with plant_spread=0.2 (experiments/configs/ppo_nozzle_tvc_spread.toml)
    "LauncherPitch-v0",
    # residual policies over a classical design (agents.residual; experiments/configs/*_residual.toml)
    "EngineTracking-v0-residual",
    "EngineTracking-v0-residual_quiet",  # with residual_penalty = 1.0: its correction kept small
    "EngineThrottle-v0-residual",
    "NozzleTVC-v0-residual",
    "LauncherPitch-v0-residual",
)


def env_and_variant(shipped: str) -> tuple[str, str]:
    """The env id and the variant (``"truth"`` for the env's own name) of a shipped directory."""
    for env_id in ENVS:
        name = env_id.split("/")[-1]
        if shipped == name or shipped.startswith(name + "-"):
            return env_id, shipped.removeprefix(name).removeprefix("-") or "truth"
    raise ValueError(f"{shipped!r} names no env of the catalogue")


def shipped_policy(env_id: str, trained_on: str = "truth") -> Path:
    """The directory of the policy shipped for an env and a variant (``"truth"``: the env's own)."""
    name = env_id.split("/")[-1] + ("" if trained_on == "truth" else f"-{trained_on}")
    if name not in SHIPPED:
        raise ValueError(f"no shipped policy {name!r}; there are {', '.join(SHIPPED)}")
    return Path(str(resources.files("agents") / "policies" / name))


def shipped_specs(env_id: str) -> dict[str, Path]:
    """``{controller spec: directory}`` of the policies shipped for an env: ``ppo`` (trained on its
    truth) and ``ppo:VARIANT`` for each other (``identified``, ``spread``, ``residual``, ...)."""
    specs = {}
    for shipped in SHIPPED:
        env, variant = env_and_variant(shipped)
        if env == env_id:
            specs["ppo" if variant == "truth" else f"ppo:{variant}"] = shipped_policy(env_id, variant)
    return specs


# the variants trained on other than a design source (``identified``) or the truth: ``ppo:VARIANT``
POLICY_VARIANTS = tuple(
    dict.fromkeys(v for _, v in map(env_and_variant, SHIPPED) if v not in ("truth", "identified"))
)

__all__ = ["POLICY_VARIANTS", "SHIPPED", "env_and_variant", "shipped_policy", "shipped_specs"]
