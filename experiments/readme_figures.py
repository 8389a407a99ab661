"""The controller and RL figures the README quotes, evaluated by the harness on the shipped
design models and policies (seed 0, the same episodes for every controller). Writes
experiments/results/readme_figures.md; tests/test_readme_figures.py checks the README against it.

    python experiments/readme_figures.py [--episodes 50]
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

from agents import parse_controller
from ssme_envs.evaluation import evaluate
from ssme_envs.evaluation_result import EvaluationResult
from ssme_envs.outputs import write_text
from ssme_envs.script_options import episodes_within_memory, script_parser

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "experiments" / "results" / "readme_figures.md"
TRACKING = "ssme_envs/EngineTracking-v0"
THROTTLE = "ssme_envs/EngineThrottle-v0"
NOZZLE = "ssme_envs/NozzleTVC-v0"
# env -> (controllers, scenarios) evaluated
RUNS = {
    TRACKING: (["lqi", "lq:truth", "ppo", "ppo:residual"], ["nominal", "noise"]),
    THROTTLE: (["scheduled", "ppo", "ppo:residual"], ["mission", "mission_nonlinear"]),
    NOZZLE: (
        ["lqi", "hysteresis", "ppo", "ppo:residual"],
        ["random_steps", "sine_sweep_strong", "sine_sweep_strong_linear"],
    ),
}


def _cost(r: EvaluationResult, scenario: str, name: str) -> float:
    return r[scenario][name].cost_mean


def _iae(r: EvaluationResult, scenario: str, name: str) -> float:
    return r[scenario][name].outputs["angle"].iae


STRONG_LQI, STRONG_HYS = ("sine_sweep_strong", "lqi"), ("sine_sweep_strong", "hysteresis")


def _ratio(value: float) -> str:
    return f"{value:.2f}x" if value < 2 else f"{value:.1f}x"


def _cost_over(env_id: str, scenario: str, name: str, reference: str) -> Callable[[dict], str]:
    """The figure "cost of ``name`` over the cost of ``reference``" on one scenario of one env."""
    return lambda e: _ratio(_cost(e[env_id], scenario, name) / _cost(e[env_id], scenario, reference))


# figure -> (what it is, how it reads in the README from the evaluations)
FIGURES: dict[str, tuple[str, Callable[[dict[str, EvaluationResult]], str]]] = {
    "strong_lqi_over_linear": (
        "NozzleTVC strong joint, sine sweep: LQ servo's IAE over its IAE on the linear twin",
        lambda e: _ratio(
            _iae(e[NOZZLE], "sine_sweep_strong", "lqi") / _iae(e[NOZZLE], "sine_sweep_strong_linear", "lqi")
        ),
    ),
    "strong_compensation_cut": (
        "NozzleTVC strong joint, sine sweep: IAE cut by the hysteresis compensation",
        lambda e: f"{100 * (1 - _iae(e[NOZZLE], *STRONG_HYS) / _iae(e[NOZZLE], *STRONG_LQI)):.0f} %",
    ),
    "tracking_ppo_over_lqi_nominal": (
        "EngineTracking nominal: PPO cost over the LQ servo's",
        _cost_over(TRACKING, "nominal", "ppo", "lqi"),
    ),
    "tracking_ppo_over_lq_truth_nominal": (
        "EngineTracking nominal: PPO cost over the LQ-optimal tracker's on the true linear model",
        _cost_over(TRACKING, "nominal", "ppo", "lq:truth"),
    ),
    "tracking_ppo_over_lqi_noise": (
        "EngineTracking full truth (valves, noise): PPO cost over the LQ servo's",
        _cost_over(TRACKING, "noise", "ppo", "lqi"),
    ),
    "throttle_ppo_over_scheduled": (
        "EngineThrottle mission: PPO cost over the scheduled servo's",
        _cost_over(THROTTLE, "mission", "ppo", "scheduled"),
    ),
    "tracking_residual_over_lq_truth_nominal": (
        "EngineTracking nominal: residual PPO (over the LQ servo) over the LQ-optimal tracker on the truth",
        _cost_over(TRACKING, "nominal", "ppo:residual", "lq:truth"),
    ),
    "throttle_residual_over_scheduled": (
        "EngineThrottle mission: residual PPO (over the scheduled servo) cost over the scheduled servo's",
        _cost_over(THROTTLE, "mission", "ppo:residual", "scheduled"),
    ),
    "throttle_residual_over_scheduled_nonlinear": (
        "EngineThrottle mission on the nonlinear engine: residual PPO cost over the scheduled servo's",
        _cost_over(THROTTLE, "mission_nonlinear", "ppo:residual", "scheduled"),
    ),
    "nozzle_residual_over_hysteresis_strong": (
        "NozzleTVC strong joint, sine sweep: residual PPO (over the compensated servo) cost over its base's",
        _cost_over(NOZZLE, "sine_sweep_strong", "ppo:residual", "hysteresis"),
    ),
    "nozzle_ppo_over_lqi": (
        "NozzleTVC random steps: PPO cost over the LQ servo's",
        _cost_over(NOZZLE, "random_steps", "ppo", "lqi"),
    ),
}


def training_steps(env_id: str) -> int:
    """Steps the shipped PPO policy of ``env_id`` was trained for (its training.json)."""
    folder = ROOT / "agents" / "policies" / env_id.split("/")[-1]
    return int(json.loads((folder / "training.json").read_text())["steps"])


def evaluations(
    episodes: int, runs: dict[str, tuple[list[str], list[str]]] = RUNS
) -> dict[str, EvaluationResult]:
    """The harness's evaluations behind the figures (seed 0)."""
    return {
        env_id: evaluate(env_id, {n: parse_controller(n, env_id) for n in names}, scenarios, episodes, seed=0)
        for env_id, (names, scenarios) in runs.items()
    }


def table(results: dict[str, EvaluationResult], episodes: int) -> str:
    """readme_figures.md: one row per figure, then the shipped policies' training steps."""
    lines = [
        "# Figures quoted in the README",
        "",
        f"Command: `python experiments/readme_figures.py --episodes {episodes}`. The harness "
        f"(`ssme_envs.evaluation.evaluate`, seed 0, {episodes} episodes per scenario, the same for "
        "every controller) on the shipped design models and PPO policies (`agents/policies/`).",
        "",
        "| figure | value | what |",
        "|---|---|---|",
    ]
    lines += [f"| {key} | {fn(results)} | {what} |" for key, (what, fn) in FIGURES.items()]
    lines += ["", "| policy | training steps |", "|---|---|"]
    lines += [f"| {env_id} | {training_steps(env_id):,} |" for env_id in (TRACKING, THROTTLE, NOZZLE)]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = script_parser(__doc__.splitlines()[0])
    pairs = {env_id: len(names) * len(scenarios) for env_id, (names, scenarios) in RUNS.items()}
    parser.add_argument("--episodes", type=episodes_within_memory(lambda: pairs), default=50)
    args = parser.parse_args()
    text = table(evaluations(args.episodes), args.episodes)
    write_text(OUT, text)
    print(text)


if __name__ == "__main__":
    main()
