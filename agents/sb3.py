"""Reinforcement learning with stable-baselines3: training from a TOML config, and trained
policies (ours, shipped with the package, or yours) as controllers of the common protocol.

A run writes ``policy.json`` and ``policy.safetensors`` (the kept policy: architecture, spaces and
weights, see :mod:`agents.policy_files`), ``normalization.json`` (VecNormalize's observation
statistics with that policy; :func:`to_vec_normalize` makes SB3's VecNormalize of it),
``config.toml`` (the resolved config that reproduces the run) and ``training.json`` (steps,
wall-clock, evaluations, which policy was kept). Nothing is pickled; SB3's own ``.zip`` loads
only with ``allow_pickle=True``.
"""

from __future__ import annotations

import importlib.util
import json
import math
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from agents.base import BatchController
from agents.normalization import NORMALIZATION, save_normalization, to_vec_normalize
from agents.policy_files import (
    ALGOS,
    POLICY_JSON,
    WEIGHTS,
    LoadedPolicy,
    load_policy,
    save_policy,
    write_atomic,
)
from agents.policy_files import algorithm_class as _algorithm
from agents.policy_zip import load_sb3_zip
from agents.residual import (
    Residual,
    ResidualController,
    base_controller,
    residual_space,
    residual_vec_env,
)
from agents.run_config import (  # the config's checks live there; re-exported for callers of agents.sb3
    check_config,
    config_toml,
    load_config,
    plan_steps,
)
from agents.shipped import SHIPPED, shipped_policy, shipped_specs  # re-exported for their callers


