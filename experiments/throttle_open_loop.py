"""Open loop on the nominal valve schedule: the linked engine model flies the mission profile.

Runs EngineThrottle-v0 with zero action (valves on u_eq(P), truth with backlash, stiction, lambda,
no sensor noise) and plots Pc and MR against their references, the valves, and the DC gains of
the linked model over 65-109 %. Writes experiments/results/throttle_open_loop.png and prints the
tracking errors.

    python experiments/throttle_open_loop.py
"""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import ssme_envs  # noqa: F401
from agents.base import columns
from ssme_envs.models.engine import POWER_LEVELS
from ssme_envs.models.linked import POWER_RANGE, LinkedEngineModel
from ssme_envs.outputs import save_figure
from ssme_envs.script_options import script_parser

OUT = Path(__file__).resolve().parent / "results" / "throttle_open_loop.png"


def main() -> None:
    env = gym.make("ssme_envs/EngineThrottle-v0", truth={"sensor_noise": 0.0})
    env.reset(seed=0)
    task = env.unwrapped.task
    shown = columns(task.observation, "pc_pct", "mr_pct", "pc_ref_pct", "mr_ref_pct")
    rows = []
    for _ in range(task.horizon):
        obs, *_ = env.step(np.zeros(2, np.float32))
        rows.append([*obs[list(shown)], *task.valve_positions(env.unwrapped._state[0])])
    rows = np.array(rows)
    t = np.arange(1, task.horizon + 1) * task.dt
    linked = LinkedEngineModel()
    grid = np.linspace(*POWER_RANGE, 300)
    gains = np.array([linked.dc_gain(p) for p in grid])
    fig, axes = plt.subplots(2, 2, figsize=(11, 6))
    for i, name in enumerate(("Pc", "MR")):
        ax = axes[i, 0]
        ax.plot(t, rows[:, i], "k", lw=1.2, label=f"{name} (open loop)")
        ax.plot(t, rows[:, 2 + i], "r--", lw=1.0, label="reference")
        ax.set_ylabel(f"{name} deviation (% of 100 %)")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    axes[1, 0].set_xlabel("time (s)")
    axes[0, 1].plot(t, rows[:, 4], label="OPOV")
    axes[0, 1].plot(t, rows[:, 5], label="FPOV")
    axes[0, 1].set_ylabel("valve (normalized, 0 at 100 %)")
    axes[0, 1].legend(fontsize=8)
    axes[0, 1].grid(alpha=0.3)
    for (i, j), style in zip(((0, 0), (0, 1), (1, 0), (1, 1)), ("-", "--", "-.", ":"), strict=True):
        axes[1, 1].plot(grid, gains[:, i, j], style, label=f"G[{i},{j}]")
    for p in POWER_LEVELS:
        axes[1, 1].axvline(p, color="0.8", lw=0.8)
    axes[1, 1].set_xlabel("power (%)")
    axes[1, 1].set_ylabel("DC gain of the linked model")
    axes[1, 1].legend(fontsize=8, ncol=2)
    axes[1, 1].grid(alpha=0.3)
    fig.suptitle("EngineThrottle-v0 open loop on the nominal valve schedule (mission profile, 60 s)")
    fig.tight_layout()
    save_figure(fig, OUT, dpi=110)
    err = rows[:, 2:4] - rows[:, :2]
    print(f"max |error| Pc {np.abs(err[:, 0]).max():.2f} %, MR {np.abs(err[:, 1]).max():.2f} %; wrote {OUT}")


if __name__ == "__main__":
    script_parser(__doc__.splitlines()[0]).parse_args()  # --help; any argument refused
    main()
