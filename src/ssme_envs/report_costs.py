"""The main report's table of each controller's cost over the zero action, with why each controller
above it costs more than doing nothing (:mod:`ssme_envs.report_causes`), and of the best learned
policy against the best classical design."""

from __future__ import annotations

import numpy as np

from ssme_envs.evaluation_result import ControllerMetrics, EvaluationResult
from ssme_envs.report_causes import (
    LAUNCHER,
    LEARNED,
    NOZZLE,
    SATURATED,
    THROTTLE,
    TRACKING,
    WRITTEN_CAUSES,
    is_classical,
    measured_causes,
    written_cause,
)


def _worse_tracking(metrics: ControllerMetrics, zero: ControllerMetrics) -> str:
    """The outputs tracked worse than with no action, as ISE ratios (a symptom, not a cause)."""
    worse = [
        f"{name} ISE {out.ise / zero.outputs[name].ise:.1f}x the zero action's"
        for name, out in metrics.outputs.items()
        if name in zero.outputs and zero.outputs[name].ise > 0 and out.ise > zero.outputs[name].ise
    ]
    return f" ({', '.join(worse)})" if worse else ""


def ratio_text(ratio: float) -> str:
    """A cost ratio for the tables: two decimals, or two significant digits below 0.1 (where two
    decimals left most of the nozzle's cells at 0.00)."""
    return f"{ratio:.2f}" if ratio >= 0.1 else f"{ratio:.2g}"


def over_zero(results: EvaluationResult) -> dict[tuple[str, str], float]:
    """``{(scenario, controller): cost / zero's cost}`` of every controller but `zero`, on the
    scenarios where `zero` ran with a positive cost."""
    ratios = {}
    for scenario, rows in results.items():
        zero = rows.get("zero")
        if zero is None or not zero.cost_mean > 0:
            continue
        for name, m in rows.items():
            if name != "zero":
                ratios[(scenario, name)] = m.cost_mean / zero.cost_mean
    return ratios


def unexplained(results: EvaluationResult) -> list[tuple[str, str]]:
    """(scenario, controller) of the classical controllers above the zero action with neither a
    measured nor a written cause."""
    from ssme_envs.evaluation import LAYOUTS

    unit = LAYOUTS[results.env_id].unit
    return [
        (s, c)
        for (s, c), ratio in over_zero(results).items()
        if ratio > 1.0 and is_classical(c) and not measured_causes(results[s][c], unit)
        and (results.env_id, s, c) not in WRITTEN_CAUSES
    ]  # fmt: skip


def cost_over_zero_tables(evaluations: dict[str, EvaluationResult]) -> list[str]:
    """One table per env of each controller's cost over the zero action's, and below it why each
    controller above 1.0 is there: measured causes, written ones, or UNEXPLAINED."""
    from ssme_envs.evaluation import LAYOUTS

    lines = [
        "### Cost over the zero action",
        "",
        "Each controller's mean episode cost divided by the zero action's on the same episodes: "
        "below 1.0 the controller beats doing nothing. Every controller above 1.0 has its cause "
        "below its table, from the metrics (early ends, limit cycles, time at the valve or torque "
        "limit) and from runs of the scenario.",
        "",
    ]
    for env_id, results in evaluations.items():
        ratios, unit = over_zero(results), LAYOUTS[env_id].unit
        names = list(dict.fromkeys(c for rows in results.values() for c in rows if c != "zero"))
        lines += [f"#### {env_id}", "", "| scenario | zero's cost | " + " | ".join(names) + " |"]
        lines.append("|---" * (len(names) + 2) + "|")
        for scenario, rows in results.items():
            cells = [ratio_text(ratios[(scenario, c)]) if (scenario, c) in ratios else "-" for c in names]
            zero = f"{rows['zero'].cost_mean:.3f}" if "zero" in rows else "-"
            lines.append(f"| {scenario} | {zero} | " + " | ".join(cells) + " |")
        above = [(s, c, r) for (s, c), r in ratios.items() if r > 1.0]
        lines.append("")
        for scenario, name, ratio in above:
            m = results[scenario][name]
            causes = measured_causes(m, unit)
            written = written_cause(results, scenario, name)
            said = "; ".join(causes + ([written] if written else []))
            if not said:
                said = (
                    "**UNEXPLAINED**: no measured or written cause" if is_classical(name)
                    else "a learned policy; no measured cause"
                )  # fmt: skip
            tracking = _worse_tracking(m, results[scenario]["zero"])
            lines.append(f"- {name} on {scenario}, {ratio:.2f}x{tracking}: {said}.")
        if above:
            lines.append("")
    return lines


