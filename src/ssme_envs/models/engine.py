"""SSME open-loop dynamics: published point models and the batched "truth" plant.

The truth is a Table I point model of NASA TM-104422 with what the paper says real hardware
adds in front of it: valve linkage backlash and valve stiction (isolated from the identified
dynamics in the paper, "determined from manufacturer's specifications or bench testing"), the
asymmetric input gains lambda of eq 36, and sensor noise on the measured outputs.

The step exists on floats (:func:`step_floats`, one engine) and on arrays (:func:`step_arrays`,
N engines), one arithmetic: the env tasks step these (``envs.engine_task``); :class:`EngineCore`
holds N engines' state around :func:`step_arrays` for the simulators below.

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


@dataclass(frozen=True)
class StepParameters:
    """What one engine step needs: the alpha-canonical shift structure, K, B, lambda - 1 (arrays,
    with a leading batch axis when every engine has its own model), and the valve widths."""

    shift_source: tuple[int, ...]
    K: np.ndarray
    B: np.ndarray
    lam_minus_one: np.ndarray
    half_backlash: float
    stiction: float

    @classmethod
    def from_model(cls, model: AlphaCanonicalModel, config: TruthConfig) -> StepParameters:
        a_o = model.structure.shift_matrix()
        lam = model.lam - 1.0 if config.asymmetric_gains else np.zeros(model.n_inputs)
        return cls(
            shift_source=tuple(int(np.argmax(row)) if row.any() else -1 for row in a_o),
            # The last p states are w = H^-1 y; they enter through A's last columns, K H.
            K=model.A[:, model.A.shape[0] - model.n_outputs :].copy(),
            B=model.B.copy(),
            lam_minus_one=lam,
            half_backlash=0.5 * config.backlash,
            stiction=float(config.stiction),
        )

    def floats(self) -> tuple[list, list, list]:
        """K and B rows and lambda - 1 as Python floats, for :func:`step_floats`."""
        return self.K.tolist(), self.B.tolist(), self.lam_minus_one.tolist()


# The engine step exists twice, on purpose: on Python floats for one engine (an order of
# magnitude faster than numpy on 1-element arrays, for the scalar environment) and on arrays
# for a batch (the vector environment, the simulators). Both perform the same IEEE operations
# in the same order, so an engine gives the same bits alone or batched; tests hold them to it.
# Order: linkage = min(max(l, c - h), c + h); valve = q if |q - v| > s else v;
# u* = v + (lambda - 1)|v|; x_i <- (x_src(i) + sum_j K_ij y_j) + sum_j B_ij u*_j, sums left to right
# (no x_src term for the first state of each output's chain).


def valves_floats(linkage: list, valve: list, command: list, half: float, stick: float) -> tuple[list, list]:
    """Backlash then stiction for one engine's valves, on floats. Returns (linkage, valve)."""
    if half:
        linkage = [min(max(lk, c - half), c + half) for lk, c in zip(linkage, command)]
    else:
        linkage = command
    if stick:
        valve = [q if abs(q - v) > stick else v for q, v in zip(linkage, valve)]
    else:
        valve = linkage
    return linkage, valve


def dynamics_floats(x: list, u: list, shift_source: tuple, k_rows: list, b_rows: list) -> list:
    """``x(k+1) = A_o x + K y + B u`` (eq 9) for one engine on floats, ``y`` the last p states."""
    y = x[len(x) - len(k_rows[0]) :]
    if len(y) == 2 and len(u) == 2:  # the SSME's two outputs and two valves, unrolled, same order
        y0, y1 = y
        u0, u1 = u
        return [
            ((x[source] + (k0 * y0 + k1 * y1)) if source >= 0 else (k0 * y0 + k1 * y1)) + (b0 * u0 + b1 * u1)
            for source, (k0, k1), (b0, b1) in zip(shift_source, k_rows, b_rows)
        ]
    x_next = []
    for source, k_row, b_row in zip(shift_source, k_rows, b_rows):
        ky = k_row[0] * y[0]
        for k, yj in zip(k_row[1:], y[1:]):
            ky = ky + k * yj
        bu = b_row[0] * u[0]
        for b, uj in zip(b_row[1:], u[1:]):
            bu = bu + b * uj
        x_next.append(((x[source] + ky) if source >= 0 else ky) + bu)
    return x_next


def step_floats(x: list, linkage: list, valve: list, command: list, p: StepParameters, rows: tuple) -> tuple:
    """One engine, one sample, on floats; ``rows`` = ``p.floats()``. Returns (x, linkage, valve)."""
    k_rows, b_rows, lam = rows
    linkage, valve = valves_floats(linkage, valve, command, p.half_backlash, p.stiction)
    u = [v + g * abs(v) for v, g in zip(valve, lam)]
    return dynamics_floats(x, u, p.shift_source, k_rows, b_rows), linkage, valve


