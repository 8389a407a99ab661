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


def _float_clip(value: float, low: float, high: float) -> float:
    return min(max(value, low), high)


def _float_select(condition: bool, if_true: float, if_false: float) -> float:
    return if_true if condition else if_false


FLOAT_OPS = (_float_clip, _float_select)
ARRAY_OPS = (np.clip, np.where)


def engine_step(
    x: list, linkage: list, valve: list, command: list, params: StepParameters, ops: tuple = ARRAY_OPS
) -> tuple[list, list, list]:
    """One sample of the engine truth: valve linkage, stiction, gains of eq 36, linear dynamics.

    The dynamics use the alpha-canonical structure (eq 9): ``x(k+1) = A_o x + K y + B u*`` with
    ``y`` the last p states, so a step costs n (p + m) multiply-adds and no product with the
    zeros and ones of A_o. Every quantity is a list of columns, one per state or valve. A column
    is a float (one engine, with ``FLOAT_OPS``) or an array of shape (N,) (N engines, with
    ``ARRAY_OPS``); the arithmetic is the same sequence of IEEE operations either way, so an
    engine gives the same bits alone as inside a batch. K, B and lambda may be floats or arrays
    of shape (N,) (one model per engine).

    Returns the new state columns, linkage positions and valve positions.
    """
    clip, select = ops
    half, stick = params.half_backlash, params.stiction
    if half:
        linkage = [clip(lk, c - half, c + half) for lk, c in zip(linkage, command)]
    else:
        linkage = command
    if stick:
        valve = [select(abs(q - v) > stick, q, v) for q, v in zip(linkage, valve)]
    else:
        valve = linkage
    u_star = [v + g * abs(v) for v, g in zip(valve, params.lam_minus_one)]
    return alpha_update(x, u_star, params.shift_source, params.K, params.B), linkage, valve


def alpha_update(x: list, u: list, shift_source: list[int], k_gain: list, b_gain: list) -> list:
    """``x(k+1) = A_o x + K y + B u`` on state columns (eq 9), ``y`` the last p states.

    ``shift_source[i]`` is the state A_o copies into state i (-1: none). Floats or (N,) arrays.
    """
    y = x[len(x) - len(k_gain[0]) :]
    x_next = []
    for source, k_row, b_row in zip(shift_source, k_gain, b_gain):
        acc = x[source] if source >= 0 else 0.0
        for k, yj in zip(k_row, y):
            acc = acc + k * yj
        for b, uj in zip(b_row, u):
            acc = acc + b * uj
        x_next.append(acc)
    return x_next


@dataclass(frozen=True)
class StepParameters:
    """What :func:`engine_step` needs: the alpha-canonical structure and K, B, lambda - 1 as nested
    lists of floats (or of (N,) arrays), and the valve widths."""

    shift_source: list[int]
    K: list
    B: list
    lam_minus_one: list
    half_backlash: float
    stiction: float

    @classmethod
    def from_model(cls, model: AlphaCanonicalModel, config: TruthConfig) -> StepParameters:
        a_o = model.structure.shift_matrix()
        lam = model.lam - 1.0 if config.asymmetric_gains else np.zeros(model.n_inputs)
        return cls(
            shift_source=[int(np.argmax(row)) if row.any() else -1 for row in a_o],
            K=model.K.tolist(),
            B=model.B.tolist(),
            lam_minus_one=lam.tolist(),
            half_backlash=0.5 * config.backlash,
            stiction=config.stiction,
        )


class EngineCore:
    """N independent engines stepped together with :func:`engine_step`.

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
        self.params = StepParameters.from_model(model, config)
        self.x = [np.zeros(n) for _ in range(model.A.shape[0])]
        self.linkage = [np.zeros(n) for _ in range(model.n_inputs)]
        self.valve = [np.zeros(n) for _ in range(model.n_inputs)]

    def reset(self, mask: np.ndarray | None = None) -> None:
        """Zero the state of all engines, or of those where ``mask`` is True."""
        for column in (*self.x, *self.linkage, *self.valve):
            if mask is None:
                column[:] = 0.0
            else:
                column[mask] = 0.0

    def output(self) -> np.ndarray:
        """Noise-free outputs y = C x (the last p states), shape (n, p)."""
        return np.column_stack(self.x[len(self.x) - self.model.n_outputs :])

    def step(self, command: np.ndarray) -> np.ndarray:
        """Advance one sample with valve commands of shape (n, m); returns the valve positions (n, m)."""
        columns = [command[:, j] for j in range(command.shape[1])]
        self.x, self.linkage, self.valve = engine_step(self.x, self.linkage, self.valve, columns, self.params)
        # copies: with no backlash or stiction these columns are views of the caller's command
        self.linkage = [np.array(c, dtype=float) for c in self.linkage]
        self.valve = [np.array(c, dtype=float) for c in self.valve]
        return np.column_stack(self.valve)


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
