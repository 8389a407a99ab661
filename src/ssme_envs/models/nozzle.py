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
parameter may differ per nozzle (a population of candidate models in a fit, or randomized plants):
the simulators and the identification use it. The envs step the same arithmetic
(:func:`rk4_floats`, :func:`rk4_arrays`) inside their tasks.

This module gathers the nozzle's names: the joint and its integrator
(:mod:`~ssme_envs.models.nozzle_joint`), the model file (:mod:`~ssme_envs.models.nozzle_model`)
and the substep rules (:mod:`~ssme_envs.models.nozzle_substeps`).
"""

from __future__ import annotations

import json

import numpy as np

from ssme_envs.models import nozzle_joint, nozzle_model, nozzle_substeps
from ssme_envs.models.nozzle_joint import *  # noqa: F403  (the joint's names, re-exported)
from ssme_envs.models.nozzle_joint import (
    _DATA,
    DEFAULT_SUBSTEPS,
    DEFAULT_TORQUE_LIMIT,
    NOZZLE_DT,
    NozzleParameters,
    rk4_arrays,
    rk4_floats,
    rk4_parameters,
)
from ssme_envs.models.nozzle_model import *  # noqa: F403
from ssme_envs.models.nozzle_model import NozzleModel
from ssme_envs.models.nozzle_substeps import *  # noqa: F403
from ssme_envs.models.statespace import check_dt

# The packaged identified models: which bench test (truth) each comes from.
IDENTIFIED_FILES = {"table1": "nozzle_identified.json", "strong": "nozzle_strong_identified.json"}


def identified_nozzle(truth: str = "table1") -> NozzleModel:
    """A packaged nozzle model identified from the embedded bench test: on Table 1's nozzle
    (``"table1"``) or on :func:`strong_nozzle` (``"strong"``)."""
    if truth not in IDENTIFIED_FILES:
        raise ValueError(f"truth must be one of {', '.join(IDENTIFIED_FILES)}, got {truth!r}")
    path = _DATA.joinpath(IDENTIFIED_FILES[truth])
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


__all__ = [
    "IDENTIFIED_FILES",
    "NozzleCore",
    "identified_nozzle",
    "simulate_nozzle",
    *nozzle_joint.__all__,
    *nozzle_model.__all__,
    *nozzle_substeps.__all__,
]
