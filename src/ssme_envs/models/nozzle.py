"""Movable nozzle with a flexible joint: linear and Bouc-Wen hysteretic dynamics, batched.

The nozzle angle x (rad) under the actuator torque tau (N m) obeys (VLS nozzle paper, eqs 1, 3, 6)

    J x'' + b x' + a k x + (1 - a) k z = tau,
    z' = A x' - |z|^n (beta + gamma sign(x' z)) x',

the torque being held constant over each sample (zero-order hold). With ``a = 1`` the joint is
linear. ``A``, ``beta``, ``gamma`` and ``(1 - a) k`` are not jointly identifiable: with
``z = A w`` the same motion follows from

    J x'' + b x' + k_el x + k_hys w = tau,
    w' = x' (1 - |w|^n (beta_n + gamma_n sign(x' w))),

where ``k_el = a k``, ``k_hys = (1 - a) k A``, ``beta_n = beta A^(n-1)``, ``gamma_n = gamma A^(n-1)``.
The core integrates this normalized form; :class:`NozzleParameters` converts both ways.
``k_el + k_hys`` is the small-signal stiffness (1.43e5 N m/rad for Table 1, equal to the
paper's linear k).

:class:`NozzleCore` steps N nozzles at once with fixed-step RK4 and ``substeps`` per sample; each
parameter may differ per nozzle (a population of candidate models in a fit, or randomized plants).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from functools import cache
from importlib import resources
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from ssme_envs.models.statespace import as_matrix, check_dt, dumps_compact, read_json
from ssme_envs.models.uncertainty import ParameterUncertainty

NOZZLE_DT = 0.008  # s, the paper's decimated sample time
BENCH_RATE_HZ = 2500.0  # the bench acquisition rate
DEFAULT_SUBSTEPS = 4  # RK4 steps per 0.008 s sample: 2 ms, about 1e-6 relative error (see tests)
DEFAULT_TORQUE_LIMIT = 3.0e4  # N m, an assumption: about 4x the 7.5e3 N m of a static 3 deg deflection

_DATA = resources.files("ssme_envs") / "models" / "data"


@dataclass(frozen=True)
class NozzleParameters:
    """Bouc-Wen nozzle in the paper's (Table 1) form. ``a = 1`` gives the linear joint.

    Attributes
    ----------
    J : kg m^2; b : N m s/rad; k : N m/rad
        Inertia, damping and joint stiffness.
    a : float
        Ratio of post-yield to pre-yield stiffness (1: linear).
    A, beta, gamma, n : float
        Bouc-Wen shape parameters (dimensionless in this form; z has the units of x).
    """

    J: float
    b: float
    k: float
    a: float = 1.0
    A: float = 1.0
    beta: float = 0.0
    gamma: float = 0.0
    n: float = 1.0

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            if isinstance(value, bool) or not isinstance(value, int | float) or not np.isfinite(value):
                raise ValueError(f"nozzle parameter {name} must be a finite number, got {value!r}")
        for name in ("J", "k", "A", "n"):
            if getattr(self, name) <= 0:
                raise ValueError(f"nozzle parameter {name} must be positive, got {getattr(self, name)}")
        if self.b < 0:
            raise ValueError(f"nozzle damping b must be >= 0, got {self.b}")
        if not 0 <= self.a <= 1:
            raise ValueError(f"nozzle parameter a must be in [0, 1], got {self.a}")
        if self.beta + self.gamma < 0:
            raise ValueError("beta + gamma must be >= 0 (otherwise z grows without bound)")
        if self.gamma < 0:
            # In this form gamma weighs sign(x' z): gamma < 0 makes unloading (x' z < 0) steeper
            # than loading, and z then grows without bound on some bounded inputs (class III of
            # Ikhouane, Manosa & Rodellar 2007, with their beta and gamma swapped).
            raise ValueError(
                f"nozzle parameter gamma must be >= 0, got {self.gamma} (with gamma < 0 the "
                "hysteretic state z grows without bound on unloading)"
            )
        try:
            norm = self.normalized()
        except OverflowError:
            norm = {"beta_n": math.inf}
        for name, value in norm.items():
            if not math.isfinite(value):
                raise ValueError(
                    f"nozzle parameter {name} = {value} of the normalized joint is not finite "
                    f"(A^(n - 1) or (1 - a) k A overflows: A = {self.A}, n = {self.n}, k = {self.k})"
                )

    @classmethod
    def linear(cls, J: float, b: float, k: float) -> NozzleParameters:
        return cls(J=J, b=b, k=k)

    @property
    def is_linear(self) -> bool:
        return self.a == 1.0

    @property
    def small_signal_stiffness(self) -> float:
        """a k + (1 - a) k A, N m/rad."""
        return self.a * self.k + (1.0 - self.a) * self.k * self.A

    def normalized(self) -> dict[str, float]:
        """The identifiable parameters (J, b, k_el, k_hys, beta_n, gamma_n, n)."""
        scale = self.A ** (self.n - 1.0)
        return {
            "J": self.J,
            "b": self.b,
            "k_el": self.a * self.k,
            "k_hys": (1.0 - self.a) * self.k * self.A,
            "beta_n": self.beta * scale,
            "gamma_n": self.gamma * scale,
            "n": self.n,
        }

    @classmethod
    def from_normalized(
        cls, J: float, b: float, k_el: float, k_hys: float, beta_n: float, gamma_n: float, n: float, A: float
    ) -> NozzleParameters:
        """Table 1 form of normalized parameters under the stated normalization ``A``."""
        k = k_el + k_hys / A
        scale = A ** (1.0 - n)
        return cls(J=J, b=b, k=k, a=k_el / k, A=A, beta=beta_n * scale, gamma=gamma_n * scale, n=n)

    def to_dict(self) -> dict[str, float]:
        return {key: float(value) for key, value in asdict(self).items()}


@cache
def _table1() -> dict[str, Any]:
    return json.loads(_DATA.joinpath("nozzle_table1.json").read_text())


def published_nozzle(which: str = "bouc_wen") -> NozzleParameters:
    """Table 1 of the VLS nozzle paper: ``"bouc_wen"`` (nonlinear row) or ``"linear"``."""
    table = _table1()
    if which not in ("bouc_wen", "linear"):
        raise ValueError(f"which must be 'bouc_wen' or 'linear', got {which!r}")
    return NozzleParameters(**table[which])


def identified_nozzle() -> NozzleModel:
    """The packaged nozzle model identified from the embedded bench test on Table 1's nozzle."""
    path = _DATA.joinpath("nozzle_identified.json")
    return NozzleModel.from_dict(json.loads(path.read_text()), source=path.name)


