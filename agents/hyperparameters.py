"""The hyperparameters a training config may set for PPO, SAC and TD3, with their ranges.

They are checked before anything is built: a value SB3 does not check itself would otherwise end in a
division by zero or an assert deep inside SB3, or train on nonsense without a word (a discount of 2, a
negative clip range). Only what a user tunes is listed: SB3's other constructor arguments (buffer and
noise classes, ``_init_setup_model``, ...) take objects a TOML file cannot hold or belong to the run, and
``optimize_memory_usage`` is refused by SB3's replay buffer with the time-limit handling these envs need.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, NamedTuple


class Rule(NamedTuple):
    """What a hyperparameter accepts: a ``kind`` of value, a test of it, and the words for both."""

    kind: str  # "int", "number", "bool", or "auto|number" (a number or SB3's "auto" strings)
    test: Callable[[Any], bool]
    text: str  # what the error message says the value must be


def _entropy_coefficient(value: Any) -> bool:
    """SAC's ``ent_coef``: a number >= 0, ``"auto"`` or ``"auto_<initial value>"`` (learnt from it, > 0)."""
    if not isinstance(value, str):
        return value >= 0
    if value == "auto":
        return True
    try:
        start = float(value.removeprefix("auto_"))
    except ValueError:
        return False
    return value.startswith("auto_") and math.isfinite(start) and start > 0


COUNT = Rule("int", lambda v: v >= 1, "an integer >= 1")
FLAG = Rule("bool", lambda v: True, "true or false")
UNIT = Rule("number", lambda v: 0 <= v <= 1, "a number in [0, 1]")
POSITIVE = Rule("number", lambda v: v > 0, "a number > 0")
NON_NEGATIVE = Rule("number", lambda v: v >= 0, "a number >= 0")
SDE_FREQUENCY = Rule("int", lambda v: v >= -1, "an integer >= -1 (-1: a new noise matrix per rollout only)")

_COMMON = {
    # 0 is allowed: a frozen network is how a fine-tuning start (init_policy) is checked bit for bit
    "learning_rate": NON_NEGATIVE,
    "gamma": UNIT,
    "batch_size": COUNT,
    "stats_window_size": COUNT,
}
_OFF_POLICY = {
    **_COMMON,
    "buffer_size": COUNT,
    "learning_starts": Rule("int", lambda v: v >= 0, "an integer >= 0"),
    "tau": Rule("number", lambda v: 0 < v <= 1, "a number in (0, 1]"),  # 0 would freeze the targets
    "train_freq": COUNT,
    "gradient_steps": Rule("int", lambda v: v >= 1 or v == -1, "an integer >= 1, or -1 (one per step)"),
    "n_steps": COUNT,  # n-step returns
}
HYPERPARAMETERS: dict[str, dict[str, Rule]] = {
    "ppo": {
        **_COMMON,
        # SB3 checks n_steps * num_envs > 1 itself and says so; only its type is checked here
        "n_steps": Rule("int", lambda v: True, "an integer"),
        "n_epochs": COUNT,
        "gae_lambda": UNIT,
        "clip_range": POSITIVE,  # 0 would clip every update away
        "clip_range_vf": POSITIVE,
        "normalize_advantage": FLAG,
        "ent_coef": NON_NEGATIVE,
        "vf_coef": NON_NEGATIVE,
        "max_grad_norm": POSITIVE,
        "target_kl": POSITIVE,
        "use_sde": FLAG,
        "sde_sample_freq": SDE_FREQUENCY,
    },
    "sac": {
        **_OFF_POLICY,
        "ent_coef": Rule(
            "auto|number", _entropy_coefficient, '"auto", "auto_<initial value > 0>" or a number >= 0'
        ),
        "target_entropy": Rule(
            "auto|number", lambda v: v == "auto" or not isinstance(v, str), '"auto" or a number'
        ),
        "target_update_interval": COUNT,
        "use_sde": FLAG,
        "sde_sample_freq": SDE_FREQUENCY,
        "use_sde_at_warmup": FLAG,
    },
    "td3": {
        **_OFF_POLICY,
        "policy_delay": COUNT,
        "target_policy_noise": NON_NEGATIVE,
        "target_noise_clip": NON_NEGATIVE,
    },
}
"""Per algorithm, the hyperparameters a config may set and what each accepts."""


def _of_kind(kind: str, value: Any) -> bool:
    number = isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
    return {
        "int": type(value) is int,
        "number": number,
        "bool": isinstance(value, bool),
        "auto|number": number or isinstance(value, str),
    }[kind]


def check_hyperparameters(algo: str, hyper: dict[str, Any], accepted: Any, source: str) -> None:
    """ValueError naming the first hyperparameter of ``hyper`` that ``algo`` does not take from a
    config (not in :data:`HYPERPARAMETERS`, or not among ``accepted``, the names the installed SB3
    algorithm takes) or whose value is of the wrong kind or out of range."""
    rules = {key: rule for key, rule in HYPERPARAMETERS[algo].items() if key in accepted}
    for key, value in hyper.items():
        rule = rules.get(key)
        if rule is None:
            raise ValueError(f"{source}: hyperparameters.{key} is not a {algo} hyperparameter a config "
                             f"can set; known: {', '.join(rules)}")  # fmt: skip
        if not (_of_kind(rule.kind, value) and rule.test(value)):
            raise ValueError(f"{source}: hyperparameters.{key} must be {rule.text}, got {value!r}")


__all__ = ["HYPERPARAMETERS", "Rule", "check_hyperparameters"]
