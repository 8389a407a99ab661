"""SSME open-loop dynamics: published point models and the batched "truth" plant.

The truth is a Table I point model of NASA TM-104422 with what the paper says real hardware
adds in front of it: valve linkage backlash and valve stiction (isolated from the identified
dynamics in the paper, "determined from manufacturer's specifications or bench testing"), the
asymmetric input gains lambda of eq 36, and sensor noise on the measured outputs.

The step exists on floats (:func:`~ssme_envs.models.engine_step.step_floats`, one engine) and on
arrays (:func:`~ssme_envs.models.engine_step.step_arrays`, N engines), one arithmetic: the env
tasks step these (``envs.engine_task``); :class:`EngineCore` holds N engines' state around
:func:`~ssme_envs.models.engine_step.step_arrays` for the simulators below.

Valve nonlinearities (defaults are assumptions: the paper gives no widths):

- backlash of total width ``b``: the linkage output follows the command only once the command
  has moved more than ``b / 2`` away from it (a play operator);
- stiction band ``s``: the valve stays put until the linkage output is more than ``s`` away
  from it, then slips to the linkage output (stick-slip, one sample).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from functools import cache
from importlib import resources

import numpy as np

from ssme_envs.models.engine_step import StepParameters, step_arrays, step_floats
from ssme_envs.models.statespace import AlphaCanonicalModel

POWER_LEVELS: tuple[int, ...] = (70, 80, 90, 100, 110)
_DATA = resources.files("ssme_envs") / "models" / "data"
ENGINE_DT = 0.04  # s, the PRBS clock of the paper; the paper does not state the sample time


@cache
def _table1_document() -> dict:
    return json.loads(_DATA.joinpath("engine_table1.json").read_text())


def published_model(power_percent: int) -> AlphaCanonicalModel:
    """Table I point model at 70, 80, 90, 100 or 110 % power."""
    doc = _table1_document()
    for entry in doc["models"]:
        if entry["power_percent"] == power_percent:
            return AlphaCanonicalModel(
                A=entry["A"],
                B=entry["B"],
                C=entry["C"],
                dt=doc["dt"],
                observability_indices=tuple(entry["observability_indices"]),
                lam=entry["lambda"],
                input_names=tuple(doc["input_names"]),
                output_names=tuple(doc["output_names"]),
                fit={"source": doc["source"]},
            )
    raise ValueError(f"no published model at {power_percent} % power; choose one of {list(POWER_LEVELS)}")


def identified_model(power_percent: int) -> AlphaCanonicalModel:
    """The packaged design model identified by the pipeline at a Table I power level."""
    if power_percent not in POWER_LEVELS:
        raise ValueError(
            f"no identified model at {power_percent} % power; choose one of {list(POWER_LEVELS)}"
        )
    path = _DATA.joinpath(f"engine_identified_{power_percent}.json")
    return AlphaCanonicalModel.from_dict(json.loads(path.read_text()), source=path.name)


@dataclass(frozen=True)
class TruthConfig:
    """What the truth plant adds to a point model. Each effect can be switched off.

    Attributes
    ----------
    asymmetric_gains : bool
        Apply the model's lambda (eq 36). Off: lambda = 1.
    backlash : float
        Total backlash width of each valve linkage, normalized valve units (assumed 5e-4).
    stiction : float
        Stick band of each valve, normalized valve units (assumed 2e-4).
    sensor_noise : float or tuple of float
        Standard deviation of the white measurement noise on each output (one value for all),
        normalized units (assumed 1e-4 on Pc and MR, 1-2 % of the response to a 0.01 PRBS).
    """

    asymmetric_gains: bool = True
    backlash: float = 5e-4
    stiction: float = 2e-4
    sensor_noise: float | tuple[float, ...] = (1e-4, 1e-4)

    def __post_init__(self) -> None:
        if not isinstance(self.asymmetric_gains, bool):
            raise ValueError(f"asymmetric_gains must be True or False, got {self.asymmetric_gains!r}")
        for name in ("backlash", "stiction"):
            value = getattr(self, name)
            if (
                isinstance(value, bool)
                or not isinstance(value, int | float)
                or not (np.isfinite(value) and value >= 0)
            ):
                raise ValueError(f"{name} must be a finite width >= 0, got {value!r}")
        try:
            noise = np.atleast_1d(np.asarray(self.sensor_noise, dtype=float))
        except (TypeError, ValueError):
            raise ValueError(f"sensor_noise must be numbers, got {self.sensor_noise!r}") from None
        if noise.ndim != 1 or not np.all(np.isfinite(noise)) or np.any(noise < 0):
            raise ValueError(
                f"sensor_noise must be finite standard deviations >= 0, got {self.sensor_noise!r}"
            )

    @classmethod
    def ideal(cls) -> TruthConfig:
        """The point model with its lambda only: no valve nonlinearity, no noise."""
        return cls(backlash=0.0, stiction=0.0, sensor_noise=0.0)


def check_stable_plant(model: AlphaCanonicalModel) -> None:
    """Refuse (ValueError) a model with an eigenvalue of A on or outside the unit circle as an
    env's plant: its open-loop state grows without bound, and a fast enough growth overflows
    within one step (to an infinite reward and NaN). The SSME models are well inside (spectral
    radius about 0.55-0.65); an unstable one is a failed identification, not an engine."""
    radius = model.spectral_radius()
    if not radius < 1.0:
        raise ValueError(
            f"engine plant refused: A has spectral radius {radius:.6g} >= 1 (an eigenvalue on or "
            "outside the unit circle), so its open-loop state grows without bound; the envs need a "
            "stable model (the identified SSME models have 0.55-0.65)"
        )


# normalized output (1 = the 100 % value) that no engine plant reaches under full valve travel:
# the SSME's models stay below 5 (see check_plant_gain); beyond, a model is a unit mistake or a
# failed fit, and near 1e150 its rewards overflow to -inf
MAX_PEAK_OUTPUT = 1e3


def check_plant_gain(model: AlphaCanonicalModel, travel: float = 1.0) -> None:
    """Refuse (ValueError) a stable model whose outputs a valve travel of ``travel`` (normalized,
    each valve, through the lambda gains) can drive beyond :data:`MAX_PEAK_OUTPUT`: the bound is
    the l1 norm of its impulse response (Markov parameters until A^k has decayed by 1e-12)."""
    radius = model.spectral_radius()
    decay = math.ceil(math.log(1e-12) / math.log(radius)) if 0.0 < radius < 1.0 else 1
    with np.errstate(over="ignore", invalid="ignore"):
        l1 = np.abs(model.markov_parameters(min(decay, 10_000) + model.A.shape[0])).sum(axis=0)
        peak = float((l1 * (1.0 + np.abs(model.lam - 1.0))).sum(axis=1).max() * travel)
    if not peak <= MAX_PEAK_OUTPUT:
        raise ValueError(
            f"engine plant refused: a valve travel of {travel:g} can drive an output to {peak:.3g} "
            f"(normalized; at most {MAX_PEAK_OUTPUT:g} is taken, the SSME models reach below 5): "
            "check the model's B, K and lambda and their units"
        )


def output_coupling(model: AlphaCanonicalModel) -> np.ndarray | None:
    """H of ``C = H [0 I]``, or None when it is the identity (the outputs are the last states)."""
    h = model.H
    return None if np.array_equal(h, np.eye(h.shape[0])) else h


class EngineCore:
    """N independent engines stepped together (:func:`step_arrays`).

    Parameters
    ----------
    model : AlphaCanonicalModel
        The point model (any model in alpha-canonical form).
    config : TruthConfig
        The valve and gain effects (sensor noise is left to the caller, who draws it).
    n : int
        Number of engines.
    """

    def __init__(self, model: AlphaCanonicalModel, config: TruthConfig, n: int = 1) -> None:
        if n < 1:
            raise ValueError(f"n must be >= 1, got {n}")
        self.model = model
        self.config = config
        self.n = n
        self.params = StepParameters.from_model(model, config)
        self.coupling = output_coupling(model)
        self.x = np.zeros((model.A.shape[0], n))  # state-major: row i is state i of every engine
        self.linkage = np.zeros((model.n_inputs, n))
        self.valve = np.zeros((model.n_inputs, n))

    def reset(self, mask: np.ndarray | None = None) -> None:
        """Zero the state of all engines, or of those where ``mask`` is True."""
        engines = slice(None) if mask is None else mask
        self.x[:, engines] = 0.0
        self.linkage[:, engines] = 0.0
        self.valve[:, engines] = 0.0

    def output(self) -> np.ndarray:
        """Noise-free outputs y = C x = H w (w the last p states), shape (n, p)."""
        w = self.x[self.x.shape[0] - self.model.n_outputs :].T
        return w.copy() if self.coupling is None else w @ self.coupling.T

    def step(self, command: np.ndarray) -> np.ndarray:
        """Advance one sample with valve commands of shape (n, m); returns the valve positions (n, m)."""
        command = np.array(np.asarray(command, dtype=float).T)  # a copy: the valves may keep it
        self.x, self.linkage, self.valve = step_arrays(self.x, self.linkage, self.valve, command, self.params)
        return self.valve.T.copy()


def simulate(
    model: AlphaCanonicalModel,
    commands: np.ndarray,
    config: TruthConfig | None = None,
    rng: np.random.Generator | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Run the truth plant on valve command sequences.

    Parameters
    ----------
    model : AlphaCanonicalModel
        Point model.
    commands : array, shape (T, m) or (N, T, m)
        Valve commands, normalized deviations, one row per sample.
    config : TruthConfig, optional
        Defaults to ``TruthConfig()``.
    rng : numpy Generator, optional
        Source of the sensor noise; required when the config has noise.

    Returns
    -------
    measured, clean : arrays of shape (T, p) or (N, T, p)
        Outputs with and without sensor noise; ``y(k) = C x(k)`` before command ``k`` acts.
    """
    config = TruthConfig() if config is None else config
    u = np.asarray(commands, dtype=float)
    single = u.ndim == 2
    if single:
        u = u[None]
    if u.ndim != 3 or u.shape[2] != model.n_inputs:
        raise ValueError(
            f"commands must have shape (T, {model.n_inputs}) or (N, T, {model.n_inputs}), "
            f"got {np.shape(commands)}"
        )
    if not np.all(np.isfinite(u)):
        raise ValueError("commands contain NaN or inf")
    n_runs, horizon, _ = u.shape
    noise_std = sensor_noise_std(config, model.n_outputs, rng)
    clean = np.empty((n_runs, horizon, model.n_outputs))
    if n_runs == 1:  # the float path: same bits, an order of magnitude faster
        params = StepParameters.from_model(model, config)
        rows = params.floats()
        x, linkage, valve = [0.0] * model.A.shape[0], [0.0] * model.n_inputs, [0.0] * model.n_inputs
        n_out = model.n_outputs
        for k, command in enumerate(u[0].tolist()):
            clean[0, k] = x[len(x) - n_out :]
            x, linkage, valve = step_floats(x, linkage, valve, command, params, rows)
    else:
        core = EngineCore(model, config, n_runs)
        for k in range(horizon):
            clean[:, k] = core.output()
            core.step(u[:, k])
    coupling = output_coupling(model)
    if coupling is not None and n_runs == 1:
        clean = clean @ coupling.T
    measured = with_sensor_noise(clean, noise_std, rng)
    return (measured[0], clean[0]) if single else (measured, clean)


def sensor_noise_std(config: TruthConfig, n_outputs: int, rng: np.random.Generator | None) -> np.ndarray:
    """The standard deviation of each output's sensor noise, (n_outputs,), from the config's one
    value or one per output; ValueError for another count, or when noise is on without ``rng``.
    (The simulators of both engine truths read their noise through it.)"""
    noise_std = np.atleast_1d(np.asarray(config.sensor_noise, dtype=float))
    if noise_std.size == 1:
        noise_std = np.full(n_outputs, noise_std[0])
    if noise_std.shape != (n_outputs,):
        raise ValueError(f"sensor_noise needs 1 or {n_outputs} values, got {noise_std.size}")
    if np.any(noise_std > 0) and rng is None:
        raise ValueError("sensor noise is on: pass a seeded numpy Generator as rng")
    return noise_std


def with_sensor_noise(
    clean: np.ndarray, noise_std: np.ndarray, rng: np.random.Generator | None
) -> np.ndarray:
    """The measured outputs: a new array, ``clean`` plus ``noise_std`` times standard normals
    drawn from ``rng`` (no draw when every deviation is zero)."""
    if np.any(noise_std > 0):
        return clean + noise_std * rng.standard_normal(clean.shape)
    return clean.copy()
