"""Controllers behind one protocol (classical and reinforcement learning) for the ssme-envs plants.

``make_controller("lqi", env)`` designs a controller on the env's design model (the identified
one; ``"lqi:truth"`` designs on the env's own plant instead). ``CONTROLLERS`` lists which
controller serves which env.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from agents.base import BatchController, Controller, task_of
from agents.lqi import LQIServo, ScheduledLQI
from agents.mpc import MPC
from agents.pid import DecoupledPI, PlacedPID
from agents.plants import DESIGN_SOURCES
from agents.tvc import HysteresisCompensated

TRACKING = "ssme_envs/EngineTracking-v0"
THROTTLE = "ssme_envs/EngineThrottle-v0"
NOZZLE = "ssme_envs/NozzleTVC-v0"
LAUNCHER = "ssme_envs/LauncherPitch-v0"


class ZeroAction(BatchController):
    """The do-nothing baseline: the zero action (the nominal schedule on EngineThrottle)."""

    name = "zero"

    def __init__(self, env: Any, design: str = "identified") -> None:
        super().__init__()
        self.size = task_of(env).n_actions

    def compute(self, obs: np.ndarray) -> np.ndarray:
        return np.zeros((len(obs), self.size))


def _compensated(env: Any, design: str) -> HysteresisCompensated:
    return HysteresisCompensated(env, LQIServo(env, design), design)


# name -> (factory(env, design), the env ids it serves)
CONTROLLERS: dict[str, tuple[Callable[[Any, str], Controller], tuple[str, ...]]] = {
    "zero": (ZeroAction, (TRACKING, THROTTLE, NOZZLE, LAUNCHER)),
    "pi": (DecoupledPI, (TRACKING, THROTTLE)),
    "lqi": (LQIServo, (TRACKING, NOZZLE, LAUNCHER)),
    "mpc": (MPC, (TRACKING,)),
    "scheduled": (ScheduledLQI, (THROTTLE,)),
    "pid": (PlacedPID, (NOZZLE, LAUNCHER)),
    "hysteresis": (_compensated, (NOZZLE,)),
}


def controller_names(env_id: str) -> list[str]:
    """The controllers that serve an env, each also as ``name:truth``."""
    return [name for name, (_, envs) in CONTROLLERS.items() if env_id in envs]


def parse_controller(spec: str, env_id: str) -> Callable[[Any], Controller]:
    """A factory ``env -> controller`` from ``name`` or ``name:design`` (design: identified,
    truth); ValueError naming the valid choices otherwise."""
    name, _, design = spec.partition(":")
    valid = controller_names(env_id)
    if name not in valid:
        raise ValueError(f"unknown controller {spec!r} for {env_id}; choose from {', '.join(valid)}")
    design = design or "identified"
    if design not in DESIGN_SOURCES:
        raise ValueError(
            f"unknown design model {design!r} in {spec!r}; choose from {', '.join(DESIGN_SOURCES)}"
        )
    factory = CONTROLLERS[name][0]
    return lambda env: factory(env, design)


def make_controller(spec: str, env: Any, env_id: str | None = None) -> Controller:
    """The controller ``spec`` (``"lqi"``, ``"pi:truth"``, ...) designed for ``env``."""
    if env_id is None:
        spec_obj = getattr(getattr(env, "unwrapped", env), "spec", None)
        env_id = getattr(spec_obj, "id", None) or TRACKING
    return parse_controller(spec, env_id)(env)


__all__ = [
    "CONTROLLERS",
    "MPC",
    "BatchController",
    "Controller",
    "DecoupledPI",
    "HysteresisCompensated",
    "LQIServo",
    "PlacedPID",
    "ScheduledLQI",
    "ZeroAction",
    "controller_names",
    "make_controller",
    "parse_controller",
]
