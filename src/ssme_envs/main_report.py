"""The main job's report.md: identification of both plants, then the controller comparisons."""

from __future__ import annotations

import inspect
import re
from pathlib import Path

from ssme_envs.evaluation import SCENARIOS
from ssme_envs.evaluation_result import EvaluationResult
from ssme_envs.outputs import write_text
from ssme_envs.report_causes import options_text
from ssme_envs.report_costs import (
    LAUNCHER,
    NOZZLE,
    THROTTLE,
    TRACKING,
    WRITTEN_CAUSES,
    cost_over_zero_tables,
    is_classical,
    learned_over_classical_tables,
    measured_causes,
    over_zero,
    unexplained,
)

# env -> the controllers `ssme-envs report` evaluates, on every scenario of the env
REPORT_CONTROLLERS: dict[str, str] = {
    TRACKING: "zero,pi,lqi,mpc,ppo,pi:truth,lqi:truth,mpc:truth,lq:truth,ppo:identified,ppo:residual,"
    "ppo:residual_quiet",
    THROTTLE: "zero,pi,pi_scheduled,scheduled,scheduled:truth,ppo,ppo:residual",
    NOZZLE: "zero,pid,lqi,hysteresis,ppo,ppo:residual",
    LAUNCHER: "zero,pid,lqi,robust,ppo,ppo:residual",
}
REPORT_PLAN: dict[str, tuple[str, list[str]]] = {
    env_id: (specs, list(SCENARIOS[env_id])) for env_id, specs in REPORT_CONTROLLERS.items()
}

# env -> (controllers, scenarios) run over drawn plants (plant_spread, DEFAULT_SPREAD), PLANTS_PER_EPISODE
# times the report's --episodes plants: 200 by default
ROBUSTNESS_PLAN: dict[str, tuple[str, list[str]]] = {
    NOZZLE: ("zero,pid,lqi,robust,hysteresis,ppo,ppo:spread", ["random_steps", "sine_sweep"]),
    LAUNCHER: ("zero,pid,lqi,robust,ppo", ["random_steps", "attitude"]),
}
PLANTS_PER_EPISODE = 10


def robustness_folder(env_id: str) -> str:
    """The report's folder of an env's robustness run."""
    return env_id.split("/")[-1] + "-robustness"


def _embedded(path: Path, folder: str, levels: int = 1) -> list[str]:
    """A sub-report's lines, headings ``levels`` down and figure paths into its folder."""
    text = path.read_text()
    text = re.sub(r"!\[([^\]]*)\]\((?!http)([^)]+)\)", lambda m: f"![{m[1]}]({folder}/{m[2]})", text)
    return [("#" * levels + line if line.startswith("#") else line) for line in text.splitlines()]


def _cost(results: EvaluationResult, scenario: str, controller: str) -> float:
    return results[scenario][controller].cost_mean


def _reversals(results: EvaluationResult, scenario: str, controller: str) -> str:
    acts = results[scenario][controller].actuators
    return " / ".join(f"{a.reversals:.1f}" for a in acts.values())


def engine_tables(results: EvaluationResult) -> list[str]:
    """LQI against PI on the linear plant, and what the valves (backlash, stiction) cost each."""
    lines = [
        "### EngineTracking: LQI against decoupled PI, and what the valves cost",
        "",
        "Episode cost (minus the return; lower is better) on random steps, noise off: `nominal` is the "
        "published linear model (no lambda, backlash or stiction); `valves` adds lambda (asymmetric "
        "gains), backlash and stiction. Reversals: changes of direction per episode, OPOV / FPOV (wear, "
        "limit cycles).",
        "",
        "| controller | cost nominal | cost with valves | valves add | reversals nominal "
        "| reversals with valves |",
        "|---|---|---|---|---|---|",
    ]
    for name in [c for c in ("pi", "lqi", "mpc", "ppo") if c in results["nominal"]]:
        nominal, valves = _cost(results, "nominal", name), _cost(results, "valves", name)
        lines.append(
            f"| {name} | {nominal:.3f} | {valves:.3f} | {100 * (valves / nominal - 1):+.0f} % | "
            f"{_reversals(results, 'nominal', name)} | {_reversals(results, 'valves', name)} |"
        )
    ratio = _cost(results, "nominal", "lqi") / _cost(results, "nominal", "pi")
    lines += [
        "",
        f"On the nominal plant LQI's cost is {100 * ratio:.0f} % of decoupled PI's "
        f"({100 * (1 - ratio):.0f} % lower).",
        "",
        "### Sim-to-real: designed on the identified model, evaluated on the truth",
        "",
        "Cost on the full truth (lambda, backlash, stiction, sensor noise; scenario `noise`) of each "
        "design on the identified model and on the truth's own linear model.",
        "",
        "| controller | designed on identified | designed on truth | gap |",
        "|---|---|---|---|",
    ]
    for name in ("pi", "lqi", "mpc", "ppo"):
        # a classical design names its truth variant, the learned policy its identified one
        pair = (name, f"{name}:truth") if name != "ppo" else ("ppo:identified", "ppo")
        if all(p in results["noise"] for p in pair):
            ident, truth = _cost(results, "noise", pair[0]), _cost(results, "noise", pair[1])
            lines.append(f"| {name} | {ident:.3f} | {truth:.3f} | {100 * (ident / truth - 1):+.1f} % |")
    if "ppo" in results["noise"]:
        lines += [
            "",
            "PPO: the shipped policy trained on the full truth (`ppo`) and the one trained on the "
            "identified linear model (`ppo:identified`), both evaluated on the truth. In the first table "
            "`ppo` is the truth-trained policy on plants it was not trained on.",
            "",
            *rl_table(results),
        ]
    return lines


