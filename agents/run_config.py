"""The TOML config of a training run: its keys and defaults, the checks that name a bad key or
value, and the steps SB3 will actually train (whole rollouts)."""

from __future__ import annotations

import inspect
import math
from pathlib import Path
from typing import Any

from agents.hyperparameters import check_hyperparameters
from agents.policy_files import algorithm_class as _algorithm
from agents.residual import check_residual
from ssme_envs.identification.arguments import MAX_SEED
from ssme_envs.input_files import FileTooLarge, NotRegularFile, read_bounded

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
    "action_noise_std": float,  # SAC's and TD3's Gaussian exploration noise on the actions, in [0, 1]
}
# Environment steps of one run at most: 1e12 is months at the adapter's speed (about 40,000 a second).
MAX_STEPS = 10**12
DEFAULTS = {"steps": 200_000, "seed": 0, "num_envs": 64, "eval_freq": 50_000, "eval_episodes": 20,
            "tensorboard": False, "env_options": {}, "hyperparameters": {}, "policy": {}}  # fmt: skip
RESIDUAL_SCALE = 0.5  # the residual's default action scale
MAX_CONFIG_BYTES = 1 << 20  # a run config is a page of TOML; this stops /dev/zero and its like
# policy.net_arch bounds: far beyond what these envs need (64 x 64 does), and a layer of MAX_UNITS
# squared float32 weights (64 MiB, times the optimizer's copies) still fits any machine that trains
MAX_LAYERS, MAX_UNITS = 16, 4096


def check_config(config: dict[str, Any], source: str = "config") -> dict[str, Any]:
    """The config with defaults filled in; ValueError naming any unknown key or wrong type."""
    typed = {}
    for key, value in config.items():
        if key not in CONFIG_KEYS:
            raise ValueError(f"{source}: unknown key {key!r}; known: {', '.join(CONFIG_KEYS)}")
        want = CONFIG_KEYS[key]
        if want is float and isinstance(value, int) and not isinstance(value, bool):
            try:
                value = float(value)  # TOML writes 1 for 1.0
            except OverflowError:  # TOML's reader takes integers of any length
                raise ValueError(f"{source}: {key} must be a float, got an integer too large") from None
        if not isinstance(value, want) or (want is int and isinstance(value, bool)):
            raise ValueError(f"{source}: {key} must be {want.__name__}, got {type(value).__name__}")
        typed[key] = value
    full = {**DEFAULTS, **typed}
    if "env" not in full or "algo" not in full:
        raise ValueError(f"{source}: needs 'env' and 'algo'")
    for key in ("steps", "num_envs", "eval_freq", "eval_episodes"):
        if full[key] < 1:
            raise ValueError(f"{source}: {key} must be positive, got {full[key]}")
    if full["steps"] > MAX_STEPS:  # beyond it a run never ends (and 1e23 steps rounded through floats)
        raise ValueError(f"{source}: steps must be at most {MAX_STEPS:,}, got {full['steps']:,}")
    if not 0 <= full["seed"] <= MAX_SEED:  # numpy's and SB3's seeding take 32 bits
        raise ValueError(f"{source}: seed must be within 0-{MAX_SEED}, got {full['seed']}")
    accepted = inspect.signature(_algorithm(full["algo"]).__init__).parameters
    check_hyperparameters(full["algo"], full["hyperparameters"], accepted, source)
    starts = full["hyperparameters"].get("learning_starts", 0)
    if starts >= full["steps"]:  # SAC and TD3 would only collect: a policy that never trained
        raise ValueError(f"{source}: hyperparameters.learning_starts {starts} leaves none of the "
                         f"{full['steps']} steps to learn from")  # fmt: skip
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
        if not (
            isinstance(value, list)
            and 0 < len(value) <= MAX_LAYERS
            and all(type(v) is int and 0 < v <= MAX_UNITS for v in value)
        ):
            raise ValueError(f"{source}: policy.net_arch must be a list of 1 to {MAX_LAYERS} layer sizes, "
                             f"each 1 to {MAX_UNITS} units, got {value!r}")  # fmt: skip
    if "action_noise_std" in full:
        noise = full["action_noise_std"]
        if full["algo"] not in ("sac", "td3"):
            algo = full["algo"]
            raise ValueError(f"{source}: action_noise_std is SAC's and TD3's exploration, not {algo}'s")
        if not (math.isfinite(noise) and 0 <= noise <= 1):
            raise ValueError(f"{source}: action_noise_std must be a number in [0, 1], got {noise!r}")
    if "residual" in full:
        scale = full.get("residual_scale", RESIDUAL_SCALE)
        checked = check_residual(full["residual"], scale, full["env"], f"{source}: residual")
        full["residual_scale"] = checked.scale
        penalty = full.setdefault("residual_penalty", 0.0)
        if not (math.isfinite(penalty) and penalty >= 0):
            raise ValueError(f"{source}: residual_penalty must be a number >= 0, got {penalty!r}")
    elif "residual_scale" in full or "residual_penalty" in full:
        key = "residual_scale" if "residual_scale" in full else "residual_penalty"
        raise ValueError(f"{source}: {key} without residual (the base controller)")
    return full


