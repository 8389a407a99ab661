"""Library functions for each arrow of the pipeline: identify, validate, evaluate, the main report.

Each reads and checks its inputs first, then writes into a fresh directory beside ``out_dir``
that is swapped in for it only when the function succeeds, under a lock that refuses a second
concurrent run into the same directory (:func:`ssme_envs.outputs.run_directory`). Errors in what
was given are ValueErrors naming the file or option; ``ssme-envs`` prints them as its one
``error:`` line. ``progress`` (default: silent) receives a line when a long step starts.
"""

from __future__ import annotations

import importlib.util
import os
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from ssme_envs.cli_checks import check_episodes
from ssme_envs.evaluation_result import EvaluationResult
from ssme_envs.identification.jobs import (  # the identification arrows, re-exported
    EngineRun,
    NozzleRun,
    Progress,
    _silent,
    engine_embedded_into,
    identify_engine,
    identify_nozzle,
    load_engine_model,
    nozzle_into,
    validate_engine,
)
from ssme_envs.main_report import PLANTS_PER_EPISODE, robustness_folder
from ssme_envs.outputs import output_directory
from ssme_envs.robustness import DEFAULT_SPREAD, spread_options, write_robustness


def _factories(env_id: str, controllers: Sequence[str] | Mapping[str, Callable] | None,
               allow_pickle: bool) -> dict[str, Callable]:  # fmt: skip
    """Controller factories by name: given, or parsed from specs (default: every one for the env)."""
    from agents import controller_names, parse_controller
    from ssme_envs.evaluation import check_distinct, check_factories

    if isinstance(controllers, Mapping):
        check_factories(controllers)
        return dict(controllers)
    if isinstance(controllers, str):  # a list of specs, not one spec split into its letters
        raise TypeError(f"controllers must be a list of controller specs, got the string {controllers!r}")
    names = controller_names(env_id) if controllers is None else list(controllers)
    factories = {name: parse_controller(name, env_id, allow_pickle) for name in names}  # checks each
    check_distinct(names, "controller")
    return factories


def evaluation_inputs(
    plant: str | Path | None, controllers: Sequence[str] | Mapping[str, Callable] | None, prefix: str = ""
) -> dict[str, str | Path]:
    """The files and directories an evaluation reads, by name (``prefix`` + plant, + controllers
    SPEC): a plant given as a model.json and the run directories of controller specs."""
    found: dict[str, str | Path] = {}
    if isinstance(plant, str | os.PathLike) and Path(plant).exists():  # else the env names it
        found[f"{prefix}plant"] = plant
    specs = [] if controllers is None or isinstance(controllers, Mapping | str) else controllers
    for spec in specs:
        run = str(spec).partition(":")[2]
        if run and Path(run).exists():
            found[f"{prefix}controllers {spec}"] = run
    return found


def _evaluate_into(
    work: Path,
    env_id: str,
    factories: Mapping[str, Callable],
    scenarios: Sequence[str] | None,
    episodes: int,
    seed: int,
    command: str,
    progress: Progress,
    spread: float | str | None = None,
    plant: str | None = None,
) -> EvaluationResult:
    """Evaluate and write results.json, results.md and the plots into ``work``; with a
    ``spread`` (Monte Carlo), every episode on a plant of its own, and robustness.md and
    robustness.json beside (:func:`_robustness_into`); ``plant``: every scenario's plant."""
    from ssme_envs.evaluation import evaluate
    from ssme_envs.results import write_evaluation

    nominal = {} if plant is None else {"plant": plant}
    options = {**nominal, **({} if spread is None else spread_options(env_id, spread))} or None
    result = evaluate(env_id, factories, scenarios, episodes, seed, progress=progress, options=options)
    write_evaluation(result, work, command)
    if spread is not None:
        _robustness_into(work, result, factories, episodes, seed, spread, command, progress, nominal or None)
    return result


