"""Which engine models an engine env is built from: the truth's effects (a TruthConfig from one or
from a dict), the point model behind ``plant=`` ("truth", "identified", a model.json or a model),
checked to be one the envs can step, with the episode's steps at its sample time, and the linear
model its controllers are designed on at a power level. These are choices made once when an env
is built, kept apart from the task that steps the chosen plant every sample."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ssme_envs.envs.task import check_keys, check_number, check_numbers
from ssme_envs.models.engine import (
    POWER_LEVELS,
    TruthConfig,
    check_plant_gain,
    check_stable_plant,
    identified_model,
    output_coupling,
    published_model,
)
from ssme_envs.models.linked import POWER_RANGE, LinkedEngineModel
from ssme_envs.models.statespace import ENGINE_INPUTS, ENGINE_OUTPUTS, AlphaCanonicalModel

# normalized output units: the largest reference step and sensor bias the engine envs take are
# 0.05 (5 % of rated Pc or MR, five times the default step); noise of a larger standard deviation
# buries every reference and bias in it (and 1e154 squares to an infinite reward)
MAX_SENSOR_NOISE = 0.05
# normalized valve travel: the widest command swing of the largest action_scale (+-0.2); a valve
# whose dead band (backlash or stick band) is wider never moves, whatever the action
MAX_DEAD_BAND = 0.4


def resolve_truth(truth: TruthConfig | Mapping[str, Any] | None) -> TruthConfig:
    """A TruthConfig from one, from a dict of its fields, or the default; its effects' widths and
    noise checked against the bounds above (ValueError naming the field), the noise as one
    standard deviation per output."""
    if truth is None:
        return TruthConfig()
    if isinstance(truth, TruthConfig):
        fields = {name: getattr(truth, name) for name in TruthConfig.__dataclass_fields__}
    elif isinstance(truth, Mapping):
        check_keys("truth", truth, tuple(TruthConfig.__dataclass_fields__), "option")
        fields = dict(truth)
    else:
        raise ValueError(f"truth must be a TruthConfig or a dict, got {type(truth).__name__}")
    # checked before TruthConfig's own checks, which raise OverflowError on an int like 10**400;
    # numpy numbers become floats, which TruthConfig takes
    for name in ("backlash", "stiction"):
        if name in fields:
            fields[name] = check_number(f"truth {name}", fields[name], 0.0, MAX_DEAD_BAND)
    if "sensor_noise" in fields:  # one per output, as the engine tasks read it
        noise = check_numbers("truth sensor_noise", fields["sensor_noise"], 2, 0.0, MAX_SENSOR_NOISE)
        fields["sensor_noise"] = tuple(noise.tolist())
    return TruthConfig(**fields)


def resolve_plant(plant: str | Path | AlphaCanonicalModel, power: float) -> AlphaCanonicalModel:
    """The engine model behind an environment.

    ``"truth"``: the linked published model at ``power`` (Table I itself at 70-100 %);
    ``"identified"``: the packaged design model identified at ``power`` (70, 80, 90, 100, 110 %);
    a path to an engine model.json; or a model object. (``"nonlinear"``, the nonlinear engine,
    is no linear model: :meth:`~ssme_envs.envs.engine_task.EngineTask.build` takes it.)
    """
    if isinstance(plant, AlphaCanonicalModel):
        return plant
    if not isinstance(plant, (str, os.PathLike)):  # an array compared with the names is ambiguous
        raise TypeError(
            "plant must be 'truth', 'identified', 'nonlinear', a model.json path or a model, got "
            f"{type(plant).__name__}"
        )
    if plant == "truth":
        # at a Table I level, Table I's model is the linked model's local model there, to the
        # bit, without building its interpolators (scipy.interpolate: a quarter of a second on
        # the first make); check_power keeps 110 %, a level outside the linked range, an error
        if power in POWER_LEVELS and LinkedEngineModel.check_power(power) == power:
            return published_model(int(power))
        return LinkedEngineModel().local_model(power)
    if plant == "identified":
        if power not in POWER_LEVELS:
            levels = [level for level in POWER_LEVELS if level <= POWER_RANGE[1]]  # 110 is off range
            raise ValueError(f"plant='identified' exists at power {levels} %, got {power!r}")
        return identified_model(int(power))
    if isinstance(plant, str | Path) and str(plant).endswith(".json"):
        return AlphaCanonicalModel.load(plant)
    raise ValueError(
        f"plant must be 'truth', 'identified', 'nonlinear', a model.json path or a model, got {plant!r}"
    )


def env_plant(plant: str | Path | AlphaCanonicalModel, power: float) -> AlphaCanonicalModel:
    """:func:`resolve_plant`, checked to be a plant the engine envs step: 2 inputs (OPOV, FPOV)
    and 2 outputs (Pc, MR) that are its last two states, stable, with a bounded gain; else
    ValueError naming what is wrong."""
    model = resolve_plant(plant, power)
    if model.n_inputs != 2 or model.n_outputs != 2:
        raise ValueError(
            "plant must have 2 inputs (OPOV, FPOV) and 2 outputs (Pc, MR), "
            f"got {model.n_inputs} and {model.n_outputs}"
        )
    # the envs read the channels by position: a model of other names, or of these in another
    # order, would be stepped with its channels swapped or unknown
    names = (tuple(model.input_names), tuple(model.output_names))
    if names != (ENGINE_INPUTS, ENGINE_OUTPUTS):
        raise ValueError(
            f"plant must map inputs {list(ENGINE_INPUTS)} to outputs {list(ENGINE_OUTPUTS)} in that order, "
            f"got {list(names[0])} -> {list(names[1])}; identify it from columns of these names "
            "(ssme-envs identify engine --inputs beta_opov,beta_fpov --outputs pc,mr)"
        )
    if output_coupling(model) is not None:
        raise ValueError(
            "plant couples its outputs (C = H [0 I] with H != I, indices "
            f"{list(model.observability_indices)}): the engine environments step models whose "
            "outputs are their last two states; identify with --indices 2,2"
        )
    check_stable_plant(model)
    check_plant_gain(model)
    return model


# the sample times an engine model.json may have: the references hold levels for whole seconds
# (at least 2 steps each up to 0.5 s; round(1 / dt) is 0 from 2 s), and an episode's draws and
# tables grow with its steps (1e-9 s asked 74 GiB at reset); the packaged models have 0.04 s
MIN_DT, MAX_DT = 1e-3, 0.5
MAX_EPISODE_STEPS = 1_000_000  # the longest episodes (MAX_EPISODE_SECONDS) down to dt = 3.6 ms


def episode_steps(dt: float, episode_seconds: float) -> int:
    """The steps of an episode of ``episode_seconds`` at the plant's ``dt`` (s), or ValueError
    when dt is outside MIN_DT-MAX_DT or the episode over MAX_EPISODE_STEPS steps."""
    # dt out of range first: round() of an episode over a tiny dt would overflow
    if not MIN_DT <= dt <= MAX_DT or round(episode_seconds / dt) > MAX_EPISODE_STEPS:
        raise ValueError(
            f"plant dt must be within {MIN_DT:g}-{MAX_DT:g} s and an episode (episode_seconds / dt) "
            f"at most {MAX_EPISODE_STEPS} steps, got dt={dt:g} s for {episode_seconds:g} s"
        )
    return round(episode_seconds / dt)


def design_model(power: float, source: str = "identified") -> AlphaCanonicalModel:
    """The linear engine model a controller is designed on at ``power`` % (lambda and the valve
    effects left out): ``"identified"``, the packaged design model identified at the Table I
    level nearest to ``power``, or ``"truth"``, the published (linked) model at ``power``."""
    if source == "truth":
        return LinkedEngineModel().local_model(power)
    if source == "identified":
        return identified_model(int(min(POWER_LEVELS, key=lambda level: abs(level - power))))
    raise ValueError(f"design model source must be 'identified' or 'truth', got {source!r}")
