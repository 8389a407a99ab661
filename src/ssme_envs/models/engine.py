"""SSME open-loop dynamics: published point models and the batched "truth" plant.

The truth is a Table I point model of NASA TM-104422 with what the paper says real hardware
adds in front of it: valve linkage backlash and valve stiction (isolated from the identified
dynamics in the paper, "determined from manufacturer's specifications or bench testing"), the
asymmetric input gains lambda of eq 36, and sensor noise on the measured outputs.

One core, :class:`EngineCore`, steps N independent engines at once; the simulators below and
the environments use it.

Valve nonlinearities (defaults are assumptions: the paper gives no widths):

- backlash of total width ``b``: the linkage output follows the command only once the command
  has moved more than ``b / 2`` away from it (a play operator);
- stiction band ``s``: the valve stays put until the linkage output is more than ``s`` away
  from it, then slips to the linkage output (stick-slip, one sample).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cache
from importlib import resources

import numpy as np

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
        for name in ("backlash", "stiction"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite width >= 0, got {value!r}")
        noise = np.atleast_1d(np.asarray(self.sensor_noise, dtype=float))
        if noise.ndim != 1 or not np.all(np.isfinite(noise)) or np.any(noise < 0):
            raise ValueError(
                f"sensor_noise must be finite standard deviations >= 0, got {self.sensor_noise!r}"
            )

    @classmethod
    def ideal(cls) -> TruthConfig:
        """The point model with its lambda only: no valve nonlinearity, no noise."""
        return cls(backlash=0.0, stiction=0.0, sensor_noise=0.0)


class EngineCore:
    """N independent engines stepped together: valves, gains, linear dynamics.

    Parameters
    ----------
    model : AlphaCanonicalModel
        The point model (any state-space model with the same semantics works).
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
        self._at = model.A.T.copy()
        self._bt = model.B.T.copy()
        self._ct = model.C.T.copy()
        self._lam_minus_one = (model.lam - 1.0) if config.asymmetric_gains else np.zeros(model.n_inputs)
        self._half_backlash = 0.5 * config.backlash
        self.x = np.zeros((n, model.A.shape[0]))
        self.linkage = np.zeros((n, model.n_inputs))
        self.valve = np.zeros((n, model.n_inputs))

    def reset(self, mask: np.ndarray | None = None) -> None:
        """Zero the state of all engines, or of those where ``mask`` is True."""
        if mask is None:
            self.x[:] = 0.0
            self.linkage[:] = 0.0
            self.valve[:] = 0.0
        else:
            self.x[mask] = 0.0
            self.linkage[mask] = 0.0
            self.valve[mask] = 0.0

    def output(self) -> np.ndarray:
        """Noise-free outputs y = C x, shape (n, p)."""
        y = self.x[:, :1] * self._ct[0]
        for j in range(1, self._ct.shape[0]):
            y += self.x[:, j : j + 1] * self._ct[j]
        return y

    def step(self, command: np.ndarray) -> np.ndarray:
        """Advance one sample with valve commands of shape (n, m); returns the valve positions."""
        if self._half_backlash > 0.0:
            np.clip(
                self.linkage, command - self._half_backlash, command + self._half_backlash, out=self.linkage
            )
            position = self.linkage
        else:
            position = command
        if self.config.stiction > 0.0:
            slip = np.abs(position - self.valve) > self.config.stiction
            np.copyto(self.valve, position, where=slip)
        else:
            self.valve[:] = position
        u_star = self.valve + self._lam_minus_one * np.abs(self.valve)
        # Column-by-column products instead of a matrix product: BLAS picks different kernels
        # for different batch sizes, and each engine must give the same bits alone or batched.
        x_next = self.x[:, :1] * self._at[0]
        for j in range(1, self._at.shape[0]):
            x_next += self.x[:, j : j + 1] * self._at[j]
        for j in range(self._bt.shape[0]):
            x_next += u_star[:, j : j + 1] * self._bt[j]
        self.x = x_next
        return self.valve


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
    noise_std = np.atleast_1d(np.asarray(config.sensor_noise, dtype=float))
    if noise_std.size == 1:
        noise_std = np.full(model.n_outputs, noise_std[0])
    if noise_std.shape != (model.n_outputs,):
        raise ValueError(f"sensor_noise needs 1 or {model.n_outputs} values, got {noise_std.size}")
    if np.any(noise_std > 0) and rng is None:
        raise ValueError("sensor noise is on: pass a seeded numpy Generator as rng")
    clean = np.empty((n_runs, horizon, model.n_outputs))
    core = EngineCore(model, config, n_runs)
    for k in range(horizon):
        clean[:, k] = core.output()
        core.step(u[:, k])
    measured = clean.copy()
    if np.any(noise_std > 0):
        measured += noise_std * rng.standard_normal(clean.shape)
    return (measured[0], clean[0]) if single else (measured, clean)
