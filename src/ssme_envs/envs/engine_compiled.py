"""The engine tasks' batch step compiled: :meth:`EngineTask.step` and its plant on (N,) rows
in one pass over the envs (``_engine_kernel.c``: ``task_batch``, ``plant_batch``).

The kernel runs, env by env, the operations of the float step (the scalar env's) in their
order, so a vector env still gives a scalar env's bits; the numpy batch step stays the
reference where no kernel is built (``SSME_ENVS_NO_KERNEL``) and for the nonlinear engine.
The tests hold the three to the same bits.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ssme_envs.models import engine_step

if TYPE_CHECKING:
    from ssme_envs.envs.engine_task import EnginePlant, EngineState, EngineTask


class BatchArgs:
    """What the kernel needs of a task beside its state: its numbers as the kernel's config
    (:func:`~ssme_envs.models.engine_step.batch_config`), the packed step table (``pair_table``)
    and the nominal valves per step ((T + 1, 2); empty for the point model)."""

    __slots__ = ("config", "offsets", "table")

    def __init__(self, task: EngineTask, table: bytes, width: int, scheduled: bool) -> None:
        fault = task.fault
        self.config = engine_step.batch_config(
            scale=task.action_scale,
            s0=task.noise_scale[0],
            s1=task.noise_scale[1],
            dt=task.dt,
            limit=task.integral_limit,
            error_weight=task.error_weight,
            rate_weight=task.rate_weight,
            envelope=task.envelope,
            cost_bound=task.step_cost_bound,
            horizon=task.horizon,
            fault_kind=engine_step.FAULT_CODES[None if fault is None else fault.kind],
            fault_index=0 if fault is None else fault.index,
            magnitude=0.0 if fault is None else fault.magnitude,
            fault_step=task.fault_step,
            half=task.params.half_backlash,
            stick=task.params.stiction,
            width=width,
            scheduled=scheduled,
        )
        self.table = table
        offsets = np.zeros((0, 2)) if task.offset_table is None else task.offset_table
        self.offsets = np.ascontiguousarray(offsets, dtype=np.float64)


def batch_args(task: EngineTask, table: bytes, width: int, scheduled: bool) -> BatchArgs | None:
    """The task's :class:`BatchArgs`, or None where the batch step stays numpy's: no kernel
    built (or one without the batch forms), or the nonlinear engine as the plant."""
    if not engine_step.has_batch(engine_step.kernel()) or task.nonlinear is not None:
        return None
    return BatchArgs(task, table, width, scheduled)


def compiled_args(task: EngineTask) -> tuple[tuple | None, BatchArgs | None]:
    """The task's compiled steps' arguments from its ``kernel_steps()``, (None, None) without the
    kernel: the float step's after the commands and nominal valves (half the backlash, stiction,
    ``pair_table``'s table and width), and :func:`batch_args`."""
    if engine_step.kernel() is None:
        return None, None
    steps, scheduled = task.kernel_steps()
    table = engine_step.pair_table(steps)
    return (*task.rows[3:], *table), batch_args(task, *table, scheduled)


def plant_step(task: EngineTask, plant: EnginePlant, command: np.ndarray, t: np.ndarray) -> EnginePlant:
    """The task's plant on arrays under the commands (2, N) of step t - 1 -> t, stepped in place
    (the arrays of ``plant``, returned)."""
    args: BatchArgs = task.batch_args
    command = np.ascontiguousarray(command)
    engine_step.kernel().plant_batch(*plant, command, t, args.config, args.table, args.offsets)
    return plant


def task_step(
    task: EngineTask, state: EngineState, action: np.ndarray, t: np.ndarray, ref: Any, noise: Any
) -> tuple[tuple, np.ndarray, np.ndarray, np.ndarray]:
    """:meth:`EngineTask.step` on arrays, the state's arrays stepped in place: (plant, integral,
    prev, held) (prev the rows of ``action``), the observation values (10, N) rounded to float32
    (a fresh table, which the vector env hands out), reward, terminated. ``action`` (2, N)
    float64, ``noise`` rows float32."""
    plant, integral, prev, held = state
    n = len(t)
    args: BatchArgs = task.batch_args
    values = np.empty((10, n), dtype=np.float32)
    reward, terminated = np.empty(n), np.empty(n, dtype=bool)
    engine_step.kernel().task_batch(
        *plant, *integral, held, *prev, action, t, ref[0], ref[1], noise[0], noise[1], values, reward,
        terminated, args.config, args.table, args.offsets,
    )  # fmt: skip
    return (plant, integral, (action[0], action[1]), held), values, reward, terminated


__all__ = ["BatchArgs", "batch_args", "compiled_args", "plant_step", "task_step"]