def rl_table(results: EvaluationResult) -> list[str]:
    """Learned against classical on the nominal plant, with the valves, and on the full truth."""
    scenarios = ("nominal", "valves", "noise")
    limit = "lq:truth" if "lq:truth" in results["nominal"] else None
    lines = [
        "### RL against the classical designs",
        "",
        "Episode cost on the nominal linear plant, with the valves (lambda, backlash, stiction) and on "
        "the full truth (plus sensor noise). `lq:truth` is the reward's LQ-optimal tracker designed on "
        "the true linear model (reference feedforward, negligible integral action): the physical limit "
        "on the nominal plant.",
        "",
        "| controller | nominal | with valves | full truth |" + (f" nominal / {limit} |" if limit else ""),
        "|---|---|---|---|" + ("---|" if limit else ""),
    ]
    names = ("pi", "lqi", "mpc", "lqi:truth", "lq:truth", "ppo", "ppo:identified")
    for name in [n for n in names if all(n in results[s] for s in scenarios)]:
        costs = " | ".join(f"{_cost(results, s, name):.3f}" for s in scenarios)
        ratio = _cost(results, "nominal", name) / _cost(results, "nominal", limit) if limit else None
        lines.append(f"| {name} | {costs} |" + (f" {ratio:.2f} |" if limit else ""))
    return lines


# NozzleTVC scenarios on the Bouc-Wen joint -> the same references on the linear joint
LINEAR_TWINS = {
    "sine_sweep": "sine_sweep_linear",
    "attitude": "attitude_linear",
    "random_steps": "linear_plant",
    "sine_sweep_strong": "sine_sweep_strong_linear",
}


def nozzle_tables(results: EvaluationResult) -> list[str]:
    lines = [
        "### NozzleTVC: hysteresis compensation",
        "",
        "Tracking IAE (deg s) on the Bouc-Wen joint of the LQ servo (`lqi`) alone and with the inverse "
        "Bouc-Wen feedforward (`hysteresis`), and of the PID; the `*_linear` scenarios and "
        "`linear_plant` (random steps) run the same references on the linear joint.",
        "",
        "| scenario | pid | lqi | lqi + compensation | change |",
        "|---|---|---|---|---|",
    ]
    change, ended = {}, False
    for scenario in results:
        rows = {c: results[scenario][c] for c in ("pid", "lqi", "hysteresis")}
        iae = {c: m.outputs["angle"].iae for c, m in rows.items()}
        change[scenario] = 100 * (iae["hysteresis"] / iae["lqi"] - 1)
        # an episode's IAE stops where it ends: a cost the IAE does not show
        cells = [
            f"{iae[c]:.4f}" + (f" ({m.terminations} of {m.episodes} ended early)" if m.terminations else "")
            for c, m in rows.items()
        ]
        ended = ended or any(m.terminations for m in rows.values())
        lines.append(f"| {scenario} | {' | '.join(cells)} | {change[scenario]:+.1f} % |")
    if ended:
        lines += [
            "",
            "An episode that leaves the envelope ends there, and its IAE counts only the steps before: "
            "where episodes ended early, the IAE understates the tracking (the cost tables above charge "
            "the steps left).",
        ]
    pairs = [(bw, lin) for bw, lin in LINEAR_TWINS.items() if bw in change and lin in change]
    if pairs:
        shares = ", ".join(f"{bw} {change[bw] - change[lin]:+.1f} (against {lin})" for bw, lin in pairs)
        lines += [
            "",
            "What the compensation does about hysteresis: its change on the Bouc-Wen joint minus its change "
            "on the same joint's linear twin (Table 1's linear row, or the strong joint's own for "
            f"sine_sweep_strong) under the same references, in points: {shares}.",
        ]
        helps = [lin for _, lin in pairs if change[lin] < 0]
        hurts = [lin for _, lin in pairs if change[lin] > 0]
        if helps:
            lines[-1] += (
                f" Its gain on the linear twins ({', '.join(helps)}) is torque along the motion, which "
                "helps a joint without hysteresis too."
            )
        if hurts:
            lines[-1] += (
                f" On {', '.join(hurts)} it adds to the cost (its feedforward is the inverse of the "
                "identified Table 1 joint's hysteresis)."
            )
    return lines


