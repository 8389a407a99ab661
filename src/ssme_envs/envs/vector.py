"""Native vector environments: N engines stepped as arrays by the same step function.

Sub-env ``i`` is seeded with ``seed + i`` and draws its episodes from its own generator exactly
as the scalar env does, so the vector env equals gymnasium's ``SyncVectorEnv`` of the scalar env
bit for bit, in either autoreset mode.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from ssme_envs.envs.engine_throttle import ThrottleTask
from ssme_envs.envs.engine_tracking import EngineTask, batch_step, initial_observation, observation_space


class EngineTrackingVectorEnv(VectorEnv):
    """``num_envs`` copies of :class:`~ssme_envs.envs.engine_tracking.EngineTrackingEnv` as one batch.

    Options are those of the scalar env; ``autoreset_mode`` is gymnasium's NEXT_STEP (default,
    like ``SyncVectorEnv``) or SAME_STEP (final observation in ``info["final_obs"]``);
    ``max_episode_steps`` truncates episodes like the TimeLimit wrapper of the scalar env.
    """

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}
    build_task = staticmethod(EngineTask.build)

    def __init__(
        self,
        num_envs: int = 1,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        render_mode: str | None = None,
        max_episode_steps: int | None = None,
        **options: Any,
    ) -> None:
        if not isinstance(num_envs, int) or num_envs < 1:
            raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
        if max_episode_steps is not None and (
            not isinstance(max_episode_steps, int) or max_episode_steps < 1
        ):
            raise ValueError(f"max_episode_steps must be a positive integer, got {max_episode_steps!r}")
        if render_mode is not None:
            raise ValueError("the native vector env does not render; render a single env instead")
        mode = AutoresetMode(autoreset_mode)
        if mode not in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP):
            raise ValueError(f"autoreset_mode must be NEXT_STEP or SAME_STEP, got {autoreset_mode!r}")
        self.task = self.build_task(**options)
        # Episodes are drawn at the task's full length, as the scalar env draws them, whatever
        # the time limit, so that both consume their generators alike.
        self._limit = min(self.task.horizon, max_episode_steps or self.task.horizon)
        self.num_envs = num_envs
        self.metadata = {**self.metadata, "autoreset_mode": mode}
        self.render_mode = None
        self.single_action_space = gym.spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.single_observation_space = observation_space()
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self._low, self._high = self.single_observation_space.low, self.single_observation_space.high
        n, t1 = num_envs, self.task.horizon + 1
        self._rngs: list[np.random.Generator] = [seeding.np_random(None)[0] for _ in range(n)]
        # episode data time-major, (T + 1, 2, N): one step's values for all envs are contiguous
        # references shared by every episode (the throttle profile) are not copied per env
        self._shared_refs = self.task.shared_references
        self._refs = None if self._shared_refs is not None else np.zeros((t1, 2, n))
        self._noise = np.zeros((t1, 2, n), dtype=np.float32)  # unit draws, scaled at each step
        self._t = np.zeros(n, dtype=np.int64)
        self._rows = np.arange(n)
        self._state = self._zero_state(n)
        self._autoreset = np.zeros(n, dtype=bool)

    def _zero_state(self, n: int) -> list:
        """[plant state, error integrals, previous actions, held command] for n envs."""
        return [self.task.initial_plant_arrays(n), np.zeros((2, n)), np.zeros((2, n)), np.zeros(n)]

    def _restart(self, envs: np.ndarray) -> np.ndarray:
        """Zero the state of the given envs and draw their next episodes; their first observations."""
        draws = np.empty((len(envs), self.task.draw_size), dtype=np.float32)
        for row, i in enumerate(envs):
            self._rngs[i].standard_normal(out=draws[row], dtype=np.float32)
        refs, noise = self.task.episodes(draws)
        cols = slice(None) if len(envs) == self.num_envs else envs  # all envs: a plain (faster) copy
        if self._refs is not None:
            self._refs[:, :, cols] = refs.transpose(1, 2, 0)
        self._noise[:, :, cols] = noise.transpose(1, 2, 0)
        fresh = self._zero_state(len(envs))
        for block, new in zip(self._state[0], fresh[0], strict=True):
            block[..., envs] = new
        for block, new in zip(self._state[1:], fresh[1:], strict=True):
            block[..., envs] = new
        self._t[envs] = 0
        first_refs = refs[:, 0].T  # (2, k)
        obs = initial_observation(self.task, first_refs, self._noise[0][:, envs]).T
        return np.clip(obs, self._low, self._high)

    def reset(self, *, seed: int | list[int | None] | None = None, options: dict | None = None):
        if isinstance(seed, int):
            seed = [seed + i for i in range(self.num_envs)]
        elif seed is None:
            seed = [None] * self.num_envs
        if len(seed) != self.num_envs:
            raise ValueError(f"seed must be an int or {self.num_envs} seeds, got {len(seed)}")
        for i, s in enumerate(seed):
            if s is not None or self._rngs[i] is None:
                self._rngs[i] = seeding.np_random(s)[0]
        self._autoreset[:] = False
        return self._restart(self._rows), {}

    def step(self, actions: np.ndarray):
        acts = np.asarray(actions, dtype=np.float64)
        if acts.shape != (self.num_envs, 2):
            raise ValueError(f"actions must have shape ({self.num_envs}, 2), got {acts.shape}")
        if not np.all(np.isfinite(acts)):
            bad = np.argwhere(~np.isfinite(acts))[0]
            raise ValueError(
                f"action of env {bad[0]} must be finite, got {acts[bad[0]].tolist()} (NaN or inf)"
            )
        acts = np.clip(acts.T, -1.0, 1.0)
        task = self.task
        t = np.minimum(self._t + 1, task.horizon)
        synced = bool((t == t[0]).all())
        if synced:  # envs in step: contiguous slices
            noise = self._noise[t[0]]
            refs = (
                self._refs[t[0]]
                if self._refs is not None
                else np.repeat(self._shared_refs[t[0], :, None], self.num_envs, axis=1)
            )
        else:
            noise = self._noise[t, :, self._rows].T
            refs = self._shared_refs[t].T if self._refs is None else self._refs[t, :, self._rows].T
        self._state, obs, reward, terminated = batch_step(task, self._state, acts, t, refs, noise, synced)
        self._t = t
        obs = np.clip(obs.T.astype(np.float32), self._low, self._high)
        truncated = t >= self._limit
        infos: dict[str, Any] = {}
        if self.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP:
            restart = np.flatnonzero(self._autoreset)
            if restart.size:
                obs[restart] = self._restart(restart)
                reward[restart] = 0.0
                terminated[restart] = False
                truncated[restart] = False
            self._autoreset = terminated | truncated
        else:
            done = np.flatnonzero(terminated | truncated)
            if done.size:
                mask = terminated | truncated
                # the layout of gymnasium's SyncVectorEnv: final observations, final step infos
                # (empty for these envs), and their masks
                infos = {
                    "final_obs": np.empty(self.num_envs, dtype=object),
                    "_final_obs": mask,
                    "final_info": {},
                    "_final_info": mask.copy(),
                }
                for i in done:
                    infos["final_obs"][i] = obs[i].copy()
                obs[done] = self._restart(done)
        return obs, reward, terminated, truncated, infos


class EngineThrottleVectorEnv(EngineTrackingVectorEnv):
    """``num_envs`` copies of :class:`~ssme_envs.envs.engine_throttle.EngineThrottleEnv` as one batch."""

    build_task = staticmethod(ThrottleTask.build_throttle)