LEARNED_GOAL = 1.10  # the benchmark's bar: the best learned cost over the best classical's
# (env, scenario) -> why the best learned policy stays above the bar there, from runs of the scenario
LEARNED_SHORT: dict[tuple[str, str], str] = {
    (TRACKING, "stuck_valve"): "a fault no policy was trained on (every EngineTracking config is "
    "fault-free); the residual's base, the LQ servo, is above the zero action there",
    (TRACKING, "ramp"): "the residuals (trained on random steps, whose episodes cost over 100x a "
    "ramp's) add thousandths to their base's cost of 0.01; the quiet one, its correction penalized, "
    "adds the least",
    (NOZZLE, "attitude"): "the residual adds a few thousandths to a cost of 0.02 (an attitude "
    "episode costs about 1 % of a random-step one in the mixed references it was trained on)",
    (NOZZLE, "attitude_linear"): "on the linear joint the residual, trained on the hysteretic one, "
    "adds a few thousandths to the LQ servo's cost of 0.017",
    (NOZZLE, "sine_sweep_strong_linear"): "the residual's base, the hysteresis compensation designed "
    "for Table 1's joint, costs over twice the LQ servo's on a joint without hysteresis, and the "
    "residual was trained on the hysteretic joint only",
}


def best_of_each(
    results: EvaluationResult, skip: tuple[str, ...] = ()
) -> dict[str, tuple[str, float, str, float]]:
    """``{scenario: (best classical, its cost, best learned, its cost)}`` on the scenarios where
    both kinds ran (classical designs on the identified model and on the truth alike), leaving
    out the controllers named in ``skip``."""
    best = {}
    for scenario, rows in results.items():
        kept = {c: m.cost_mean for c, m in rows.items() if c not in skip}
        classical = {c: cost for c, cost in kept.items() if is_classical(c)}
        learned = {c: cost for c, cost in kept.items() if c.split(":")[0] in LEARNED}
        if classical and learned:
            c, lc = min(classical.items(), key=lambda kv: kv[1])
            p, lp = min(learned.items(), key=lambda kv: kv[1])
            best[scenario] = (c, lc, p, lp)
    return best


def ratio_standard_error(results: EvaluationResult, scenario: str, top: str, bottom: str) -> float | None:
    """Standard error of the ratio of two controllers' mean episode costs on the same episodes:
    ``std(a_i - r b_i) / (sqrt(n) mean(b))`` (the ratio estimator's, paired); None without both
    controllers' per-episode costs (their rollouts)."""
    from ssme_envs.robustness import episode_costs

    runs = results.rollouts
    if (scenario, top) not in runs or (scenario, bottom) not in runs:
        return None
    a, b = episode_costs(runs[(scenario, top)]), episode_costs(runs[(scenario, bottom)])
    if len(a) != len(b) or len(a) < 2 or not b.mean() > 0:
        return None
    r = a.mean() / b.mean()
    return float(np.std(a - r * b, ddof=1) / (np.sqrt(len(a)) * b.mean()))


def learned_over_classical_tables(
    evaluations: dict[str, EvaluationResult], skip: tuple[str, ...] = ()
) -> list[str]:
    """Per env and scenario the best learned policy's cost over the best classical design's
    (controllers in ``skip`` left out)."""
    lines = [
        "### Best learned policy against the best classical design",
        "",
        f"Per scenario the cheapest classical design (on the identified model or on the truth) and the "
        f"cheapest shipped policy, on the same episodes; the benchmark's bar is {LEARNED_GOAL:.2f}x. "
        "`ppo:residual` is PPO trained to add a correction to a classical design's action "
        "(agents/residual.py): it starts from that design, so it shows what learning adds to it "
        "(`ppo:residual_quiet`: trained with the correction's square taken off its reward, so that it "
        "corrects less); `ppo` learns the whole action. The standard error is the ratio's over the "
        "episodes, both run on the same ones (paired); a ratio within two of them of another is not "
        "told apart from it by these episodes.",
        "",
        "| env | scenario | best classical | cost | best learned | cost | learned / classical "
        "(+- 2 standard errors) |",
        "|---|---|---|---|---|---|---|",
    ]
    above = []
    for env_id, results in evaluations.items():
        for scenario, (c, lc, p, lp) in best_of_each(results, skip).items():
            flag = ""
            if lp > LEARNED_GOAL * lc:
                flag = " (above the bar)"
                above.append((env_id, scenario))
            se = ratio_standard_error(results, scenario, p, c)
            spread = "" if se is None else f" +- {2 * se:.2g}"
            lines.append(
                f"| {env_id} | {scenario} | {c} | {lc:.3f} | {p} | {lp:.3f} | {lp / lc:.2f}{spread}{flag} |"
            )
    if above:
        lines.append("")
        for env_id, scenario in above:
            said = LEARNED_SHORT.get((env_id, scenario), "**no written reason**")
            lines.append(f"- {env_id.split('/')[-1]} {scenario}: {said}.")
    return lines


__all__ = [
    "LAUNCHER",
    "LEARNED",
    "LEARNED_GOAL",
    "LEARNED_SHORT",
    "NOZZLE",
    "SATURATED",
    "THROTTLE",
    "TRACKING",
    "WRITTEN_CAUSES",
    "best_of_each",
    "cost_over_zero_tables",
    "is_classical",
    "learned_over_classical_tables",
    "measured_causes",
    "over_zero",
    "ratio_standard_error",
    "ratio_text",
    "unexplained",
]