class NozzleCore:
    """N nozzles integrated together by RK4 with the torque held over each sample.

    Parameters
    ----------
    params : NozzleParameters or sequence of them, or a dict of normalized parameter arrays
        One parameter set for all nozzles, one per nozzle, or arrays of shape (n,) keyed like
        :meth:`NozzleParameters.normalized`.
    n : int
        Number of nozzles (taken from the parameters when they are per nozzle).
    dt : float
        Sample time, s.
    substeps : int
        RK4 steps per sample.
    torque_limit : float
        Actuator torque saturation, N m (inf: none).
    """

    def __init__(
        self,
        params: NozzleParameters | list[NozzleParameters] | dict[str, np.ndarray],
        n: int = 1,
        dt: float = NOZZLE_DT,
        substeps: int = DEFAULT_SUBSTEPS,
        torque_limit: float = DEFAULT_TORQUE_LIMIT,
    ) -> None:
        if isinstance(params, NozzleParameters):
            params = [params] * n
        if isinstance(params, list | tuple):
            norm = [p.normalized() for p in params]
            params = {key: np.array([d[key] for d in norm]) for key in norm[0]}
        self.n = len(np.atleast_1d(params["J"]))
        dt = check_dt(dt)
        if int(substeps) != substeps or substeps < 1:
            raise ValueError(f"substeps must be a positive integer, got {substeps!r}")
        if not torque_limit > 0:
            raise ValueError(f"torque_limit must be positive, got {torque_limit!r}")
        p = {key: np.broadcast_to(np.asarray(value, dtype=float), (self.n,)) for key, value in params.items()}
        self._k_el, self._k_hys = p["k_el"], p["k_hys"]
        shared = all(np.all(q == q[0]) for q in p.values())
        # floats when every nozzle has the same parameters (always for one): the float integrator's
        self._params = rk4_parameters({k: (float(q[0]) if shared else q) for k, q in p.items()})
        self.dt = float(dt)
        self.substeps = int(substeps)
        self.torque_limit = float(torque_limit)
        self.state = np.zeros((3, self.n))  # angle x (rad), rate x' (rad/s), normalized hysteresis w (rad)

    def reset(self, mask: np.ndarray | None = None) -> None:
        if mask is None:
            self.state[:] = 0.0
        else:
            self.state[:, mask] = 0.0

    def step(self, torque: np.ndarray | float) -> np.ndarray:
        """Advance one sample under the (saturated) torque; returns the angles, shape (n,)."""
        tau = np.clip(torque, -self.torque_limit, self.torque_limit)
        if self.n == 1:  # plain floats: an order of magnitude faster than 1-element arrays
            x, v, w = rk4_floats(
                *(float(c[0]) for c in self.state),
                float(np.ravel(tau)[0]),
                self.dt / self.substeps,
                self.substeps,
                self._params,
            )
            self.state[:, 0] = (x, v, w)
        else:
            rk4_arrays(self.state, tau, self.dt / self.substeps, self.substeps, self._params)
        return self.state[0]

    def restoring_torque(self) -> np.ndarray:
        """k_el x + k_hys w, N m: the joint's restoring torque F of eq 6."""
        return self._k_el * self.state[0] + self._k_hys * self.state[2]