def train(config: dict[str, Any], out: Path, progress: bool = True, source: str = "config") -> dict[str, Any]:
    """Train on the env's native vector env through the SB3 adapter, observations (and rewards)
    normalized by VecNormalize, and keep the policy of the best evaluation (the final policy
    is evaluated too; every evaluation runs the same ``eval_episodes`` episodes). Writes
    ``policy.json``, ``policy.safetensors``, ``normalization.json``, ``config.toml`` and
    ``training.json`` into ``out`` (no pickle, no zip). With ``residual`` in the config the policy
    learns a correction to that classical controller's action (:mod:`agents.residual`).

    Parameters
    ----------
    config : dict
        The run's config (checked here; see :data:`CONFIG_KEYS`).
    out : Path
        The run directory (created).
    progress : bool
        Show SB3's progress bar (tqdm and rich) and print the evaluations, on stderr.
    source : str
        Where the config came from, to begin its error messages (``config PATH``).

    Returns
    -------
    dict
        The training summary written to ``training.json``.
    """
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize, sync_envs_normalization

    from ssme_envs.envs.sb3_adapter import make_sb3_vec_env
    from ssme_envs.evaluation import check_env_id

    config = check_config(config, source)
    check_env_id(config["env"])
    if config["tensorboard"] and importlib.util.find_spec("tensorboard") is None:
        raise ValueError('TensorBoard logs need the tensorboard package: pip install "ssme-envs[rl]"')
    steps, hyper, note = plan_steps(config, source)
    config = {**config, "hyperparameters": hyper}  # config.toml records a fitted n_steps
    bar = progress and all(importlib.util.find_spec(m) is not None for m in ("tqdm", "rich"))
    algo, env_id, seed, n = config["algo"], config["env"], config["seed"], config["num_envs"]
    options = config["env_options"]
    residual = Residual(config["residual"], config["residual_scale"]) if "residual" in config else None

    def vec_env(num_envs: int, env_seed: int, penalty: float = 0.0) -> Any:
        sb3_env = make_sb3_vec_env(env_id, num_envs, env_seed, **options)
        if residual is not None:  # each vector env with its own base controller
            import gymnasium as gym

            design_env = gym.make(env_id, **options)
            base = base_controller(residual, design_env, env_id)
            design_env.close()
            sb3_env = residual_vec_env(sb3_env, base, residual.scale, penalty)
        return VecMonitor(sb3_env)

    try:
        venv = VecNormalize(
            vec_env(n, seed, config.get("residual_penalty", 0.0)), gamma=hyper.get("gamma", 0.99)
        )
        evaluation = VecNormalize(vec_env(config["eval_episodes"], seed + 100_000), training=False,
                                  norm_reward=False)  # fmt: skip
    except TypeError as exc:  # an option the env does not take
        raise ValueError(f"{source}: env_options: {exc}") from None
    except ValueError as exc:  # a value the env refuses: the message names it, the file where it is
        raise ValueError(f"{source}: {exc}") from None
    out.mkdir(parents=True, exist_ok=True)  # once the envs are made: a refused config leaves nothing
    policy_kwargs = dict(config["policy"]) or None
    noise = {}
    if config.get("action_noise_std"):  # (TD3 explores by nothing else; SB3 adds none by default)
        from stable_baselines3.common.noise import NormalActionNoise

        width = venv.action_space.shape[0]
        sigma = config["action_noise_std"] * np.ones(width)
        noise = {"action_noise": NormalActionNoise(np.zeros(width), sigma)}
    try:
        model = _algorithm(algo)(
            "MlpPolicy", venv, seed=seed, device="cpu", verbose=0, policy_kwargs=policy_kwargs,
            tensorboard_log=str(out / "tensorboard") if config["tensorboard"] else None, **hyper, **noise,
        )  # fmt: skip
    except (AssertionError, ValueError) as exc:  # SB3 checks hyperparameter values with asserts
        raise ValueError(f"{source}: hyperparameters: {exc}") from None
    except Exception as exc:  # building the model only runs the config's values: what the checks
        # above let through and SB3 or torch refuse here is the config's doing, not a bug to trace
        raise ValueError(f"{source}: hyperparameters or policy: cannot build the {algo} model "
                         f"({type(exc).__name__}: {exc})") from None  # fmt: skip
    if "init_policy" in config:
        _start_from(model, venv, config["init_policy"], algo, env_id, residual)
    history: list[dict[str, Any]] = []
    best: dict[str, Any] = {"return": -math.inf}

    def evaluate_now() -> None:
        sync_envs_normalization(venv, evaluation)
        evaluation.seed(seed + 100_000)  # the same episodes at every evaluation: returns compare
        mean, _ = evaluate_policy(model, evaluation, n_eval_episodes=config["eval_episodes"], warn=False)
        entry: dict[str, Any] = {"steps": int(model.num_timesteps), "return": float(mean)}
        history.append(entry)
        model.logger.record("eval/mean_reward", float(mean))
        model.logger.dump(model.num_timesteps)  # at its own step, as SB3's EvalCallback writes it
        if mean > best["return"] or "steps" not in best:  # keep it, with the statistics it saw
            entry["best"] = True
            best.update(steps=entry["steps"], **{"return": entry["return"]})
            save_policy(model.policy, algo, env_id, out, residual)
            save_normalization(venv, out / NORMALIZATION)
        if progress:
            print(f"evaluation at {model.num_timesteps:,} steps: return {mean:.3f}", file=sys.stderr)

    class Evaluate(BaseCallback):
        def _on_step(self) -> bool:
            if self.n_calls % max(config["eval_freq"] // n, 1) == 0:
                evaluate_now()
            return True

    if note:
        print(note, file=sys.stderr)
    start = time.perf_counter()
    model.learn(steps, callback=[Evaluate(), *([_progress_bar()] if bar else [])])
    seconds = time.perf_counter() - start
    if not history or history[-1]["steps"] != model.num_timesteps:
        evaluate_now()  # the final policy: kept when no evaluation ran or when it is the best
    final = best["steps"] == model.num_timesteps
    summary = {
        "env": env_id,
        "algo": algo,
        "steps": int(model.num_timesteps),
        "steps_requested": config["steps"],
        "seconds": seconds,
        "steps_per_s": model.num_timesteps / seconds,
        "best_return": best["return"],
        "kept": {"model": "final" if final else "best", "steps": best["steps"]},
        "evaluations": history,
    }
    write_atomic(out / "config.toml", config_toml(config))
    write_atomic(out / "training.json", json.dumps(summary, indent=1) + "\n")
    return summary


def _start_from(
    model: Any, venv: Any, path: str, algo: str, env_id: str, residual: Residual | None = None
) -> None:
    """Start ``model`` (and ``venv``'s observation statistics) from a trained policy directory
    of the same algorithm, env and network (fine-tuning); ValueError naming a mismatch."""
    loaded = load_trained(path, algo)
    if loaded.env_id != env_id:
        raise ValueError(f"init_policy {path}: trained on {loaded.env_id}, not {env_id}")
    if loaded.residual != residual:

        def said(r: Residual | None) -> str:
            return "no residual" if r is None else f"a residual over {r.base} (scale {r.scale:g})"

        raise ValueError(f"init_policy {path}: it is {said(loaded.residual)}, this config {said(residual)}")
    check_spaces(loaded, model.policy.observation_space, model.policy.action_space, env_id)
    mine, theirs = model.policy.state_dict(), loaded.policy.state_dict()
    if {k: v.shape for k, v in mine.items()} != {k: v.shape for k, v in theirs.items()}:
        raise ValueError(f"init_policy {path}: its network differs from policy.net_arch of this config")
    model.policy.load_state_dict(theirs)
    if loaded.normalization is not None:
        venv.obs_rms.mean = loaded.normalization.mean.copy()
        venv.obs_rms.var = loaded.normalization.var.copy()
        venv.obs_rms.count = loaded.normalization.count


def _progress_bar() -> Any:
    """SB3's progress bar (tqdm and rich), drawn on stderr (SB3's own goes to stdout)."""
    from rich.console import Console
    from stable_baselines3.common.callbacks import ProgressBarCallback
    from tqdm import TqdmExperimentalWarning
    from tqdm.rich import tqdm

    class StderrProgressBar(ProgressBarCallback):
        def _on_training_start(self) -> None:
            total = self.locals["total_timesteps"] - self.model.num_timesteps
            with warnings.catch_warnings():  # tqdm calls its rich bar experimental
                warnings.simplefilter("ignore", TqdmExperimentalWarning)
                self.pbar = tqdm(total=total, options={"console": Console(stderr=True)})

    return StderrProgressBar()


def load_trained(path: str | Path, algo: str | None = None, allow_pickle: bool = False) -> LoadedPolicy:
    """A trained policy: a policy directory (``policy.json``, no pickle) or, only with
    ``allow_pickle=True``, SB3's own ``.zip`` (unpickled: it can execute arbitrary code).

    Parameters
    ----------
    path : str or Path
        The run directory of ``ssme-envs train`` (or a shipped policy), or an SB3 ``.zip``.
    algo : str, optional
        The algorithm (ppo, sac, td3): checked against a directory's, needed for a zip.
    allow_pickle : bool
        Accept an SB3 zip.
    """
    path = Path(path)
    if path.suffix == ".zip":
        if algo is None:
            raise ValueError(f"{path}: name the algorithm of an SB3 zip ({', '.join(ALGOS)})")
        return load_sb3_zip(path, algo, allow_pickle=allow_pickle)  # without it refused, naming the risk
    if path.is_file():
        raise ValueError(f"{path}: a trained policy is a directory ({POLICY_JSON}, {WEIGHTS}, "
                         f"{NORMALIZATION}) or, with allow_pickle, an SB3 .zip")  # fmt: skip
    loaded = load_policy(path)
    if algo is not None and loaded.algo != algo:
        raise ValueError(f"{path}: holds a {loaded.algo} policy, not {algo}")
    return loaded


def policy_controller(loaded: LoadedPolicy, env: Any, env_id: str) -> BatchController:
    """A loaded policy as the controller of ``env``: a :class:`PolicyController`, or for a residual
    policy the :class:`~agents.residual.ResidualController` over its base designed for ``env``."""
    # a native vector env (the evaluation harness's) has the spaces of one env as single_*
    observation_space = getattr(env, "single_observation_space", env.observation_space)
    action_space = getattr(env, "single_action_space", env.action_space)
    controller = PolicyController(loaded)
    if loaded.residual is None:
        check_spaces(loaded, observation_space, action_space, env_id)
        return controller
    from agents.base import task_of

    task = task_of(env)
    expected = len(task.observation.names) + task.n_actions
    if controller.size != expected:
        raise ValueError(f"{loaded.source}: a residual policy on {controller.size} observations; {env_id} "
                         f"with its base action gives {expected}")  # fmt: skip
    n_actions = int(np.prod(action_space.shape))
    check_spaces(loaded, residual_space(observation_space, n_actions), action_space, env_id)
    base = base_controller(loaded.residual, env, env_id)
    return ResidualController(controller, base, loaded.residual.scale)


def check_spaces(loaded: LoadedPolicy, observation_space: Any, action_space: Any, env_id: str) -> None:
    """ValueError unless the policy's recorded observation and action spaces are the ones given (of
    the env it is to act on): same shape, low and high. SB3 clips or rescales a policy's actions to
    its own action space, so other bounds would act wrongly without any error."""
    pairs = (("observation", loaded.policy.observation_space, observation_space),
             ("action", loaded.policy.action_space, action_space))  # fmt: skip
    for what, mine, theirs in pairs:
        same = mine.shape == getattr(theirs, "shape", None) and all(
            np.allclose(getattr(mine, bound), getattr(theirs, bound), rtol=1e-6, atol=0)
            for bound in ("low", "high")
        )  # float32 and float64 spaces of one env agree to float32's precision
        if not same:
            raise ValueError(f"{loaded.source}: the policy's {what} space {mine} is not {env_id}'s {theirs}")


class PolicyController(BatchController):
    """A trained SB3 policy as a controller: observations normalized with the run's statistics,
    deterministic actions.

    Parameters
    ----------
    source : str, Path or LoadedPolicy
        A policy directory (see :func:`load_trained`), or a policy already loaded.
    algo : str, optional
        The algorithm, checked against the directory's (needed for an SB3 zip).
    allow_pickle : bool
        Accept an SB3 ``.zip`` (unpickled on load: it can execute arbitrary code).

    A residual policy (:mod:`agents.residual`) is the learned part alone here, acting on the env's
    observation with its base's action appended; :func:`policy_controller` pairs it with its base.
    """

    name = "rl"

    def __init__(
        self, source: str | Path | LoadedPolicy, algo: str | None = None, allow_pickle: bool = False
    ) -> None:
        super().__init__()
        loaded = source if isinstance(source, LoadedPolicy) else load_trained(source, algo, allow_pickle)
        self.policy = loaded.policy
        self.normalization = loaded.normalization
        self.size = int(np.prod(loaded.policy.observation_space.shape))
        self.env_id = loaded.env_id or str(loaded.source)
        self.name = loaded.algo
        self.residual = loaded.residual

    def compute(self, obs: np.ndarray) -> np.ndarray:
        if obs.shape[1] != self.size:
            hint = (
                ""
                if self.residual is None
                else f" (a residual policy over {self.residual.base}: its observations are the env's and the "
                "base action; act with its base through the spec ppo:RUN_DIR or agents.sb3.policy_controller)"
            )
            raise ValueError(
                f"{self.name}: the policy was trained on {self.env_id} ({self.size} observations), "
                f"got {obs.shape[1]}{hint}"
            )
        stats = self.normalization
        normalized = obs.astype(np.float32) if stats is None else stats.normalize(obs)
        action, _ = self.policy.predict(normalized, deterministic=True)
        return np.asarray(action, dtype=np.float64)


__all__ = [
    "ALGOS",
    "SHIPPED",
    "PolicyController",
    "check_config",
    "check_spaces",
    "load_config",
    "load_trained",
    "plan_steps",
    "policy_controller",
    "shipped_policy",
    "shipped_specs",
    "to_vec_normalize",
    "train",
]
