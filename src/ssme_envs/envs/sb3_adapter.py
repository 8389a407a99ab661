"""Train stable-baselines3 on a native gymnasium vector env.

SB3 takes its own ``VecEnv``, not a gymnasium ``VectorEnv``. :class:`SB3VecEnv` presents a
native vector env (created in SAME_STEP autoreset mode, SB3's convention) as an SB3 ``VecEnv``:
finished sub-envs are reset within the step, the last observation of the episode goes to
``info["terminal_observation"]`` and truncations are marked ``info["TimeLimit.truncated"]``.

The rest of SB3's contract holds per sub-env, as in its ``DummyVecEnv``: ``seed(seed)`` gives
sub-env ``i`` the seed ``seed + i`` at the next ``reset`` (then the streams continue);
``set_options`` reaches the next ``reset`` only; ``get_attr``, ``set_attr`` and ``env_method``
act on the indexed sub-envs only, through the vector env's per-sub-env views
(:class:`~ssme_envs.envs.vector.SubEnv`: what cannot be done to one sub-env alone raises
AttributeError rather than acting on all), or on the sub-env objects of a ``SyncVectorEnv``.

No Monitor is added (SB3's ``make_vec_env`` adds one per env): wrap the result in ``VecMonitor``
for episode statistics (``ep_info_buffer``, ``rollout/ep_rew_mean``), outermost of any reward
shaping, as ``ssme-envs train`` does. The observations are the vector env's own arrays (an
engine's steps give column-major ones): the same values as ``DummyVecEnv``'s, but torch's products over a
column-major batch can differ from a row-major one's in the last bits, so training through this
adapter and through a ``SyncVectorEnv`` agree to round-off, not bit for bit (each is
reproducible; the shipped policies were trained through this adapter). Usage::

    from stable_baselines3.common.vec_env import VecMonitor
    from ssme_envs.envs.sb3_adapter import make_sb3_vec_env
    venv = VecMonitor(make_sb3_vec_env("ssme_envs/EngineTracking-v0", num_envs=64, seed=0))
    model = stable_baselines3.PPO("MlpPolicy", venv, n_steps=64)
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.env_util import is_wrapped
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices, VecEnvStepReturn

from ssme_envs.envs.inputs import check_seed
from ssme_envs.envs.sub_env import sub_env_index

FINAL_KEYS = ("final_obs", "_final_obs", "final_info", "_final_info")


class SB3VecEnv(VecEnv):
    """An SB3 ``VecEnv`` over a gymnasium vector env in SAME_STEP autoreset mode.

    Parameters
    ----------
    vector_env
        A native vector env (:class:`~ssme_envs.envs.vector.TrackingVectorEnv`, possibly inside
        gymnasium vector wrappers) or a ``SyncVectorEnv``, in SAME_STEP autoreset mode.
    seed
        Seeds of the first ``reset`` (sub-env ``i`` gets ``seed + i``), as ``seed(seed)``;
        None: the sub-envs' generators as they are.
    """

    def __init__(self, vector_env: gym.vector.VectorEnv, seed: int | None = None) -> None:
        if vector_env.metadata.get("autoreset_mode") != AutoresetMode.SAME_STEP:
            raise ValueError("the vector env must use autoreset_mode=SAME_STEP (SB3 resets within the step)")
        base = vector_env.unwrapped
        if hasattr(base, "sub_env"):
            self._sub_envs = [base.sub_env(i) for i in range(base.num_envs)]
        elif hasattr(base, "envs"):
            self._sub_envs = list(base.envs)
        else:
            raise TypeError(
                f"{type(base).__name__} has neither sub_env(i) nor envs: no per-sub-env access for SB3"
            )
        self.venv = vector_env
        # the info keys under which gymnasium's RecordEpisodeStatistics puts an ended episode's
        # statistics: at the top of a SAME_STEP info, among the reset's entries, where SB3 wants
        # them in the ending step's info (as its Monitor puts them)
        self._episode_keys = tuple(
            getattr(env, "_stats_key", "episode")
            for env in _vector_wrappers(vector_env)
            if isinstance(env, gym.wrappers.vector.RecordEpisodeStatistics)
        )
        super().__init__(
            vector_env.num_envs, vector_env.single_observation_space, vector_env.single_action_space
        )
        if seed is not None:
            self.seed(check_seed(seed, type(self).__name__))
        self._actions: np.ndarray | None = None

    def reset(self) -> np.ndarray:
        """Reset every sub-env with the seeds and options set since the last reset (each used
        once); sub-envs with different options reset in groups (partial resets)."""
        groups: list[tuple[dict[str, Any], np.ndarray]] = []
        for i, options in enumerate(self._options):
            if "reset_mask" in options:
                raise ValueError("set_options: 'reset_mask' is not an option of a sub-env (reset resets all)")
            for same, mask in groups:
                if same == options:
                    mask[i] = True
                    break
            else:
                groups.append((options, np.arange(self.num_envs) == i))
        for options, mask in groups:
            if len(groups) > 1:
                options = {**options, "reset_mask": mask}
            obs, info = self.venv.reset(seed=list(self._seeds), options=options or None)
            for i in np.flatnonzero(mask):
                self.reset_infos[i] = _sub_info(info, i)
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self) -> VecEnvStepReturn:
        obs, rewards, terminated, truncated, info = self.venv.step(self._actions)
        dones = terminated | truncated
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if any(key not in FINAL_KEYS for key in info):  # step infos beside the final observations
            infos = [_sub_info(info, i) for i in range(self.num_envs)]
        for i in np.flatnonzero(dones):
            # SAME_STEP: the ending step's info is in final_info, the reset's at the top
            self.reset_infos[i] = infos[i]
            infos[i] = _sub_info(info["final_info"], i)
            for key in self._episode_keys:
                if key in self.reset_infos[i]:
                    infos[i][key] = self.reset_infos[i].pop(key)
            infos[i]["terminal_observation"] = info["final_obs"][i]
            infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
        return obs, rewards.astype(np.float32), dones, infos

    def close(self) -> None:
        self.venv.close()

    def get_images(self) -> Sequence[np.ndarray | None]:
        if self.render_mode != "rgb_array":
            warnings.warn(f"The render mode is {self.render_mode}, get_images needs rgb_array", stacklevel=2)
            return [None] * self.num_envs
        return [env.render() for env in self._sub_envs]

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The attribute of each indexed sub-env (AttributeError if a sub-env has none)."""
        return [env.get_wrapper_attr(attr_name) for env in self._targets(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set the attribute on each indexed sub-env (AttributeError where it is not per sub-env)."""
        for env in self._targets(indices):
            setattr(env, attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs: Any
    ) -> list[Any]:
        """Call the method of each indexed sub-env; the results."""
        return [
            env.get_wrapper_attr(method_name)(*method_args, **method_kwargs) for env in self._targets(indices)
        ]

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        """Whether each indexed sub-env is wrapped by ``wrapper_class``: a gymnasium wrapper of a
        ``SyncVectorEnv``'s sub-env, or a vector wrapper around the whole vector env."""
        targets = self._targets(indices)
        if self._sub_envs and isinstance(self._sub_envs[0], gym.Env):
            return [is_wrapped(env, wrapper_class) for env in targets]
        wrapped = any(isinstance(env, wrapper_class) for env in _vector_wrappers(self.venv))
        return [wrapped] * len(targets)

    def _targets(self, indices: VecEnvIndices) -> list[Any]:
        """The sub-envs of ``indices`` (None: all; an int or ints, negative ones counted from the
        end as in a list), checked."""
        if indices is None:  # every sub-env: nothing to check
            return list(self._sub_envs)
        return [self._sub_envs[sub_env_index(i, self.num_envs)] for i in self._get_indices(indices)]


def _vector_wrappers(env: gym.vector.VectorEnv) -> list[gym.vector.VectorWrapper]:
    """The gymnasium vector wrappers around a vector env, outermost first."""
    wrappers = []
    while isinstance(env, gym.vector.VectorWrapper):
        wrappers.append(env)
        env = env.env
    return wrappers


def _sub_info(info: dict[str, Any], i: int) -> dict[str, Any]:
    """Sub-env ``i``'s entries of a gymnasium vector info dict (values batched, ``_key`` masks
    marking the sub-envs that have the key; nested for dict values), SAME_STEP's final
    observation and info left out."""
    out = {}
    for key, value in info.items():
        if key in FINAL_KEYS or key.startswith("_") or not info.get(f"_{key}", np.ones(i + 1, bool))[i]:
            continue
        out[key] = _sub_info(value, i) if isinstance(value, dict) else value[i]
    return out


def make_sb3_vec_env(env_id: str, num_envs: int, seed: int | None = None, **options: Any) -> SB3VecEnv:
    """A registered env's native vector env (SAME_STEP autoreset) wrapped for stable-baselines3
    (no Monitor: see the module docs)."""
    venv = gym.make_vec(
        env_id,
        num_envs=num_envs,
        vectorization_mode="vector_entry_point",
        autoreset_mode=AutoresetMode.SAME_STEP,
        **options,
    )
    return SB3VecEnv(venv, seed=seed)
