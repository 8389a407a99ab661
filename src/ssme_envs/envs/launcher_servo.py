"""The launcher's nozzle position servo: its gains, the rigid body's transition over a servo
sample, and the servo loop on floats (one launcher) beside the compiled kernel's loop (one
launcher or N; :mod:`ssme_envs.models.nozzle_joint`), which performs the same operations in the
same order."""

from __future__ import annotations

import functools
import math
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np

from ssme_envs.envs import nozzle_task
from ssme_envs.models import nozzle_joint
from ssme_envs.models.nozzle import NozzleParameters, RK4Parameters

SERVO_BANDWIDTH_HZ = 15.0
SERVO_DAMPING = 0.7


def nozzle_servo_gains(plant: NozzleParameters) -> tuple[float, float, float]:
    """Gains (feedforward, proportional, derivative) of the nozzle's position servo
    ``tau = k_ff d_cmd - k_p d - k_d d'`` (N m/rad, N m/rad, N m s/rad).

    Designed on the joint's small-signal (linear) stiffness k: with ``k_ff = k + k_p`` the linear
    joint follows a constant command exactly, and ``J d'' + (b + k_d) d' + (k + k_p) d = k_ff d_cmd``
    has 15 Hz natural frequency and 0.7 damping (gains floored at zero for a joint that is
    already stiffer or better damped). The hysteretic part of a Bouc-Wen joint is what this
    design does not see.
    """
    omega = 2.0 * math.pi * SERVO_BANDWIDTH_HZ
    k = plant.small_signal_stiffness
    k_p = max(plant.J * omega**2 - k, 0.0)
    k_d = max(2.0 * SERVO_DAMPING * plant.J * omega - plant.b, 0.0)
    return k + k_p, k_p, k_d


def body_transition(instability: float, effectiveness: float, h: float) -> tuple[float, ...]:
    """Exact discretization over h (s) of ``theta'' = mu_a theta + mu_c d`` with d linear
    between samples (first-order hold): ``(theta, q)+ = Phi (theta, q) + G0 d_k + G1 d_k+1``.
    Returns Phi00, Phi01, Phi10, Phi11, G0_theta, G0_q, G1_theta, G1_q."""
    m = np.zeros((4, 4))
    m[0, 1] = 1.0
    m[1, 0] = instability
    m[1, 2] = effectiveness
    m[2, 3] = 1.0 / h
    import scipy.linalg  # here: its import costs more than the whole env's

    e = scipy.linalg.expm(m * h)
    phi, ramp_start, ramp = e[:2, :2], e[:2, 2], e[:2, 3]
    g0, g1 = ramp_start - ramp, ramp
    return (*phi.ravel().tolist(), *g0.tolist(), *g1.tolist())


def compiled_servo(batched: bool) -> Any:
    """The compiled kernel, where it runs, gives :func:`servo_floats`' bits (checked once) and
    the nozzle task integrates with the package's own RK4: the kernel's servo is that loop with
    that RK4 inside (a substituted integrator, as a test's, gets the Python loop); else None."""
    kernel = nozzle_joint.kernel()
    if kernel is None or not _kernel_agrees():
        return None
    own = (
        nozzle_task.rk4_arrays is nozzle_joint.rk4_arrays
        if batched
        else nozzle_task.rk4_floats is nozzle_joint.rk4_floats
    )
    return kernel if own else None


def servo_batch(
    kernel: Any, nozzle: np.ndarray, theta: np.ndarray, q: np.ndarray, *args: Any
) -> tuple | None:
    """The kernel's servo over N launchers, ``args`` those of :func:`servo_floats` after ``q``
    (but its integrator): the nozzle (3, N) in place, the attitude and pitch rate after it
    returned (new arrays); None, nothing changed, for a layout the kernel does not take."""
    theta, q = np.array(theta, dtype=np.float64), np.array(q, dtype=np.float64)
    try:
        kernel.servo_batch(nozzle, theta, q, *args)
    except TypeError:
        return None
    return theta, q


@functools.cache
def _kernel_agrees() -> bool:
    """Whether the kernel's servo gives the reference's bits on a check set (a strong joint
    through a saturating torque and a fault's gain, one launcher and a batch, whose joint is
    shared and per launcher); a warning if not."""
    kernel = nozzle_joint.kernel()
    joint = nozzle_joint.rk4_parameters(nozzle_joint.strong_nozzle().normalized())
    per_nozzle = joint._replace(
        **{name: np.full(2, value) for name, value in joint._asdict().items() if name != "hysteretic"}
    )
    servo, body = (3.2e5, 1.6e5, 900.0), (1.0, 0.02, 0.06, 1.0, 5e-4, 0.1, 5e-4, 0.1)
    start = [(0.01, 0.5, 0.004, 0.02, -0.1, 4e3, None), (-0.02, -1.0, 0.0, 0.0, 0.3, -9e3, 0.5)]
    agree = True
    for x, v, w, theta, q, drive, gain in start:
        args = (theta, q, drive, gain, servo, 3e4, body, 1e-3, 2, 10, joint)
        reference = servo_floats(x, v, w, *args, nozzle_joint._rk4_floats_py)
        agree &= kernel.servo_float(x, v, w, *args) == reference
        for p in (joint, per_nozzle):  # one joint for all, and one per launcher (drawn plants)
            state = np.array([[x, x], [v, v], [w, w]])
            batch = servo_batch(kernel, state, np.full(2, theta), np.full(2, q), *args[2:-1], p)
            agree &= batch is not None and np.array_equal(
                np.vstack([state, *batch]), np.array([reference] * 2).T
            )
    if not agree:
        warnings.warn(
            "ssme_envs: the compiled launcher servo differs from its reference and is not used",
            RuntimeWarning,
            stacklevel=3,
        )
    return bool(agree)


def servo_floats(
    x: float, v: float, w: float, theta: float, q: float, drive: float, gain: float | None,
    servo: tuple, lim: float, body: tuple, rk4_h: float, rk4_steps: int, samples: int, params: RK4Parameters,
    rk4_floats: Callable[..., tuple[float, float, float]],
) -> tuple[float, float, float, float, float]:  # fmt: skip
    """``samples`` servo samples of one launcher on floats, the operations of
    :meth:`LauncherTask.plant_step`'s array loop in its order: the nozzle (x, v, w), attitude and pitch rate
    after them."""
    _, k_p, k_d = servo
    p00, p01, p10, p11, g0_theta, g0_q, g1_theta, g1_q = body
    low = -lim
    for _ in range(samples):
        torque = drive - k_p * x - k_d * v
        torque = low if low > torque else torque  # min(max(torque, -lim), lim), as FLOATS.clip
        torque = lim if lim < torque else torque
        if gain is not None:
            torque = torque * gain
        theta_next = p00 * theta + p01 * q + g0_theta * x
        q_next = p10 * theta + p11 * q + g0_q * x
        x, v, w = rk4_floats(x, v, w, torque, rk4_h, rk4_steps, params)
        theta, q = theta_next + g1_theta * x, q_next + g1_q * x
    return x, v, w, theta, q


__all__ = [
    "SERVO_BANDWIDTH_HZ",
    "SERVO_DAMPING",
    "body_transition",
    "compiled_servo",
    "nozzle_servo_gains",
    "servo_batch",
    "servo_floats",
]
