"""The innovations-form model and the result DSR_e returns, with the model read as a continuous-time
system and as the J, b, k of a mass-spring joint: what the algorithm of :mod:`.subspace` hands
out, kept apart from it (:mod:`.subspace` re-exports these names)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from ssme_envs.identification.arguments import real_record
from ssme_envs.models.linear import Dimensions, StateSpace, check_dt


@dataclass(frozen=True, eq=False)
class InnovationsModel(Dimensions):
    """Discrete innovations-form model ``x+ = A x + B u + K e``, ``y = C x + D u + e``.

    Attributes
    ----------
    A, B, C, D, K : ndarray
        Shapes (n, n), (n, m), (p, n), (p, m), (n, p); inputs and outputs in the units of the
        identification record.
    dt : float
        Sample time, s.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    K: np.ndarray
    dt: float

    def __post_init__(self) -> None:
        mats = {name: np.array(getattr(self, name), dtype=float, ndmin=2) for name in "ABCDK"}
        n, m, p = mats["A"].shape[0], mats["B"].shape[1], mats["C"].shape[0]
        expected = {"A": (n, n), "B": (n, m), "C": (p, n), "D": (p, m), "K": (n, p)}
        for name, shape in expected.items():
            if mats[name].shape != shape:
                raise ValueError(f"{name} has shape {mats[name].shape}, expected {shape}")
            if not np.all(np.isfinite(mats[name])):
                raise ValueError(f"{name} has NaN or inf entries")
            mats[name].setflags(write=False)
            object.__setattr__(self, name, mats[name])
        object.__setattr__(self, "dt", check_dt(self.dt))

    def state_space(self) -> StateSpace:
        """The deterministic part ``(A, B, C, D)`` as the package's one state-space type (the
        innovations gain ``K`` is the predictor's, not the plant's)."""
        return StateSpace(self.A, self.B, self.C, self.dt, self.D)

    def simulate(self, u: np.ndarray, y: np.ndarray | None = None) -> np.ndarray:
        """Model output, shape (T, p).

        Parameters
        ----------
        u : array, shape (T, m) or (T,) for one input
            Inputs.
        y : array, shape (T, p) or (T,), optional
            Measured outputs. When given, the result is the one-step prediction of the Kalman
            filter ``x+ = A x + B u + K (y - C x - D u)``, ``y_hat = C x + D u``; otherwise the
            pure simulation ``x+ = A x + B u``. Both start from the zero state.
        """
        u = _as_columns(u, "u", "inputs")
        if u.shape[1] != self.n_inputs:
            raise ValueError(f"u has {u.shape[1]} channels but the model has {self.n_inputs} inputs")
        if y is None:
            a, b_in, inputs = self.A, self.B, u
        else:
            y = _as_columns(y, "y", "outputs")
            if y.shape != (u.shape[0], self.n_outputs):
                raise ValueError(f"y has shape {y.shape}, expected {(u.shape[0], self.n_outputs)}")
            a = self.A - self.K @ self.C
            b_in = np.hstack([self.B - self.K @ self.D, self.K])
            inputs = np.hstack([u, y])
        if not np.all(np.isfinite(inputs)):
            raise ValueError("u and y must be finite")
        states = np.empty((u.shape[0], self.n_states))
        x = np.zeros(self.n_states)
        drive = inputs @ b_in.T
        for k in range(u.shape[0]):
            states[k] = x
            x = a @ x + drive[k]
        return states @ self.C.T + u @ self.D.T


@dataclass
class SubspaceResult:
    """Outcome of :func:`.subspace.dsr_e`.

    Attributes
    ----------
    model : InnovationsModel
        The identified model.
    singular_values : ndarray
        Singular values of the projected data matrix ``Z``, largest first (order selection).
    order : int
        Number of states.
    past_horizon : int
        Past horizon ``J`` used, samples.
    future_horizon : int
        Future horizon ``L`` used: the extended observability matrix has ``L + 1`` block rows.
    """

    model: InnovationsModel
    singular_values: np.ndarray
    order: int
    past_horizon: int
    future_horizon: int


def _as_columns(x: np.ndarray, name: str, channels: str) -> np.ndarray:
    """``x`` as a float (samples, channels) array; real numbers only, as ``identify`` takes them
    (:func:`~ssme_envs.identification.arguments.real_record`: a complex record is not cut to its
    real part)."""
    x = np.asarray(real_record(x, name, channels), dtype=float)
    return x[:, None] if x.ndim == 1 else x


