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
import inspect
import json
import math
import sys
import time
import warnings
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from agents.base import BatchController
from agents.policy_files import (
    ALGOS,
    NORMALIZATION,
    POLICY_JSON,
    WEIGHTS,
    LoadedPolicy,
    load_policy,
    save_normalization,
    save_policy,
    to_vec_normalize,
    write_atomic,
)
from agents.policy_files import algorithm_class as _algorithm
from agents.policy_zip import load_sb3_zip
from agents.residual import Residual, ResidualController, base_controller, check_residual, residual_vec_env

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

CONFIG_KEYS = {
    "env": str,
    "algo": str,
    "steps": int,
    "seed": int,
    "num_envs": int,
    "eval_freq": int,
    "eval_episodes": int,
    "tensorboard": bool,
    "env_options": dict,
    "hyperparameters": dict,
    "policy": dict,
    "init_policy": str,  # a policy directory whose weights and normalization start the training
    "residual": str,  # a classical controller of the env the policy's action is added to (agents.residual)
    "residual_scale": float,  # the residual's action scale, in (0, 2]
    "residual_penalty": float,  # training reward minus this x |the correction|^2 (agents.residual)
}
DEFAULTS = {"steps": 200_000, "seed": 0, "num_envs": 64, "eval_freq": 50_000, "eval_episodes": 20,
            "tensorboard": False, "env_options": {}, "hyperparameters": {}, "policy": {}}  # fmt: skip
RESIDUAL_SCALE = 0.5  # the residual's default action scale
# the shipped policies: trained on each env's full truth, and on EngineTracking's identified model
SHIPPED = (
    "EngineTracking-v0",
    "EngineTracking-v0-identified",
    "EngineThrottle-v0",
    "NozzleTVC-v0",
    "NozzleTVC-v0-spread",  # trained with plant_spread=0.2 (experiments/configs/ppo_nozzle_tvc_spread.toml)
    "LauncherPitch-v0",
    # residual policies over a classical design (agents.residual; experiments/configs/*_residual.toml)
    "EngineTracking-v0-residual",
    "EngineThrottle-v0-residual",
    "NozzleTVC-v0-residual",
    "LauncherPitch-v0-residual",
)


def check_config(config: dict[str, Any], source: str = "config") -> dict[str, Any]:
    """The config with defaults filled in; ValueError naming any unknown key or wrong type."""
    for key, value in config.items():
        if key not in CONFIG_KEYS:
            raise ValueError(f"{source}: unknown key {key!r}; known: {', '.join(CONFIG_KEYS)}")
        want = CONFIG_KEYS[key]
        if want is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if not isinstance(value, want) or (want is int and isinstance(value, bool)):
            raise ValueError(f"{source}: {key} must be {want.__name__}, got {type(value).__name__}")
    full = {**DEFAULTS, **config}
    if "env" not in full or "algo" not in full:
        raise ValueError(f"{source}: needs 'env' and 'algo'")
    for key in ("steps", "num_envs", "eval_freq", "eval_episodes"):
        if full[key] < 1:
            raise ValueError(f"{source}: {key} must be positive, got {full[key]}")
    algorithm = _algorithm(full["algo"])
    signature = inspect.signature(algorithm.__init__).parameters
    reserved = {"self", "policy", "env", "seed", "device", "verbose", "tensorboard_log", "policy_kwargs"}
    for key, value in full["hyperparameters"].items():
        if key not in signature or key in reserved:
            raise ValueError(f"{source}: hyperparameters.{key} is not a {full['algo']} hyperparameter")
        default = signature[key].default
        if isinstance(default, bool) and not isinstance(value, bool):
            raise ValueError(f"{source}: hyperparameters.{key} must be true or false, got {value!r}")
        if isinstance(default, int | float) and not isinstance(default, bool):
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
                raise ValueError(f"{source}: hyperparameters.{key} must be a number, got {value!r}")
    for key, value in full["policy"].items():
        if key == "log_std_init":  # the initial exploration noise, log of its std (PPO's Gaussian)
            if full["algo"] != "ppo":
                raise ValueError(
                    f"{source}: policy.log_std_init sets PPO's initial noise, not {full['algo']}'s"
                )
            if isinstance(value, bool) or not isinstance(value, int | float) or not -5 <= value <= 2:
                raise ValueError(f"{source}: policy.log_std_init must be a number in [-5, 2], got {value!r}")
            continue
        if key != "net_arch":
            raise ValueError(f"{source}: unknown key policy.{key}; known: net_arch, log_std_init")
        if not (isinstance(value, list) and value and all(isinstance(v, int) and v > 0 for v in value)):
            raise ValueError(f"{source}: policy.net_arch must be a list of positive integers, got {value!r}")
    if "residual" in full:
        scale = full.get("residual_scale", RESIDUAL_SCALE)
        checked = check_residual(full["residual"], scale, full["env"], f"{source}: residual")
        full["residual_scale"] = checked.scale
        penalty = full.get("residual_penalty", 0.0)
        penalty = float(penalty) if isinstance(penalty, int) and not isinstance(penalty, bool) else penalty
        full["residual_penalty"] = penalty
        if not (isinstance(penalty, float) and math.isfinite(penalty) and penalty >= 0):
            raise ValueError(f"{source}: residual_penalty must be a number >= 0, got {penalty!r}")
    elif "residual_scale" in full or "residual_penalty" in full:
        key = "residual_scale" if "residual_scale" in full else "residual_penalty"
        raise ValueError(f"{source}: {key} without residual (the base controller)")
    return full


