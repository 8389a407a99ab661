"""Rendering of the tracking environments: outputs against references, and actuators, over time."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np


def render_history(
    history: np.ndarray,
    dt: float,
    figure: Any,
    mode: str,
    output_names: Sequence[str],
    actuator_names: Sequence[str],
    scale: float = 100.0,
    units: tuple[str, str] = ("%", "normalized"),
) -> tuple[np.ndarray | None, Any]:
    """Draw ``history`` (rows: outputs, references, actuators) and return (RGB image or None, figure).

    ``history`` columns are the p outputs, the p references, then the actuator positions; outputs
    and references are multiplied by ``scale`` for display. The figure is created on the first
    call and reused.
    """
    import matplotlib

    if mode == "rgb_array":
        matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    p = len(output_names)
    if figure is None:
        figure, _ = plt.subplots(p + 1, 1, figsize=(6, 1.8 * (p + 1)), sharex=True)
    axes = figure.axes
    t = np.arange(history.shape[0]) * dt
    for i, ax in enumerate(axes[:p]):
        ax.clear()
        ax.plot(t, scale * history[:, i], color="k", lw=1.2, label=output_names[i])
        ax.plot(t, scale * history[:, p + i], color="tab:red", ls="--", lw=1.0, label="reference")
        ax.set_ylabel(f"{output_names[i]} ({units[0]})")
        ax.legend(loc="upper right", fontsize=7)
        ax.grid(alpha=0.3)
    ax = axes[p]
    ax.clear()
    for j, name in enumerate(actuator_names):
        ax.step(t, history[:, 2 * p + j], where="post", lw=1.0, label=name)
    ax.set_ylabel(f"actuators ({units[1]})")
    ax.set_xlabel("time (s)")
    ax.legend(loc="upper right", fontsize=7)
    ax.grid(alpha=0.3)
    figure.tight_layout()
    figure.canvas.draw()
    if mode == "human":
        plt.pause(0.001)
        return None, figure
    image = np.asarray(figure.canvas.buffer_rgba())[..., :3].copy()
    return image, figure


def close_figure(figure: Any) -> None:
    import matplotlib.pyplot as plt

    plt.close(figure)


class HistoryRendering:
    """Setup, ``render`` and ``close`` of a tracking env: it keeps ``self._history`` rows (outputs,
    references, actuators) and its figure in ``self._figure``; the env class names what it draws."""

    output_names: tuple[str, ...] = ()
    actuator_names: tuple[str, ...] = ()
    display_scale: float = 100.0
    display_units: tuple[str, str] = ("%", "normalized")

    def _setup(self, render_mode: str | None, options: dict[str, Any]) -> None:
        """Build the task from the options, check the render mode, make the spaces."""
        import gymnasium as gym

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

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            import gymnasium as gym

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
