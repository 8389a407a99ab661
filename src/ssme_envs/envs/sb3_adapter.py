"""Train stable-baselines3 on a native gymnasium vector env.

SB3 takes its own ``VecEnv``, not a gymnasium ``VectorEnv``. :class:`SB3VecEnv` presents a
native vector env (created in SAME_STEP autoreset mode, SB3's convention) as an SB3 ``VecEnv``:
finished sub-envs are reset within the step, the last observation of the episode goes to
``info["terminal_observation"]`` and truncations are marked ``info["TimeLimit.truncated"]``.

Usage::

    from ssme_envs.envs.sb3_adapter import make_sb3_vec_env
    venv = make_sb3_vec_env("ssme_envs/EngineTracking-v0", num_envs=64, seed=0)
    model = stable_baselines3.PPO("MlpPolicy", venv)
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env.base_vec_env import VecEnv


class SB3VecEnv(VecEnv):
    """An SB3 ``VecEnv`` over a gymnasium vector env in SAME_STEP autoreset mode."""

    def __init__(self, vector_env: gym.vector.VectorEnv, seed: int | None = None) -> None:
        if vector_env.metadata.get("autoreset_mode") != AutoresetMode.SAME_STEP:
            raise ValueError("the vector env must use autoreset_mode=SAME_STEP (SB3 resets within the step)")
        self.venv = vector_env
        super().__init__(
            vector_env.num_envs, vector_env.single_observation_space, vector_env.single_action_space
        )
        self._seed = seed
        self._actions: np.ndarray | None = None

    def reset(self) -> np.ndarray:
        obs, _ = self.venv.reset(seed=self._seed)
        self._seed = None  # later resets continue the sub-envs' streams
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self):
        obs, rewards, terminated, truncated, info = self.venv.step(self._actions)
        dones = terminated | truncated
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        for i in np.flatnonzero(dones):
            infos[i]["terminal_observation"] = info["final_obs"][i]
            infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
        return obs, rewards.astype(np.float32), dones, infos

    def seed(self, seed: int | None = None) -> list[int | None]:
        self._seed = seed
        return [None if seed is None else seed + i for i in range(self.num_envs)]

    def close(self) -> None:
        self.venv.close()

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        return [getattr(self.venv, attr_name)] * len(self._get_indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list[Any]:
        result = getattr(self.venv, method_name)(*method_args, **method_kwargs)
        return [result] * len(self._get_indices(indices))

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False] * len(self._get_indices(indices))


def make_sb3_vec_env(env_id: str, num_envs: int, seed: int | None = None, **options: Any) -> SB3VecEnv:
    """A registered env's native vector env (SAME_STEP autoreset) wrapped for stable-baselines3."""
    venv = gym.make_vec(
        env_id,
        num_envs=num_envs,
        vectorization_mode="vector_entry_point",
        autoreset_mode=AutoresetMode.SAME_STEP,
        **options,
    )
    return SB3VecEnv(venv, seed=seed)
