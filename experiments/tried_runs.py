"""The runs tried beside the package's policies: where they live and which are missing.

Each run's kept policy, its config and its training record lie in experiments/tried/NAME/
(``ssme-envs train --config experiments/configs/NAME.toml --out experiments/tried/NAME`` makes
one), so the records of learned_vs_classical.py and launcher_rl.py come from files in the
repository. They are not controllers of the package (``agents.shipped``). A run found missing is
left out of the tables, and the records say which.
"""

from __future__ import annotations

from pathlib import Path

HERE = Path(__file__).resolve().parent
RUNS = HERE / "tried"
# name in the tables -> experiments/tried/ folder pattern (the off-policy algorithms, and
# NozzleTVC's residual trained with residual_penalty = 1.0)
TRIED = {"sac": "sac_{}", "td3": "td3_{}", "ppo:penalty": "ppo_{}_residual_penalty"}
# each env's stem in the names of experiments/configs/*.toml
CONFIG_STEMS = {
    "ssme_envs/EngineTracking-v0": "engine_tracking",
    "ssme_envs/EngineThrottle-v0": "engine_throttle",
    "ssme_envs/NozzleTVC-v0": "nozzle_tvc",
    "ssme_envs/LauncherPitch-v0": "launcher_pitch",
}
REMAKE = "ssme-envs train --config experiments/configs/NAME.toml --out experiments/tried/NAME"


def _tried_folders(env_id: str) -> dict[str, Path]:
    """``{name: run directory}`` of the runs tried for an env that have a config."""
    folders = {name: RUNS / folder.format(CONFIG_STEMS[env_id]) for name, folder in TRIED.items()}
    return {name: run for name, run in folders.items() if (HERE / "configs" / f"{run.name}.toml").exists()}


def tried_runs(env_id: str) -> dict[str, Path]:
    """``{name: run directory}`` of the tried runs of an env found in experiments/tried/."""
    return {name: run for name, run in _tried_folders(env_id).items() if (run / "training.json").exists()}


def missing_runs(env_id: str) -> list[Path]:
    """The tried runs of an env that have a config but no run in experiments/tried/ (their
    columns then drop out of the tables)."""
    return [run for run in _tried_folders(env_id).values() if not (run / "training.json").exists()]


def missing_note(missing: list[Path]) -> list[str]:
    """The record's lines on the tried runs left out (none where nothing is missing), printed as
    a note too."""
    if not missing:
        return []
    names = ", ".join(run.name for run in missing)
    print(f"note: tried runs not in experiments/tried/, left out of the tables: {names}", flush=True)
    return [
        f"Tried runs not found in experiments/tried/ when this file was written, so not in its "
        f"tables: {names} (train each with `{REMAKE}`).",
        "",
    ]