# The env tasks' engines have two valves and two outputs: their float step is the one above,
# unrolled over unpacked floats (a third of its time, which is list building and zips), the
# same operations in the same order.


def pair_rows(shift_source: tuple, k_rows: list, b_rows: list) -> tuple:
    """Per state ``(source, K_i0, K_i1, B_i0, B_i1)`` of a two-output, two-valve model, for
    :func:`dynamics_pair_floats`."""
    return tuple(
        (source, k0, k1, b0, b1)
        for source, (k0, k1), (b0, b1) in zip(shift_source, k_rows, b_rows, strict=True)
    )


def valves_pair_floats(
    linkage: tuple, valve: tuple, c0: float, c1: float, half: float, stick: float
) -> tuple[tuple, tuple]:
    """:func:`valves_floats` for two valves. ``min(max(l, lo), hi)`` is spelled as the builtins
    decide (each returns its first argument unless the second lies strictly beyond it), which
    gives the same value, NaN and signed zeros included, without two calls per valve."""
    l0, l1 = linkage
    if half:
        lo, hi = c0 - half, c0 + half
        l0 = lo if lo > l0 else l0
        l0 = hi if hi < l0 else l0
        lo, hi = c1 - half, c1 + half
        l1 = lo if lo > l1 else l1
        l1 = hi if hi < l1 else l1
    else:
        l0, l1 = c0, c1
    if stick:
        v0, v1 = valve
        v0 = l0 if abs(l0 - v0) > stick else v0
        v1 = l1 if abs(l1 - v1) > stick else v1
    else:
        v0, v1 = l0, l1
    return (l0, l1), (v0, v1)


def dynamics_pair_floats(x: list, u0: float, u1: float, rows: tuple) -> list:
    """:func:`dynamics_floats` for two outputs and two valves; ``rows`` from :func:`pair_rows`."""
    y0, y1 = x[-2], x[-1]
    return [
        ((x[source] + (k0 * y0 + k1 * y1)) if source >= 0 else (k0 * y0 + k1 * y1)) + (b0 * u0 + b1 * u1)
        for source, k0, k1, b0, b1 in rows
    ]


def valves_arrays(linkage: np.ndarray, valve: np.ndarray, command: np.ndarray, half: float, stick: float):
    """Backlash then stiction for N engines' valves, (m, N) arrays. Returns (linkage, valve)."""
    linkage = np.minimum(np.maximum(linkage, command - half), command + half) if half else command
    valve = np.where(np.abs(linkage - valve) > stick, linkage, valve) if stick else linkage
    return linkage, valve


def dynamics_arrays(
    x: np.ndarray, u: np.ndarray, shift_source: tuple, k_gain: np.ndarray, b_gain: np.ndarray
):
    """``x(k+1) = A_o x + K y + B u`` for N engines, state-major x (n, N), u (m, N); K (n, p) and
    B (n, m), or (n, p, N) and (n, m, N) for one model per engine."""
    n_out = k_gain.shape[1]
    y = x[x.shape[0] - n_out :]
    scratch = np.empty((x.shape[0], x.shape[1]))
    x_next = np.multiply(_column(k_gain, 0), y[0])
    for j in range(1, n_out):
        x_next += np.multiply(_column(k_gain, j), y[j], out=scratch)
    for i, source in enumerate(shift_source):  # the shift part of A_o: x_i += x_src(i)
        if source >= 0:
            x_next[i] += x[source]
    bu = np.multiply(_column(b_gain, 0), u[0])
    for j in range(1, b_gain.shape[1]):
        bu += np.multiply(_column(b_gain, j), u[j], out=scratch)
    x_next += bu
    return x_next


def step_arrays(
    x: np.ndarray, linkage: np.ndarray, valve: np.ndarray, command: np.ndarray, p: StepParameters
):
    """N engines, one sample, state-major: x (n, N), linkage, valve, command (m, N). Returns
    (x, linkage, valve). Rows are contiguous, so every operation runs over N engines at once."""
    linkage, valve = valves_arrays(linkage, valve, command, p.half_backlash, p.stiction)
    lam = p.lam_minus_one
    u = valve + (lam[:, None] if lam.ndim == 1 else lam) * np.abs(valve)
    return dynamics_arrays(x, u, p.shift_source, p.K, p.B), linkage, valve


def _column(gain: np.ndarray, j: int) -> np.ndarray:
    """Column j of a gain as (n, 1) to multiply a row of N engines, or (n, N) when per engine."""
    return gain[:, j, None] if gain.ndim == 2 else gain[:, j]


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
