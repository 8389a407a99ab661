"""VecNormalize's observation statistics as ``normalization.json``: written from a training run,
read back checked (bounds on clip and epsilon that keep the policy's inputs finite and
informative), and turned into SB3's own ``VecNormalize``."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from agents.json_fields import check_keys, finite, load_object, numbers, short
from ssme_envs.outputs import atomic_write

NORMALIZATION = "normalization.json"
_NORMALIZATION_KEYS = {"mean", "var", "count", "clip", "epsilon"}
# SB3's VecNormalize hands the policy clip((obs - mean) / sqrt(var + epsilon), -clip, clip) as float32.
# clip: the bound in standard deviations (SB3's default 10). It must be finite and fit float32 (else
# the cast overflows to inf, and inf becomes NaN in the network); below 1e-3 every observation is
# squashed to +-clip, and below float32's smallest numbers to 0: the policy would see (almost) only
# constants, a silently wrong normalization.
CLIP_RANGE = (1e-3, float(np.finfo(np.float32).max))
# epsilon: keeps the divisor above 0 for a constant observation (SB3's default 1e-8). Above 1 it
# swamps the variance of any observation of unit scale or less and squashes it towards 0 (at 1e308 or
# inf every observation becomes 0); below 1e-12 a constant observation is scaled by more than 1e6,
# amplifying its float noise to the clip bound. Both are far from any real VecNormalize setting.
EPSILON_RANGE = (1e-12, 1.0)


@dataclass(frozen=True)
class Normalization:
    """VecNormalize's observation statistics: ``(obs - mean) / sqrt(var + epsilon)`` clipped to
    ``[-clip, clip]``; ``count`` is the number of observations behind them."""

    mean: np.ndarray
    var: np.ndarray
    count: float
    clip: float
    epsilon: float

    def normalize(self, obs: np.ndarray) -> np.ndarray:
        """Normalized observations as float32 (what the policy was trained on)."""
        scale = 1.0 / np.sqrt(self.var + self.epsilon)
        # an overflow to +-inf (a huge observation minus a huge mean) is clipped to +-clip: no warning
        with np.errstate(over="ignore"):
            return np.clip((obs - self.mean) * scale, -self.clip, self.clip).astype(np.float32)


def save_normalization(venv: Any, path: Path) -> None:
    """Write a VecNormalize's observation statistics as JSON (atomically)."""
    rms = venv.obs_rms
    data = {"mean": rms.mean.tolist(), "var": rms.var.tolist(), "count": float(rms.count),
            "clip": float(venv.clip_obs), "epsilon": float(venv.epsilon)}  # fmt: skip
    with atomic_write(Path(path), "w") as fh:
        fh.write(json.dumps(data) + "\n")


def read_normalization(path: Path) -> Normalization:
    """The checked statistics of a ``normalization.json``; ValueError naming the problem."""
    data = load_object(Path(path))
    check_keys(data, _NORMALIZATION_KEYS, _NORMALIZATION_KEYS - {"count"}, str(path))
    mean, var = numbers(data["mean"], f"{path}: mean"), numbers(data["var"], f"{path}: var")
    if len(mean) != len(var) or not mean or not all(np.isfinite(mean + var)) or min(var) < 0:
        raise ValueError(f"{path}: mean and var must be finite lists of one length (var >= 0)")
    count = finite(data.get("count", 1e-4))  # SB3's RunningMeanStd starts from 1e-4
    if count is None or not count > 0:
        raise ValueError(f"{path}: count must be a finite positive number, got {short(data.get('count'))}")
    scalars = {}
    for key, (low, high) in (("clip", CLIP_RANGE), ("epsilon", EPSILON_RANGE)):
        value = finite(data[key])
        if value is None or not low <= value <= high:
            raise ValueError(f"{path}: {key} must be a finite positive number in [{low:g}, {high:g}], "
                             f"got {short(data[key])}")  # fmt: skip
        scalars[key] = value
    return Normalization(np.array(mean), np.array(var), count, scalars["clip"], scalars["epsilon"])


def to_vec_normalize(path: Path, venv: Any, training: bool = False, norm_reward: bool = False) -> Any:
    """SB3's ``VecNormalize`` around ``venv`` holding the statistics of a ``normalization.json``
    (by default frozen, rewards not normalized: as for evaluation)."""
    from stable_baselines3.common.vec_env import VecNormalize

    stats = read_normalization(Path(path))
    shape = getattr(venv.observation_space, "shape", None)
    if shape != stats.mean.shape:
        raise ValueError(f"{path}: statistics of shape {stats.mean.shape} for observations of shape {shape}")
    vec = VecNormalize(venv, training=training, norm_obs=True, norm_reward=norm_reward,
                       clip_obs=stats.clip, epsilon=stats.epsilon)  # fmt: skip
    vec.obs_rms.mean, vec.obs_rms.var, vec.obs_rms.count = stats.mean.copy(), stats.var.copy(), stats.count
    return vec
