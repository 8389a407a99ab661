"""The nozzle family's score and observation compiled: what follows the plant in the batch steps
of :class:`~ssme_envs.envs.nozzle_task.NozzleTask` and
:class:`~ssme_envs.envs.launcher_pitch.LauncherTask`, in one pass over the envs
(``_score_kernel.c``: ``score_batch``).

In numpy, :meth:`NozzleTask.score` and the observation take about twenty passes over the (N,)
rows and a float32 table filled row by row, a quarter of a vector step beside the joint's RK4.
The kernel runs each env's operations of the float step (the scalar env's) in their order, and
is used only where it gives the scalar step's bits on a check set (:func:`score_kernel`); the
numpy step stays the reference (``SSME_ENVS_NO_KERNEL``), and the tests hold both to the scalar
env's bits.
"""

from __future__ import annotations

import functools
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from ssme_envs.models.kernels import load_kernel

if TYPE_CHECKING:
    from ssme_envs.envs.nozzle_task import NozzleTask


def score_config(task: NozzleTask, rate_scale: float, measured: bool) -> np.ndarray:
    """The kernel's float64 config of a nozzle task's scoring (``_score_kernel.c``'s order): the
    observation's rate column is ``(m - m_prev) rate_scale`` where ``measured`` (the nozzle's
    angle rate), else the given rate times ``rate_scale`` (the launcher's pitch rate)."""
    from ssme_envs.envs.nozzle_task import DEG  # the task's own (it imports this module)

    fault = task.fault
    bias = fault is not None and fault.kind == "sensor_bias"
    return np.array(
        [
            task.noise_std,
            bias,
            task.fault_step if bias else 0,
            fault.magnitude if bias else 0.0,
            task.dt,
            task.integral_limit,
            task.error_weight,
            task.rate_weight,
            task.envelope,
            task.step_cost_bound,
            task.horizon,
            DEG,
            rate_scale,
            measured,
        ],
        dtype=np.float64,
    )


