"""Native vector environments: N plants stepped as arrays by their task's batched step.

One class, :class:`TrackingVectorEnv`, serves every tracking task
(:class:`~ssme_envs.envs.task.TrackingTask`: engine, throttle, nozzle, launcher), stepping it on
(N,) rows with the array carrier.
Sub-env ``i`` is seeded with ``seed + i`` and draws its episodes from its own
generator exactly as the scalar env does, so the vector env equals gymnasium's
``SyncVectorEnv`` of the scalar env bit for bit, in each autoreset mode (NEXT_STEP, SAME_STEP,
DISABLED) and through partial resets (``reset(options={"reset_mask": mask})``).
"""

from __future__ import annotations

import copy
import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from ssme_envs.envs.engine_task import EngineTask
from ssme_envs.envs.engine_throttle import ThrottleTask
from ssme_envs.envs.episode_draws import EpisodeDraws
from ssme_envs.envs.episode_streams import EpisodeSource, episode_bytes, episode_source
from ssme_envs.envs.inputs import batch_actions, check_seeds, check_vector_memory, positive_int
from ssme_envs.envs.launcher_pitch import LauncherTask
from ssme_envs.envs.nozzle_task import NozzleTask
from ssme_envs.envs.sub_env import SubEnv, reset_mask, sub_env_index
from ssme_envs.envs.task import CLIP_UFUNC, GATHER, SYNCED, set_columns
from ssme_envs.envs.tracking_env import EpisodeOverError

_FLOATS = (np.dtype(np.float32), np.dtype(np.float64))  # action dtypes clipped without a copy
# what ``gymnasium.make_vec`` adds to a vector env's spec kwargs beside the scalar env's own
VECTOR_KWARGS = ("num_envs", "vectorization_mode", "vector_kwargs", "wrappers", "autoreset_mode")