def load_config(path: Path) -> dict[str, Any]:
    try:
        data = tomllib.loads(Path(path).read_text())
    except OSError as exc:
        raise ValueError(f"cannot read config {path}: {exc.strerror}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: not valid TOML ({exc})") from None
    return data


def _toml(config: dict[str, Any]) -> str:
    """The resolved config as TOML (flat values and one level of tables)."""

    def value(v: Any) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        if isinstance(v, dict):
            return "{" + ", ".join(f"{k} = {value(x)}" for k, x in v.items()) + "}"
        return repr(v)

    lines = [f"{k} = {value(v)}" for k, v in config.items() if not isinstance(v, dict)]
    for key, table in config.items():
        if isinstance(table, dict):
            lines += ["", f"[{key}]"] + [f"{k} = {value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"


def plan_steps(config: dict[str, Any]) -> tuple[int, dict[str, Any], str | None]:
    """The steps SB3 will train, the hyperparameters and a note when they differ from ``steps``.

    SB3 trains in whole collections: PPO in rollouts of ``n_steps`` per env, SAC and TD3 in
    ``train_freq`` steps per env. PPO's ``n_steps``, when the config does not set it, is fitted
    (at most SB3's default 2048) so that whole rollouts come close to ``steps``; the steps are
    then rounded up to whole collections.

    Parameters
    ----------
    config : dict
        A checked config (:func:`check_config`).

    Returns
    -------
    steps, hyperparameters, note
        The steps to train, the hyperparameters (``n_steps`` added when fitted), and a line
        saying how the steps were rounded (None when they are the ones asked).
    """
    algo, asked, n = config["algo"], config["steps"], config["num_envs"]
    hyper = dict(config["hyperparameters"])
    defaults = inspect.signature(_algorithm(algo).__init__).parameters
    fitted = ""
    if algo == "ppo":
        if "n_steps" not in hyper:
            default = defaults["n_steps"].default
            rollouts = math.ceil(asked / (default * n))
            n_steps = max(math.ceil(asked / (rollouts * n)), 2 if n == 1 else 1)
            batch = int(hyper.get("batch_size", defaults["batch_size"].default))
            multiple = batch // math.gcd(batch, n)  # whole minibatches per rollout where it costs little
            if n_steps >= multiple:
                n_steps = math.ceil(n_steps / multiple) * multiple
            hyper["n_steps"] = n_steps
            fitted = f" (n_steps {n_steps} fitted to the steps asked; set hyperparameters.n_steps to choose)"
        unit, what = int(hyper["n_steps"]) * n, f"rollouts of n_steps {hyper['n_steps']} x {n} envs"
    else:
        freq = hyper.get("train_freq", defaults["train_freq"].default)
        if not isinstance(freq, int):
            raise ValueError(f"hyperparameters: train_freq must be an integer number of steps, got {freq!r}")
        unit, what = freq * n, f"collections of train_freq {freq} x {n} envs"
    unit = max(unit, 1)  # a zero n_steps or train_freq: SB3 names it when the model is made
    steps = math.ceil(asked / unit) * unit
    note = None
    if steps != asked or fitted:
        note = f"{algo} trains in whole {what}: {steps:,} steps for the {asked:,} asked{fitted}"
    return steps, hyper, note


def train(config: dict[str, Any], out: Path, progress: bool = True) -> dict[str, Any]:
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

    config = check_config(config)
    check_env_id(config["env"])
    if config["tensorboard"] and importlib.util.find_spec("tensorboard") is None:
        raise ValueError('TensorBoard logs need the tensorboard package: pip install "ssme-envs[rl]"')
    steps, hyper, note = plan_steps(config)
    config = {**config, "hyperparameters": hyper}  # config.toml records a fitted n_steps
    bar = progress and all(importlib.util.find_spec(m) is not None for m in ("tqdm", "rich"))
    out.mkdir(parents=True, exist_ok=True)
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
        raise ValueError(f"env_options: {exc}") from None
    policy_kwargs = dict(config["policy"]) or None
    try:
        model = _algorithm(algo)(
            "MlpPolicy", venv, seed=seed, device="cpu", verbose=0, policy_kwargs=policy_kwargs,
            tensorboard_log=str(out / "tensorboard") if config["tensorboard"] else None, **hyper,
        )  # fmt: skip
    except (AssertionError, TypeError, ValueError) as exc:  # SB3 checks values with asserts
        raise ValueError(f"hyperparameters or policy: {exc}") from None
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
    write_atomic(out / "config.toml", _toml(config))
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
        return load_sb3_zip(path, algo, allow_pickle=allow_pickle)
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
    controller = PolicyController(loaded, residual_ok=True)
    if loaded.residual is None:
        return controller
    from agents.base import task_of

    task = task_of(env)
    expected = len(task.observation.names) + task.n_actions
    if controller.size != expected:
        raise ValueError(f"{loaded.source}: a residual policy on {controller.size} observations; {env_id} "
                         f"with its base action gives {expected}")  # fmt: skip
    base = base_controller(loaded.residual, env, env_id)
    return ResidualController(controller, base, loaded.residual.scale)


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
    residual_ok : bool
        Accept a residual policy (the learned part alone: :func:`policy_controller` pairs it with
        its base); refused otherwise, as it cannot act without its base.
    """

    name = "rl"

    def __init__(
        self,
        source: str | Path | LoadedPolicy,
        algo: str | None = None,
        allow_pickle: bool = False,
        residual_ok: bool = False,
    ) -> None:
        super().__init__()
        loaded = source if isinstance(source, LoadedPolicy) else load_trained(source, algo, allow_pickle)
        if loaded.residual is not None and not residual_ok:
            raise ValueError(
                f"{loaded.source}: a residual policy over {loaded.residual.base}; load it with its base: "
                "the controller spec ppo:RUN_DIR, or agents.sb3.policy_controller(loaded, env, env_id)"
            )
        self.policy = loaded.policy
        self.normalization = loaded.normalization
        self.size = int(np.prod(loaded.policy.observation_space.shape))
        self.env_id = loaded.env_id or str(loaded.source)
        self.name = loaded.algo

    def compute(self, obs: np.ndarray) -> np.ndarray:
        if obs.shape[1] != self.size:
            raise ValueError(
                f"{self.name}: the policy was trained on {self.env_id} ({self.size} observations), "
                f"got {obs.shape[1]}"
            )
        stats = self.normalization
        normalized = obs.astype(np.float32) if stats is None else stats.normalize(obs)
        action, _ = self.policy.predict(normalized, deterministic=True)
        return np.asarray(action, dtype=np.float64)


def shipped_policy(env_id: str, trained_on: str = "truth") -> Path:
    """The directory of the policy shipped for an env, trained on its truth or its identified model."""
    name = env_id.split("/")[-1] + ("" if trained_on == "truth" else f"-{trained_on}")
    if name not in SHIPPED:
        raise ValueError(f"no shipped policy {name!r}; there are {', '.join(SHIPPED)}")
    return Path(str(resources.files("agents") / "policies" / name))


__all__ = [
    "ALGOS",
    "SHIPPED",
    "PolicyController",
    "check_config",
    "load_config",
    "load_trained",
    "plan_steps",
    "policy_controller",
    "shipped_policy",
    "to_vec_normalize",
    "train",
]
