"""Residual policies: a learned correction added to a classical controller's action.

Residual policy learning (Johannink et al., 2019; Silver et al., 2018) trains a policy whose
action is *added* to a fixed base controller's: the env applies

    clip(a_base + scale * clip(a_policy, -1, 1), -1, 1),

and the policy observes the env's observation with the base action appended (the base
controller's integrator and observer state reach the policy only through it). A zero correction
is the base controller itself, and a freshly built SB3 policy's action is near zero (its output
layer starts at a small scale), so learning starts near the classical design. The policy kept is
the best of the training's evaluations (all on the same episodes); it can still cost more than its
base on scenarios the evaluations weigh little (the main report says where).

The base is a controller spec of the env (``"scheduled"``, ``"hysteresis"``, ...) with its
design model; a trained residual policy records it in ``policy.json`` and acts only with it
(:class:`ResidualController`).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import gymnasium as gym
import numpy as np

from agents.base import BatchController, Controller
from agents.json_fields import short


class Residual(NamedTuple):
    """How a residual policy acts: its base controller spec and the scale of its action."""

    base: str  # a controller spec of the env, e.g. "scheduled" or "lqi:identified"
    scale: float  # action units per unit of the policy's action, in (0, 2]


def check_residual(base: Any, scale: Any, env_id: str, where: str = "residual") -> Residual:
    """The residual, or ValueError naming what is wrong: ``base`` a classical controller of the env
    (not a learned policy: a residual over a residual would hide what acts), ``scale`` in (0, 2]."""
    from agents import CONTROLLERS, controller_names, takes_design
    from agents.plants import DESIGN_SOURCES
    from ssme_envs.envs.catalogue import ENVS

    if env_id not in ENVS:
        raise ValueError(f"{where}: unknown env {env_id!r}; choose one of {', '.join(ENVS)}")
    if not isinstance(base, str):
        raise ValueError(f"{where}: base must be a controller name, got {base!r}")
    name, _, design = base.partition(":")
    classical = [c for c in controller_names(env_id) if c != "ppo"]
    if name not in classical or name not in CONTROLLERS:
        raise ValueError(f"{where}: base {base!r} is not a classical controller of {env_id}; "
                         f"choose from {', '.join(classical)}")  # fmt: skip
    if design and not takes_design(name):
        raise ValueError(
            f"{where}: base {base!r}: the {name} controller is designed on no model; write {name!r}"
        )
    if design and design not in DESIGN_SOURCES:
        raise ValueError(f"{where}: base {base!r} names no design model; after the colon write "
                         f"{' or '.join(DESIGN_SOURCES)}")  # fmt: skip
    # an integer beyond float's range is no number in (0, 2] either (math.isfinite would overflow)
    ok = isinstance(scale, int | float) and not isinstance(scale, bool) and -2 <= scale <= 2
    if not ok or not math.isfinite(scale) or not 0 < scale <= 2:
        raise ValueError(f"{where}: scale must be a number in (0, 2], got {short(scale)}")
    return Residual(base, float(scale))


def base_controller(residual: Residual, env: Any, env_id: str) -> Controller:
    """The residual's base controller designed for ``env`` (a scalar env or a native vector env)."""
    from agents import make_controller

    return make_controller(residual.base, env, env_id)


def residual_space(observation_space: gym.spaces.Box, n_actions: int) -> gym.spaces.Box:
    """The policy's observation space: the env's with ``n_actions`` base actions in [-1, 1] appended."""
    ones = np.ones(n_actions, dtype=np.float32)
    low = np.concatenate([observation_space.low.astype(np.float32), -ones])
    high = np.concatenate([observation_space.high.astype(np.float32), ones])
    return gym.spaces.Box(low, high, dtype=np.float32)


def applied_action(base: np.ndarray, correction: np.ndarray, scale: float) -> np.ndarray:
    """What the env gets: ``clip(base + scale * clip(correction, -1, 1), -1, 1)`` as float32."""
    total = np.asarray(base, dtype=np.float64) + scale * np.clip(correction, -1.0, 1.0)
    return np.clip(total, -1.0, 1.0).astype(np.float32)