def to_continuous(model: InnovationsModel) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Continuous-time (Ac, Bc, Cc, Dc) whose zero-order-hold discretization is the model.

    The exact inverse of ZOH: ``logm([[A, B], [0, I]]) / dt`` holds ``[[Ac, Bc], [0, 0]]``.
    ``Ac`` in 1/s, ``Bc`` in output units per input unit per s; ``Cc = C``, ``Dc = D``.
    ``B`` enters the logarithm divided by the power of two nearest its largest entry, and ``Bc``
    is multiplied back: the similarity ``diag(I, s I)`` leaves ``Ac`` and ``Bc / s`` exact, so
    the result does not depend on the input's units (entries of 1e150 in ``B`` overflowed the
    logarithm's squarings).

    Raises
    ------
    ValueError
        When ``A`` has an eigenvalue at zero or on the negative real axis: no real
        continuous system sampled with a zero-order hold gives such a pole.
    """
    n, m = model.n_states, model.n_inputs
    for pole in model.poles():
        if abs(pole.imag) <= 1e-12 * max(abs(pole), 1e-300) and pole.real <= 0:
            raise ValueError(
                f"A has the eigenvalue {pole.real:.6g} on the negative real axis or at zero: the "
                "zero-order hold cannot be inverted (no real continuous-time equivalent)"
            )
    largest = float(np.max(np.abs(model.B), initial=0.0))
    b_exp = int(np.round(np.log2(largest))) if largest > 0 else 0
    block = np.zeros((n + m, n + m))
    block[:n, :n] = model.A
    block[:n, n:] = np.ldexp(model.B, -b_exp)
    block[n:, n:] = np.eye(m)
    log_block = scipy.linalg.logm(block)
    if np.iscomplexobj(log_block):
        if np.max(np.abs(log_block.imag)) > 1e-8 * max(np.max(np.abs(log_block.real)), 1.0):
            raise ValueError("the matrix logarithm of the model is not real: no continuous equivalent")
        log_block = log_block.real
    gen = log_block / model.dt
    return gen[:n, :n], np.ldexp(gen[:n, n:], b_exp), model.C.copy(), model.D.copy()


def _second_order_transfer(
    ac: np.ndarray, bc: np.ndarray, cc: np.ndarray, dc: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Numerator [b2, b1, b0] and denominator [1, a1, a0] of ``Cc (sI - Ac)^-1 Bc + Dc``, 2 states.

    The polynomials of ``scipy.signal.ss2tf``, written out for two states: ``a1 = -tr Ac``,
    ``a0 = det Ac``, and with ``adj(sI - Ac) = sI - adj(Ac)``, ``b2 = Dc``,
    ``b1 = Cc Bc + Dc a1``, ``b0 = Dc a0 - Cc adj(Ac) Bc``. ss2tf forms the numerator as
    ``poly(Ac - Bc Cc) - poly(Ac)``, whose constant terms cancel to ``b0`` (``a0 + b0`` minus
    ``a0``): it loses ``log10(a0 / b0)`` digits (``a0 / b0 = k``), about 5 on the nozzle in N m
    and rad (J, b, k 4e-11 to 1e-10 off), all of them once the angle is in units 1e10 times
    larger.
    """
    a1 = -(ac[0, 0] + ac[1, 1])
    a0 = ac[0, 0] * ac[1, 1] - ac[0, 1] * ac[1, 0]
    adjugate = np.array([[ac[1, 1], -ac[0, 1]], [-ac[1, 0], ac[0, 0]]])
    # adj(Ac) Bc first: Bc and Cc may carry reciprocal unit scales that would overflow together
    b1 = float((cc @ bc)[0, 0] + dc[0, 0] * a1)
    b0 = float(dc[0, 0] * a0 - (cc @ (adjugate @ bc))[0, 0])
    return np.array([float(dc[0, 0]), b1, b0]), np.array([1.0, float(a1), float(a0)])


def second_order_parameters(model: InnovationsModel) -> dict[str, float | list[float]]:
    """Physical parameters of a SISO second-order model ``J x'' + b x' + k x = tau``.

    The continuous transfer function (inverse ZOH, :func:`to_continuous`) is written
    ``(b2 s^2 + b1 s + b0) / (s^2 + a1 s + a0)``; the physical model has
    ``(1/J) / (s^2 + (b/J) s + k/J)``, so ``J = 1/b0``, ``b = a1 J``, ``k = a0 J``. An identified
    model usually also has small ``b1`` and ``b2`` (sampling zeros, noise), reported as they are.
    The coefficients come in closed form (:func:`_second_order_transfer`), with no difference of
    polynomials: J, b, k keep their digits whatever the units of torque and angle.

    Returns
    -------
    dict
        ``numerator`` [b2, b1, b0] and ``denominator`` [1, a1, a0] (s-polynomials, highest power
        first); ``numerator_s_coefficient`` b1; ``J`` (input units s^2 per output unit), ``b``
        (input units s per output unit), ``k`` (input units per output unit);
        ``natural_frequency_hz`` sqrt(a0) / 2 pi; ``damping_ratio`` a1 / (2 sqrt(a0));
        ``resonance_frequency_hz`` the peak of the magnitude, ``f_n sqrt(1 - 2 zeta^2)``, NaN when
        ``zeta >= 1/sqrt(2)`` (no peak).

    Raises
    ------
    ValueError
        Not SISO, not second order, no DC gain (b0 = 0), or not an oscillator (a0 <= 0).
    """
    if model.n_inputs != 1 or model.n_outputs != 1:
        raise ValueError(
            f"a single-input single-output model is needed, got {model.n_inputs} inputs and "
            f"{model.n_outputs} outputs"
        )
    if model.n_states != 2:
        raise ValueError(f"a second-order model is needed, got order {model.n_states}")
    num, den = _second_order_transfer(*to_continuous(model))
    b2, b1, b0 = num
    _, a1, a0 = den
    if abs(b0) <= 1e-12 * max(np.max(np.abs(num)), 1e-300):
        raise ValueError("the model has no static gain (b0 = 0): J = 1/b0 is undefined")
    if a0 <= 0:
        raise ValueError(f"the model is not an oscillator (a0 = {a0:.6g} <= 0): no natural frequency")
    inertia = 1.0 / b0
    omega_n = math.sqrt(a0)
    zeta = a1 / (2.0 * omega_n)
    resonance = omega_n * math.sqrt(1.0 - 2.0 * zeta**2) if zeta < 1.0 / math.sqrt(2.0) else math.nan
    return {
        "numerator": [float(b2), float(b1), float(b0)],
        "denominator": [1.0, float(a1), float(a0)],
        "numerator_s_coefficient": float(b1),
        "J": float(inertia),
        "b": float(a1 * inertia),
        "k": float(a0 * inertia),
        "natural_frequency_hz": omega_n / (2.0 * math.pi),
        "damping_ratio": float(zeta),
        "resonance_frequency_hz": resonance / (2.0 * math.pi),
    }