def simulate_nozzle(
    params: NozzleParameters | list[NozzleParameters] | dict[str, np.ndarray],
    torque: np.ndarray,
    dt: float = NOZZLE_DT,
    substeps: int = DEFAULT_SUBSTEPS,
    torque_limit: float = DEFAULT_TORQUE_LIMIT,
) -> np.ndarray:
    """Angles x(k) (rad) of nozzles driven by torque sequences, from rest.

    Parameters
    ----------
    params : see :class:`NozzleCore`
    torque : array, shape (T,) for every nozzle alike, or (N, T)
        Torque commands, N m, held over each sample.

    Returns
    -------
    ndarray, shape (T,) or (N, T): x(k) is the angle before torque k acts.
    """
    tau = np.asarray(torque, dtype=float)
    if tau.ndim not in (1, 2) or tau.shape[-1] == 0:
        raise ValueError(f"torque must have shape (T,) or (N, T), got {tau.shape}")
    if not np.all(np.isfinite(tau)):
        raise ValueError("torque contains NaN or inf")
    n = tau.shape[0] if tau.ndim == 2 else 1
    core = NozzleCore(params, n=n, dt=dt, substeps=substeps, torque_limit=torque_limit)
    if tau.ndim == 2 and core.n != n:
        raise ValueError(f"{core.n} parameter sets for {n} torque sequences")
    horizon = tau.shape[-1]
    if core.n == 1:  # rk4_floats without the per-sample bookkeeping of NozzleCore.step
        limit, h, steps, params = (
            core.torque_limit,
            core.dt / core.substeps,
            core.substeps,
            core._params,
        )
        x = v = w = 0.0
        angles = [0.0] * horizon
        for k, torque_k in enumerate(np.ravel(tau).tolist()):
            angles[k] = x
            x, v, w = rk4_floats(x, v, w, min(max(torque_k, -limit), limit), h, steps, params)
        out = np.array(angles)
        return out[None] if tau.ndim == 2 else out
    out = np.empty((core.n, horizon))
    columns = tau.T if tau.ndim == 2 else tau[:, None]
    for k in range(horizon):
        out[:, k] = core.state[0]
        core.step(columns[k])
    return out


class RK4Parameters(NamedTuple):
    """The normalized nozzle as the integrators use it: floats, or (N,) arrays per nozzle."""

    inv_j: Any  # 1/J, 1/(kg m^2)
    b_j: Any  # b/J, 1/s
    k_el_j: Any  # k_el/J, 1/s^2
    k_hys_j: Any  # k_hys/J, 1/s^2
    beta: Any  # beta_n
    gamma: Any  # gamma_n
    n: Any
    w_floor: Any  # floor of |w| in |w|^n, rad
    hysteretic: bool


def rk4_parameters(norm: dict[str, Any]) -> RK4Parameters:
    """Integrator parameters from normalized ones (floats or arrays, keyed as
    :meth:`NozzleParameters.normalized`)."""
    inv_j = 1.0 / norm["J"]
    return RK4Parameters(
        inv_j=inv_j,
        b_j=norm["b"] * inv_j,
        k_el_j=norm["k_el"] * inv_j,
        k_hys_j=norm["k_hys"] * inv_j,
        beta=norm["beta_n"],
        gamma=norm["gamma_n"],
        n=norm["n"],
        w_floor=np.maximum(1e-30 ** (1.0 / np.asarray(norm["n"])), 1e-300)[()].tolist()
        if np.ndim(norm["n"]) == 0
        else np.maximum(1e-30 ** (1.0 / norm["n"]), 1e-300),
        hysteretic=bool(np.any(np.asarray(norm["k_hys"]) != 0)),
    )


# Two carriers of one arithmetic: rk4_floats for one nozzle on Python floats (no array
# overhead), rk4_arrays for a batch in place. Both run the same IEEE operations in the same order
# on every nozzle, so a nozzle gives the same bits alone and in a batch (tested). The power is
# numpy's on both carriers (Python's pow differs from it in the last bit). In the Bouc-Wen law,
# gamma sign(x' w) is written copysign(gamma, x' w), one operation: the same value wherever it
# matters (at x' w = 0 either x' = 0 or |w|^n = 0 multiplies it away). |w| is floored where
# |w|^n = 1e-30 (or at 1e-300): the power of an exact zero takes a slow path in numpy, and below
# the floor 1 - c |w|^n is exactly 1 either way (for |c| = |beta +- gamma| < 1e13).


