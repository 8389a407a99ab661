"""Reinforcement learning with stable-baselines3: training from a TOML config, and trained
policies (ours, shipped with the package, or yours) as controllers of the common protocol.

A run writes ``model.zip`` (the best evaluation's policy, SB3's format), ``normalization.json``
(the observation statistics of VecNormalize at that evaluation, plain JSON), ``config.toml`` (the
resolved config that reproduces the run) and ``training.json`` (steps, wall-clock, evaluations).
"""

from __future__ import annotations

import importlib.util
import inspect
import json
import math
import sys
import time
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from agents.base import BatchController

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

ALGOS = ("ppo", "sac", "td3")
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
}
DEFAULTS = {"steps": 200_000, "seed": 0, "num_envs": 64, "eval_freq": 50_000, "eval_episodes": 20,
            "tensorboard": False, "env_options": {}, "hyperparameters": {}, "policy": {}}  # fmt: skip
# the shipped policies: trained on each env's full truth, and on EngineTracking's identified model
SHIPPED = ("EngineTracking-v0", "EngineTracking-v0-identified", "EngineThrottle-v0", "NozzleTVC-v0")


def _algorithm(name: str) -> Any:
    if name not in ALGOS:
        raise ValueError(f"unknown algo {name!r}; choose one of {', '.join(ALGOS)}")
    try:
        import stable_baselines3
    except ModuleNotFoundError:
        raise ValueError(
            'RL training and trained policies need stable-baselines3: pip install "ssme-envs[rl]"'
        ) from None
    return getattr(stable_baselines3, name.upper())


def check_config(config: dict[str, Any], source: str = "config") -> dict[str, Any]:
    """The config with defaults filled in; ValueError naming any unknown key or wrong type."""
    for key, value in config.items():
        if key not in CONFIG_KEYS:
            raise ValueError(f"{source}: unknown key {key!r}; known: {', '.join(CONFIG_KEYS)}")
        want = CONFIG_KEYS[key]
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
        if key != "net_arch":
            raise ValueError(f"{source}: unknown key policy.{key}; known: net_arch")
        if not (isinstance(value, list) and value and all(isinstance(v, int) and v > 0 for v in value)):
            raise ValueError(f"{source}: policy.net_arch must be a list of positive integers, got {value!r}")
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


