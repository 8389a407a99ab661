"""Model predictive control with input magnitude and rate limits, solved by OSQP.

The prediction model, weights and estimator are the LQ servo's (:mod:`agents.lqi`): the state
``z = [x; u_(k-1); q]`` driven by input changes, the reward's weights, the Riccati solution as
terminal cost (so that without active limits the MPC acts as the LQ servo does), and the same
Kalman filter. Over ``horizon`` steps it minimizes the predicted cost subject to
``|u| <= input limit`` (the action's range) and ``|du| <= rate_limit x input limit`` per step.
The QPs of all envs of a batch are one block-diagonal QP, one OSQP call per step.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import osqp
import scipy.sparse as sparse

from agents.base import BatchController
from agents.lqi import (
    design_servo,
    reference_step,
    servo_advance,
    servo_deviation,
    servo_estimate,
    servo_feedback,
    servo_state,
)
from agents.plants import linear_design


def condensed(a: np.ndarray, b: np.ndarray, q: np.ndarray, r: np.ndarray, terminal: np.ndarray, horizon: int):
    """Hessian H (horizon m, horizon m) and linear map F with ``cost = du' H du + 2 z0' F' du``
    (plus terms free of du) of the predicted cost over the horizon."""
    nz, m = b.shape
    powers = [np.eye(nz)]
    for _ in range(horizon):
        powers.append(a @ powers[-1])
    gamma = np.zeros((horizon * nz, horizon * m))
    for i in range(horizon):
        for j in range(i + 1):
            gamma[i * nz : (i + 1) * nz, j * m : (j + 1) * m] = powers[i - j] @ b
    phi = np.vstack(powers[1:])
    weights = sparse.block_diag([q] * (horizon - 1) + [terminal]).toarray()
    hessian = gamma.T @ weights @ gamma + np.kron(np.eye(horizon), r)
    return 0.5 * (hessian + hessian.T), gamma.T @ weights @ phi


class MPC(BatchController):
    """Constrained MPC on an env's design model; see the module doc.

    Parameters
    ----------
    env : an ssme-envs env (scalar or native vector)
    design : "identified" (default) or "truth"
    horizon : prediction horizon, steps (10: 0.4 s on the engine, longer than its settling)
    rate_limit : largest input change per step as a fraction of the input limit (0.5: the
        valve crosses its range in 4 steps)
    """

    name = "mpc"

    def __init__(
        self, env: Any, design: str = "identified", horizon: int = 10, rate_limit: float = 0.5
    ) -> None:
        super().__init__()
        if not isinstance(horizon, int) or isinstance(horizon, bool) or horizon < 1:
            raise ValueError(f"horizon must be a positive integer, got {horizon!r}")
        if not isinstance(rate_limit, int | float) or not 0 < rate_limit <= 2:
            raise ValueError(f"rate_limit must be in (0, 2], got {rate_limit!r}")
        self.design = linear_design(env, design)
        self.servo = design_servo(self.design)
        s = self.servo
        self.horizon = horizon
        self.m = s.B.shape[1]
        self.hessian, self.linear = condensed(s.a_aug, s.b_aug, s.q_aug, s.r_aug, s.cost_to_go, horizon)
        self.max_change = rate_limit * self.design.input_limit
        # rows: inputs u_k = u_(k-1) + cumulative du (magnitude limits), then du (rate limits)
        self.cumulative = np.kron(np.tril(np.ones((horizon, horizon))), np.eye(self.m))
        self.ahead = np.arange(1, horizon + 1).repeat(self.m)  # steps of the motion by each input
        self.failures = 0
        self._solver: osqp.OSQP | None = None

    def initial_state(self, n: int) -> dict[str, np.ndarray]:
        if self._solver is None or self._solver_envs != self.num_envs:  # one QP for the whole batch
            self._setup(self.num_envs)
        return servo_state(self.servo, n)

    def _setup(self, n: int) -> None:
        size = self.horizon * self.m
        constraints = sparse.vstack([sparse.csc_matrix(self.cumulative), sparse.identity(size)])
        self._solver = osqp.OSQP()
        self._solver.setup(
            P=sparse.triu(sparse.kron(sparse.identity(n), sparse.csc_matrix(self.hessian)), format="csc"),
            q=np.zeros(n * size),
            A=sparse.kron(sparse.identity(n), constraints, format="csc"),
            l=-np.ones(2 * n * size),
            u=np.ones(2 * n * size),
            verbose=False,
            warm_starting=True,
            polishing=False,
            eps_abs=1e-7,
            eps_rel=1e-7,
            max_iter=4000,
        )
        self._solver_envs = n

    def compute(self, obs: np.ndarray) -> np.ndarray:
        s, state, limit = self.servo, self.state, self.design.input_limit
        y, r = self.design.ports.read(obs)
        x = servo_estimate(s, state, y)
        step = reference_step(state, r)
        # the decision is the input change beyond the reference motion's (change per step)
        z, change = servo_deviation(s, state, x, r, step)
        n, size = len(obs), self.horizon * self.m
        rate = np.tile(change, (1, self.horizon))
        u_motion = np.tile(state["u"], (1, self.horizon)) + self.ahead * rate
        lower = np.concatenate([-limit - u_motion, -self.max_change - rate], axis=1)
        upper = np.concatenate([limit - u_motion, self.max_change - rate], axis=1)
        self._solver.update(q=(z @ self.linear.T).ravel(), l=lower.ravel(), u=upper.ravel())
        result = self._solver.solve(raise_error=False)
        if result.info.status_val in (
            osqp.SolverStatus.OSQP_SOLVED,
            osqp.SolverStatus.OSQP_SOLVED_INACCURATE,
        ):
            du = change + result.x.reshape(n, size)[:, : self.m]
        else:  # an infeasible or failed QP: the unconstrained law, counted
            self.failures += 1
            du = servo_feedback(s, state, x, r, step)
        return servo_advance(s, state, x, y, r, du, limit) / self.design.ports.input_scale


__all__ = ["MPC", "condensed"]