def rk4_floats(
    x: float, v: float, w: float, tau: float, h: float, steps: int, p: RK4Parameters
) -> tuple[float, float, float]:
    """``steps`` RK4 steps of length h (s) of one nozzle under the torque tau (N m), held.

    x (rad), v (rad/s) and w (rad, normalized hysteresis) in, the same out."""
    inv_j, b_j, k_el_j, k_hys_j, beta, gamma, n, floor, hys = p
    accel0 = tau * inv_j
    power, copysign = np.power, math.copysign
    half, sixth = 0.5 * h, h / 6.0

    # The Bouc-Wen rate v (1 - (beta + gamma sign(v w)) |w|^n) written out at each stage: a
    # function call per stage would cost a tenth of the step.
    for _ in range(steps):
        a1 = accel0 - b_j * v - k_el_j * x - k_hys_j * w
        w1 = v * (1.0 - (copysign(gamma, v * w) + beta) * float(power(max(abs(w), floor), n))) if hys else v
        x2, v2, w2 = half * v + x, half * a1 + v, half * w1 + w
        a2 = accel0 - b_j * v2 - k_el_j * x2 - k_hys_j * w2
        w2_rate = (
            v2 * (1.0 - (copysign(gamma, v2 * w2) + beta) * float(power(max(abs(w2), floor), n)))
            if hys
            else v2
        )
        x3, v3, w3 = half * v2 + x, half * a2 + v, half * w2_rate + w
        a3 = accel0 - b_j * v3 - k_el_j * x3 - k_hys_j * w3
        w3_rate = (
            v3 * (1.0 - (copysign(gamma, v3 * w3) + beta) * float(power(max(abs(w3), floor), n)))
            if hys
            else v3
        )
        x4, v4, w4 = h * v3 + x, h * a3 + v, h * w3_rate + w
        a4 = accel0 - b_j * v4 - k_el_j * x4 - k_hys_j * w4
        w4_rate = (
            v4 * (1.0 - (copysign(gamma, v4 * w4) + beta) * float(power(max(abs(w4), floor), n)))
            if hys
            else v4
        )
        x = sixth * ((v2 + v3) * 2.0 + v + v4) + x
        v = sixth * ((a2 + a3) * 2.0 + a1 + a4) + v
        w = sixth * ((w2_rate + w3_rate) * 2.0 + w1 + w4_rate) + w
    return x, v, w


def rk4_arrays(state: np.ndarray, tau: np.ndarray | float, h: float, steps: int, p: RK4Parameters) -> None:
    """``steps`` RK4 steps of N nozzles in place: ``state`` (3, N) rows x (rad), v (rad/s), w
    (rad), torques tau (N,) in N m held over the steps; the arithmetic of :func:`rk4_floats`."""
    n = state.shape[1]
    rates = np.empty((4, 3, n))  # the four RK4 stages' derivatives of (x, v, w)
    stage = np.empty((3, n))
    tmp, coef = np.empty((2, n))
    accel0 = np.multiply(tau, p.inv_j)
    half, sixth = 0.5 * h, h / 6.0
    # row views made once: taking them costs about as much as an operation on a row
    state_rows, stage_rows, rate_rows = tuple(state), tuple(stage), [tuple(r) for r in rates]

    def derivative(rows: tuple, out: tuple) -> None:
        x, v, w = rows
        x_rate, accel, w_rate = out
        np.copyto(x_rate, v)
        np.multiply(p.b_j, v, out=tmp)
        np.subtract(accel0, tmp, out=accel)
        np.multiply(p.k_el_j, x, out=tmp)
        accel -= tmp
        np.multiply(p.k_hys_j, w, out=tmp)
        accel -= tmp
        if not p.hysteretic:
            np.copyto(w_rate, v)
            return
        np.multiply(v, w, out=tmp)
        np.copysign(p.gamma, tmp, out=coef)
        np.add(coef, p.beta, out=coef)
        np.abs(w, out=tmp)
        np.maximum(tmp, p.w_floor, out=tmp)
        np.power(tmp, p.n, out=tmp)
        np.multiply(coef, tmp, out=coef)
        np.subtract(1.0, coef, out=coef)
        np.multiply(v, coef, out=w_rate)

    for _ in range(steps):
        for i, weight in enumerate((half, half, h)):
            derivative(state_rows if i == 0 else stage_rows, rate_rows[i])
            np.multiply(weight, rates[i], out=stage)
            stage += state
        derivative(stage_rows, rate_rows[3])
        np.add(rates[1], rates[2], out=stage)
        stage *= 2.0
        stage += rates[0]
        stage += rates[3]
        stage *= sixth
        state += stage


NOZZLE_MODEL_SCHEMA = "ssme-envs/nozzle-model"
# Version 2 added the optional ``uncertainty`` blocks in ``linear`` and ``bouc_wen``; version 1
# files (without them) still load.
NOZZLE_MODEL_SCHEMA_VERSION = 2
_READABLE_VERSIONS = (1, 2)
_LINEAR_MATRICES = ("A", "B", "C", "D", "K")
LINEAR_UNCERTAIN = ("J", "b", "k")
BOUC_WEN_UNCERTAIN = ("J", "b", "k_el", "k_hys", "beta_n", "gamma_n", "n")


def _read_uncertainty(block: Any, known: tuple[str, ...], where: str) -> ParameterUncertainty:
    """An ``uncertainty`` block of model.json (see :class:`NozzleModel`); ValueError naming the flaw."""
    result = ParameterUncertainty.from_dict(block, known, f"{where}.uncertainty")
    listed = block.get("standard_errors")
    if listed is not None:
        try:
            values = np.array(listed, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"{where}.uncertainty.standard_errors must be a list of numbers") from None
        expected = result.standard_errors
        if values.shape != expected.shape or not np.allclose(values, expected, rtol=1e-9, atol=0.0):
            raise ValueError(
                f"{where}.uncertainty.standard_errors {listed} disagree with the square roots of the "
                "covariance's diagonal"
            )
    return result


