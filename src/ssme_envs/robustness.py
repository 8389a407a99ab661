"""Robustness evaluation: every controller over N plants drawn from a spread (Monte Carlo).

An env that takes the ``plant_spread`` option draws the plant of each episode afresh (see
:mod:`ssme_envs.envs.plant_spread`); evaluating N episodes of a scenario with it is evaluating
each controller on N drawn plants, the same N for every controller (the same seeds). The
summary per controller is the episode cost's mean, its worst case and its CVaR (the mean of the
worst 10 %), beside the same controller's mean cost on the nominal plant when given.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from ssme_envs.evaluation_result import EvaluationResult
from ssme_envs.outputs import write_text

DEFAULT_SPREAD = 0.2  # relative (log-normal) spread of each joint parameter
CVAR_LEVEL = 0.9


class RobustnessRow(NamedTuple):
    """One controller over the drawn plants of one scenario: episode cost mean, worst, CVaR
    (mean of the worst 10 %), episodes that left the envelope, and the plants drawn."""

    mean: float
    worst: float
    cvar: float
    terminations: int
    plants: int


def spread_envs() -> list[str]:
    """The envs of the catalogue that draw their plant per episode (take ``plant_spread``)."""
    from ssme_envs.envs.catalogue import ENVS

    return [env_id for env_id, entry in ENVS.items() if "plant_spread" in entry.default_options]


def spread_options(env_id: str, spread: float | str = DEFAULT_SPREAD) -> dict[str, Any]:
    """The env options of a Monte-Carlo evaluation: ``{"plant_spread": spread}``; ValueError if the
    env cannot draw its plant, or the spread is not a number in (0, 0.5] or ``"uncertainty"``."""
    supported = spread_envs()
    if env_id not in supported:
        raise ValueError(
            f"{env_id} has one plant in every episode; --monte-carlo needs an env that draws its plant "
            f"per episode: {', '.join(supported)}"
        )
    if isinstance(spread, str) and spread != "uncertainty":
        try:
            spread = float(spread)
        except ValueError:
            raise ValueError(f"plant spread must be a number or 'uncertainty', got {spread!r}") from None
    # the env takes 0 as one plant in every episode: no Monte Carlo, whatever the table would say
    if not isinstance(spread, str) and not spread > 0:
        raise ValueError(f"plant spread must be above 0 to draw plants, got {spread!r}")
    return {"plant_spread": spread}


def episode_costs(run: Any) -> np.ndarray:
    """Each episode's cost (minus its return, counted until its first end), (N,)."""
    return -(run.rewards * run.alive).sum(axis=0)


def cvar(costs: np.ndarray, level: float = CVAR_LEVEL) -> float:
    """The mean of the worst ``1 - level`` share of the costs: of the ``ceil((1 - level) N)``
    largest of N (at least one)."""
    count = max(1, math.ceil(round((1.0 - level) * len(costs), 9)))  # 0.1 * 200 = 20, not 20.000001
    return float(np.sort(costs)[len(costs) - count :].mean())


def summarize(costs: np.ndarray, terminations: int = 0) -> RobustnessRow:
    """Mean, worst case and CVaR (at :data:`CVAR_LEVEL`) of episode costs."""
    return RobustnessRow(float(costs.mean()), float(costs.max()), cvar(costs), terminations, len(costs))


def robustness(result: EvaluationResult) -> dict[str, dict[str, RobustnessRow]]:
    """``{scenario: {controller: RobustnessRow}}`` of a Monte-Carlo evaluation."""
    table: dict[str, dict[str, RobustnessRow]] = {}
    for (scenario, controller), run in result.rollouts.items():
        steps = run.alive.sum(axis=0)
        ended = int((steps < len(run.alive)).sum())
        table.setdefault(scenario, {})[controller] = summarize(episode_costs(run), ended)
    return table


