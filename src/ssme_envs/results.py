"""Evaluation results as files: results.json, a markdown table per scenario, response plots."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from ssme_envs.evaluation import Rollout, layout_of
from ssme_envs.evaluation_result import ControllerMetrics, EvaluationResult, OutputMetrics
from ssme_envs.metrics import AT_LIMIT_TOL
from ssme_envs.outputs import save_figure, write_text


def _clean(value: Any) -> Any:
    """JSON-ready: NaN and inf become null, numpy scalars plain numbers."""
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    if isinstance(value, float | np.floating):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def _fmt(value: float | None, digits: int = 3) -> str:
    if value is None or not math.isfinite(value):
        return "-"
    return f"{value:.{digits}g}" if abs(value) < 1e4 else f"{value:.3e}"


def _limit_cycle_cell(o: OutputMetrics) -> str:
    """Share of episodes with a limit cycle, its median period and amplitude; "none <= X s" when
    the windows showed none with a period up to X; "-" when no window was long enough."""
    share = o.limit_cycle_fraction
    if not math.isfinite(share):
        return "-"
    if share == 0:
        return f"none ≤ {_fmt(o.limit_cycle_longest_period, 2)} s"
    return f"{100 * share:.0f} % ({_fmt(o.limit_cycle_period, 2)} s, ±{_fmt(o.limit_cycle_amplitude, 2)})"


def scenario_table(env_id: str, scenario: str, rows: dict[str, ControllerMetrics]) -> str:
    """A markdown table of every controller's metrics on one scenario."""
    layout = layout_of(env_id)
    head = ["controller", "return", "cost CVaR90", "ends"]
    for out in layout.outputs:
        head += [f"{out} IAE", f"{out} ITAE", f"{out} overshoot %", f"{out} settling s", f"{out} ss err",
                 f"{out} limit cycle (period, ±amplitude)"]  # fmt: skip
    for act in layout.actuators:
        head += [f"{act} reversals", f"{act} % of time at limit"]
    lines = [f"**{scenario}** (errors in {layout.unit}, times in s)", "", "| " + " | ".join(head) + " |"]
    lines.append("|" + "---|" * len(head))
    for name, m in rows.items():
        cells = [
            name,
            f"{m.return_mean:.3f} ± {m.return_std:.3f}",
            _fmt(m.cost_cvar90),
            str(m.terminations),
        ]
        for out in layout.outputs:
            o = m.outputs[out]
            cells += [_fmt(o.iae), _fmt(o.itae), _fmt(o.overshoot), _fmt(o.settling_time),
                      _fmt(o.steady_state_error), _limit_cycle_cell(o)]  # fmt: skip
        for act in layout.actuators:
            a = m.actuators[act]
            cells += [_fmt(a.reversals), _fmt(100 * a.time_at_limit, 2)]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot_scenario(env_id: str, scenario: str, runs: dict[str, Rollout], path: Path) -> None:
    """Responses of the first episode of every controller overlaid: one panel per output (and its
    reference), one per actuator."""
    from ssme_envs.identification.report_figures import agg_pyplot

    plt = agg_pyplot()
    layout = layout_of(env_id)
    panels = len(layout.outputs) + len(layout.actuators)
    fig, axes = plt.subplots(panels, 1, figsize=(8, 2.2 * panels), sharex=True, squeeze=False)
    for c, (name, run) in enumerate(runs.items()):
        steps = int(run.alive[:, 0].sum())
        t = np.arange(steps + 1) * run.dt
        color = f"C{c}"
        for i, out in enumerate(layout.outputs):
            ax = axes[i, 0]
            if c == 0:
                ax.plot(
                    t, run.obs[: steps + 1, 0, layout.reference_columns[i]], "k--", lw=1, label="reference"
                )
            ax.plot(t, run.obs[: steps + 1, 0, layout.output_columns[i]], color=color, lw=1, label=name)
            ax.set_ylabel(f"{out} ({layout.unit})")
        for j, act in enumerate(layout.actuators):
            ax = axes[len(layout.outputs) + j, 0]
            ax.step(t[1:], run.actions[:steps, 0, j], where="pre", color=color, lw=1)
            ax.set_ylabel(f"{act} action")
    axes[0, 0].legend(loc="best", fontsize=8, ncol=2)
    axes[-1, 0].set_xlabel("time (s)")
    fig.suptitle(f"{env_id}: {scenario} (first episode)")
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    plt.close(fig)


def write_evaluation(results: EvaluationResult, out: Path, command: str) -> Path:
    """results.json, results.md and one PNG per scenario under ``out``; returns results.md."""
    out.mkdir(parents=True, exist_ok=True)
    env_id = results.env_id
    data = {"env": env_id, "command": command, "scenarios": results.to_dict()}
    write_text(out / "results.json", json.dumps(_clean(data), indent=1) + "\n")
    lines = [f"# Evaluation on {env_id}", "", f"Command: `{command}`", ""]
    lines += [
        "Return: mean ± std over the episodes (higher is better); cost CVaR90: mean cost of the worst 10 %; "
        "ends: episodes terminated early. IAE, ITAE over the episode; overshoot and settling time (2 %) on "
        "single-step references; ss err: mean |error| over each episode's own last 10 % (at least one "
        "step), averaged over the episodes; limit cycle: "
        "share of the episodes (of those long enough to test) whose error oscillates persistently while "
        "the references hold still "
        "(autocorrelation of each stretch of constant reference after its first quarter: at least three "
        "regular cycles carrying more power than the sensor noise, not decaying), with the median period "
        "and sine-equivalent amplitude (error unit); 'none ≤ X s': none found with a period up to X, the "
        "longest the stretches could show; '-': no stretch long enough. Reversals: changes of direction "
        "of each actuator per episode (wear); % of time at limit: share of the episode's steps at which "
        "the action the env applied (after its clip to [-1, 1]) sat at full scale (within "
        f"{AT_LIMIT_TOL:g} of it), whatever the controller requested.",
        "",
    ]
    for scenario in results:
        figure = f"{scenario}.png"
        plot_scenario(env_id, scenario, results.runs(scenario), out / figure)
        lines += [scenario_table(env_id, scenario, results[scenario]), "", f"![{scenario}]({figure})", ""]
    path = out / "results.md"
    write_text(path, "\n".join(lines))
    return path


__all__ = ["plot_scenario", "scenario_table", "write_evaluation"]