@dataclass
class NozzleModel:
    """A nozzle model.json: the linear innovations model with its J, b, k, and the Bouc-Wen joint.

    Attributes
    ----------
    linear : dict
        ``A, B, C, D, K`` (arrays) of ``x(k+1) = A x + B tau + K e``, ``beta = C x + D tau + e``
        at ``dt`` (s), and ``J``, ``b``, ``k`` from its continuous transfer function.
    bouc_wen : NozzleParameters or None
        The hysteretic joint, or None when the data did not determine it.
    fit : dict
        Fit figures and provenance (JSON-serializable).
    linear_uncertainty : ParameterUncertainty or None
        Covariance of ``J``, ``b``, ``k`` (parameters named "J", "b", "k").
    bouc_wen_uncertainty : ParameterUncertainty or None
        Covariance of the Bouc-Wen joint's normalized parameters "J", "b", "k_el", "k_hys",
        "beta_n", "gamma_n", "n" (:meth:`NozzleParameters.normalized`), the ones the data
        determine; only with ``bouc_wen``.

    In model.json each covariance is an ``uncertainty`` object inside ``linear`` and inside
    ``bouc_wen``: ``{"parameters": [names], "covariance": [[...]], "standard_errors": [...],
    "method": "...", "samples": N}``, the covariance in the parameters' units squared (J in
    kg m^2, b in N m s/rad, k, k_el, k_hys in N m/rad, the rest dimensionless), the standard
    errors the square roots of its diagonal. The block is optional (schema version 2).
    """

    linear: dict[str, Any]
    bouc_wen: NozzleParameters | None
    fit: dict[str, Any]
    input_name: str = "tau"
    output_name: str = "beta"
    linear_uncertainty: ParameterUncertainty | None = None
    bouc_wen_uncertainty: ParameterUncertainty | None = None

    def __post_init__(self) -> None:
        for name, uncertainty, known in (
            ("linear", self.linear_uncertainty, LINEAR_UNCERTAIN),
            ("bouc_wen", self.bouc_wen_uncertainty, BOUC_WEN_UNCERTAIN),
        ):
            if uncertainty is None:
                continue
            if not isinstance(uncertainty, ParameterUncertainty):
                raise ValueError(f"{name} uncertainty must be a ParameterUncertainty")
            unknown = sorted(set(uncertainty.parameters) - set(known))
            if unknown:
                raise ValueError(f"{name}.uncertainty names parameters the model lacks: {', '.join(unknown)}")
        if self.bouc_wen_uncertainty is not None and self.bouc_wen is None:
            raise ValueError("bouc_wen.uncertainty is given but the Bouc-Wen joint is not")
        lin = dict(self.linear)
        if "uncertainty" in lin:
            raise ValueError(
                "linear: give the covariance as linear_uncertainty, not a linear['uncertainty'] entry"
            )
        missing = [key for key in (*_LINEAR_MATRICES, "dt", "J", "b", "k") if key not in lin]
        if missing:
            raise ValueError(f"linear: missing key(s) {', '.join(missing)}")
        a = as_matrix(lin["A"], "linear.A", (None, None))
        n = a.shape[0]
        if a.shape[1] != n:
            raise ValueError(f"linear.A must be square, got shape {a.shape}")
        lin["A"] = a
        lin["B"] = as_matrix(lin["B"], "linear.B", (n, 1))
        lin["C"] = as_matrix(lin["C"], "linear.C", (1, n))
        lin["D"] = as_matrix(lin["D"], "linear.D", (1, 1))
        lin["K"] = as_matrix(lin["K"], "linear.K", (n, 1))
        for key in ("dt", "J", "b", "k"):
            value = lin[key]
            if isinstance(value, bool) or not isinstance(value, int | float) or not np.isfinite(value):
                raise ValueError(f"linear.{key} must be a finite number, got {value!r}")
            if value < 0 or (key != "b" and value == 0):
                kind = ">= 0 (damping)" if key == "b" else "positive"
                raise ValueError(f"linear.{key} must be {kind}, got {value!r}")
            lin[key] = float(value)
        self.linear = lin

    @property
    def dt(self) -> float:
        return self.linear["dt"]

    def plant(self) -> NozzleParameters:
        """The joint to simulate: the Bouc-Wen one when determined, else the linear J, b, k."""
        if self.bouc_wen is not None:
            return self.bouc_wen
        return NozzleParameters.linear(self.linear["J"], self.linear["b"], self.linear["k"])

    def to_dict(self) -> dict[str, Any]:
        lin = {
            key: (value.tolist() if isinstance(value, np.ndarray) else value)
            for key, value in self.linear.items()
        }
        if self.linear_uncertainty is not None:
            lin["uncertainty"] = self.linear_uncertainty.to_dict()
        bw = None if self.bouc_wen is None else self.bouc_wen.to_dict()
        if bw is not None and self.bouc_wen_uncertainty is not None:
            bw["uncertainty"] = self.bouc_wen_uncertainty.to_dict()
        return {
            "schema": NOZZLE_MODEL_SCHEMA,
            "schema_version": NOZZLE_MODEL_SCHEMA_VERSION,
            "input_name": self.input_name,
            "output_name": self.output_name,
            "linear": lin,
            "bouc_wen": bw,
            "fit": self.fit,
        }

    @classmethod
    def from_dict(cls, data: Any, source: str = "model") -> NozzleModel:
        if not isinstance(data, dict):
            raise ValueError(f"{source}: expected a JSON object, got {type(data).__name__}")
        if data.get("schema") != NOZZLE_MODEL_SCHEMA:
            raise ValueError(f"{source}: schema is {data.get('schema')!r}, expected {NOZZLE_MODEL_SCHEMA!r}")
        if data.get("schema_version") not in _READABLE_VERSIONS:
            raise ValueError(f"{source}: unsupported schema_version {data.get('schema_version')!r}")
        if not isinstance(data.get("linear"), dict):
            raise ValueError(f"{source}: 'linear' must be an object with A, B, C, D, K, dt, J, b, k")
        linear = dict(data["linear"])
        bw = data.get("bouc_wen")
        uncertainty: dict[str, ParameterUncertainty | None] = {"linear": None, "bouc_wen": None}
        try:
            if "uncertainty" in linear:
                uncertainty["linear"] = _read_uncertainty(
                    linear.pop("uncertainty"), LINEAR_UNCERTAIN, "linear"
                )
            if bw is not None:
                if not isinstance(bw, dict):
                    raise ValueError("'bouc_wen' must be an object or null")
                bw = dict(bw)
                if "uncertainty" in bw:
                    uncertainty["bouc_wen"] = _read_uncertainty(
                        bw.pop("uncertainty"), BOUC_WEN_UNCERTAIN, "bouc_wen"
                    )
                unknown = sorted(set(bw) - set(NozzleParameters.__dataclass_fields__))
                if unknown:
                    raise ValueError(f"bouc_wen: unknown key(s) {', '.join(unknown)}")
                missing = sorted(set(NozzleParameters.__dataclass_fields__) - set(bw))
                if missing:
                    raise ValueError(f"bouc_wen: missing key(s) {', '.join(missing)}")
                bw = NozzleParameters(**bw)
            fit = data.get("fit", {})
            if not isinstance(fit, dict):
                raise ValueError("fit must be an object")
            for key in ("input_name", "output_name"):
                if not isinstance(data.get(key, "x"), str):
                    raise ValueError(f"{key} must be a string")
            return cls(
                linear=linear,
                bouc_wen=bw,
                fit=dict(fit),
                input_name=str(data.get("input_name", "tau")),
                output_name=str(data.get("output_name", "beta")),
                linear_uncertainty=uncertainty["linear"],
                bouc_wen_uncertainty=uncertainty["bouc_wen"],
            )
        except ValueError as exc:
            raise ValueError(f"{source}: {exc}") from None

    def save(self, path: str | Path) -> None:
        from ssme_envs.outputs import write_text  # atomic: a reader never sees half a model

        write_text(path, dumps_compact(self.to_dict()) + "\n")

    @classmethod
    def load(cls, path: str | Path) -> NozzleModel:
        return cls.from_dict(read_json(path), source=str(path))


