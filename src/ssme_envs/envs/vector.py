"""Native vector environments: N plants stepped as arrays by their task's batched step.

One class, :class:`TrackingVectorEnv`, serves every tracking task (engine, throttle, nozzle, launcher).
A task provides ``horizon``, ``n_actions``, ``observation_space()``, ``draw_size``,
``episodes(uniforms, noise_out)``, ``shared_references``, ``zero_state(n)``,
``initial_observation(refs, noise)`` and ``batch_step(state, actions, t, refs, noise, synced)``.
Sub-env ``i`` is seeded with ``seed + i`` and draws its episodes from its own
generator exactly as the scalar env does, so the vector env equals gymnasium's
``SyncVectorEnv`` of the scalar env bit for bit, in either autoreset mode.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from ssme_envs.envs.engine_throttle import ThrottleTask
from ssme_envs.envs.engine_tracking import EngineTask
from ssme_envs.envs.launcher_pitch import LauncherTask
from ssme_envs.envs.nozzle_tvc import NozzleTask


class TrackingVectorEnv(VectorEnv):
    """``num_envs`` copies of a tracking env as one batch (subclasses name the task).

    Options are those of the scalar env; ``autoreset_mode`` is gymnasium's NEXT_STEP (default,
    like ``SyncVectorEnv``) or SAME_STEP (final observation in ``info["final_obs"]``);
    ``max_episode_steps`` truncates episodes like the TimeLimit wrapper of the scalar env.
    """

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}
    build_task: Any = None  # the task's constructor, set by each subclass

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
        self.single_action_space = gym.spaces.Box(-1.0, 1.0, (self.task.n_actions,), dtype=np.float32)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.single_observation_space = self.task.observation_space()
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self._low, self._high = self.single_observation_space.low, self.single_observation_space.high
        n, length, channels = num_envs, self.task.horizon + 1, self.task.n_channels
        self._rngs: list[np.random.Generator] = [seeding.np_random(None)[0] for _ in range(n)]
        # Episode data with the env axis last: one step's values of every env are contiguous.
        # References common to every episode (the throttle profile) are not stored per env.
        shared = self.task.shared_references
        self._shared_refs = None if shared is None else np.ascontiguousarray(shared.T)  # (channels, T + 1)
        self._refs = None if shared is not None else np.zeros((channels, length, n))
        self._noise = np.zeros((channels, length, n), dtype=np.float32)  # unit draws, scaled at each step
        # Buffers reused from episode to episode: fresh tens of MB would cost page faults.
        self._draws = np.empty((n, self.task.draw_size), dtype=np.float32)
        self._uniforms = np.empty((self.task.draw_size, n), dtype=np.float32)
        self._t = np.zeros(n, dtype=np.int64)
        self._synced = True  # every env at the same step: reads are slices, not gathers
        self._rows = np.arange(n)
        self._state = self.task.zero_state(n)
        self._autoreset = np.zeros(n, dtype=bool)

    def _restart(self, envs: np.ndarray) -> np.ndarray:
        """Zero the state of the given envs and draw their next episodes; their first observations."""
        task, k = self.task, len(envs)
        every = k == self.num_envs
        if every:
            self._state = task.zero_state(k)
        else:
            _set_columns(self._state, task.zero_state(k), envs)
        draws = self._draws[:k]
        for row, i in enumerate(envs):
            self._rngs[i].random(out=draws[row], dtype=np.float32)
        uniforms = _transpose(draws, self._uniforms if every else None)
        refs, noise = task.episodes(uniforms, self._noise if every else None)
        if every:
            self._refs = None if self._refs is None else refs
        else:
            self._noise[:, :, envs] = noise
            if self._refs is not None:
                self._refs[:, :, envs] = refs
        self._t[envs] = 0
        self._synced = bool((self._t == self._t[0]).all())
        obs = task.initial_observation(refs[:, 0], noise[:, 0]).T
        return np.clip(obs, self._low, self._high)

    def reset(self, *, seed: int | list[int | None] | None = None, options: dict | None = None):
        if isinstance(seed, int):
            seed = [seed + i for i in range(self.num_envs)]
        elif seed is None:
            seed = [None] * self.num_envs
        if len(seed) != self.num_envs:
            raise ValueError(f"seed must be an int or {self.num_envs} seeds, got {len(seed)}")
        for i, s in enumerate(seed):
            if s is not None:
                self._rngs[i] = seeding.np_random(s)[0]
        self._autoreset[:] = False
        return self._restart(self._rows), {}

    def step(self, actions: np.ndarray):
        acts = np.asarray(actions, dtype=np.float64)
        shape = (self.num_envs, self.task.n_actions)
        if acts.shape != shape:
            raise ValueError(f"actions must have shape {shape}, got {acts.shape}")
        if not math.isfinite(acts.sum()):  # one reduction; the element search only on failure
            bad = np.argwhere(~np.isfinite(acts))
            if bad.size:
                raise ValueError(
                    f"action of env {bad[0, 0]} must be finite, got {acts[bad[0, 0]].tolist()} (NaN or inf)"
                )
        clipped = np.empty(shape[::-1])  # state-major and contiguous, as the core wants
        np.maximum(acts.T, -1.0, out=clipped)
        np.minimum(clipped, 1.0, out=clipped)
        task = self.task
        t = self._t
        t += 1
        np.minimum(t, task.horizon, out=t)  # an env past its end is restarted below
        if self._synced:  # contiguous slices
            noise = self._noise[:, t[0]]
            refs = self._refs[:, t[0]] if self._refs is not None else self._shared_refs[:, t[0], None]
        else:  # one flat index for both tables: take is much faster than fancy indexing
            flat = t * self.num_envs + self._rows
            noise = np.take(self._noise.reshape(len(self._noise), -1), flat, axis=1)
            if self._refs is None:
                refs = np.take(self._shared_refs, t, axis=1)
            else:
                refs = np.take(self._refs.reshape(len(self._refs), -1), flat, axis=1)
        self._state, obs, reward, terminated = task.batch_step(
            self._state, clipped, t, refs, noise, self._synced
        )
        np.maximum(obs, self._low, out=obs)  # into the observation bounds, as the scalar envs do
        np.minimum(obs, self._high, out=obs)
        truncated = t >= self._limit
        infos: dict[str, Any] = {}
        if self.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP:
            if self._autoreset.any():
                restart = np.flatnonzero(self._autoreset)
                obs[restart] = self._restart(restart)
                reward[restart] = 0.0
                terminated[restart] = False
                truncated[restart] = False
            self._autoreset = terminated | truncated
        else:
            mask = terminated | truncated
            if mask.any():
                done = np.flatnonzero(mask)
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


def _transpose(table: np.ndarray, out: np.ndarray | None = None, tile: int = 256) -> np.ndarray:
    """A C-contiguous transpose copied tile by tile (into ``out`` if given): numpy's one-pass
    copy of a transposed view strides through memory, several times slower on tens of MB."""
    rows, cols = table.shape
    out = np.empty((cols, rows), dtype=table.dtype) if out is None else out
    for i in range(0, rows, tile):
        for j in range(0, cols, tile):
            out[j : j + tile, i : i + tile] = table[i : i + tile, j : j + tile].T
    return out


def _set_columns(state: list, fresh: list, envs: np.ndarray) -> None:
    """Write the columns (last axis) ``envs`` of every array in a nested state list."""
    for block, new in zip(state, fresh, strict=True):
        if isinstance(block, list):
            _set_columns(block, new, envs)
        else:
            block[..., envs] = new


class EngineTrackingVectorEnv(TrackingVectorEnv):
    """``num_envs`` copies of :class:`~ssme_envs.envs.engine_tracking.EngineTrackingEnv` as one batch."""

    build_task = staticmethod(EngineTask.build)


class EngineThrottleVectorEnv(TrackingVectorEnv):
    """``num_envs`` copies of :class:`~ssme_envs.envs.engine_throttle.EngineThrottleEnv` as one batch."""

    build_task = staticmethod(ThrottleTask.build_throttle)


class NozzleTVCVectorEnv(TrackingVectorEnv):
    """``num_envs`` copies of :class:`~ssme_envs.envs.nozzle_tvc.NozzleTVCEnv` as one batch."""

    build_task = staticmethod(NozzleTask.build)


class LauncherPitchVectorEnv(TrackingVectorEnv):
    """``num_envs`` copies of :class:`~ssme_envs.envs.launcher_pitch.LauncherPitchEnv` as one batch."""

    build_task = staticmethod(LauncherTask.build_launcher)
