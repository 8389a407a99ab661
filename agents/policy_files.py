"""Trained policies as data: safetensors weights and JSON, no pickle anywhere.

A policy directory (written by ``ssme-envs train``, or shipped in ``agents/policies/``) holds

- ``policy.json``: the algorithm, the SB3 policy class and its constructor arguments (net_arch,
  activation, ...), the observation and action spaces (low/high/shape/dtype), the env id and the
  SHA-256 of the weights;
- ``policy.safetensors``: the policy's ``state_dict`` (actor and critics);
- ``normalization.json``: the VecNormalize observation statistics (mean, var, count, clip,
  epsilon), read and written by :mod:`agents.normalization`;
- ``config.toml`` and ``training.json``: the resolved training config and the training summary.

:func:`load_policy` rebuilds the SB3 policy from the JSON and loads the weights; nothing in it
unpickles. SB3's own ``.zip`` files unpickle on load (a crafted zip runs code), so
:func:`agents.policy_zip.load_sb3_zip` reads one only with ``allow_pickle=True``.
"""

from __future__ import annotations

import hashlib
import inspect
import itertools
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from agents.json_fields import check_keys, file_problem, finite, load_object, numbers, short
from agents.normalization import NORMALIZATION, Normalization, read_normalization
from agents.residual import Residual, check_residual
from ssme_envs.input_files import read_or_refuse
from ssme_envs.outputs import atomic_write

FORMAT = "ssme-envs/policy"
VERSION = 1
POLICY_JSON = "policy.json"
WEIGHTS = "policy.safetensors"
ALGOS = ("ppo", "sac", "td3")
ACTIVATIONS = ("Tanh", "ReLU", "ELU", "LeakyReLU", "GELU", "SiLU", "Sigmoid")
PICKLE_WARNING = (
    "loading an SB3 zip unpickles it, which can execute arbitrary code: load only files you trust"
)
# constructor arguments of the SB3 policies kept in policy.json: name -> JSON kind
_KWARGS = {
    "net_arch": "net_arch", "activation_fn": "activation", "normalize_images": "bool", "use_sde": "bool",
    "ortho_init": "bool", "share_features_extractor": "bool", "squash_output": "bool?",
    "full_std": "bool?", "use_expln": "bool?", "log_std_init": "number", "clip_mean": "number",
    "n_critics": "int",
}  # fmt: skip
# needed to train, not to act: left out of policy.json (a rebuilt policy takes the defaults)
_TRAINING_ONLY = ("observation_space", "action_space", "lr_schedule", "optimizer_class", "optimizer_kwargs")
_POLICY_KEYS = {"format", "version", "algo", "env", "policy", "policy_kwargs", "observation_space",
                "action_space", "weights_sha256", "residual"}  # fmt: skip
_SPACE_KEYS = {"type", "shape", "dtype", "low", "high"}
# The shipped policies' weights (agents/policies, experiments/tried) are 10-130 kB; SB3 MLP policies
# of any size one would train here stay below a few MB. 256 MiB (64 M float32 weights) is far above
# all of them and keeps a wrong path (a disk image, a sparse file) from being read into memory whole.
MAX_WEIGHTS_BYTES = 256 * 2**20


def write_atomic(path: Path, data: bytes | str) -> None:
    """Write ``data`` (text as UTF-8) to ``path`` atomically (:func:`ssme_envs.outputs.atomic_write`)."""
    with atomic_write(path, "w" if isinstance(data, str) else "wb") as fh:
        fh.write(data)


def algorithm_class(name: str) -> Any:
    """The SB3 algorithm class of ``name`` (ppo, sac, td3); ValueError otherwise."""
    if name not in ALGOS:
        raise ValueError(f"unknown algo {name!r}; choose one of {', '.join(ALGOS)}")
    try:
        import stable_baselines3
    except ModuleNotFoundError:
        raise ValueError(
            'RL training and trained policies need stable-baselines3: pip install "ssme-envs[rl]"'
        ) from None
    return getattr(stable_baselines3, name.upper())