def _robustness_into(
    work: Path, drawn: EvaluationResult, factories: Mapping[str, Callable], episodes: int, seed: int,
    spread: float | str, command: str, progress: Progress, options: Mapping[str, Any] | None = None,
) -> None:  # fmt: skip
    """robustness.md and .json in ``work`` for the drawn-plant evaluation ``drawn``, the nominal
    plant's mean cost from a second run on the same seeds (with the env ``options``)."""
    from ssme_envs.evaluation import evaluate

    progress("the same episodes on the nominal plant ...")
    nominal = evaluate(
        drawn.env_id, factories, list(drawn), episodes, seed, progress=progress, options=options
    )
    write_robustness(work, drawn, nominal, spread, command)


def evaluate_to(
    out_dir: str | Path,
    env_id: str,
    controllers: Sequence[str] | Mapping[str, Callable] | None = None,
    scenarios: Sequence[str] | None = None,
    episodes: int = 20,
    seed: int = 0,
    *,
    allow_pickle: bool = False,
    command: str | None = None,
    progress: Progress = _silent,
    monte_carlo: int | None = None,
    plant_spread: float | str = DEFAULT_SPREAD,
    plant: str | None = None,
) -> EvaluationResult:
    """Evaluate controllers on an env's scenarios; write results.json, results.md and plots.

    Parameters
    ----------
    controllers : sequence of str or mapping, optional
        Controller specs (``pi``, ``lqi:truth``, ``ppo:RUN_DIR``, ...) or factories by name
        (default: every controller of the env).
    scenarios : sequence of str, optional
        Default: every scenario of the env.
    episodes : int
        Per scenario; checked against the free memory first.
    command : str, optional
        The command line quoted in results.md (default: this call's ``ssme-envs evaluate``).
    monte_carlo : int, optional
        Robustness: run each controller over this many plants drawn with ``plant_spread`` (a
        relative spread, or ``"uncertainty"``: the model.json's covariance), one per episode
        (``episodes`` is then this number), and write robustness.md: mean, worst case and CVaR
        per controller, the nominal plant's mean beside (:mod:`ssme_envs.robustness`).
    plant : str, optional
        The env's ``plant`` option for every scenario, in place of the scenario's own (a plant
        name such as ``"identified"``, or a model.json path).

    Returns
    -------
    EvaluationResult
    """
    from ssme_envs.evaluation import check_env_id, check_scenarios, scenario_names

    check_env_id(env_id)
    names = scenario_names(env_id) if scenarios is None else check_scenarios(env_id, scenarios)
    spread = None
    if monte_carlo is not None:
        spread = spread_options(env_id, plant_spread)["plant_spread"]  # checked before any work
        episodes = monte_carlo
    factories = _factories(env_id, controllers, allow_pickle)
    check_episodes(
        episodes,
        {env_id: len(names) * len(factories) * (1 if spread is None else 2)},
        "--episodes" if spread is None else "--monte-carlo",
    )
    if command is None:
        runs = (
            f"--episodes {episodes}"
            if spread is None
            else f"--monte-carlo {episodes} --plant-spread {spread}"
        ) + ("" if plant is None else f" --plant {plant}")
        command = (f"ssme-envs evaluate --env {env_id} --controllers {','.join(factories)} --scenario "
                   f"{','.join(names)} {runs} --seed {seed} --out {out_dir}")  # fmt: skip
    with output_directory(out_dir, evaluation_inputs(plant, controllers)) as work:
        return _evaluate_into(
            work, env_id, factories, scenarios, episodes, seed, command, progress, spread, plant
        )


def report_plan(learned: bool | None = None) -> dict[str, tuple[list[str], list[str]]]:
    """``{env_id: (controller specs, scenarios)}`` of the main report, every env of the catalogue in
    its order; the PPO policies only when stable-baselines3 is installed (``learned`` None: find
    out)."""
    from ssme_envs.envs.catalogue import ENVS
    from ssme_envs.main_report import REPORT_PLAN

    if learned is None:
        learned = importlib.util.find_spec("stable_baselines3") is not None
    plan = {}
    for env_id in ENVS:  # every env has its plan (tests/test_catalogue_readers.py)
        specs, scenarios = REPORT_PLAN[env_id]
        plan[env_id] = ([s for s in specs.split(",") if learned or not s.startswith("ppo")], scenarios)
    return plan