class StiffRate(NamedTuple):
    """A rate (1/s) that limits RK4's step on a joint: its name, value and the parameters
    behind it (for messages)."""

    name: str
    rate: float
    detail: str


def accuracy_rate(params: NozzleParameters, amplitude: float) -> StiffRate:
    """The rate (1/s) of :func:`recommended_substeps`: the faster of the joint's natural
    frequency ``omega_n`` and, once the joint yields, the hysteresis variable's own rate
    ``omega_n * amplitude * n / w_max`` with ``w_max = (beta_n + gamma_n)^(-1/n)`` (``inf`` where
    it overflows)."""
    norm = params.normalized()
    omega = float(np.sqrt((norm["k_el"] + norm["k_hys"]) / norm["J"]))
    load = norm["beta_n"] + norm["gamma_n"]
    detail = f"k = {norm['k_el'] + norm['k_hys']:.6g} N m/rad, J = {norm['J']:.6g} kg m^2"
    if norm["k_hys"] > 0 and load > 0:
        try:
            w_max = load ** (-1.0 / norm["n"])
        except OverflowError:  # a vanishing load: no saturation within reach
            w_max = math.inf
        hysteresis = omega * amplitude * norm["n"] / w_max if w_max > 0 else math.inf
        if hysteresis > omega:
            detail += f", beta_n + gamma_n = {load:.6g}, n = {norm['n']:.6g}, amplitude = {amplitude:g} rad"
            return StiffRate("hysteresis rate omega_n amplitude n / w_max", hysteresis, detail)
    return StiffRate("natural frequency sqrt(k/J)", omega, detail)


def recommended_substeps(
    params: NozzleParameters, dt: float, amplitude: float, step_rate: float = 0.2
) -> int:
    """RK4 substeps per sample so that ``h * rate <= step_rate`` for a motion of ``amplitude`` rad
    (an accuracy rule; :func:`integration_substeps` adds the stability rule).

    ``rate`` (:func:`accuracy_rate`) is the faster of the joint's natural frequency ``omega_n``
    and, once the joint yields, the hysteresis variable's own rate ``omega_n * amplitude * n /
    w_max`` with ``w_max = (beta_n + gamma_n)^(-1/n)``: large beta + gamma make the z equation
    stiff. The default 0.2 keeps the angle within about 2e-4 of a fine reference for Table 1's
    nozzle and for a strongly hysteretic one (experiments/results/nozzle_integration_accuracy.md);
    the sign switch of the Bouc-Wen law at velocity reversals limits RK4 to about second order.

    Raises
    ------
    ValueError
        When the rate overflows (no finite count).
    """
    if not (amplitude > 0 and step_rate > 0 and dt > 0):
        raise ValueError("dt, amplitude and step_rate must be positive")
    fastest = accuracy_rate(params, amplitude)
    count = dt * fastest.rate / step_rate
    if not math.isfinite(count):
        raise ValueError(f"the joint's {fastest.name} overflows ({fastest.detail})")
    return max(1, int(np.ceil(count)))