@dataclass(frozen=True)
class LoadedPolicy:
    """An SB3 policy ready to act, with where it came from."""

    policy: Any  # stable_baselines3 BasePolicy
    algo: str
    env_id: str | None
    normalization: Normalization | None
    source: Path
    residual: Residual | None = None  # a residual policy's base controller and scale (agents.residual)


def _encode_numbers(array: np.ndarray) -> list[float | str]:
    return [v if math.isfinite(v) else ("inf" if v > 0 else "-inf") for v in array.ravel().tolist()]


def encode_space(space: Any) -> dict[str, Any]:
    """A gymnasium ``Box`` as JSON (low/high flattened); ValueError for other spaces."""
    from gymnasium import spaces

    if not isinstance(space, spaces.Box) or space.dtype.name not in ("float32", "float64"):
        raise ValueError(f"only float Box spaces can be saved, got {space}")
    return {"type": "Box", "shape": list(space.shape), "dtype": space.dtype.name,
            "low": _encode_numbers(space.low), "high": _encode_numbers(space.high)}  # fmt: skip


def decode_space(data: Any, where: str) -> Any:
    """The ``Box`` of :func:`encode_space`'s JSON; ValueError for anything else."""
    from gymnasium import spaces

    if not isinstance(data, dict):
        raise ValueError(f"{where} must be a JSON object")
    check_keys(data, _SPACE_KEYS, _SPACE_KEYS, where)
    shape = data["shape"]
    if data["type"] != "Box" or data["dtype"] not in ("float32", "float64"):
        raise ValueError(f"{where}: only float32/float64 Box spaces, got {data['type']} {data['dtype']}")
    if not (isinstance(shape, list) and shape and all(type(n) is int and n > 0 for n in shape)):
        raise ValueError(f"{where}.shape must be a list of positive integers, got {shape!r}")
    size = math.prod(shape)
    low, high = numbers(data["low"], f"{where}.low"), numbers(data["high"], f"{where}.high")
    if len(low) != size or len(high) != size:
        raise ValueError(f"{where}: low and high need {size} values each for shape {shape}")
    dtype = np.dtype(data["dtype"])
    largest = float(np.finfo(dtype).max)
    for name, values in (("low", low), ("high", high)):
        for i, v in enumerate(values):
            if math.isfinite(v) and abs(v) > largest:  # the cast would overflow to inf (with a warning)
                raise ValueError(
                    f"{where}.{name}[{i}] = {v!r} does not fit {dtype.name} (at most {largest:g})"
                )
    low_array, high_array = np.array(low, dtype).reshape(shape), np.array(high, dtype).reshape(shape)
    if np.any(low_array > high_array):
        raise ValueError(f"{where}: low exceeds high")
    return spaces.Box(low_array, high_array, tuple(shape), dtype)


def _encode_kwargs(policy: Any) -> dict[str, Any]:
    from stable_baselines3.common.torch_layers import FlattenExtractor

    kwargs = {}
    for key, value in policy._get_constructor_parameters().items():
        if key in _TRAINING_ONLY:
            continue
        if key == "features_extractor_class" and value is FlattenExtractor:
            continue
        if key == "features_extractor_kwargs" and not value:
            continue
        if key not in _KWARGS:
            raise ValueError(f"cannot save a policy with {key}={value!r} (only MLP policies)")
        if _KWARGS[key] == "activation":
            if value.__name__ not in ACTIVATIONS:
                raise ValueError(f"cannot save activation {value.__name__}; known: {', '.join(ACTIVATIONS)}")
            value = value.__name__
        kwargs[key] = value
    return kwargs


def _decode_kwargs(data: Any, policy_class: Any, where: str) -> dict[str, Any]:
    import torch

    if not isinstance(data, dict):
        raise ValueError(f"{where} must be a JSON object")
    accepted = inspect.signature(policy_class.__init__).parameters
    kwargs = {}
    for key, value in data.items():
        kind = _KWARGS.get(key)
        if kind is None or key not in accepted:
            raise ValueError(f"{where}: unexpected field {key!r} for {policy_class.__name__}")
        ok = {
            "bool": isinstance(value, bool),
            "bool?": value is None or isinstance(value, bool),
            "number": finite(value) is not None,
            "int": type(value) is int and 0 < value <= 16,
            "activation": value in ACTIVATIONS,
            "net_arch": _valid_net_arch(value),
        }[kind]
        if not ok:
            raise ValueError(f"{where}.{key}: invalid value {short(value)}")
        kwargs[key] = getattr(torch.nn, value) if kind == "activation" else value
    return kwargs