def score_observe(
    kernel: Any, config: np.ndarray, x: np.ndarray, a: np.ndarray, prev: np.ndarray, t: np.ndarray,
    ref: np.ndarray, noise: np.ndarray, integral: np.ndarray, rate: np.ndarray, extra: np.ndarray | None,
    restarting: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """What follows the tracked output x (rad, (N,)) in a batch step: the observation columns
    (6, or 7 with ``extra``, N) float32, reward and terminated (fresh arrays); ``prev`` (<- a),
    ``integral`` and, where the config measures the rate, ``rate`` (<- the measurement) are
    stepped in place. Where ``restarting`` (a bool (N,) row) is True: the task's first
    observation of that ref and noise (its ``initial_observation``), reward 0, not terminated."""
    n = len(t)
    values = np.empty((7 if extra is not None else 6, n), dtype=np.float32)
    reward, terminated = np.empty(n), np.empty(n, dtype=bool)
    kernel.score_batch(
        x, np.ascontiguousarray(a), prev, t, np.ascontiguousarray(ref), np.ascontiguousarray(noise),
        integral, rate, extra, values, reward, terminated, config, restarting,
    )  # fmt: skip
    return values, reward, terminated


@functools.cache
def score_kernel(measured: bool) -> Any:
    """The compiled module for the nozzle's scoring (``measured``: its rate from the
    measurements) or the launcher's, where it was built and gives the scalar step's bits on a
    check set (once per form); None otherwise (numpy's batch step then)."""
    return load_kernel("_score_kernel", functools.partial(_kernel_agrees, measured=measured), "score")


def _kernel_agrees(kernel: Any, measured: bool) -> bool:
    """Whether ``score_batch`` gives, env by env, what the task's float step gives after its
    plant: a sensor bias on and off, an integral clipped both ways, envs ended by the
    envelope (with their penalty) and a NaN output; and for restarting envs what the task's
    ``initial_observation`` gives, the bias on at step 0 and off."""
    from ssme_envs.envs.launcher_pitch import LAUNCHER_DT, LauncherState, LauncherTask
    from ssme_envs.envs.nozzle_task import NOZZLE_DT, NozzleState, NozzleTask
    from ssme_envs.envs.task import FLOATS

    build, dt = (NozzleTask.build, NOZZLE_DT) if measured else (LauncherTask.build_launcher, LAUNCHER_DT)
    fault = {"kind": "sensor_bias", "time": 5 * dt, "magnitude": 0.002}  # on from step 5
    task: Any = build(fault=fault, sensor_noise=0.003)
    starts = (  # angle, rate, integral, previous action, action, step, reference, noise
        (0.001, 0.0, 0.0, 0.0, 0.3, 1, 0.02, 0.5),
        (-0.04, 2.0, 9.99, -0.2, 1.0, 7, -0.03, -1.7),
        (0.04, -3.0, -9.99, 1.0, -1.0, 5, 0.03, 2.2),
        (0.5, 0.1, 1.0, 0.5, 0.25, 3, 0.0, 0.1),
        (-0.5, -0.1, -1.0, -0.5, -0.25, 9, 0.01, -0.3),
        (math.nan, 0.0, 0.0, 0.0, 0.1, 4, 0.0, 0.0),
    )
    x0, _, integral, prev, a, steps, ref, noise = np.array(starts).T
    t = steps.astype(np.int64)
    after = []
    for x, v, i, p, act, step, r, z in starts:
        if measured:
            state = NozzleState((x, v, 0.0), 0.0, x, i, p)
        else:
            state = LauncherState((0.01 * x, 0.0, 0.0), x, v, i, p)
        after.append(task.step(state, (act,), int(step), (r,), (z,), FLOATS))
    states = [s for s, *_ in after]
    if measured:  # the rate from the measurements: the last one (the start angle) stepped in place
        x, rate, extra = np.array([s.plant[0] for s in states]), x0.copy(), None
    else:  # the pitch rate given, the nozzle's deflection an extra column
        x, rate = np.array([s.theta for s in states]), np.array([s.q for s in states])
        extra = np.array([s.nozzle[0] for s in states])
    integral, prev = integral.copy(), prev.copy()
    args = (task.score_config, x, a, prev, t, ref, noise, integral, rate, extra)
    values, reward, terminated = score_observe(kernel, *args)
    same = _same_bits(values, np.array([obs for _, obs, _, _ in after], dtype=np.float32).T)
    same &= _same_bits(reward, np.array([r for *_, r, _ in after]))
    same &= terminated.tolist() == [bool(d) for *_, d in after]
    same &= _same_bits(integral, np.array([s.integral for s in states]))
    same &= _same_bits(prev, a)
    if measured:
        same &= _same_bits(rate, np.array([s.m_prev for s in states]))
    for bias_time in (0.0, 5 * dt):  # restarting envs (the odd ones): their first observations
        task = build(fault={**fault, "time": bias_time}, sensor_noise=0.003)
        restarting = np.arange(len(t)) % 2 == 1
        values, reward, terminated = score_observe(
            kernel, task.score_config, *args[1:], restarting=restarting
        )  # fmt: skip
        first = task.initial_observation(ref[None, restarting], noise[None, restarting])
        same &= _same_bits(values[:, restarting], first)
        same &= not reward[restarting].any() and not terminated[restarting].any()
    return bool(same)


def __getattr__(name: str) -> str:
    """``KERNEL``: ``"compiled"`` where both forms of the scoring run the kernel, else
    ``"python"`` (numpy's batch step); found at first read, as the check builds two tasks."""
    if name == "KERNEL":
        both = score_kernel(measured=True) is not None and score_kernel(measured=False) is not None
        return "compiled" if both else "python"
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _same_bits(got: np.ndarray, want: np.ndarray) -> bool:
    """The same bits, but NaN's payload (which C leaves open, and which no env hands out)."""
    nan = np.isnan(got)
    if not np.array_equal(nan, np.isnan(want)):
        return False
    return np.where(nan, 0.0, got).tobytes() == np.where(nan, 0.0, want).tobytes()


__all__ = ["KERNEL", "score_config", "score_kernel", "score_observe"]  # noqa: F822 (KERNEL: __getattr__)
