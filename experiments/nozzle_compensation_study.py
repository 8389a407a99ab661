"""Where the nozzle's hysteresis compensation gains: the Bouc-Wen joint against the linear one.

The LQ servo alone, with the inverse Bouc-Wen feedforward (scaled 1x and 2x), and with a plain
rate feedforward ``b r'`` (the joint's damping times the reference's rate, by differences) instead,
on the same references on Table 1's Bouc-Wen joint and on its linear row. A feedforward that
cancels hysteresis should gain on the first and not on the second. Prints and writes
experiments/results/nozzle_compensation_study.md.

    python experiments/nozzle_compensation_study.py [--episodes 20]
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from agents.base import task_of
from agents.lqi import LQIServo
from agents.plants import nozzle_joint
from agents.tvc import HysteresisCompensated
from ssme_envs.evaluation import evaluate
from ssme_envs.outputs import write_text
from ssme_envs.script_options import episodes_within_memory, script_parser

NOZZLE = "ssme_envs/NozzleTVC-v0"
# (reference / joint) -> the evaluation scenario that runs it
SCENARIO_OF = {
    "sine_sweep/bouc_wen": "sine_sweep",
    "sine_sweep/linear": "sine_sweep_linear",
    "attitude/bouc_wen": "attitude",
    "attitude/linear": "attitude_linear",
    "random_steps/bouc_wen": "random_steps",
    "random_steps/linear": "linear_plant",
}
OUT = Path(__file__).resolve().parent / "results" / "nozzle_compensation_study.md"


class RateFeedforward(LQIServo):
    """The LQ servo plus the damping torque of the reference's rate, ``b (r_k - r_(k-1)) / dt``."""

    def __init__(self, env: Any) -> None:
        super().__init__(env)
        task = task_of(env)
        self.damping, self.dt = nozzle_joint(task, "identified").b, task.dt

    def compute(self, obs: np.ndarray) -> np.ndarray:
        r = self.design.ports.read(obs)[1][:, 0]  # the reference, rad
        previous = self.state["r"][:, 0]  # the servo's last reference (NaN before the first)
        torque = self.damping * (r - np.where(np.isnan(previous), r, previous)) / self.dt
        return super().compute(obs) + (torque / self.design.ports.input_scale)[:, None]


def _compensated(scale: float) -> Any:
    def factory(env: Any) -> HysteresisCompensated:
        controller = HysteresisCompensated(env, LQIServo(env))
        controller.k_hys *= scale
        return controller

    return factory


FACTORIES = {
    "lqi": LQIServo,
    "lqi + compensation": _compensated(1.0),
    "lqi + 2x compensation": _compensated(2.0),
    "lqi + b r' feedforward": RateFeedforward,
}


def main() -> None:
    parser = script_parser(__doc__.splitlines()[0])
    parser.add_argument(
        "--episodes",
        type=episodes_within_memory(lambda: {NOZZLE: len(FACTORIES) * len(SCENARIO_OF)}),
        default=20,
    )
    args = parser.parse_args()
    scenarios = list(SCENARIO_OF)
    results = evaluate(NOZZLE, FACTORIES, list(SCENARIO_OF.values()), episodes=args.episodes)
    results = {label: results[SCENARIO_OF[label]] for label in scenarios}
    lines = [
        "# Nozzle hysteresis compensation on the Bouc-Wen and the linear joint",
        "",
        f"Command: `python experiments/nozzle_compensation_study.py --episodes {args.episodes}`. Tracking "
        "IAE (deg s) on NozzleTVC, mean over the episodes (the harness's seeds), change against the LQ "
        "servo alone in brackets.",
        "",
        "| reference / joint | " + " | ".join(FACTORIES) + " |",
        "|---|" + "---|" * len(FACTORIES),
    ]
    for scenario in scenarios:
        base = results[scenario]["lqi"]["outputs"]["angle"]["iae"]
        cells = []
        for name in FACTORIES:
            iae = results[scenario][name]["outputs"]["angle"]["iae"]
            cells.append(f"{iae:.4f}" + ("" if name == "lqi" else f" ({100 * (iae / base - 1):+.1f} %)"))
        lines.append(f"| {scenario} | " + " | ".join(cells) + " |")
    write_text(OUT, "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