def _valid_net_arch(value: Any) -> bool:
    def layers(v: Any) -> bool:
        return isinstance(v, list) and all(type(n) is int and 0 < n <= 65536 for n in v)

    if isinstance(value, dict):
        return set(value) <= {"pi", "vf", "qf"} and all(layers(v) for v in value.values())
    return layers(value)


def save_policy(
    policy: Any, algo: str, env_id: str, directory: Path, residual: Residual | None = None
) -> None:
    """Write ``policy.safetensors`` and ``policy.json`` for an SB3 MLP policy (``model.policy``),
    with the base controller and scale of a residual policy (:mod:`agents.residual`)."""
    from safetensors.torch import save

    if policy.__class__ is not algorithm_class(algo).policy_aliases["MlpPolicy"]:
        raise ValueError(f"cannot save {type(policy).__name__}: only {algo}'s MlpPolicy")
    tensors = {k: v.detach().cpu().contiguous().clone() for k, v in policy.state_dict().items()}
    raw = save(tensors, metadata={"format": FORMAT})
    meta = {
        "format": FORMAT,
        "version": VERSION,
        "algo": algo,
        "env": env_id,
        "policy": "MlpPolicy",
        "policy_kwargs": _encode_kwargs(policy),
        "observation_space": encode_space(policy.observation_space),
        "action_space": encode_space(policy.action_space),
        "weights_sha256": hashlib.sha256(raw).hexdigest(),
    }
    if residual is not None:
        meta["residual"] = residual._asdict()
    directory = Path(directory)
    write_atomic(directory / WEIGHTS, raw)
    write_atomic(directory / POLICY_JSON, json.dumps(meta, indent=1) + "\n")


def read_policy_json(directory: Path) -> dict[str, Any]:
    """The checked ``policy.json`` of a policy directory; ValueError naming what is missing or wrong."""
    directory = Path(directory)
    if not directory.is_dir():
        raise ValueError(
            f"{directory}: no such policy directory (one holds {POLICY_JSON}, {WEIGHTS}, {NORMALIZATION})"
        )
    problems = {name: file_problem(directory / name) for name in (POLICY_JSON, WEIGHTS, NORMALIZATION)}
    special = [
        f"{name} is {problem}" for name, problem in problems.items() if problem not in (None, "missing")
    ]
    if special:
        raise ValueError(f"{directory}: not a trained policy ({', '.join(special)}, not a regular file)")
    missing = [name for name, problem in problems.items() if problem == "missing"]
    if missing:
        hint = ""
        if POLICY_JSON in missing and (directory / "model.zip").is_file():
            hint = (f"; it holds an SB3 model.zip (pickle): convert a trusted one with "
                    f"python -m agents.policy_zip {directory} --allow-pickle")  # fmt: skip
        raise ValueError(f"{directory}: not a trained policy (missing {', '.join(missing)}){hint}")
    path = directory / POLICY_JSON
    meta = load_object(path)
    check_keys(meta, _POLICY_KEYS, _POLICY_KEYS - {"residual"}, str(path))
    # type(...) is int: True == 1 would otherwise pass as version 1
    if meta["format"] != FORMAT or type(meta["version"]) is not int or meta["version"] != VERSION:
        raise ValueError(f"{path}: not an {FORMAT} v{VERSION} file")
    if meta["algo"] not in ALGOS or meta["policy"] != "MlpPolicy" or not isinstance(meta["env"], str):
        raise ValueError(f"{path}: needs algo ({', '.join(ALGOS)}), policy MlpPolicy and an env id")
    if "residual" in meta:
        entry = meta["residual"]
        if not isinstance(entry, dict) or set(entry) != set(Residual._fields):
            raise ValueError(f"{path}: residual must be an object with {', '.join(Residual._fields)}")
        meta["residual"] = check_residual(entry["base"], entry["scale"], meta["env"], f"{path}: residual")
    return meta