def train(config: dict[str, Any], out: Path, progress: bool = True) -> dict[str, Any]:
    """Train on the env's native vector env through the SB3 adapter, observations (and rewards)
    normalized by VecNormalize, the best evaluation kept. Returns the training summary."""
    from stable_baselines3.common.callbacks import BaseCallback, EvalCallback
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from ssme_envs.envs.sb3_adapter import make_sb3_vec_env
    from ssme_envs.evaluation import check_env_id

    config = check_config(config)
    check_env_id(config["env"])
    if config["tensorboard"] and importlib.util.find_spec("tensorboard") is None:
        raise ValueError("TensorBoard logs need the tensorboard package: pip install tensorboard")
    out.mkdir(parents=True, exist_ok=True)
    algorithm = _algorithm(config["algo"])
    env_id, seed, n = config["env"], config["seed"], config["num_envs"]
    options = config["env_options"]
    hyper = dict(config["hyperparameters"])
    try:
        venv = VecNormalize(
            VecMonitor(make_sb3_vec_env(env_id, n, seed, **options)), gamma=hyper.get("gamma", 0.99)
        )
        evaluation = VecNormalize(
            VecMonitor(make_sb3_vec_env(env_id, config["eval_episodes"], seed + 100_000, **options)),
            training=False,
            norm_reward=False,
        )
    except TypeError as exc:  # an option the env does not take
        raise ValueError(f"env_options: {exc}") from None
    policy_kwargs = {"net_arch": config["policy"]["net_arch"]} if config["policy"] else None
    try:
        model = algorithm(
            "MlpPolicy", venv, seed=seed, device="cpu", verbose=0, policy_kwargs=policy_kwargs,
            tensorboard_log=str(out / "tensorboard") if config["tensorboard"] else None, **hyper,
        )  # fmt: skip
    except (AssertionError, ValueError) as exc:  # SB3 checks hyperparameter values with asserts
        raise ValueError(f"hyperparameters: {exc}") from None
    history: list[dict[str, float]] = []

    class SaveNormalization(BaseCallback):
        def _on_step(self) -> bool:
            save_normalization(venv, out / "normalization.json")
            history[-1]["best"] = True
            return True

    class Progress(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.start = time.perf_counter()
            self.next = 0.0

        def _on_step(self) -> bool:
            done = self.num_timesteps / config["steps"]
            if progress and done >= self.next:
                rate = self.num_timesteps / max(time.perf_counter() - self.start, 1e-9)
                print(
                    f"{100 * done:5.1f} % ({self.num_timesteps:,} steps, {rate:,.0f} steps/s)",
                    file=sys.stderr,
                )
                self.next += 0.05
            return True

    class Record(EvalCallback):
        def _on_step(self) -> bool:
            evaluating = self.eval_freq > 0 and self.n_calls % self.eval_freq == 0
            if evaluating:
                history.append({"steps": float(self.num_timesteps)})
            result = super()._on_step()
            if evaluating:
                history[-1]["return"] = float(self.last_mean_reward)
                if progress:
                    print(f"evaluation at {self.num_timesteps:,} steps: return {self.last_mean_reward:.3f}",
                          file=sys.stderr)  # fmt: skip
            return result

    evaluator = Record(
        evaluation,
        callback_on_new_best=SaveNormalization(),
        n_eval_episodes=config["eval_episodes"],
        eval_freq=max(config["eval_freq"] // n, 1),
        best_model_save_path=str(out),
        deterministic=True,
        verbose=0,
    )
    start = time.perf_counter()
    model.learn(config["steps"], callback=[evaluator, Progress()])
    seconds = time.perf_counter() - start
    (out / "best_model.zip").replace(out / "model.zip")
    summary = {
        "env": env_id,
        "algo": config["algo"],
        "steps": int(model.num_timesteps),
        "seconds": seconds,
        "steps_per_s": model.num_timesteps / seconds,
        "best_return": max(h["return"] for h in history),
        "evaluations": history,
    }
    (out / "config.toml").write_text(_toml(config))
    (out / "training.json").write_text(json.dumps(summary, indent=1) + "\n")
    return summary


def save_normalization(venv: Any, path: Path) -> None:
    rms = venv.obs_rms
    data = {
        "mean": rms.mean.tolist(),
        "var": rms.var.tolist(),
        "clip": venv.clip_obs,
        "epsilon": venv.epsilon,
    }
    path.write_text(json.dumps(data) + "\n")


class PolicyController(BatchController):
    """A trained SB3 policy as a controller: observations normalized with the run's statistics,
    deterministic actions. ``path``: a run directory (model.zip, normalization.json, config.toml)."""

    name = "rl"

    def __init__(self, path: str | Path) -> None:
        super().__init__()
        path = Path(path)
        files = [path / "model.zip", path / "normalization.json", path / "config.toml"]
        missing = [f.name for f in files if not f.exists()]
        if missing:
            raise ValueError(f"{path}: not a trained policy (missing {', '.join(missing)})")
        config = check_config(load_config(path / "config.toml"), str(path / "config.toml"))
        self.model = _algorithm(config["algo"]).load(path / "model.zip", device="cpu")
        norm = json.loads((path / "normalization.json").read_text())
        self.mean, self.scale = np.array(norm["mean"]), 1.0 / np.sqrt(np.array(norm["var"]) + norm["epsilon"])
        self.clip = float(norm["clip"])
        self.env_id = config["env"]
        self.name = config["algo"]

    def compute(self, obs: np.ndarray) -> np.ndarray:
        if obs.shape[1] != len(self.mean):
            raise ValueError(
                f"{self.name}: the policy was trained on {self.env_id} ({len(self.mean)} observations), "
                f"got {obs.shape[1]}"
            )
        normalized = np.clip((obs - self.mean) * self.scale, -self.clip, self.clip).astype(np.float32)
        action, _ = self.model.predict(normalized, deterministic=True)
        return np.asarray(action, dtype=np.float64)


def shipped_policy(env_id: str, trained_on: str = "truth") -> Path:
    """The directory of the policy shipped for an env, trained on its truth or its identified model."""
    name = env_id.split("/")[-1] + ("" if trained_on == "truth" else f"-{trained_on}")
    if name not in SHIPPED:
        raise ValueError(f"no shipped policy {name!r}; there are {', '.join(SHIPPED)}")
    return Path(str(resources.files("agents") / "policies" / name))


__all__ = ["ALGOS", "SHIPPED", "PolicyController", "check_config", "load_config", "shipped_policy", "train"]
