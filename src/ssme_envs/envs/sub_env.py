"""One sub-env's view of a native vector env: what a sub-env has alone."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np

from ssme_envs.envs.tracking_env import check_reset_options

if TYPE_CHECKING:
    from ssme_envs.envs.vector import TrackingVectorEnv

RESET_OPTIONS = {"reset_mask": "a numpy bool array of shape (num_envs,), at least one True"}


def sub_env_index(index: Any, num_envs: int) -> int:
    """``index`` as a sub-env number in ``[0, num_envs)``: an int (Python's or numpy's, not a
    bool), negative ones counted from the end as in a list; TypeError or IndexError otherwise."""
    if isinstance(index, bool | np.bool_) or not isinstance(index, int | np.integer):
        raise TypeError(f"indices must be sub-env numbers (ints), got {index!r}")
    if not -num_envs <= index < num_envs:
        raise IndexError(f"sub-env index {index} out of range for {num_envs} sub-envs")
    return int(index) % num_envs


def reset_mask(options: Any, num_envs: int, name: str) -> np.ndarray | None:
    """The checked ``reset_mask`` of a vector env's reset options, or None (every sub-env); the
    errors of ``SyncVectorEnv`` for a bad mask, and the scalar env's for other options."""
    options = check_reset_options(options, RESET_OPTIONS, name)
    if "reset_mask" not in options:
        return None
    mask = options["reset_mask"]
    if not isinstance(mask, np.ndarray):
        raise TypeError(f"options['reset_mask'] must be a numpy array, got {type(mask).__name__}")
    if mask.shape != (num_envs,):
        raise ValueError(f"options['reset_mask'] must have shape ({num_envs},), got {mask.shape}")
    if mask.dtype != np.bool_:
        raise TypeError(f"options['reset_mask'] must have dtype bool, got {mask.dtype}")
    if not mask.any():
        raise ValueError("options['reset_mask'] must have at least one True entry")
    return mask


class SubEnv:
    """Sub-env ``index`` of a :class:`TrackingVectorEnv`: a view of what one sub-env has alone.

    A native vector env holds no sub-env objects, only per-sub-env entries of its arrays; this
    view presents them as the attributes of the scalar env:

    - per sub-env: ``np_random`` (settable: its generator; ``np_random_seed`` becomes -1, as in
      gymnasium), ``np_random_seed``, ``elapsed_steps`` (steps in the current episode), and
      ``reset(seed=None, options=None)``: a partial reset of this sub-env alone, returning its
      observation and info (options as the scalar env's: none);
    - shared by every sub-env, read-only: ``task``, ``action_space`` and ``observation_space``
      (the single spaces), ``render_mode``, ``spec`` (a fresh copy of the spec that makes one
      sub-env, see :meth:`TrackingVectorEnv.single_spec`);
    - ``get_wrapper_attr``, ``has_wrapper_attr``, ``set_wrapper_attr``, as on a gymnasium env.

    Nothing else exists per sub-env: ``step``, ``close``, ``render`` and other names raise
    AttributeError (a sub-env steps with its batch), as does setting anything but ``np_random``.
    """

    __slots__ = ("_index", "_venv")
    _names = (
        "np_random", "np_random_seed", "elapsed_steps", "reset", "task", "action_space",
        "observation_space", "render_mode", "spec", "get_wrapper_attr", "has_wrapper_attr",
        "set_wrapper_attr",
    )  # fmt: skip

    def __init__(self, venv: TrackingVectorEnv, index: int) -> None:
        object.__setattr__(self, "_venv", venv)
        object.__setattr__(self, "_index", index)

    def __repr__(self) -> str:
        return f"SubEnv({type(self._venv).__name__}, index={self._index})"

    def __reduce__(self) -> tuple:
        """Pickled and copied as the view it is (its slots are set in ``__init__`` only)."""
        return type(self), (self._venv, self._index)

    def __getattr__(self, name: str) -> Any:
        raise AttributeError(
            f"{name!r} does not exist per sub-env of the native {type(self._venv).__name__} (a sub-env "
            f"steps, renders and closes with its batch); a sub-env has {', '.join(self._names)}"
        )

    def __setattr__(self, name: str, value: Any) -> None:
        if name != "np_random":
            raise AttributeError(
                f"cannot set {name!r} on one sub-env of the native {type(self._venv).__name__}: "
                "only np_random is per sub-env and settable"
            )
        object.__setattr__(self, name, value)

    @property
    def np_random(self) -> np.random.Generator:
        return self._venv._draws.generators[self._index]

    @np_random.setter
    def np_random(self, value: np.random.Generator) -> None:
        if not isinstance(value, np.random.Generator):  # else the next reset fails, far from here
            raise TypeError(f"np_random must be a numpy Generator, got {type(value).__name__}")
        self._venv._draws.set_generator(self._index, value)
        self._venv._seeds[self._index] = -1

    @property
    def np_random_seed(self) -> int:
        return self._venv._seeds[self._index]

    @property
    def elapsed_steps(self) -> int:
        return int(self._venv._t[self._index])

    @property
    def task(self) -> Any:
        return self._venv.task

    @property
    def action_space(self) -> gym.spaces.Box:
        return self._venv.single_action_space

    @property
    def observation_space(self) -> gym.spaces.Box:
        return self._venv.single_observation_space

    @property
    def render_mode(self) -> None:
        return self._venv.render_mode

    @property
    def spec(self) -> gym.envs.registration.EnvSpec | None:
        return self._venv.single_spec()

    def reset(
        self, *, seed: int | None = None, options: Mapping[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start a new episode in this sub-env only; its first observation and info."""
        venv = self._venv
        options = check_reset_options(options, {}, f"sub-env of {type(venv).__name__}")
        seeds: list[int | None] = [None] * venv.num_envs
        seeds[self._index] = seed
        mask = np.zeros(venv.num_envs, dtype=bool)
        mask[self._index] = True
        obs, _ = venv.reset(seed=seeds, options={**options, "reset_mask": mask})
        return obs[self._index], {}

    def get_wrapper_attr(self, name: str) -> Any:
        return getattr(self, name)

    def has_wrapper_attr(self, name: str) -> bool:
        return hasattr(self, name)

    def set_wrapper_attr(self, name: str, value: Any, *, force: bool = True) -> None:
        setattr(self, name, value)


__all__ = ["RESET_OPTIONS", "SubEnv", "reset_mask"]