def load_policy(directory: Path) -> LoadedPolicy:
    """Rebuild the SB3 policy of a policy directory from its JSON and load its safetensors
    weights (no pickle); ValueError naming the file and the problem."""
    from safetensors.torch import load

    directory = Path(directory)
    meta = read_policy_json(directory)
    where = str(directory / POLICY_JSON)
    policy_class = algorithm_class(meta["algo"]).policy_aliases["MlpPolicy"]
    kwargs = _decode_kwargs(meta["policy_kwargs"], policy_class, f"{where}: policy_kwargs")
    observation_space = decode_space(meta["observation_space"], f"{where}: observation_space")
    action_space = decode_space(meta["action_space"], f"{where}: action_space")
    normalization = read_normalization(directory / NORMALIZATION)
    if normalization.mean.shape != observation_space.shape:
        raise ValueError(f"{directory / NORMALIZATION}: {normalization.mean.shape[0]} means for the "
                         f"observation space of shape {observation_space.shape}")  # fmt: skip
    raw = _read_weights(directory / WEIGHTS)
    if hashlib.sha256(raw).hexdigest() != meta["weights_sha256"]:
        raise ValueError(f"{directory / WEIGHTS}: its SHA-256 differs from the one in {POLICY_JSON}")
    try:
        tensors = load(raw)
    except Exception as exc:  # the parser's own error types vary with the damage
        raise ValueError(f"{directory / WEIGHTS}: not a safetensors file ({exc})") from None
    _check_size(kwargs.get("net_arch", []), sum(t.numel() for t in tensors.values()), where)
    try:
        policy = policy_class(observation_space, action_space, lambda _: 0.0, **kwargs)
    except (AssertionError, TypeError, ValueError) as exc:
        raise ValueError(f"{where}: cannot build {policy_class.__name__} ({exc})") from None
    _load_state(policy, tensors, directory / WEIGHTS)
    return LoadedPolicy(policy, meta["algo"], meta["env"], normalization, directory, meta.get("residual"))


def _read_weights(path: Path) -> bytes:
    """The bytes of ``policy.safetensors``, a regular file of at most :data:`MAX_WEIGHTS_BYTES`."""
    return read_or_refuse(path, MAX_WEIGHTS_BYTES, "a safetensors file", "the weights of a policy")


def _check_size(net_arch: list[int] | dict[str, list[int]], stored: int, where: str) -> None:
    """Refuse, before building, layers larger than all the stored weights (their matrices would be
    in the file): a crafted net_arch cannot make the loader allocate much beyond the file's size."""
    for layers in net_arch.values() if isinstance(net_arch, dict) else [net_arch]:
        if any(a * b > stored for a, b in itertools.pairwise([1, *layers])):
            raise ValueError(f"{where}: net_arch {layers} does not fit the {stored} stored weights")


def _load_state(policy: Any, tensors: dict[str, Any], path: Path) -> None:
    expected = policy.state_dict()
    missing, unexpected = sorted(set(expected) - set(tensors)), sorted(set(tensors) - set(expected))
    if missing or unexpected:
        raise ValueError(f"{path}: weights do not fit the policy (missing {missing or 'none'}, "
                         f"unexpected {unexpected or 'none'})")  # fmt: skip
    for key, value in expected.items():
        if tensors[key].shape != value.shape or tensors[key].dtype != value.dtype:
            raise ValueError(f"{path}: {key} is {tensors[key].dtype} {tuple(tensors[key].shape)}, "
                             f"the policy needs {value.dtype} {tuple(value.shape)}")  # fmt: skip
        if tensors[key].is_floating_point() and not bool(tensors[key].isfinite().all()):
            # the SHA-256 only says the file is the one recorded; NaN would fail later, far from here
            raise ValueError(f"{path}: {key} holds non-finite weights (NaN or inf)")
    policy.load_state_dict(tensors, strict=True)
    policy.set_training_mode(False)