class ResidualController(BatchController):
    """A trained residual policy with its base controller, as one controller of the protocol.

    Parameters
    ----------
    policy : Controller
        The learned part (a :class:`~agents.sb3.PolicyController`), acting on the observation with
        the base action appended.
    base : Controller
        The base controller, designed for the env it acts on.
    scale : float
        The residual's scale (:class:`Residual`).
    """

    def __init__(self, policy: Controller, base: Controller, scale: float) -> None:
        super().__init__()
        self.policy, self.base, self.scale = policy, base, float(scale)
        self.name = f"{policy.name}+{base.name}"

    def reset(self, seed: int | None = None, num_envs: int = 1, envs: np.ndarray | None = None) -> None:
        super().reset(seed, num_envs, envs)
        self.base.reset(seed, num_envs, envs)
        self.policy.reset(seed, num_envs, envs)

    def compute(self, obs: np.ndarray) -> np.ndarray:
        base = np.asarray(self.base.act(obs), dtype=np.float64)
        correction = self.policy.act(np.concatenate([obs, base], axis=1))
        return applied_action(base, correction, self.scale).astype(np.float64)


def residual_vec_env(venv: Any, base: Controller, scale: float, penalty: float = 0.0) -> Any:
    """An SB3 ``VecEnv`` on which a policy learns a residual over ``base`` (module docstring).

    ``venv`` is an SB3 VecEnv (resets within the step, SB3's convention); the base controller is
    reset with each sub-env's episode. ``penalty`` >= 0 takes ``penalty * |scale * correction|^2``
    (action units) off each step's reward, so that the policy corrects its base only where that
    pays: without it, a correction that does not matter to the return is left as it comes, and
    on scenarios whose costs are small it shows (for training; evaluate without it). An episode's
    terminal observation (SB3 bootstraps the value of a truncated episode from it) carries the base
    action of the episode's last step, as the base controller does not act on it.
    """
    from stable_baselines3.common.vec_env import VecEnvWrapper

    class ResidualVecEnv(VecEnvWrapper):
        def __init__(self) -> None:
            self.base, self.scale = base, float(scale)
            n_actions = int(np.prod(venv.action_space.shape))
            super().__init__(venv, observation_space=residual_space(venv.observation_space, n_actions))
            self._base_action = np.zeros((venv.num_envs, n_actions))
            self._cost = np.zeros(venv.num_envs)

        def _observe(self, obs: np.ndarray) -> np.ndarray:
            self._base_action = np.asarray(self.base.act(obs), dtype=np.float64)
            return np.concatenate([obs, self._base_action], axis=1).astype(np.float32)

        def reset(self) -> np.ndarray:
            obs = self.venv.reset()
            self.base.reset(num_envs=self.num_envs)
            return self._observe(obs)

        def step_async(self, actions: np.ndarray) -> None:
            if penalty:
                self._cost = penalty * np.sum(np.square(self.scale * np.clip(actions, -1.0, 1.0)), axis=1)
            self.venv.step_async(applied_action(self._base_action, actions, self.scale))

        def step_wait(self) -> Any:
            obs, rewards, dones, infos = self.venv.step_wait()
            if penalty:
                rewards = rewards - self._cost.astype(rewards.dtype)
            ended = np.flatnonzero(dones)
            for i in ended.tolist():
                last = infos[i].get("terminal_observation")
                if last is not None:
                    infos[i]["terminal_observation"] = np.concatenate([last, self._base_action[i]]).astype(
                        np.float32
                    )
            if ended.size:
                self.base.reset(envs=ended)
            return self._observe(obs), rewards, dones, infos

    return ResidualVecEnv()


__all__ = [
    "Residual",
    "ResidualController",
    "applied_action",
    "base_controller",
    "check_residual",
    "residual_space",
    "residual_vec_env",
]
