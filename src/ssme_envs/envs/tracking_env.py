"""What the single tracking envs share: setup from options, episode draws, reset options, the
end-of-episode rule, render and close."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from ssme_envs.envs.rendering import close_figure, render_history


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
    """Base of the single tracking envs. A subclass names its task constructor (``build_task``)
    and what it draws (``output_names``, ``actuator_names``, ``display_scale``,
    ``display_units``); it keeps ``self._history`` rows (outputs, references, actuators) for
    rendering.

    ``reset`` takes no options (``None`` or ``{}``; anything else raises). ``step`` after the
    episode ended (terminated or truncated), or before the first ``reset``, raises
    :class:`EpisodeOverError`: call ``reset`` first."""

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 25}
    output_names: tuple[str, ...] = ()
    actuator_names: tuple[str, ...] = ()
    display_scale: float = 100.0
    display_units: tuple[str, str] = ("%", "normalized")
    build_task: Any = None

    def __init__(self, render_mode: str | None = None, **options: Any) -> None:
        self.task = self.build_task(**options)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}"
            )
        self.render_mode = render_mode
        self.action_space = gym.spaces.Box(-1.0, 1.0, (self.task.n_actions,), dtype=np.float32)
        self.observation_space = self.task.observation_space()
        self._low, self._high = self.observation_space.low, self.observation_space.high
        self._history: list[list[float]] = []
        self._figure = None
        self._t = 0
        self._ended = "never reset"  # why step() is refused: "" while an episode runs

    reset_options: Mapping[str, str] = {}  # the keys ``reset(options=...)`` accepts: none

    @property
    def elapsed_steps(self) -> int:
        """Steps taken in the current episode."""
        return self._t

    def _draw_episode(
        self, seed: int | None, options: Any = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Check the reset options, seed, draw the episode as the vector env does: references
        (channels, T + 1), unit noise (channels, T + 1) and the first observation (clipped)."""
        check_reset_options(options, self.reset_options, type(self).__name__)
        gym.Env.reset(self, seed=seed)
        self._ended = ""
        uniforms = self.np_random.random(self.task.draw_size, dtype=np.float32)
        refs, noise = self.task.episodes(uniforms[:, None])
        obs = self.task.initial_observation(refs[:, 0], noise[:, 0])[:, 0]
        self._t = 0
        return refs[:, :, 0], noise[:, :, 0], np.clip(obs, self._low, self._high)

    def _check_running(self) -> None:
        """Refuse a step outside an episode (after its end, or before the first reset)."""
        if self._ended:
            raise EpisodeOverError(f"the episode is over ({self._ended}): call reset() before step()")

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array' or 'human'")
            return None
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
