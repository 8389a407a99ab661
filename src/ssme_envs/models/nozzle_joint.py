"""The nozzle joint: its parameters (Table 1 of the nozzle paper) and the RK4 arithmetic that
integrates it, on floats (one nozzle) and on arrays (a batch) alike (see :mod:`ssme_envs.models.nozzle`).

:func:`rk4_floats` and :func:`rk4_arrays` run the compiled kernel (``_joint_kernel.c``) where it
was built and gives the Python reference's bits at import (:data:`KERNEL` says which), the
reference (``_rk4_floats_py``, ``_rk4_arrays_py``) otherwise: the same bits either way."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, fields
from functools import cache
from importlib import resources
from typing import Any, NamedTuple

import numpy as np

from ssme_envs.models.joint_power import power_array, power_float, tables
from ssme_envs.models.kernels import load_kernel
from ssme_envs.models.linear import finite_float

NOZZLE_DT = 0.008  # s, the paper's decimated sample time
BENCH_RATE_HZ = 2500.0  # the bench acquisition rate
DEFAULT_SUBSTEPS = 4  # RK4 steps per 0.008 s sample: 2 ms, about 1e-6 relative error (see tests)
DEFAULT_TORQUE_LIMIT = 3.0e4  # N m, an assumption: about 4x the 7.5e3 N m of a static 3 deg deflection

_DATA = resources.files("ssme_envs") / "models" / "data"


# The Bouc-Wen exponent's largest value: fits give n of 1-2 and the literature under 20; at 1e22
# the joint's steps turned non-finite at once (|w|^n and its floor 1e-30^(1/n) round to 0 and 1).
MAX_N = 1000.0


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
        for field in fields(self):  # not asdict: it would copy (and recurse into) a nested list
            finite_float(getattr(self, field.name), f"nozzle parameter {field.name}")
        for name in ("J", "k", "A", "n"):
            if getattr(self, name) <= 0:
                raise ValueError(f"nozzle parameter {name} must be positive, got {getattr(self, name)}")
        if self.n > MAX_N:
            raise ValueError(
                f"nozzle parameter n must be at most {MAX_N:g}, got {self.n:g} (a larger exponent gives "
                "the elastoplastic loop, and past about 1e20 non-finite steps)"
            )
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


def strong_nozzle() -> NozzleParameters:
    """A nozzle of our own with far stronger hysteresis than Table 1 (illustrative, not VLS data).

    Its joint yields at about 1.7 deg (w_max = 0.029 rad) against Table 1's 20 deg, so the +-3 deg
    working range sweeps well into the hysteretic regime; small-signal stiffness 1.6e5 N m/rad,
    J = 20 kg m^2, b = 250 N m s/rad.
    """
    return NozzleParameters(J=20.0, b=250.0, k=1.6e5, a=0.15, A=1.0, beta=120.0, gamma=80.0, n=1.5)


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


# Two carriers of one arithmetic: _rk4_floats_py for one nozzle on Python floats (no array
# overhead), _rk4_arrays_py for a batch in place. Both run the same IEEE operations in the same
# order on every nozzle, so a nozzle gives the same bits alone and in a batch (tested); the power
# is joint_power's, which keeps that promise where the C library's and numpy's differ. The
# compiled kernel (_joint_kernel.c) runs these operations too, 20-30x faster; rk4_floats and
# rk4_arrays are it where it was built and gives the reference's bits at import, these otherwise.
# In the Bouc-Wen law, gamma sign(x' w) is written copysign(gamma, x' w), one operation: the same
# value wherever it matters (at x' w = 0 either x' = 0 or |w|^n = 0 multiplies it away). |w| is
# floored where |w|^n = 1e-30 (or at 1e-300), which keeps the power's argument a normal float;
# below the floor 1 - c |w|^n is exactly 1 either way (for |c| = |beta +- gamma| < 1e13).


def _rk4_floats_py(
    x: float, v: float, w: float, tau: float, h: float, steps: int, p: RK4Parameters
) -> tuple[float, float, float]:
    """``steps`` RK4 steps of length h (s) of one nozzle under the torque tau (N m), held.

    x (rad), v (rad/s) and w (rad, normalized hysteresis) in, the same out."""
    inv_j, b_j, k_el_j, k_hys_j, beta, gamma, n, floor, hys = p
    accel0 = tau * inv_j
    half, sixth = 0.5 * h, h / 6.0
    if not hys:  # the linear joint: w moves as x does (its rate is v), the same increments
        for _ in range(steps):
            a1 = accel0 - b_j * v - k_el_j * x - k_hys_j * w
            x2, v2, w2 = half * v + x, half * a1 + v, half * v + w
            a2 = accel0 - b_j * v2 - k_el_j * x2 - k_hys_j * w2
            x3, v3, w3 = half * v2 + x, half * a2 + v, half * v2 + w
            a3 = accel0 - b_j * v3 - k_el_j * x3 - k_hys_j * w3
            x4, v4, w4 = h * v3 + x, h * a3 + v, h * v3 + w
            a4 = accel0 - b_j * v4 - k_el_j * x4 - k_hys_j * w4
            dx = sixth * ((v2 + v3) * 2.0 + v + v4)
            x, v, w = dx + x, sixth * ((a2 + a3) * 2.0 + a1 + a4) + v, dx + w
        return x, v, w
    power, copysign = power_float, math.copysign
    # The Bouc-Wen rate v (1 - (beta + gamma sign(v w)) |w|^n) written out at each stage: a
    # function call per stage would cost a tenth of the step. max(|w|, floor) is spelled as
    # the builtin decides (its first argument unless the second is strictly larger, NaN kept).
    for _ in range(steps):
        a1 = accel0 - b_j * v - k_el_j * x - k_hys_j * w
        aw = abs(w)
        w1 = v * (1.0 - (copysign(gamma, v * w) + beta) * power(floor if floor > aw else aw, n))
        x2, v2, w2 = half * v + x, half * a1 + v, half * w1 + w
        a2 = accel0 - b_j * v2 - k_el_j * x2 - k_hys_j * w2
        aw = abs(w2)
        w2_rate = v2 * (1.0 - (copysign(gamma, v2 * w2) + beta) * power(floor if floor > aw else aw, n))
        x3, v3, w3 = half * v2 + x, half * a2 + v, half * w2_rate + w
        a3 = accel0 - b_j * v3 - k_el_j * x3 - k_hys_j * w3
        aw = abs(w3)
        w3_rate = v3 * (1.0 - (copysign(gamma, v3 * w3) + beta) * power(floor if floor > aw else aw, n))
        x4, v4, w4 = h * v3 + x, h * a3 + v, h * w3_rate + w
        a4 = accel0 - b_j * v4 - k_el_j * x4 - k_hys_j * w4
        aw = abs(w4)
        w4_rate = v4 * (1.0 - (copysign(gamma, v4 * w4) + beta) * power(floor if floor > aw else aw, n))
        x = sixth * ((v2 + v3) * 2.0 + v + v4) + x
        v = sixth * ((a2 + a3) * 2.0 + a1 + a4) + v
        w = sixth * ((w2_rate + w3_rate) * 2.0 + w1 + w4_rate) + w
    return x, v, w


def _rk4_arrays_py(
    state: np.ndarray, tau: np.ndarray | float, h: float, steps: int, p: RK4Parameters,
    skip: np.ndarray | None = None,
) -> None:  # fmt: skip
    """``steps`` RK4 steps of N nozzles in place: ``state`` (3, N) rows x (rad), v (rad/s), w
    (rad), torques tau (N,) in N m held over the steps; the arithmetic of :func:`_rk4_floats_py`.
    ``skip`` (the nozzles a caller discards, see :func:`rk4_arrays`) is taken and all are stepped."""
    n = state.shape[1]
    rates = np.empty((4, 3, n))  # the four RK4 stages' derivatives of (x, v, w)
    stage = np.empty((3, n))
    tmp, coef = np.empty((2, n))
    # the floor as a row: np.maximum against a Python float takes a path about 3x slower
    floor = np.broadcast_to(p.w_floor, (n,)).copy()
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
        np.maximum(tmp, floor, out=tmp)
        tmp[...] = power_array(tmp, p.n)
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


def _kernel_agrees(kernel: Any) -> bool:
    """Whether the kernel gives the references' bits on a check set (both joints, both carriers,
    NaN and inf included, and a batch that leaves nozzles out), its tables set first."""
    kernel.set_tables(*tables())
    states = np.array(
        [[0.01, -0.03, 0.0, 0.05, np.nan], [0.5, -2.0, 0.0, -3.0, 0.0], [0.02, 0.01, 0.0, -0.02, 0.0]]
    )
    tau = np.array([120.0, -900.0, 0.0, 3.0e4, 1.0])
    strong = rk4_parameters(strong_nozzle().normalized())
    powers = [(x, n) for x in (0.0, 5e-320, 1e-300, 0.03, 1.0, 7.5, math.inf) for n in (0.99, 1.5)]
    agrees = all(kernel.power(x, n) == power_float(x, n) for x, n in powers)
    agrees &= math.isnan(kernel.power(math.nan, 1.5))
    # a joint per nozzle (drawn plants) as well as one for all: the kernel reads them apart
    lanes = [strong._replace(n=n) for n in (2.0, 0.99, 1.0, 1.5)] + [strong._replace(beta=-strong.beta)]
    per_nozzle = RK4Parameters(*(np.array(values) for values in zip(*lanes, strict=True)))
    per_nozzle = per_nozzle._replace(hysteretic=True)
    for p in (strong, strong._replace(n=0.99), strong._replace(hysteretic=False), per_nozzle):
        batch, expected = states.copy(), states.copy()
        kernel.rk4_batch(batch, tau, 0.002, 3, p)
        _rk4_arrays_py(expected, tau, 0.002, 3, p)
        agrees &= np.array_equal(batch, expected, equal_nan=True)
        if p is not per_nozzle:
            columns = zip(states.T.tolist(), tau.tolist(), strict=True)
            floats = [kernel.rk4_float(*col, t, 0.002, 3, p) for col, t in columns]
            agrees &= np.array_equal(np.array(floats).T, expected, equal_nan=True)
    # nozzles a caller discards (skip) left out: the others keep their bits where the kernel packs them
    wide, taus, skip = np.tile(states, 8), np.tile(tau, 8), np.arange(40) % 3 == 0
    tiled = RK4Parameters(*(np.tile(v, 8) if isinstance(v, np.ndarray) else v for v in per_nozzle))
    for p in (strong, tiled):
        batch, expected = wide.copy(), wide.copy()
        kernel.rk4_batch(batch, taus, 0.002, 3, p, skip)
        _rk4_arrays_py(expected, taus, 0.002, 3, p)
        agrees &= np.array_equal(batch[:, ~skip], expected[:, ~skip], equal_nan=True)
    return bool(agrees) and all(hasattr(kernel, name) for name in ("servo_float", "servo_batch"))


def _load_kernel() -> Any:
    """The compiled kernel where it was built and :func:`_kernel_agrees` (:func:`load_kernel`)."""
    return load_kernel("_joint_kernel", _kernel_agrees, "nozzle")


_KERNEL = _load_kernel()
KERNEL = "python" if _KERNEL is None else "compiled"  # which arithmetic rk4_floats and rk4_arrays run


def kernel() -> Any:
    """The compiled kernel module the package runs, None where it runs the Python reference
    (not built, turned off by ``SSME_ENVS_NO_KERNEL``, or not giving the reference's bits)."""
    return _KERNEL


# One nozzle's RK4: (x, v, w, tau, h, steps, p) -> (x, v, w), as _rk4_floats_py (a C function
# where the kernel is used: no Python frame per call).
rk4_floats: Callable[..., tuple[float, float, float]] = (
    _rk4_floats_py if _KERNEL is None else _KERNEL.rk4_float
)


def rk4_arrays(
    state: np.ndarray, tau: np.ndarray | float, h: float, steps: int, p: RK4Parameters,
    skip: np.ndarray | None = None,
) -> None:  # fmt: skip
    """``steps`` RK4 steps of N nozzles in place: ``state`` (3, N) rows x (rad), v (rad/s), w
    (rad), torques tau (N,) in N m held over the steps; the arithmetic of :func:`rk4_floats`.
    ``skip``: None or a bool (N,) row of nozzles whose state the caller discards (a vector env's
    restarting envs), which may be left as they were (the kernel leaves them out of its blocks
    where AVX-512 packs the others; the reference steps them)."""
    if _KERNEL is not None:
        try:
            _KERNEL.rk4_batch(state, tau, h, steps, p, skip)
            return
        except TypeError:  # a layout it does not take (a strided view): the reference, the same bits
            pass
    _rk4_arrays_py(state, tau, h, steps, p)


__all__ = [
    "BENCH_RATE_HZ",
    "DEFAULT_SUBSTEPS",
    "DEFAULT_TORQUE_LIMIT",
    "KERNEL",
    "MAX_N",
    "NOZZLE_DT",
    "NozzleParameters",
    "RK4Parameters",
    "kernel",
    "published_nozzle",
    "rk4_arrays",
    "rk4_floats",
    "rk4_parameters",
    "strong_nozzle",
]
