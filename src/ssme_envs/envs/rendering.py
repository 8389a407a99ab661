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