def load_config(path: Path) -> dict[str, Any]:
    """The TOML of a run config as a dict; ValueError naming the file for anything but a regular
    UTF-8 file of at most :data:`MAX_CONFIG_BYTES` holding valid TOML (a FIFO would block the
    read, a device such as /dev/zero never end it)."""
    try:
        data = tomllib.loads(read_bounded(path, MAX_CONFIG_BYTES).decode("utf-8"))
    except FileNotFoundError:
        raise ValueError(f"cannot read config {path}: no such file") from None
    except NotRegularFile as exc:
        raise ValueError(f"cannot read config {path}: not a regular file ({exc.kind})") from None
    except FileTooLarge:
        raise ValueError(f"cannot read config {path}: larger than {MAX_CONFIG_BYTES >> 10} KiB") from None
    except OSError as exc:
        raise ValueError(f"cannot read config {path}: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise ValueError(f"cannot read config {path}: not UTF-8 text") from None
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: not valid TOML ({exc})") from None
    return data


def config_toml(config: dict[str, Any]) -> str:
    """The resolved config as TOML (flat values and one level of tables)."""
    from ssme_envs.outputs import toml_value

    lines = [f"{k} = {toml_value(v)}" for k, v in config.items() if not isinstance(v, dict)]
    for key, table in config.items():
        if isinstance(table, dict):
            lines += ["", f"[{key}]"] + [f"{k} = {toml_value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"


def plan_steps(config: dict[str, Any], source: str = "config") -> tuple[int, dict[str, Any], str | None]:
    """The steps SB3 will train, the hyperparameters and a note when they differ from ``steps``.

    SB3 trains in whole collections: PPO in rollouts of ``n_steps`` per env, SAC and TD3 in
    ``train_freq`` steps per env. PPO's ``n_steps``, when the config does not set it, is fitted
    (at most SB3's default 2048) so that whole rollouts come close to ``steps``; the steps are
    then rounded up to whole collections.

    Parameters
    ----------
    config : dict
        A checked config (:func:`check_config`).
    source : str
        What the config came from, for the errors (ValueError).

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
            rollouts = -(-asked // (default * n))  # integer ceilings: exact for any steps
            n_steps = max(-(-asked // (rollouts * n)), 2 if n == 1 else 1)
            batch = int(hyper.get("batch_size", defaults["batch_size"].default))
            multiple = batch // math.gcd(batch, n)  # whole minibatches per rollout where it costs little
            if n_steps >= multiple:
                n_steps = -(-n_steps // multiple) * multiple
            hyper["n_steps"] = n_steps
            fitted = f" (n_steps {n_steps} fitted to the steps asked; set hyperparameters.n_steps to choose)"
        unit, what = int(hyper["n_steps"]) * n, f"rollouts of n_steps {hyper['n_steps']} x {n} envs"
        batch = int(hyper.get("batch_size", defaults["batch_size"].default))
        if batch > unit > 1:
            # SB3 would train on the whole rollout as one minibatch, and say so in a warning
            if "batch_size" in config["hyperparameters"]:
                raise ValueError(
                    f"{source}: hyperparameters.batch_size {batch} is more than a rollout holds ({what}: "
                    f"{unit} transitions); set batch_size to at most {unit} or raise n_steps"
                )
            hyper["batch_size"] = unit
            fitted += f" (batch_size {unit}: one rollout)"
    else:
        freq = hyper.get("train_freq", defaults["train_freq"].default)
        if not isinstance(freq, int):
            raise ValueError(
                f"{source}: hyperparameters.train_freq must be an integer number of steps, got {freq!r}"
            )
        unit, what = freq * n, f"collections of train_freq {freq} x {n} envs"
    unit = max(unit, 1)  # a zero n_steps or train_freq: SB3 names it when the model is made
    steps = -(-asked // unit) * unit
    note = None
    if steps != asked or fitted:
        note = f"{algo} trains in whole {what}: {steps:,} steps for the {asked:,} asked{fitted}"
    return steps, hyper, note


__all__ = [
    "CONFIG_KEYS",
    "DEFAULTS",
    "MAX_LAYERS",
    "MAX_STEPS",
    "MAX_UNITS",
    "RESIDUAL_SCALE",
    "check_config",
    "config_toml",
    "load_config",
    "plan_steps",
]
