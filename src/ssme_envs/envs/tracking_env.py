"""What the single tracking envs share: setup from options, episode draws, render and close."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from ssme_envs.envs.rendering import close_figure, render_history


class TrackingEnv(gym.Env):
    """Base of the single tracking envs. A subclass names its task constructor (``build_task``)
    and what it draws (``output_names``, ``actuator_names``, ``display_scale``,
    ``display_units``); it keeps ``self._history`` rows (outputs, references, actuators) for
    rendering."""

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

    def _draw_episode(self, seed: int | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Seed, draw the episode as the vector env does: references (channels, T + 1), unit noise
        (channels, T + 1) and the first observation (clipped)."""
        gym.Env.reset(self, seed=seed)
        uniforms = self.np_random.random(self.task.draw_size, dtype=np.float32)
        refs, noise = self.task.episodes(uniforms[:, None])
        obs = self.task.initial_observation(refs[:, 0], noise[:, 0])[:, 0]
        self._t = 0
        return refs[:, :, 0], noise[:, :, 0], np.clip(obs, self._low, self._high)

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