# RK4's stability: on y' = lambda y one step multiplies y by R(h lambda) = 1 + z + z^2/2 + z^3/6 +
# z^4/24, and |R| <= 1 holds on [-2.785, 0] of the real axis, on [-2.828, 2.828] i of the
# imaginary axis (2 sqrt 2), and on the whole half-disc |z| <= 2.61, Re z <= 0 (the region's
# boundary comes closest to 0 at about 123 degrees, radius 2.616). A rate bound that holds for
# every eigenvalue in the left half-plane, whatever its angle, is therefore h |lambda| <= 2.61.
# The env rule keeps half of that (STABILITY_SAFETY = 0.5): the rates of stiff_rates bound a
# linearized, state-dependent Jacobian rather than give its eigenvalues (the joint's three
# rates add up in coupled modes, and the speed bound behind the hysteresis rate is an energy
# estimate), and at half the limit a step still damps a fast real mode as the flow does
# (R(-1.3) = 0.27, exp(-1.3) = 0.27) instead of ringing at the edge of the region.
RK4_REAL_AXIS_LIMIT = 2.785  # h |lambda| where RK4's stability region meets the negative real axis
RK4_IMAGINARY_AXIS_LIMIT = 2.828  # ... and the imaginary axis
RK4_HALF_DISC_LIMIT = 2.61  # radius of the largest left half-disc inside the region
STABILITY_SAFETY = 0.5
STABLE_STEP_RATE = STABILITY_SAFETY * RK4_HALF_DISC_LIMIT  # h * rate bound of the stability rule
MAX_SUBSTEPS = 10_000  # RK4 steps per env step; a plant that needs more is refused


def stiff_rates(
    params: NozzleParameters, amplitude: float, torque_limit: float, dt: float
) -> list[StiffRate]:
    """The rates (1/s) that bound the eigenvalues of the joint's Jacobian for an env that ends
    its episode once ``|x| > amplitude`` (rad) at the end of a sample of ``dt`` s, under torques
    up to ``torque_limit`` N m (finite).

    - ``stiffness``: ``sqrt((k_el + k_hys) / J)``, the natural frequency at small signal (the
      modulus of the complex pair of the linear joint);
    - ``damping``: ``b / J``, the bound of the fast real root of an overdamped joint (the roots'
      modulus never exceeds ``max(b / J, sqrt(k / J))``);
    - ``hysteresis`` (a joint with ``k_hys > 0`` only): the slope in w of the normalized Bouc-Wen
      law ``w' = v (1 - c |w|^n)``, ``c = beta_n + gamma_n sign(v w)``, as the integrators
      implement it: ``|dw'/dw| = |v| |c| n |w|^(n - 1) <= v_max (|beta_n| + gamma_n) n
      w_b^(n - 1)``, ``|beta_n| + gamma_n`` being the larger of the loading and the unloading
      ``|c|`` (gamma_n >= 0). For n < 1 the slope is larger nearer w = 0, but the term
      ``c |w|^n`` it belongs to vanishes there: no growth follows.

    The speed and travel behind the third are energy estimates, not proofs (the non-finite
    guard of the envs is the net). With ``X = amplitude``, ``T = torque_limit``:

    - ``v_0 = sqrt((k X^2 + 4 X T) / J)``: the speed inside the envelope, from the elastic energy
      at a turning point plus the torque's work over one traverse;
    - ``X_t = X + v_0 dt + T dt^2 / (2 J)``: the travel within the sample that leaves the
      envelope (the envelope is checked at the sample's end);
    - ``w_b = min(w_max, 2 X_t)``: ``|w|`` never passes ``w_max = (beta_n + gamma_n)^(-1/n)``
      from rest, and grows at most as fast as x (while loading);
    - ``v_max = sqrt((k X_t^2 + 4 X_t F) / J) + F dt / J`` with ``F = T + k_hys w_b``: the energy
      bound over that travel, plus what the torque and the hysteretic force add in one sample.

    A rate that overflows reads ``inf``.
    """
    if not (amplitude > 0 and dt > 0 and torque_limit > 0 and math.isfinite(torque_limit)):
        raise ValueError("amplitude, dt and torque_limit must be positive and finite")
    norm = params.normalized()
    j, k, k_hys = norm["J"], norm["k_el"] + norm["k_hys"], norm["k_hys"]
    rates = [
        StiffRate("stiffness rate sqrt(k/J)", math.sqrt(k / j), f"k = {k:.6g} N m/rad, J = {j:.6g} kg m^2"),
        StiffRate("damping rate b/J", norm["b"] / j, f"b = {norm['b']:.6g} N m s/rad, J = {j:.6g} kg m^2"),
    ]
    if k_hys > 0:
        beta, gamma, n = norm["beta_n"], norm["gamma_n"], norm["n"]
        x, torque = amplitude, torque_limit
        v_0 = math.sqrt((k * x * x + 4.0 * x * torque) / j)
        travel = x + v_0 * dt + 0.5 * torque * dt * dt / j
        load = beta + gamma
        log_w = math.log(2.0 * travel) if math.isfinite(travel) else math.inf
        if load > 0:
            log_w = min(log_w, -math.log(load) / n)
        w_b = math.exp(min(log_w, 700.0))
        force = torque + k_hys * w_b
        v_max = math.sqrt((k * travel * travel + 4.0 * travel * force) / j) + force * dt / j
        c_max = abs(beta) + gamma
        rate = 0.0
        if c_max > 0 and v_max > 0:  # in logs: |w|^(n - 1) over- or underflows for extreme n
            log_rate = math.log(v_max) + math.log(c_max) + math.log(n) + (n - 1.0) * log_w
            rate = math.exp(log_rate) if log_rate < 700.0 else math.inf
        detail = (
            f"beta_n = {beta:.6g}, gamma_n = {gamma:.6g}, n = {n:.6g}, |v| <= {v_max:.6g} rad/s, "
            f"|w| <= {w_b:.6g} rad"
        )
        rates.append(StiffRate("hysteresis rate |v| (|beta_n| + gamma_n) n |w|^(n-1)", rate, detail))
    return rates


