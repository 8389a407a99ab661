"""Controllers behind one protocol (classical and reinforcement learning) for the ssme-envs plants.

``make_controller("lqi", env)`` designs a controller on the env's design model (the identified
one; ``"lqi:truth"`` designs on the env's own plant instead); ``"ppo:RUN_DIR"`` (or ``sac:``,
``td3:``) loads a policy trained by ``ssme-envs train``. ``CONTROLLERS`` lists which controller
serves which env.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from agents.base import BatchController, Controller, env_id_of, task_of
from agents.lqi import LQIServo, ScheduledLQI
from agents.mpc import MPC
from agents.pid import DecoupledPI, PlacedPID, ScheduledPI
from agents.plants import DESIGN_SOURCES
from agents.policy_files import ALGOS
from agents.shipped import POLICY_VARIANTS, shipped_policy
from agents.tvc import HysteresisCompensated
from ssme_envs.envs.catalogue import ENVS

TRACKING = "ssme_envs/EngineTracking-v0"
THROTTLE = "ssme_envs/EngineThrottle-v0"
NOZZLE = "ssme_envs/NozzleTVC-v0"
LAUNCHER = "ssme_envs/LauncherPitch-v0"


class ZeroAction(BatchController):
    """The do-nothing baseline: the zero action (the nominal schedule on EngineThrottle)."""

    name = "zero"

    def __init__(self, env: Any, design: str | None = None) -> None:
        super().__init__()
        self.size = task_of(env).n_actions

    def compute(self, obs: np.ndarray) -> np.ndarray:
        return np.zeros((len(obs), self.size))


def _compensated(env: Any, design: str) -> HysteresisCompensated:
    return HysteresisCompensated(env, LQIServo(env, design), design)


def _lq_tracker(env: Any, design: str) -> LQIServo:
    """The reward's LQ-optimal tracker: the LQ servo with a negligible integral weight (1e-5 of the
    errors'), reference feedforward only. On the true linear plant (``lq:truth``) it is the
    physical limit a learned policy is measured against; on a mismatched model it leaves
    steady-state error (what the integral weight of ``lqi`` buys back)."""
    servo = LQIServo(env, design, integral_ratio=1e-5)
    servo.name = "lq"
    return servo


def _robust(env: Any, design: str) -> Controller:
    """The LQ servo tuned for a spread of plants (agents.robust; imported when used)."""
    from agents.robust import RobustLQI

    return RobustLQI(env, design)


def _shipped_ppo(env: Any, design: str) -> Controller:
    """The PPO policy shipped for the env, trained on its full truth (``design="truth"``) or, for
    EngineTracking, on the identified model (``"identified"``)."""
    from agents.sb3 import load_trained, policy_controller

    env_id = env_id_of(env)
    return policy_controller(load_trained(shipped_policy(env_id, design)), env, env_id)


# name -> (factory of env and design model, the envs it serves, its default design model: None for
# a controller designed on no model, which takes none)
CONTROLLERS: dict[str, tuple[Callable[[Any, Any], Controller], tuple[str, ...], str | None]] = {
    "zero": (ZeroAction, tuple(ENVS), None),  # the baseline of every env
    "pi": (DecoupledPI, (TRACKING, THROTTLE), "identified"),
    "lqi": (LQIServo, (TRACKING, NOZZLE, LAUNCHER), "identified"),
    "mpc": (MPC, (TRACKING,), "identified"),
    "scheduled": (ScheduledLQI, (THROTTLE,), "identified"),
    "pi_scheduled": (ScheduledPI, (THROTTLE,), "identified"),
    "pid": (PlacedPID, (NOZZLE, LAUNCHER), "identified"),
    "hysteresis": (_compensated, (NOZZLE,), "identified"),
    "lq": (_lq_tracker, (TRACKING,), "identified"),
    "robust": (_robust, (NOZZLE, LAUNCHER), "identified"),
    # learned on the truth by default: a policy is trained on an env, not designed on a model
    "ppo": (_shipped_ppo, (TRACKING, THROTTLE, NOZZLE, LAUNCHER), "truth"),
}


def controller_names(env_id: str) -> list[str]:
    """The controllers that serve an env (each designed on a model also usable as ``name:truth``)."""
    return [name for name, (_, envs, _) in CONTROLLERS.items() if env_id in envs]


def takes_design(name: str) -> bool:
    """Whether the controller ``name`` (a key of :data:`CONTROLLERS`) is designed on a model."""
    return CONTROLLERS[name][2] is not None


def parse_controller(spec: str, env_id: str, allow_pickle: bool = False) -> Callable[[Any], Controller]:
    """A factory ``env -> controller`` from a controller spec; ValueError naming the valid choices
    otherwise.

    Parameters
    ----------
    spec : str
        ``name`` or ``name:design`` (design: identified, truth; for ``ppo`` the plant the shipped
        policy was trained on, ``spread``: NozzleTVC's policy trained on plants drawn per
        episode, or ``residual``: the policy that corrects a classical design's action), or
        ``algo:PATH`` (algo: ppo, sac, td3) for the run directory of ``ssme-envs train`` (write
        ``ppo:./truth`` for a directory named like a design).
    env_id : str
        The env the controller is for.
    allow_pickle : bool
        Accept ``algo:FILE.zip``, an SB3 zip: it is unpickled on load, which can execute
        arbitrary code.
    """
    if not isinstance(spec, str):
        raise TypeError(f"a controller spec is a string such as 'lqi' or 'ppo:RUN_DIR', got {spec!r}")
    name, colon, design = spec.partition(":")
    if colon and not design:
        raise ValueError(f"controller spec {spec!r} names nothing after ':'; write {name!r} or {name}:DESIGN")
    if name in ALGOS and design and design not in (*DESIGN_SOURCES, *POLICY_VARIANTS):
        return _trained(name, design, env_id, allow_pickle)
    if name in ALGOS and name in CONTROLLERS and (Path(design) / "policy.json").is_file():
        raise ValueError(
            f"{spec!r} names a shipped policy, and ./{design} is a run directory too: write "
            f"{name}:./{design} for the run (or run from another directory for the shipped policy)"
        )
    valid = controller_names(env_id)
    if name not in valid:
        trained = ", ".join(f"{algo}:RUN_DIR" for algo in ALGOS)
        raise ValueError(
            f"unknown controller {spec!r} for {env_id}; choose from {', '.join(valid)} or {trained}"
        )
    factory, default = CONTROLLERS[name][0], CONTROLLERS[name][2]
    if default is None:  # designed on no model (takes_design)
        if design:
            raise ValueError(f"{spec!r}: the {name} controller is designed on no model; write {name!r}")
        return lambda env: factory(env, None)
    design = design or default
    if design not in DESIGN_SOURCES and not (name == "ppo" and design in POLICY_VARIANTS):
        raise ValueError(
            f"unknown design model {design!r} in {spec!r}; choose from {', '.join(DESIGN_SOURCES)}"
        )
    return lambda env: factory(env, design)


def _trained(algo: str, path: str, env_id: str, allow_pickle: bool) -> Callable[[Any], Controller]:
    """The factory of a trained policy, loaded (and checked) once, here."""
    from agents.sb3 import load_trained, policy_controller

    loaded = load_trained(path, algo, allow_pickle)
    if loaded.env_id is not None and loaded.env_id != env_id:
        raise ValueError(f"{path}: the {algo} policy was trained on {loaded.env_id}, not {env_id}")
    return lambda env: policy_controller(loaded, env, env_id)


def make_controller(spec: str, env: Any, env_id: str | None = None, allow_pickle: bool = False) -> Controller:
    """The controller ``spec`` (``"lqi"``, ``"pi:truth"``, ``"ppo"``, ``"sac:RUN_DIR"``, ...)
    designed for ``env`` (see :func:`parse_controller`)."""
    return parse_controller(spec, env_id or env_id_of(env), allow_pickle)(env)


__all__ = [
    "CONTROLLERS",
    "MPC",
    "POLICY_VARIANTS",
    "BatchController",
    "Controller",
    "DecoupledPI",
    "HysteresisCompensated",
    "LQIServo",
    "PlacedPID",
    "ScheduledLQI",
    "ScheduledPI",
    "ZeroAction",
    "controller_names",
    "make_controller",
    "parse_controller",
    "takes_design",
]