class TrackingVectorEnv(VectorEnv):
    """``num_envs`` copies of a tracking env as one batch (subclasses name the task).

    Options are those of the scalar env; ``max_episode_steps`` truncates episodes like the
    TimeLimit wrapper of the scalar env (-1: none, as ``gymnasium.make`` reads it).
    ``autoreset_mode``, as gymnasium's ``SyncVectorEnv``:

    - NEXT_STEP (default): the step after an episode's end resets that sub-env (reward 0, not
      terminated or truncated).
    - SAME_STEP: the ending step resets it; the final observation is in ``info["final_obs"]``.
    - DISABLED: nothing resets by itself; reset ended sub-envs with
      ``reset(options={"reset_mask": mask})``. Stepping while a sub-env's episode is over (or
      before the first reset) raises :class:`~ssme_envs.envs.tracking_env.EpisodeOverError`
      and steps none: the scalar env raises it after ``terminated`` or ``truncated``, and
      ``SyncVectorEnv`` refuses the step with an ``AssertionError`` (a base of that error).

    ``reset(seed=..., options=...)``: ``seed`` an int >= 0 (sub-env ``i`` gets ``seed + i``), a
    list of ``num_envs`` such ints or Nones, or None, all checked first. ``options`` None, ``{}``
    or ``{"reset_mask": mask}`` (a bool array of shape ``(num_envs,)`` with at least one True):
    only the masked sub-envs reset (with their entries of ``seed``), the others keep their
    episodes and their last observations. Any other option raises ValueError (TypeError for a
    mask or ``options`` of the wrong type), as the scalar env does.

    A sub-env whose step went non-finite (the nozzle and launcher tasks' ``nonfinite_reward``)
    ends its episode as the scalar env does: terminated, finite reward and observation, and
    ``infos["nonfinite"]`` / ``infos["_nonfinite"]`` (inside ``infos["final_info"]`` in SAME_STEP
    mode), the layout ``SyncVectorEnv`` gathers from the scalar envs' ``{"nonfinite": True}``.

    ``np_random`` and ``np_random_seed`` are tuples over the sub-envs, as ``SyncVectorEnv``'s;
    :meth:`sub_env` gives one sub-env's view (its attributes and partial reset), which the SB3
    adapter uses for ``get_attr``, ``set_attr`` and ``env_method``.
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
        num_envs = positive_int("num_envs", num_envs)
        if isinstance(max_episode_steps, (int, np.integer)) and max_episode_steps == -1:
            max_episode_steps = None  # gymnasium.make's "no TimeLimit": the task's own horizon
        if max_episode_steps is not None:
            max_episode_steps = positive_int("max_episode_steps", max_episode_steps)
        if render_mode is not None:
            raise ValueError("the native vector env does not render; render a single env instead")
        try:
            mode = AutoresetMode(autoreset_mode)
        except ValueError:
            raise ValueError(
                f"autoreset_mode must be one of {[m.value for m in AutoresetMode]}, got {autoreset_mode!r}"
            ) from None
        self.task = self.build_task(**options)
        check_vector_memory(num_envs, episode_bytes(self.task))  # before a table or generator is made
        # Episodes are drawn at the task's full length, as the scalar env draws them, whatever
        # the time limit, so that both consume their generators alike.
        self._limit = min(self.task.horizon, max_episode_steps or self.task.horizon)
        self.num_envs = num_envs
        self.metadata = {**self.metadata, "autoreset_mode": mode}
        self.render_mode = None
        self.single_action_space = gym.spaces.Box(-1.0, 1.0, (self.task.n_actions,), dtype=np.float32)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.single_observation_space = self.task.observation.space()
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self._low, self._high = self.single_observation_space.low, self.single_observation_space.high
        self._low_col, self._high_col = (
            self._low[:, None],
            self._high[:, None],
        )  # bounds of the (columns, N) table
        # a task that scales float32 unit noise into float64 itself is handed it as drawn
        self._noise_as_drawn = getattr(self.task, "scales_float32_noise", False)
        # a task that writes restarting envs' first observations in its step is told which they are
        self._observes_restarts = getattr(self.task, "observes_restarts", False)
        # whether the task ends episodes whose step went non-finite (None: it passes them on)
        self._ends_nonfinite = self.task.nonfinite_reward(np.zeros(1, dtype=np.int64)) is not None
        n = num_envs
        rngs, seeds = zip(*(seeding.np_random(None) for _ in range(n)), strict=True)
        self._seeds: list[int] = list(seeds)  # np_random_seed of each sub-env (-1: generator set directly)
        # each sub-env's episode draw, made as its episode reaches it (``episode_draws``)
        self._draws = EpisodeDraws(self.task.draw_size, rngs)
        self._episodes: EpisodeSource = episode_source(self.task, self._draws)
        self._t = np.zeros(n, dtype=np.int64)
        self._t_bound = 0  # at least the largest t: truncation and the tables' blocks skip most steps
        self._synced = True  # every env at the same step: reads are slices, not gathers
        self._rows = np.arange(n)
        self._state = self.task.initial_state(n)
        # NEXT_STEP: restart at the next step; DISABLED: the episode is over until a reset
        self._autoreset = np.full(n, mode == AutoresetMode.DISABLED)  # written in place only
        # the carriers (gathered, synced) that name the restarting envs, read from _autoreset
        self._restarting = (GATHER.with_restarts(self._autoreset), SYNCED.with_restarts(self._autoreset))
        self._obs = np.zeros((n, *self.single_observation_space.shape), dtype=np.float32)  # last returned
        self._unstarted = np.ones(n, dtype=bool)  # sub-envs never reset
        self._started = False  # every sub-env reset at least once

    @property
    def np_random(self) -> tuple[np.random.Generator, ...]:
        """The generators of the sub-envs (a tuple, as ``SyncVectorEnv``'s)."""
        return tuple(self._draws.generators)

    @property
    def np_random_seed(self) -> tuple[int, ...]:
        """The seeds of the sub-envs' generators (a tuple, as ``SyncVectorEnv``'s)."""
        return tuple(self._seeds)

    def sub_env(self, index: int) -> SubEnv:
        """The view of sub-env ``index`` (negative counts from the end): see :class:`SubEnv`."""
        return SubEnv(self, sub_env_index(index, self.num_envs))

    def single_spec(self) -> gym.envs.registration.EnvSpec | None:
        """The spec that makes one sub-env with ``gymnasium.make`` (None if this env has no
        spec): this env's spec without the vector arguments, its time limit as
        ``max_episode_steps``."""
        if self.spec is None:
            return None
        spec = copy.deepcopy(self.spec)  # nothing shared with this env's spec
        kwargs = {k: v for k, v in spec.kwargs.items() if k not in VECTOR_KWARGS}
        limit = kwargs.pop("max_episode_steps", spec.max_episode_steps)
        return dataclasses.replace(spec, kwargs=kwargs, max_episode_steps=limit)

    def _restart(self, envs: np.ndarray) -> np.ndarray:
        """Zero the state of the given envs and draw their next episodes; their first observations."""
        plants = self._draw(envs)
        self._reset_state(envs, plants)
        self._rewind(envs)
        obs = self.task.initial_observation(*self._episodes.restart(envs)).T
        return CLIP_UFUNC(obs, self._low, self._high)

    def _draw(self, envs: np.ndarray) -> np.ndarray | None:
        """Draw the next episodes of the given envs; the uniforms of their plants (None where the
        task draws none)."""
        task = self.task
        self._draws.start(envs)
        m = task.plant_draw_size  # the last uniforms of each draw: the episode's plant
        return self._draws.rows(envs, task.draw_size - m, task.draw_size) if m else None

    def _rewind(self, envs: np.ndarray) -> None:
        """Put the given envs at step 0."""
        self._t[envs] = 0
        if len(envs) == self.num_envs:
            self._t_bound = 0
        t = self._t  # the ends differ in most partial restarts: the pass over t only where they agree
        self._synced = bool(t[0] == t[-1] and (t == t[0]).all())

    def _reset_state(self, envs: np.ndarray, plants: np.ndarray | None) -> None:
        """The initial state in the given envs, their plants drawn from ``plants``."""
        initial = self.task.initial_state(len(envs), plants)
        if len(envs) == self.num_envs:
            self._state = initial
        else:
            set_columns(self._state, initial, envs)

    def reset(
        self, *, seed: int | Sequence[int | None] | None = None, options: Mapping[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start new episodes in every sub-env, or only in those of ``options["reset_mask"]``
        (see the class docs); the observations of every sub-env and ``{}``."""
        mask = reset_mask(options, self.num_envs, type(self).__name__)
        seed = check_seeds(seed, self.num_envs, type(self).__name__)  # all, before any is used
        envs = self._rows if mask is None or mask.all() else np.flatnonzero(mask)
        for i in envs:
            if seed[i] is not None:
                rng, self._seeds[i] = seeding.np_random(seed[i])
                self._draws.set_generator(i, rng)
        self._autoreset[envs] = False
        self._obs[envs] = self._restart(envs)
        self._unstarted[envs] = False
        self._started = not self._unstarted.any()
        return self._obs.copy(), {}

    def step(
        self, actions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """One step of every sub-env; (observations, rewards, terminated, truncated, infos)."""
        acts = actions  # float32 or float64 as given: cast once, into the clipped rows below
        # exactly ndarray: a subclass (a masked array) goes through the checks, which read its mask
        if type(acts) is not np.ndarray or acts.dtype not in _FLOATS:
            acts = batch_actions(actions)  # real numbers only: not complex, bools or strings
        shape = (self.num_envs, self.task.n_actions)
        if acts.shape != shape:
            raise ValueError(f"actions must have shape {shape}, got {acts.shape}")
        mode = self.metadata["autoreset_mode"]
        if not self._started:
            raise EpisodeOverError(
                f"sub-env(s) {np.flatnonzero(self._unstarted).tolist()} never reset: "
                "call reset() before step()"
            )
        if mode == AutoresetMode.DISABLED and self._autoreset.any():
            raise EpisodeOverError(
                f"the episodes of sub-env(s) {np.flatnonzero(self._autoreset).tolist()} are over and "
                "autoreset_mode is DISABLED: reset them with reset(options={'reset_mask': mask}) "
                "before step()"
            )
        # two reductions that cannot overflow (a sum of 1e308s warned); the search only on failure
        if not (math.isfinite(acts.max()) and math.isfinite(acts.min())):
            bad = np.argwhere(~np.isfinite(acts))
            if bad.size:
                raise ValueError(
                    f"action of env {bad[0, 0]} must be finite, got {acts[bad[0, 0]].tolist()} (NaN or inf)"
                )
        clipped = np.empty(shape[::-1])  # state-major and contiguous, as the core wants
        clipped[...] = acts.T  # the exact float64 values, clipped as such
        CLIP_UFUNC(clipped, -1.0, 1.0, out=clipped)
        task = self.task
        t = self._t
        t += 1
        if self._t_bound >= task.horizon:  # an env past its end (restarted below) stays at it
            np.minimum(t, task.horizon, out=t)
        self._t_bound = min(self._t_bound + 1, task.horizon)
        # NEXT_STEP restarts draw their episodes before the step's episode values are read, so
        # that one read gives their step 0 beside the others' step t. The task steps every env
        # (its steps t >= 1 as ever); what it makes of the restarting ones' state is discarded
        # below, and their observations are their first (the task's own where it observes them).
        fresh, read_t, synced = None, t, self._synced
        if mode == AutoresetMode.NEXT_STEP and self._autoreset.any():
            fresh = np.flatnonzero(self._autoreset)
            plants = self._draw(fresh)
            self._episodes.begin(fresh)
            read_t = t.copy()
            read_t[fresh] = 0
            synced = False
        refs, drawn, self._t_bound = self._episodes.at(read_t, self._t_bound, synced)
        noise = drawn if self._noise_as_drawn else drawn.astype(np.float64)
        observed = fresh is not None and self._observes_restarts
        ops = self._restarting[self._synced] if observed else SYNCED if self._synced else GATHER
        self._state, values, reward, terminated = task.step(self._state, clipped, t, refs, noise, ops)
        # the observation values as rows of a float32 table, handed out transposed (N, columns): a
        # task's own fresh float32 table (the compiled engine step's), or one made here
        if isinstance(values, np.ndarray) and values.dtype == np.float32:
            table = values
        else:
            table = np.empty((len(values), self.num_envs), dtype=np.float32)
            for row, value in zip(table, values, strict=True):
                row[...] = value
        if fresh is not None and not observed:  # the restarts' first observations (refs read unsynced)
            table[:, fresh] = task.initial_observation(refs[:, fresh], drawn[:, fresh])
        # into the observation bounds, as the scalar envs do: one pass over the table
        CLIP_UFUNC(table, self._low_col, self._high_col, out=table)
        obs = table.T
        # no t reaches the limit while their bound is below it: a fresh all-False row then
        truncated = t >= self._limit if self._t_bound >= self._limit else np.zeros(self.num_envs, bool)
        # one reduction; the sub-envs whose step went NaN or infinite only on failure (tasks
        # that pass such values on, the engines', skip it)
        step_infos = (
            {}
            if not self._ends_nonfinite or math.isfinite(reward.sum())
            else self._end_nonfinite(obs, reward, terminated, t)
        )
        infos: dict[str, Any] = {}
        if mode == AutoresetMode.NEXT_STEP:
            if fresh is not None:
                self._reset_state(fresh, plants)
                self._rewind(fresh)
                if not observed:  # a task that observes restarts gave them reward 0, not terminated
                    reward[fresh] = 0.0
                    terminated[fresh] = False
                truncated[fresh] = False
            np.logical_or(terminated, truncated, out=self._autoreset)
            infos = step_infos
        elif mode == AutoresetMode.DISABLED:
            np.logical_or(terminated, truncated, out=self._autoreset)
            infos = step_infos
        else:
            mask = terminated | truncated
            if mask.any():
                done = np.flatnonzero(mask)
                # the layout of gymnasium's SyncVectorEnv: final observations, final step infos
                # (empty for these envs), and their masks
                infos = {
                    "final_obs": np.empty(self.num_envs, dtype=object),
                    "_final_obs": mask,
                    "final_info": step_infos,
                    "_final_info": mask.copy(),
                }
                for i in done:
                    infos["final_obs"][i] = obs[i].copy()
                obs[done] = self._restart(done)
        # what a partial reset returns for the sub-envs it leaves alone; a copy in the layout of
        # obs (the engine's is column-major), as a transposing copy costs several % of a step
        self._obs = obs.copy(order="K")
        return obs, reward, terminated, truncated, infos

    def _end_nonfinite(
        self, obs: np.ndarray, reward: np.ndarray, terminated: np.ndarray, t: np.ndarray
    ) -> dict[str, Any]:
        """End, in place, the episodes whose step's reward came out NaN or infinite (the plant's
        state overflowed), as the scalar env does (``NozzleTVCEnv``'s Episode End): terminated,
        the task's ``nonfinite_reward``, NaN observation entries 0. Returns their step infos
        ``{"nonfinite": True}`` as ``SyncVectorEnv`` gathers them (``{}`` if none). Sub-envs that
        restart at this step (NEXT_STEP) are left alone: their step is discarded. Tasks without
        ``nonfinite_reward`` (the engines, whose unstable plants are refused) pass values on."""
        bad = ~np.isfinite(reward) & ~self._autoreset
        if not bad.any():
            return {}
        rows = np.flatnonzero(bad)
        penalty = self.task.nonfinite_reward(t[rows])
        if penalty is None:
            return {}
        reward[rows] = penalty
        terminated[rows] = True
        obs[rows] = np.nan_to_num(obs[rows], nan=0.0)
        return {"nonfinite": bad.copy(), "_nonfinite": bad}


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