def robustness_plan(learned: bool | None = None) -> dict[str, tuple[list[str], list[str]]]:
    """``{env_id: (controller specs, scenarios)}`` of the main report's robustness runs (the
    policies only when stable-baselines3 is installed)."""
    from ssme_envs.main_report import ROBUSTNESS_PLAN

    if learned is None:
        learned = importlib.util.find_spec("stable_baselines3") is not None
    return {
        env_id: ([s for s in specs.split(",") if learned or not s.startswith("ppo")], scenarios)
        for env_id, (specs, scenarios) in ROBUSTNESS_PLAN.items()
    }


def run_report(out_dir: str | Path, episodes: int = 20, progress: Progress = _silent) -> Path:
    """The main job: identify the engine and the nozzle on their embedded experiments, evaluate the
    controllers of each env on its scenarios, and write report.md (sub-reports in engine/,
    nozzle/ and one folder per env) under ``out_dir``. Returns the report's path."""
    from ssme_envs.main_report import write_main_report

    out_dir = Path(out_dir)
    learned = importlib.util.find_spec("stable_baselines3") is not None
    plan = report_plan(learned)
    check_episodes(episodes, {e: len(s) * len(c) for e, (c, s) in plan.items()})
    robust = robustness_plan(learned)
    check_episodes(PLANTS_PER_EPISODE * episodes, {e: 2 * len(s) * len(c) for e, (c, s) in robust.items()})
    start = time.perf_counter()
    with output_directory(out_dir) as work:
        progress("identifying the engine (embedded experiment, five power levels) ...")
        engine_embedded_into(work / "engine", None, {})
        progress("identifying the nonlinear engine truth (the same experiment) ...")
        from ssme_envs.identification.engine_nonlinear_pipeline import nonlinear_into

        nonlinear_into(work / "engine")
        progress("identifying the nozzle (bench test) ...")
        nozzle_into(work / "nozzle", None, None, 2, None, None, progress)
        if not learned:
            progress("stable-baselines3 is not installed: the report leaves out the PPO policies "
                     '(pip install ".[rl]")')  # fmt: skip
        evaluations = {}
        for env_id, (specs, scenarios) in plan.items():
            folder = env_id.split("/")[-1]
            command = (
                f"ssme-envs evaluate --env {env_id} --controllers {','.join(specs)} --scenario "
                f"{','.join(scenarios)} --episodes {episodes} --out {out_dir / folder}"
            )
            progress(f"evaluating on {env_id} ...")
            factories = _factories(env_id, specs, False)
            evaluations[env_id] = _evaluate_into(
                work / folder, env_id, factories, scenarios, episodes, 0, command, progress
            )
        plants = PLANTS_PER_EPISODE * episodes
        for env_id, (specs, scenarios) in robust.items():
            folder = robustness_folder(env_id)
            command = (
                f"ssme-envs evaluate --env {env_id} --controllers {','.join(specs)} --scenario "
                f"{','.join(scenarios)} --monte-carlo {plants} --out {out_dir / folder}"
            )
            progress(f"robustness on {env_id}: {plants} drawn plants ...")
            factories = _factories(env_id, specs, False)
            _evaluate_into(
                work / folder, env_id, factories, scenarios, plants, 0, command, progress, DEFAULT_SPREAD
            )
        write_main_report(work, evaluations, episodes, time.perf_counter() - start, shown=out_dir)
    return out_dir / "report.md"


__all__ = [
    "EngineRun",
    "NozzleRun",
    "evaluate_to",
    "evaluation_inputs",
    "identify_engine",
    "identify_nozzle",
    "load_engine_model",
    "report_plan",
    "run_report",
    "validate_engine",
]
