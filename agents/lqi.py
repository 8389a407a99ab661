"""LQ servo with integral action and a Kalman filter, designed on an env's linear design model.

The design model ``x+ = A x + B u, y = C x`` is augmented with the previous input and the error
integrals, ``z = [x; u_(k-1); q]`` driven by the input change ``du``:

    x+ = A x + B u_(k-1) + B du,   u_k = u_(k-1) + du,   q+ = q + r - C x,

so that the LQ cost ``e' Qe e + du' R du + q' Qi q`` is the env's reward (errors and action
changes) plus a small integral weight that removes steady-state error on a mismatched plant.
``scipy.linalg.solve_discrete_are`` gives the gain; a steady-state Kalman filter (the dual
Riccati equation) estimates x from the measured outputs; a reference feedforward moves the
regulation target to ``(x_ss, u_ss)`` with ``A x_ss + B u_ss = x_ss``, ``C x_ss = r``. Integration
stops while the input saturates (anti-windup).

A moving reference is followed as a ramp: with ``s`` the reference's increment per sample, the
target is the model's ramp-following motion (``x_k = x0 + k d``, ``u_k = u0 + k e`` with
``(A - I) d + B e = 0``, ``C d = s``, ``(A - I) x0 + B u0 = d``, ``C x0 = r``) and the input
changes by ``e`` per sample on top of the LQ law. ``s`` is the minmod of the last two increments
of the reference (the smaller one when both have the same sign, else zero): a ramp or a sine
shows two alike increments, a step one, so steps get no feedforward kick. Designs whose model
leaves out dynamics the feedforward would drive (``LinearDesign.follow_ramps``) hold the static
target only.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import numpy as np
import scipy.linalg

from agents.base import BatchController, columns, task_of
from agents.plants import LinearDesign, linear_design
from ssme_envs.models.linear import PlantMatrices, StateSpace


@dataclass(frozen=True)
class ServoDesign(PlantMatrices):
    """Gains of the LQ servo on one design model (all arrays 2-D, model units)."""

    plant: StateSpace  # the design model the gains are for
    gain: np.ndarray  # (m, n + m + p): du = -gain @ (z - z_target)
    kalman: np.ndarray  # (n, p): x_hat = x_pred + kalman (y - C x_pred)
    target: np.ndarray  # (n + m, p): [x_ss; u_ss] = target @ r
    ramp: np.ndarray  # (n + m, p): [x0; u0] = target @ r + ramp @ s on a ramp of s per sample
    ramp_change: np.ndarray  # (m, p): e = ramp_change @ s (zeros for both without follow_ramps)
    cost_to_go: np.ndarray  # (n + m + p, n + m + p), the Riccati solution (MPC terminal cost)
    a_aug: np.ndarray
    b_aug: np.ndarray
    q_aug: np.ndarray
    r_aug: np.ndarray


def augmented(design: LinearDesign, integral_ratio: float) -> tuple[np.ndarray, ...]:
    """(A_z, B_z, Q_z, R) of the servo model z = [x; u_(k-1); q] with input du."""
    a, b, c = design.A, design.B, design.C
    n, m, p = a.shape[0], b.shape[1], c.shape[0]
    a_z = np.block([
        [a, b, np.zeros((n, p))],
        [np.zeros((m, n)), np.eye(m), np.zeros((m, p))],
        [-c, np.zeros((p, m)), np.eye(p)],
    ])  # fmt: skip
    b_z = np.vstack([b, np.eye(m), np.zeros((p, m))])
    q_z = scipy.linalg.block_diag(
        design.error_weight * c.T @ c,
        1e-6 * design.rate_weight * np.eye(m),  # keeps the input modes detectable
        integral_ratio * design.error_weight * np.eye(p),
    )
    return a_z, b_z, q_z, design.rate_weight * np.eye(m)


def _riccati(a: np.ndarray, b: np.ndarray, q: np.ndarray, r: np.ndarray, what: str, hint: str) -> np.ndarray:
    """``scipy.linalg.solve_discrete_are``, with a ValueError naming the gain and the likely cause
    where the equation has no stabilizing solution (scipy's own text speaks of Schur forms)."""
    try:
        return scipy.linalg.solve_discrete_are(a, b, q, r)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise ValueError(
            f"cannot design {what} on this design model: its Riccati equation has no stabilizing "
            f"solution ({str(exc).splitlines()[0]}); {hint}"
        ) from None


def design_servo(
    design: LinearDesign, integral_ratio: float = 0.02, process_ratio: float = 10.0
) -> ServoDesign:
    """The LQ servo gains and the Kalman gain on a design model.

    integral_ratio : weight of the error integrals relative to the errors' (per sample).
    process_ratio : the Kalman filter's process noise, an input disturbance of this many
        percent of the input's range (the model's error: larger trusts the measurements more).
    """
    for name, value in (("integral_ratio", integral_ratio), ("process_ratio", process_ratio)):
        if isinstance(value, bool) or not isinstance(value, int | float) or not 0 < value < np.inf:
            raise ValueError(f"{name} must be a positive number, got {value!r}")
    a_z, b_z, q_z, r = augmented(design, integral_ratio)
    if not np.any(design.B):
        raise ValueError(
            "the design model's B is zero: its inputs move nothing, so no controller can be designed on it"
        )
    p_z = _riccati(
        a_z, b_z, q_z, r, "the LQ servo's gain", "has it an unstable mode out of the inputs' reach?"
    )
    gain = np.linalg.solve(r + b_z.T @ p_z @ b_z, b_z.T @ p_z @ a_z)
    a, b, c = design.A, design.B, design.C
    n, m, p = a.shape[0], b.shape[1], c.shape[0]
    disturbance = 0.01 * process_ratio * design.input_limit
    proc = disturbance**2 * (b @ b.T + 1e-6 * np.max(np.abs(b)) ** 2 * np.eye(n))
    # Never trust a measurement more than a quarter of what the disturbance moves it by in one
    # step: a noise-free design would make the filter nearly deadbeat, which leaves the loop
    # fragile to model error (the identified 70 % model on the 67 % engine: spectral radius
    # 0.998 instead of 0.87).
    meas = np.diag(np.maximum(design.noise_std, 0.25 * disturbance * np.max(np.abs(c @ b))) ** 2)
    cov = _riccati(
        a.T, c.T, proc, meas, "the Kalman filter's gain", "has it an unstable mode the outputs do not see?"
    )
    kalman = cov @ c.T @ np.linalg.inv(c @ cov @ c.T + meas)
    square = np.block([[a - np.eye(n), b], [c, np.zeros((p, m))]])
    target = np.linalg.lstsq(square, np.vstack([np.zeros((n, p)), np.eye(p)]), rcond=None)[0]
    # [d; e] = target @ s, then [x0; u0] solves square [x0; u0] = [d; r]
    ramp = np.linalg.lstsq(square, np.vstack([target[:n], np.zeros((p, p))]), rcond=None)[0]
    ramp_change = target[n:]
    if not design.follow_ramps:
        ramp, ramp_change = np.zeros_like(ramp), np.zeros_like(ramp_change)
    return ServoDesign(design.plant, gain, kalman, target, ramp, ramp_change, p_z, a_z, b_z, q_z, r)


class LQIServo(BatchController):
    """LQ servo (integral action, Kalman filter) on an env's design model; see the module doc.

    Parameters
    ----------
    env : an ssme-envs env (scalar or native vector)
    design : "identified" (default) or "truth", the model it is designed on
    integral_ratio, process_ratio : see :func:`design_servo`
    """

    name = "lqi"

    def __init__(
        self, env: Any, design: str = "identified", integral_ratio: float = 0.02, process_ratio: float = 10.0
    ) -> None:
        super().__init__()
        self.design = linear_design(env, design)
        self.servo = design_servo(self.design, integral_ratio, process_ratio)

    def initial_state(self, n: int) -> dict[str, np.ndarray]:
        return servo_state(self.servo, n)

    def compute(self, obs: np.ndarray) -> np.ndarray:
        y, r = self.design.ports.read(obs)
        x = servo_estimate(self.servo, self.state, y)
        du = servo_feedback(self.servo, self.state, x, r, reference_step(self.state, r))
        return servo_advance(self.servo, self.state, x, y, r, du, self.design.input_limit) / (
            self.design.ports.input_scale
        )


# The servo's step in three parts, on a batch: the matrices are shared, (n, ...), or per env,
# (N, n, ...) for the scheduled servo.


def _apply(matrix: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.einsum("nij,nj->ni", matrix, v) if matrix.ndim == 3 else v @ matrix.T


def servo_state(s: ServoDesign | Any, n: int) -> dict[str, np.ndarray]:
    """The servo's state for n fresh episodes: estimate x, last input u, integrals q, and the last
    reference and its last increment (NaN: none yet)."""
    p = s.C.shape[0]
    return {
        "x": np.zeros((n, s.A.shape[-1])),
        "u": np.zeros((n, s.B.shape[-1])),
        "q": np.zeros((n, p)),
        "r": np.full((n, p), np.nan),
        "dr": np.zeros((n, p)),
    }


def reference_step(state: dict, r: np.ndarray) -> np.ndarray:
    """The reference's increment per sample to feed forward (N, p): the minmod of its last two
    increments. Advances the reference history; call once per sample."""
    increment = np.where(np.isnan(state["r"]), 0.0, r - state["r"])
    last = state["dr"]
    state["r"], state["dr"] = r, increment
    alike = increment * last > 0
    return np.where(alike, np.sign(increment) * np.minimum(np.abs(increment), np.abs(last)), 0.0)


def servo_estimate(s: ServoDesign | Any, state: dict, y: np.ndarray) -> np.ndarray:
    """The Kalman filter's estimate of x (N, n) given the measured outputs y (N, p)."""
    return state["x"] + _apply(s.kalman, y - _apply(s.C, state["x"]))


def servo_deviation(
    s: ServoDesign | Any, state: dict, x: np.ndarray, r: np.ndarray, step: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """z - z_target (N, n + m + p), the augmented state from the motion that follows the
    reference (at rest on r, or a ramp of ``step`` per sample), and that motion's input change e
    (N, m)."""
    n, m = s.A.shape[-1], s.B.shape[-1]
    goal = _apply(s.target, r) + _apply(s.ramp, step)
    change = _apply(s.ramp_change, step)
    deviation = [x - goal[:, :n], state["u"] - (goal[:, n : n + m] - change), state["q"]]
    return np.concatenate(deviation, axis=1), change


def servo_feedback(
    s: ServoDesign | Any, state: dict, x: np.ndarray, r: np.ndarray, step: np.ndarray
) -> np.ndarray:
    """The input change du (N, m): the reference motion's change plus the LQ law."""
    deviation, change = servo_deviation(s, state, x, r, step)
    return change - _apply(s.gain, deviation)


def servo_advance(
    s: ServoDesign | Any,
    state: dict,
    x: np.ndarray,
    y: np.ndarray,
    r: np.ndarray,
    du: np.ndarray,
    limit: float,
) -> np.ndarray:
    """Apply du: the saturated input u (N, m), the integrators (held while saturated) and the
    filter's prediction. Returns u."""
    u = np.clip(state["u"] + du, -limit, limit)
    free = np.all(np.abs(u) < limit, axis=1, keepdims=True)
    state["q"] = np.where(free, state["q"] + (r - y), state["q"])
    state["x"] = _apply(s.A, x) + _apply(s.B, u)
    state["u"] = u
    return u


def schedule_levels(design: str) -> np.ndarray:
    """The power levels (%) a design scheduled in power for EngineThrottle is made at: the
    identified models' 70-110 %, or the linked truth every 4 % over 65-109 %."""
    levels = [70.0, 80.0, 90.0, 100.0, 110.0] if design == "identified" else list(range(65, 110, 4))
    return np.array(levels, dtype=float)


def schedule_weights(levels: np.ndarray, power: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Linear interpolation between the tables at ``levels``: for each power (clipped to the
    levels' range), the lower level's index i and the weight w of level i + 1, each (N,)."""
    p = np.clip(power, levels[0], levels[-1])
    i = np.clip(np.searchsorted(levels, p, side="right") - 1, 0, len(levels) - 2)
    return i, (p - levels[i]) / (levels[i + 1] - levels[i])


def scheduled_tables(
    levels: np.ndarray, tables: dict[str, np.ndarray], power: np.ndarray
) -> dict[str, np.ndarray]:
    """Each table (one row per level, any shape after) interpolated at each power, (N, ...)."""
    i, w = schedule_weights(levels, power)
    out = {}
    for key, table in tables.items():
        wk = w.reshape(-1, *(1,) * (table.ndim - 1))
        out[key] = (1 - wk) * table[i] + wk * table[i + 1]
    return out


class ScheduledLQI(BatchController):
    """Gain-scheduled LQ servo for EngineThrottle: servos designed at several power levels
    (the identified models at 70-110 %, or the linked truth every 4 % over 65-109 %), their
    matrices interpolated linearly in the commanded power read from the reference
    (``P = 100 + Pc reference in %``)."""

    name = "scheduled"

    def __init__(self, env: Any, design: str = "identified", integral_ratio: float = 0.02) -> None:
        super().__init__()
        self.levels = schedule_levels(design)
        designs = [linear_design(env, design, power=level) for level in self.levels.tolist()]
        self.design = designs[0]
        (self.power_reference,) = columns(task_of(env).observation, "pc_ref_pct")
        servos = [design_servo(d, integral_ratio) for d in designs]
        self.first = servos[0]  # the shapes of the state
        self.tables = {
            key: np.stack([getattr(s, key) for s in servos])
            for key in ("A", "B", "C", "gain", "kalman", "target", "ramp", "ramp_change")
        }

    def initial_state(self, n: int) -> dict[str, np.ndarray]:
        return servo_state(self.first, n)

    def scheduled(self, power: np.ndarray) -> Any:
        """The servo matrices at each env's power, (N, ...) each."""
        return SimpleNamespace(**scheduled_tables(self.levels, self.tables, power))

    def compute(self, obs: np.ndarray) -> np.ndarray:
        y, r = self.design.ports.read(obs)
        servo = self.scheduled(100.0 + obs[:, self.power_reference])
        x = servo_estimate(servo, self.state, y)
        du = servo_feedback(servo, self.state, x, r, reference_step(self.state, r))
        return servo_advance(servo, self.state, x, y, r, du, self.design.input_limit) / (
            self.design.ports.input_scale
        )


__all__ = [
    "LQIServo",
    "ScheduledLQI",
    "ServoDesign",
    "augmented",
    "design_servo",
    "reference_step",
    "schedule_levels",
    "schedule_weights",
    "scheduled_tables",
    "servo_advance",
    "servo_deviation",
    "servo_estimate",
    "servo_feedback",
    "servo_state",
]