def robustness_markdown(
    result: EvaluationResult,
    spread: float | str,
    nominal: EvaluationResult | None = None,
    notes: Mapping[str, str] | None = None,
) -> list[str]:
    """A markdown table per scenario: mean, worst and CVaR of the cost over the drawn plants
    (and the nominal plant's mean cost beside, when ``nominal`` holds the scenario); ``notes``
    by controller, written under the table."""
    what = f"relative spread {spread:g} (log-normal, +-3 sigma)" if isinstance(spread, float) else str(spread)
    lines = []
    for scenario, rows in robustness(result).items():
        plants = next(iter(rows.values())).plants
        lines += [
            f"**{result.env_id.split('/')[-1]}, {scenario}**: {plants} plants drawn with {what}, the same "
            "plants for every controller.",
            "",
            "| controller | nominal plant mean | drawn plants mean | worst | CVaR 90 % | left the envelope |",
            "|---|---|---|---|---|---|",
        ]
        for name, row in rows.items():
            base = nominal[scenario][name].cost_mean if nominal and scenario in nominal else None
            nominal_cell = "-" if base is None else f"{base:.3f}"
            lines.append(
                f"| {name} | {nominal_cell} | {row.mean:.3f} | {row.worst:.3f} | {row.cvar:.3f} | "
                f"{row.terminations} of {row.plants} |"
            )
        for name, note in (notes or {}).items():
            if name in rows:
                lines.append(f"\n- `{name}`: {note}")
        for name, twin in same_costs(result, scenario).items():
            lines.append(
                f"\n- `{name}` gives every episode the cost `{twin}` gives it, to the bit: the two act "
                "alike on these plants (a row repeated, not a typo)."
            )
        lines.append("")
    return lines


def same_costs(result: EvaluationResult, scenario: str) -> dict[str, str]:
    """``{controller: the first controller before it with the same episode costs, bit for bit}``
    on one scenario of a Monte-Carlo evaluation."""
    runs = [(c, episode_costs(run)) for (s, c), run in result.rollouts.items() if s == scenario]
    twins = {}
    for i, (name, costs) in enumerate(runs):
        for earlier, theirs in runs[:i]:
            if earlier not in twins and np.array_equal(costs, theirs):
                twins[name] = earlier
                break
    return twins


def robustness_dict(
    result: EvaluationResult, nominal: EvaluationResult | None = None
) -> dict[str, dict[str, dict[str, float]]]:
    """The table as plain dicts, for robustness.json, with each controller's mean cost on the
    nominal plant (``nominal_mean``) where ``nominal`` holds the scenario."""
    table = {s: {c: row._asdict() for c, row in rows.items()} for s, rows in robustness(result).items()}
    for scenario, rows in table.items():
        if nominal is not None and scenario in nominal:
            for name, row in rows.items():
                row["nominal_mean"] = nominal[scenario][name].cost_mean
    return table


def write_robustness(
    out: Path, result: EvaluationResult, nominal: EvaluationResult | None, spread: float | str, command: str
) -> Path:
    """robustness.md and robustness.json under ``out``; returns robustness.md."""
    lines = [f"# Robustness on {result.env_id}", "", f"Command: `{command}`", ""]
    lines += [
        "Each episode runs on a plant of its own, drawn from the spread with the episode's seed; cost: "
        f"minus the return. Worst: the largest episode cost; CVaR {CVAR_LEVEL:.0%}: the mean of the worst "
        f"{1 - CVAR_LEVEL:.0%}. Nominal plant mean: the same episodes (references, noise) on the "
        "nominal plant.",
        "",
        *robustness_markdown(result, spread, nominal),
    ]
    data = {
        "env": result.env_id,
        "command": command,
        "plant_spread": spread,
        "scenarios": robustness_dict(result, nominal),
    }
    write_text(out / "robustness.json", json.dumps(data, indent=1) + "\n")
    path = out / "robustness.md"
    write_text(path, "\n".join(lines) + "\n")
    return path


__all__ = [
    "CVAR_LEVEL",
    "DEFAULT_SPREAD",
    "RobustnessRow",
    "cvar",
    "episode_costs",
    "robustness",
    "robustness_dict",
    "robustness_markdown",
    "same_costs",
    "spread_envs",
    "spread_options",
    "summarize",
    "write_robustness",
]