def stable_substeps(
    params: NozzleParameters,
    dt: float,
    amplitude: float,
    torque_limit: float,
    step_rate: float = STABLE_STEP_RATE,
) -> tuple[float, StiffRate]:
    """RK4 steps per sample of ``dt`` s that keep ``h * rate <= step_rate`` for every rate of
    :func:`stiff_rates`: the count (a float, at least 1; ``inf`` where a rate overflowed) and
    the rate that sets it."""
    fastest = max(stiff_rates(params, amplitude, torque_limit, dt), key=lambda r: r.rate)
    count = dt * fastest.rate / step_rate
    return (float(max(1, math.ceil(count))) if math.isfinite(count) else math.inf), fastest


def integration_substeps(
    params: NozzleParameters,
    dt: float,
    amplitude: float,
    torque_limit: float,
    accuracy_step_rate: float,
    max_substeps: int = MAX_SUBSTEPS,
    sample: str = "sample",
) -> int:
    """RK4 steps per ``sample`` of ``dt`` s for an env: the larger of the accuracy rule
    (:func:`recommended_substeps` at ``accuracy_step_rate``) and the stability rule
    (:func:`stable_substeps`), for a travel of ``amplitude`` rad under torques up to
    ``torque_limit`` N m. Computed once per plant.

    Raises
    ------
    ValueError
        When more than ``max_substeps`` are needed, naming the rate and its parameters.
    """
    stable, _ = stable_substeps(params, dt, amplitude, torque_limit)
    accurate = accuracy_rate(params, amplitude)
    accurate_count = dt * accurate.rate / accuracy_step_rate
    accurate_count = float(max(1, math.ceil(accurate_count))) if math.isfinite(accurate_count) else math.inf
    count = max(stable, accurate_count)
    if count > max_substeps:
        stability = f"RK4 stability at safety {STABILITY_SAFETY:g}"
        rules = [(r, STABLE_STEP_RATE, stability) for r in stiff_rates(params, amplitude, torque_limit, dt)]
        rules.append((accurate, accuracy_step_rate, "accuracy"))
        over = sorted(
            (rule for rule in rules if dt * rule[0].rate / rule[1] > max_substeps),
            key=lambda rule: -rule[0].rate / rule[1],
        )
        causes = "; ".join(
            f"its {r.name} = {r.rate:.4g} 1/s ({r.detail}) asks for h <= {step_rate / r.rate:.3g} s "
            f"(h * rate <= {step_rate:.3g}, {why})"
            for r, step_rate, why in over
        )
        raise ValueError(
            f"nozzle plant refused: it needs {count:.3g} RK4 substeps per {dt * 1e3:g} ms {sample}, more "
            f"than {max_substeps}: {causes}"
        )
    return int(count)


def check_stable_substeps(
    params: NozzleParameters, substeps: int, dt: float, amplitude: float, torque_limit: float
) -> None:
    """Refuse (ValueError naming the rate) a given count of RK4 steps per sample of ``dt`` s
    that the stability rule (:func:`stable_substeps`) finds too few."""
    needed, fastest = stable_substeps(params, dt, amplitude, torque_limit)
    if substeps < needed:
        raise ValueError(
            f"substeps={substeps} is too few for this nozzle plant: RK4 needs {needed:.3g} per "
            f"{dt * 1e3:g} ms for its {fastest.name} = {fastest.rate:.4g} 1/s ({fastest.detail}) at "
            f"h * rate <= {STABLE_STEP_RATE:.3g}"
        )
