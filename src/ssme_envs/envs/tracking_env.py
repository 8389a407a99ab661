"""The single env of any tracking task: setup from options, episode draws, reset options, the
step on floats, the end-of-episode rule, render and close."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from ssme_envs.envs.inputs import action_floats, check_seed
from ssme_envs.envs.rendering import close_figure, render_history
from ssme_envs.envs.task import CLIP_UFUNC, FLOATS, next_stop


class EpisodeOverError(gym.error.ResetNeeded, ValueError, AssertionError):
    """``step()`` on an env (or a sub-env of a vector env) whose episode has ended or never began.

    Every env of the package raises it, alone and batched, rather than stepping on: a scalar env
    after ``terminated`` or ``truncated``, and the native vector env in ``AutoresetMode.DISABLED``
    on a sub-env not reset since its episode ended. gymnasium's ``SyncVectorEnv`` refuses the same
    step in DISABLED mode with an ``AssertionError`` of its own (under ``python -O`` the scalar
    env's error); this class derives from ``AssertionError`` too, so that one ``except`` clause
    catches the refusal of every vectorization, and from ``ValueError`` and gymnasium's
    ``ResetNeeded``, what the envs raised before.
    """


def check_reset_options(options: Any, accepted: Mapping[str, str], owner: str) -> Mapping[str, Any]:
    """``options`` of a ``reset`` checked against the keys an env accepts: a mapping (or None,
    returned as ``{}``) with known keys only. ``accepted`` maps each key to a description of its
    values, for the error message; ``owner`` names the env.

    Raises
    ------
    TypeError
        ``options`` is not a mapping or None.
    ValueError
        ``options`` has a key outside ``accepted``.
    """
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise TypeError(f"{owner}.reset: options must be a dict or None, got {type(options).__name__}")
    unknown = [key for key in options if key not in accepted]
    if unknown:
        takes = (
            "no options (None or {})"
            if not accepted
            else "only " + ", ".join(f"{key!r} ({kind})" for key, kind in accepted.items())
        )
        raise ValueError(
            f"{owner}.reset: unknown option(s) {', '.join(map(repr, unknown))}; it accepts {takes}"
        )
    return options


class TrackingEnv(gym.Env):
    """A single env of a tracking task (:class:`~ssme_envs.envs.task.TrackingTask`). A subclass
    names its task constructor (``build_task``) and what it draws (``output_names``,
    ``display_scale``, ``display_units``); the actuators are the task's ``action_names``.

    ``reset`` takes no options (``None`` or ``{}``; anything else raises) and a seed that is an
    integer >= 0 or None (else TypeError or ValueError). ``step`` takes ``n_actions`` real numbers:
    a real array, a list or a tuple (bools, complex numbers, strings or dicts raise
    :class:`~ssme_envs.envs.inputs.ActionTypeError`, a TypeError). ``step`` after the
    episode ended (terminated or truncated), or before the first ``reset``, raises
    :class:`EpisodeOverError`: call ``reset`` first. A step whose reward comes out NaN or
    infinite ends the episode where the task gives a ``nonfinite_reward`` (see NozzleTVC-v0)."""

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 25}
    output_names: tuple[str, ...] = ()
    display_scale: float = 100.0
    display_units: tuple[str, str] = ("%", "normalized")
    action_meaning: str = ""  # what the action is, for the error message: the actuators' names
    build_task: Any = None

    def __init__(self, render_mode: str | None = None, **options: Any) -> None:
        self.task = self.build_task(**options)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}"
            )
        self.render_mode = render_mode
        # a frame per step plays the episode in real time (RecordVideo reads this)
        self.metadata = {**self.metadata, "render_fps": max(1, round(1.0 / self.task.dt))}
        self.action_space = gym.spaces.Box(-1.0, 1.0, (self.task.n_actions,), dtype=np.float32)
        self.observation_space = self.task.observation.space()
        self._low, self._high = self.observation_space.low, self.observation_space.high
        self._n_obs = len(self._low)
        self._history: list[list[float]] = []
        self._figure = None
        self._t = 0
        self._ended = "never reset"  # why step() is refused: "" while an episode runs

    reset_options: Mapping[str, str] = {}  # the keys ``reset(options=...)`` accepts: none

    @property
    def actuator_names(self) -> tuple[str, ...]:
        return self.task.action_names

    @property
    def elapsed_steps(self) -> int:
        """Steps taken in the current episode."""
        return self._t

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        """Seed, draw the episode as the vector env does; the first observation and ``{}``."""
        check_reset_options(options, self.reset_options, type(self).__name__)
        gym.Env.reset(self, seed=check_seed(seed, type(self).__name__))
        self._ended = ""
        task = self.task
        self._uniforms = self.np_random.random(task.draw_size, dtype=np.float32)[:, None]
        # per step, per channel, as floats (the float carrier's operands), the steps the episode
        # has reached so far
        self._refs: list[list[float]] = []
        self._noise: list[list[float]] = []
        refs, noise = self._extend()
        obs = task.initial_observation(refs[:, 0], noise[:, 0])[:, 0]
        obs = CLIP_UFUNC(obs, self._low, self._high)
        m = task.plant_draw_size  # the last uniforms of the draw: the episode's plant
        self._state = task.initial_state(None, self._uniforms[task.draw_size - m :] if m else None)
        self._t = 0
        if self.render_mode:
            self._history = [task.render_row(self._state, obs.tolist(), self._refs[0])]
        return obs, {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        task = self.task
        n = task.n_actions
        if type(action) is np.ndarray and action.shape == (n,) and action.dtype.kind == "f":
            values = action.tolist()  # the Python floats float() gives, in one call
        else:
            values = self._action_values(action)
        # one sum; the element search only when it is not finite (finite values whose sum
        # overflows are actions, clipped below)
        if not math.isfinite(sum(values)) and not all(map(math.isfinite, values)):
            raise ValueError(f"action must be finite, got {values if n > 1 else values[0]} (NaN or inf)")
        if self._ended:  # _check_running, inline: a call per step spared
            self._check_running()
        # min(max(a, -1), 1) as the builtins decide, without their calls (the values are finite)
        values = [-1.0 if a < -1.0 else 1.0 if a > 1.0 else a for a in values]
        t = self._t + 1
        if t == len(self._noise):
            self._extend()
        ref = self._refs[t]
        self._state, obs, reward, terminated = task.step(self._state, values, t, ref, self._noise[t], FLOATS)
        self._t = t
        if self.render_mode:
            self._history.append(task.render_row(self._state, obs, ref))
            if self.render_mode == "human":
                self.render()
        # into the bounds (np.clip, without its wrapper), from the float32 values
        out = CLIP_UFUNC(np.fromiter(obs, np.float32, self._n_obs), self._low, self._high)
        info = {}
        if not math.isfinite(reward):  # the state overflowed or went NaN: end the episode (see Episode End)
            penalty = task.nonfinite_reward(t)
            if penalty is not None:
                reward, terminated, info = penalty, True, {"nonfinite": True}
                np.nan_to_num(out, copy=False, nan=0.0)
        terminated, truncated = bool(terminated), t >= task.horizon
        self._ended = "terminated" if terminated else "truncated" if truncated else ""
        return out, float(reward), terminated, truncated, info

    def _action_values(self, action: Any) -> list[float]:
        """The action as ``n_actions`` Python floats (:func:`~ssme_envs.envs.inputs.action_floats`)."""
        meaning = self.action_meaning or ", ".join(self.task.action_names)
        return action_floats(action, self.task.n_actions, meaning)

    def _extend(self) -> tuple[np.ndarray, np.ndarray]:
        """Convert the episode's next block of steps (``next_stop``, as the vector env's) to
        floats; its references and noise (channels, steps, 1). The first block is computed at
        reset, all the rest at once when the episode leaves it: on one env a block costs about
        as much as the whole episode."""
        start, length = len(self._noise), self.task.horizon + 1
        stop, first = next_stop(start, length), next_stop(0, length)
        if start == 0:
            refs, noise = self.task.episodes(self._uniforms, 0, stop)
        else:
            if start == first:  # leaving the first block: the rest of the episode, from here
                self._rest = self.task.episodes(self._uniforms, first, length)
            refs, noise = (values[:, start - first : stop - first] for values in self._rest)
        self._refs += refs[:, :, 0].T.tolist()
        self._noise += noise[:, :, 0].T.astype(np.float64).tolist()
        return refs, noise

    def _check_running(self) -> None:
        """Refuse a step outside an episode (after its end, or before the first reset)."""
        if self._ended:
            raise EpisodeOverError(f"the episode is over ({self._ended}): call reset() before step()")

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array' or 'human'")
            return None
        if not self._history:  # nothing to draw (gymnasium's OrderEnforcing says so through make)
            raise EpisodeOverError("render() before the first reset(): call reset()")
        image, self._figure = render_history(
            np.array(self._history),
            self.task.dt,
            self._figure,
            self.render_mode,
            self.output_names,
            self.actuator_names,
            self.display_scale,
            self.display_units,
        )
        return image

    def close(self) -> None:
        if self._figure is not None:
            close_figure(self._figure)
            self._figure = None
