"""The benchmark's RL line: on every scenario of every env, the best shipped policy beside the best
classical design, with each shipped policy's training record.

    python experiments/learned_vs_classical.py [--episodes 50]

Evaluates the main report's classical controllers (``ssme_envs.pipelines.report_plan``) and every
shipped policy (``ppo``, ``ppo:identified``, ``ppo:spread``, ``ppo:residual``,
``ppo:residual_quiet`` where the env has one) on every scenario of each env
(``ssme_envs.evaluation.scenario_names``) with the harness (seed 0, the same episodes for every
controller), and writes
experiments/results/learned_vs_classical.md. The residual policies are trained by
``ssme-envs train --config experiments/configs/ppo_<env>_residual.toml --out
agents/policies/<Env>-v0-residual`` (EngineTracking's quiet one from
``ppo_engine_tracking_residual_quiet.toml`` into ``EngineTracking-v0-residual_quiet``).
"""

from __future__ import annotations

import json
from pathlib import Path

import tomllib
from tried_runs import CONFIG_STEMS, REMAKE, TRIED, missing_note, missing_runs, tried_runs

from agents import parse_controller
from agents.shipped import shipped_specs
from ssme_envs.evaluation import evaluate, scenario_names
from ssme_envs.outputs import write_text
from ssme_envs.pipelines import report_plan
from ssme_envs.report_costs import LEARNED_GOAL, best_of_each, learned_over_classical_tables
from ssme_envs.script_options import episodes_within_memory, script_parser

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results" / "learned_vs_classical.md"
SEED = 0


def training_rows() -> list[str]:
    rows = [
        "| policy | config | residual base (scale) | steps | wall-clock s | kept at |",
        "|---|---|---|---|---|---|",
    ]
    for env_id in CONFIG_STEMS:
        for folder in shipped_specs(env_id).values():
            name = folder.name
            summary = json.loads((folder / "training.json").read_text())
            config = tomllib.loads((folder / "config.toml").read_text())
            residual = f"{config['residual']} ({config['residual_scale']:g})" if "residual" in config else "-"
            kept = f"{summary['kept']['steps']:,}" if "kept" in summary else "not recorded"
            rows.append(
                f"| {name} | agents/policies/{name}/config.toml | {residual} | {summary['steps']:,} | "
                f"{summary['seconds']:.0f} | {kept} |"
            )
    return rows


def controller_specs() -> dict[str, dict[str, str]]:
    """``{env id: {name in the tables: controller spec}}``: the report's classical controllers,
    the shipped policies and the tried runs found."""
    plan = {}
    for env_id, (specs, _) in report_plan(learned=True).items():
        names = [s for s in specs if not s.startswith("ppo")] + list(shipped_specs(env_id))
        plan[env_id] = {name: name for name in names}
        plan[env_id].update({name: f"{name.split(':')[0]}:{run}" for name, run in tried_runs(env_id).items()})
    return plan


def plan() -> dict[str, int]:
    """``{env id: scenario-controller pairs}`` of the run, for the memory check of --episodes."""
    return {env_id: len(specs) * len(scenario_names(env_id)) for env_id, specs in controller_specs().items()}


def main() -> None:
    parser = script_parser(__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=episodes_within_memory(plan), default=50)
    args = parser.parse_args()
    evaluations = {}
    for env_id, specs in controller_specs().items():
        scenarios = scenario_names(env_id)
        factories = {name: parse_controller(spec, env_id) for name, spec in specs.items()}
        names = list(specs)
        print(f"{env_id}: {', '.join(names)} on {', '.join(scenarios)}", flush=True)
        evaluations[env_id] = evaluate(env_id, factories, scenarios, args.episodes, SEED)
    bests = {env_id: best_of_each(r, tuple(TRIED)) for env_id, r in evaluations.items()}
    counts = ", ".join(
        f"{e.split('/')[-1]} {sum(lp <= LEARNED_GOAL * lc for _, lc, _, lp in b.values())} of {len(b)}"
        for e, b in bests.items()
    )
    lines = [
        "# Learned policies against classical designs",
        "",
        f"Command: `python experiments/learned_vs_classical.py --episodes {args.episodes}` (seed {SEED}, the "
        "same episodes for every controller; every scenario of each env, the main report's classical "
        "controllers and every shipped policy of the env; the runs tried beside them (experiments/tried/) "
        "appear in the cost tables only: SAC, TD3, and `ppo:penalty`, NozzleTVC's residual trained with "
        "residual_penalty = 1.0).",
        "",
        *learned_over_classical_tables(evaluations, tuple(TRIED))[2:],
        "",
        f"Scenarios where the best learned policy is within {LEARNED_GOAL:.2f}x the best classical design: "
        f"{counts}.",
        "",
        "## Every cost",
        "",
    ]
    for env_id, results in evaluations.items():
        names = list(dict.fromkeys(c for rows in results.values() for c in rows))
        header = "| scenario | " + " | ".join(names) + " |"
        lines += [f"### {env_id}", "", header, "|---" * (len(names) + 1) + "|"]
        for scenario, rows in results.items():
            cells = " | ".join(f"{rows[c].cost_mean:.3f}" if c in rows else "-" for c in names)
            lines.append(f"| {scenario} | {cells} |")
        lines.append("")
    lines += ["## Training of the shipped policies (this machine's 2 CPU cores)", "", *training_rows(), ""]
    tried = [(e, a, r) for e in evaluations for a, r in tried_runs(e).items()]
    if tried:
        lines += [
            "Tried beside them (configs in experiments/configs/; each run's kept policy and training "
            f"record in experiments/tried/NAME/, not a controller of the package; `{REMAKE}` trains one "
            "again, RL training being chaotic, to a policy of its own: see experiments/tried/README.md):",
            "",
        ]
        for env_id, algo, run in tried:
            summary = json.loads((run / "training.json").read_text())
            lines.append(
                f"- {env_id} {algo}: experiments/configs/{run.name}.toml, {summary['steps']:,} steps in "
                f"{summary['seconds']:.0f} s, the policy of {summary['kept']['steps']:,} steps kept"
            )
        lines.append("")
    lines += missing_note([run for e in evaluations for run in missing_runs(e)])
    write_text(RESULTS, "\n".join(lines))
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main()
