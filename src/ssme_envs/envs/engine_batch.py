"""The engine task's step on (2, N) rows: :meth:`EngineTask.step`'s arithmetic for a batch.

:meth:`~ssme_envs.envs.engine_task.EngineTask.step` spells one step once for floats and arrays;
on arrays that spelling costs a ufunc call per channel per operation, a fresh array per
result and a float32 copy per observation column. Here both channels go through each operation
together, results are written into their rows of one (10, N) float64 observation table, and
the table is handed on whole. Every value is the same IEEE operation on the same operands as
there (products and sums only commuted, never reassociated), so the bits are the float
carrier's: the tests hold the vector env to the scalar env.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ssme_envs.envs.task import CLIP_UFUNC, Carrier

if TYPE_CHECKING:
    from ssme_envs.envs.engine_task import EngineState, EngineTask


def step_rows(
    task: EngineTask, state: EngineState, action: np.ndarray, t: np.ndarray, ref: np.ndarray,
    noise: np.ndarray, ops: Carrier,
) -> tuple[EngineState, np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """One step of N engine episodes: ``action`` (2, N) float64 in [-1, 1], ``ref`` (2, N) or
    (2, 1), unit ``noise`` (2, N) float32. Returns (state, the observation values as a (10, N)
    float64 table in the layout's order, reward (N,), terminated (N,))."""
    plant, integral, prev, held = state
    cmd = action * task.action_scale
    nominal = None
    if task.offsets is not None:  # the throttle's nominal valve schedule
        nominal = ops.at(task.offsets, t)
        cmd += nominal
    fault = task.fault
    if fault is not None and fault.kind != "sensor_bias":
        i, active = fault.index, t > task.fault_step
        if fault.kind == "stuck_valve":
            held = np.where(t == task.fault_step + 1, cmd[i], held)
            cmd[i] = np.where(active, held, cmd[i])
        else:  # gain_loss
            cmd[i] = np.where(active, cmd[i] * fault.magnitude, cmd[i])
    plant, y0, y1 = task.advance(plant, cmd, t, nominal, ops)
    # the point models' outputs are x's last two rows, one block; the nonlinear engine's are not
    y = plant.x[-2:] if task.nonlinear is None else np.stack((y0, y1))
    table = np.empty((10, y.shape[1]))
    m, r100, e, integral_next, last = table[0:2], table[2:4], table[4:6], table[6:8], table[8:10]
    m[...] = noise  # the exact upcast: the products below are the float carrier's
    # row by row where an operand is not one contiguous block (the scales, the references'
    # rows of their table): numpy's contiguous loops, without its general iterator
    m0, m1, r0, r1 = m[0], m[1], ref[0], ref[1]
    s0, s1 = task.noise_scale
    np.multiply(m0, s0, out=m0)
    np.multiply(m1, s1, out=m1)
    m += y  # y + noise * std
    if fault is not None and fault.kind == "sensor_bias":
        i = fault.index
        m[i] = np.where(t >= task.fault_step, m[i] + fault.magnitude, m[i])
    np.subtract(r0, m0, out=e[0])
    np.subtract(r1, m1, out=e[1])
    e *= 100.0
    np.multiply(r0, 100.0, out=r100[0])
    np.multiply(r1, 100.0, out=r100[1])
    np.multiply(e, task.dt, out=integral_next)
    integral_next += integral  # integral + e dt
    CLIP_UFUNC(integral_next, -task.integral_limit, task.integral_limit, out=integral_next)
    last[...] = action
    scratch = np.empty_like(e)
    np.subtract(y[0], r0, out=scratch[0])
    np.subtract(y[1], r1, out=scratch[1])
    np.abs(scratch, out=scratch)
    over = np.greater(scratch, task.envelope)
    terminated = np.logical_or(over[0], over[1])
    np.multiply(e, e, out=scratch)
    reward = np.add(scratch[0], scratch[1])
    reward *= -task.error_weight
    np.subtract(action, prev, out=scratch)
    scratch *= scratch
    rate = np.add(scratch[0], scratch[1])
    rate *= task.rate_weight
    reward -= rate
    if terminated.any():  # the penalty's passes only on the (rare) steps that need them
        reward = np.where(terminated, reward - task.step_cost_bound * (task.horizon - t + 1), reward)
    m *= 100.0
    # type(state): EngineState, which imports this module
    return type(state)(plant, integral_next, action, held), table, reward, terminated


__all__ = ["step_rows"]