def reward_lines(evaluations: dict[str, EvaluationResult]) -> list[str]:
    """Each evaluated env's reward, as its own docs (the env class's "Rewards" section) give it."""
    import gymnasium as gym
    from gymnasium.envs.registration import load_env_creator

    lines = []
    for env_id in evaluations:
        entry = gym.spec(env_id).entry_point
        doc = inspect.getdoc(entry if callable(entry) else load_env_creator(entry)) or ""
        found = re.search(r"^## [^\n]*Rewards\n(.*?)(?:\n\n|\Z)", doc, re.S | re.M)
        said = " ".join(found.group(1).split()) if found else "see the env's docs"
        lines.append(f"- {env_id}: {said}")
    return lines


def write_main_report(
    out: Path,
    evaluations: dict[str, EvaluationResult],
    episodes: int,
    seconds: float,
    shown: Path | None = None,
) -> Path:
    """report.md under ``out`` from the identification reports in out/engine and out/nozzle and
    the evaluations (``{env_id: evaluate() result}``, written to out/<env name>/).

    ``shown`` is the --out of the command line quoted in the report (default ``out``), when
    ``out`` is the temporary directory the run is built in.
    """
    lines = [
        "# ssme-envs: identification and controller comparison",
        "",
        f"Command: `ssme-envs report --out {shown or out} --episodes {episodes}` ({seconds:.0f} s). "
        "Every number below but that run time comes from a seeded run and is reproduced bit for bit by "
        "the same command on a machine of the same CPU family (numpy's float32 log1p, sin and cos, which "
        "make the envs' sensor noise, differ in their last bits between SIMD builds: see the README's "
        "vector env section).",
        "",
        "## Controllers",
        "",
        f"Each controller is designed on the identified model (`name:truth`: on the truth's linear model) "
        f"and evaluated on the truth, {episodes} episodes per scenario (episode i seeded with i, "
        f"i = 0..{episodes - 1}), the same episodes for every controller. An episode's cost is minus its "
        "return, the sum of the env's rewards (what each scenario sets is listed under \"Every "
        'scenario" below):',
        "",
        *reward_lines(evaluations),
        "",
        *cost_over_zero_tables(evaluations),
        *learned_over_classical_tables(evaluations),
        "",
    ]
    if TRACKING in evaluations:
        lines += [*engine_tables(evaluations[TRACKING]), ""]
    if NOZZLE in evaluations:
        lines += [*nozzle_tables(evaluations[NOZZLE]), ""]
    lines += ["### Every scenario", ""]
    for env_id, results in evaluations.items():
        folder = env_id.split("/")[-1]
        scenarios = list(results)
        lines += [f"#### {env_id}", "", f"Tables and plots: [{folder}/results.md]({folder}/results.md).", ""]
        lines += [f"![{scenarios[0]}]({folder}/{scenarios[0]}.png)", ""]
        for scenario in scenarios:
            costs = ", ".join(f"{c} {m.cost_mean:.3f}" for c, m in results[scenario].items())
            options = options_text(SCENARIOS[env_id].get(scenario, {})) or "the env's defaults"
            lines.append(f"- {scenario} ({options}): cost {costs}")
        lines.append("")
    robust = [
        env_id for env_id in ROBUSTNESS_PLAN if (out / robustness_folder(env_id) / "robustness.md").exists()
    ]
    if robust:
        from agents.robust import DESIGN_PLANTS, PROCESS_RATIOS, RATE_FACTORS

        rates = ", ".join(f"{f:g}" for f in RATE_FACTORS)
        ratios = " or ".join(f"{r:g} %" for r in PROCESS_RATIOS)
        lines += [
            "## Robustness: plants drawn per episode",
            "",
            "Each controller over the same plants, drawn per episode with the nozzle joint's parameters "
            "spread (log-normal, relative 0.2, +-3 sigma; J, b, k_el, k_hys, beta_n, gamma_n), designed on "
            "the nominal identified model. `robust` is the LQ servo with its weights chosen for each "
            f"scenario, on its own references and noise, for the smallest CVaR over {DESIGN_PLANTS} plants "
            f"drawn around the *design* model (agents/robust.py): its action-change weight R times one of "
            f"{rates} and its Kalman filter's process-noise ratio {ratios}; where the nominal weights win, "
            "its rows are the nominal servo's (`lqi`). `ppo:spread` is the PPO policy trained with the "
            "plant drawn per episode, `ppo` the one trained on the nominal plant.",
            "",
        ]
        for env_id in robust:
            folder = robustness_folder(env_id)
            lines += [*_embedded(out / folder / "robustness.md", folder, levels=2), ""]  # "### Robustness on"
    lines += ["## Identification", ""]
    for folder in ("engine", "nozzle"):
        if (out / folder / "report.md").exists():
            lines += [*_embedded(out / folder / "report.md", folder), ""]
    path = out / "report.md"
    write_text(path, "\n".join(lines) + "\n")
    return path


__all__ = [
    "PLANTS_PER_EPISODE",
    "REPORT_PLAN",
    "ROBUSTNESS_PLAN",
    "WRITTEN_CAUSES",
    "cost_over_zero_tables",
    "engine_tables",
    "is_classical",
    "measured_causes",
    "nozzle_tables",
    "over_zero",
    "rl_table",
    "robustness_folder",
    "unexplained",
    "write_main_report",
]
