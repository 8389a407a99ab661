"""Where the nozzle's hysteresis compensation gains: the Bouc-Wen joint against the linear one.

The LQ servo alone, with the inverse Bouc-Wen feedforward (scaled 1x and 2x), and with a plain
rate feedforward ``b r'`` (the joint's damping times the reference's rate, by differences) instead,
on the same references on Table 1's Bouc-Wen joint and on its linear row. A feedforward that
cancels hysteresis should gain on the first and not on the second. Prints and writes
experiments/results/nozzle_compensation_study.md.

    python experiments/nozzle_compensation_study.py [--episodes 20]
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from agents.base import DEG, task_of
from agents.lqi import LQIServo
from agents.plants import nozzle_joint
from agents.tvc import HysteresisCompensated
from ssme_envs.evaluation import SCENARIOS, evaluate

NOZZLE = "ssme_envs/NozzleTVC-v0"
REFERENCES = ("sine_sweep", "attitude", "random_steps")
OUT = Path(__file__).resolve().parent / "results" / "nozzle_compensation_study.md"


class RateFeedforward(LQIServo):
    """The LQ servo plus the damping torque of the reference's rate, ``b (r_k - r_(k-1)) / dt``."""

    def __init__(self, env: Any) -> None:
        super().__init__(env)
        task = task_of(env)
        self.damping, self.dt = nozzle_joint(task, "identified").b, task.dt

    def initial_state(self, n: int) -> dict[str, np.ndarray]:
        return super().initial_state(n) | {"r_previous": np.full(n, np.nan)}

    def compute(self, obs: np.ndarray) -> np.ndarray:
        r = obs[:, 2] / DEG
        previous = np.where(np.isnan(self.state["r_previous"]), r, self.state["r_previous"])
        self.state["r_previous"] = r
        torque = self.damping * (r - previous) / self.dt
        return super().compute(obs) + (torque / self.design.ports.input_scale)[:, None]


def _compensated(scale: float) -> Any:
    def factory(env: Any) -> HysteresisCompensated:
        controller = HysteresisCompensated(env, LQIServo(env))
        controller.k_hys *= scale
        return controller

    return factory


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=20)
    args = parser.parse_args()
    scenarios = []
    for reference in REFERENCES:
        for joint in ("bouc_wen", "linear"):
            name = f"{reference}/{joint}"
            SCENARIOS[NOZZLE][name] = {"reference": reference, "plant": joint}
            scenarios.append(name)
    factories = {
        "lqi": LQIServo,
        "lqi + compensation": _compensated(1.0),
        "lqi + 2x compensation": _compensated(2.0),
        "lqi + b r' feedforward": RateFeedforward,
    }
    results = evaluate(NOZZLE, factories, scenarios, episodes=args.episodes)
    lines = [
        "# Nozzle hysteresis compensation on the Bouc-Wen and the linear joint",
        "",
        f"Command: `python experiments/nozzle_compensation_study.py --episodes {args.episodes}`. Tracking "
        "IAE (deg s) on NozzleTVC, mean over the episodes (the harness's seeds), change against the LQ "
        "servo alone in brackets.",
        "",
        "| reference / joint | " + " | ".join(factories) + " |",
        "|---|" + "---|" * len(factories),
    ]
    for scenario in scenarios:
        base = results[scenario]["lqi"]["outputs"]["angle"]["iae"]
        cells = []
        for name in factories:
            iae = results[scenario][name]["outputs"]["angle"]["iae"]
            cells.append(f"{iae:.4f}" + ("" if name == "lqi" else f" ({100 * (iae / base - 1):+.1f} %)"))
        lines.append(f"| {scenario} | " + " | ".join(cells) + " |")
    OUT.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
