"""The nonlinear engine truth as the plant of the engine environments (``plant="nonlinear"``).

:class:`NonlinearPlantCore` steps :class:`~ssme_envs.models.engine_nonlinear.NonlinearEngine`
(its valve authority and flow curve, and its Table I parameters and trim scheduled on the power
implied by its own chamber pressure) behind the valve backlash and stiction of the truth, on
both carriers of :mod:`ssme_envs.envs.task`: Python floats for one env and (N,) rows for a
batch, the same IEEE operations in the same order, so that an env gives the same bits alone and
in a batch. The schedule table is the engine's own piecewise cubic (``NonlinearEngine.coef``):
the env evaluates it at the engine's scheduling variable each step, in the order of
``NonlinearEngine.table``.

``EngineTracking-v0`` at power P starts at the engine's trim at P; its valve commands are
deviations from the trim valve positions ``v_eq(P)`` and its outputs deviations from the trim
outputs. ``EngineThrottle-v0`` starts at the trim at the profile's first power; its nominal valve
schedule is the engine's own trim ``v_eq(P(t))`` at the commanded power (zero action holds the
engine on the profile at steady state); commands and outputs are measured from the 100 % trim.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from functools import cache, lru_cache
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from ssme_envs.envs.task import CLIP_UFUNC, Carrier, Value
from ssme_envs.models.engine_nonlinear import (
    GRID_STEP,
    PC_PER_PERCENT,
    SCHEDULE_RANGE,
    NonlinearEngine,
)
from ssme_envs.models.engine_step import dynamics_arrays, valves_arrays, valves_pair_floats
from ssme_envs.models.engine_valve_flow import valve_effect

if TYPE_CHECKING:
    from ssme_envs.envs.engine_task import EngineTask

PLANT_NAME = "nonlinear"  # the plant option that selects the nonlinear engine


class NonlinearPlant(NamedTuple):
    """The nonlinear plant's state: x (n states, absolute: 0 at the 100 % trim), the scheduling
    variable rho (%), valve linkage and valve positions (2 each, as the commands measure them);
    floats for one env, (n, N), (N,) and (2, N) arrays for a batch."""

    x: Any
    rho: Value
    linkage: Any
    valve: Any


@cache
def default_engine() -> NonlinearEngine:
    """The Table I nonlinear engine (no schedule lag), built once."""
    return NonlinearEngine()


def nonlinear_engine_of(plant: Any) -> NonlinearEngine | None:
    """The nonlinear engine a ``plant`` option names: ``"nonlinear"``, the Table I engine; a
    :class:`NonlinearEngine`, itself; anything else, None."""
    if isinstance(plant, NonlinearEngine):
        return plant
    if isinstance(plant, str) and plant == PLANT_NAME:
        return default_engine()
    return None


@lru_cache(maxsize=8)
def _tables(engine: NonlinearEngine) -> tuple[list, list, np.ndarray, tuple[int, ...]]:
    """The engine's schedule table for both carriers (per segment, the four coefficients of
    every column as floats; the nodes as floats; (4, columns, segments)) and the source of each
    state in A_o's shift (-1: none), built once per engine (a few ms)."""
    coef = engine.coef
    rows = [list(map(tuple, coef[:, s].T.tolist())) for s in range(coef.shape[1])]
    shift = tuple(int(np.argmax(row)) if row.any() else -1 for row in engine.shift)
    table = np.ascontiguousarray(np.moveaxis(coef, 1, 2))
    table.flags.writeable = False  # shared by every env on this engine
    return rows, engine.grid.tolist(), table, shift


@dataclass(frozen=True)
class NonlinearPlantCore:
    """One step of the nonlinear engine behind the valves, on floats or on arrays.

    ``input_offset`` is added to the valve positions to make them absolute (from the 100 % trim),
    ``output_offset`` subtracted from the outputs; the plant starts at ``x_start``, ``rho_start``
    with linkage and valves at ``valve_start``.
    """

    engine: NonlinearEngine = field(repr=False)
    asymmetric: bool
    half_backlash: float
    stiction: float
    input_offset: tuple[float, float]
    output_offset: tuple[float, float]
    x_start: tuple[float, ...]
    rho_start: float
    valve_start: tuple[float, float]
    # the table for the float carrier: per segment, the (c0, c1, c2, c3) of every column
    float_table: list = field(init=False, repr=False)
    float_grid: list = field(init=False, repr=False)  # the table's nodes, %, as floats
    array_table: np.ndarray = field(init=False, repr=False)  # (4, columns, segments)
    input_column: np.ndarray = field(init=False, repr=False)  # input_offset as (2, 1)
    shift_source: tuple = field(init=False, repr=False)  # per state, its source in A_o (-1: none)
    authority: tuple[float, float] = field(init=False, repr=False)  # the engine's (g, b), read per step

    def __post_init__(self) -> None:
        layout = self.engine.layout
        if (layout.p, layout.m) != (2, 2):
            raise ValueError(f"the engine envs need 2 valves and 2 outputs, got {layout.m} and {layout.p}")
        for name, value in zip(("float_table", "float_grid", "array_table", "shift_source"),
                               _tables(self.engine), strict=True):  # fmt: skip
            object.__setattr__(self, name, value)
        object.__setattr__(self, "input_column", np.array(self.input_offset)[:, None])
        object.__setattr__(self, "authority", (self.engine.authority_loss, self.engine.authority_travel))

    @classmethod
    def at_trim(cls, engine: NonlinearEngine, power: float, asymmetric: bool, half_backlash: float,
                stiction: float, absolute: bool) -> NonlinearPlantCore:  # fmt: skip
        """The core starting at the engine's trim at ``power`` %: commands and outputs measured from
        that trim (``absolute`` False, the tracking env) or from the 100 % trim (True, the
        throttle env, whose valves then start at the trim's positions)."""
        x, _, v = engine.trim(power)
        x_start, v_trim = tuple(x[0].tolist()), tuple(v[0].tolist())
        zero = (0.0, 0.0)
        return cls(
            engine, bool(asymmetric), float(half_backlash), float(stiction),
            input_offset=zero if absolute else v_trim,
            # the trim's own outputs (C x_eq(P) = y_eq(P) to round-off): the env starts at exactly 0
            output_offset=zero if absolute else x_start[-2:],
            x_start=x_start, rho_start=float(power), valve_start=v_trim if absolute else zero,
        )  # fmt: skip

    @property
    def initial_outputs(self) -> np.ndarray:
        """The outputs at the start, (2,)."""
        return np.array(self.x_start[-2:]) - np.array(self.output_offset)

    def initial_plant(self, n: int | None) -> NonlinearPlant:
        """The plant at reset: floats (``n`` None) or arrays of ``n`` envs."""
        if n is None:
            return NonlinearPlant(list(self.x_start), self.rho_start, self.valve_start, self.valve_start)
        x = np.repeat(np.array(self.x_start)[:, None], n, axis=1)
        valve = np.repeat(np.array(self.valve_start)[:, None], n, axis=1)
        return NonlinearPlant(x, np.full(n, self.rho_start), valve, valve.copy())

    def advance(
        self, plant: NonlinearPlant, command: Any, t: Any, nominal: Any, ops: Carrier
    ) -> tuple[NonlinearPlant, Value, Value]:
        """One sample under the valve commands (a (2, N) array, or two floats): (plant, Pc, MR).
        ``t`` and ``nominal`` (the task's step and schedule offset) are not read: the commands
        are absolute already and the schedule is the engine's own."""
        if ops.batched:
            return self._advance_arrays(plant, command)
        return self._advance_floats(plant, *command)

    def _advance_floats(self, plant: NonlinearPlant, u0: float, u1: float) -> tuple:
        x, rho, linkage, valve = plant
        linkage, (v0, v1) = valves_pair_floats(linkage, valve, u0, u1, self.half_backlash, self.stiction)
        lo, hi = SCHEDULE_RANGE
        r = lo if lo > rho else rho
        r = hi if hi < r else r
        table = self.float_table
        seg = int((r - lo) / GRID_STEP)
        seg = len(table) - 1 if seg > len(table) - 1 else seg
        s = r - self.float_grid[seg]
        vals = [((c0 * s + c1) * s + c2) * s + c3 for c0, c1, c2, c3 in table[seg]]
        cols = self.engine.columns
        n = len(x)
        k_vals, b_vals = vals[cols["K"]], vals[cols["B"]]
        g0, g1 = vals[cols["lam"]]
        q0, q1 = vals[cols["v_eq"]]
        x_eq = vals[cols["x_eq"]]
        e = [xi - qi for xi, qi in zip(x, x_eq, strict=True)]
        o0, o1 = self.input_offset
        d0, d1 = (v0 + o0) - q0, (v1 + o1) - q1
        asymmetric, (loss, travel) = self.asymmetric, self.authority
        d0 = valve_effect(d0, g0, math.sqrt, asymmetric, loss, travel)
        d1 = valve_effect(d1, g1, math.sqrt, asymmetric, loss, travel)
        y0, y1 = e[n - 2], e[n - 1]
        x = [
            (((e[src] + (k_vals[2 * i] * y0 + k_vals[2 * i + 1] * y1)) if src >= 0
              else (k_vals[2 * i] * y0 + k_vals[2 * i + 1] * y1))
             + (b_vals[2 * i] * d0 + b_vals[2 * i + 1] * d1)) + x_eq[i]
            for i, src in enumerate(self.shift_source)
        ]  # fmt: skip
        rho = rho + self.engine.alpha * ((100.0 + x[n - 2] / PC_PER_PERCENT) - rho)
        p0, p1 = self.output_offset
        return NonlinearPlant(x, rho, linkage, (v0, v1)), x[n - 2] - p0, x[n - 1] - p1

    def _advance_arrays(self, plant: NonlinearPlant, command: np.ndarray) -> tuple:
        x, rho, linkage, valve = plant
        linkage, valve = valves_arrays(linkage, valve, command, self.half_backlash, self.stiction)
        lo, hi = SCHEDULE_RANGE
        r = CLIP_UFUNC(rho, lo, hi)
        seg = ((r - lo) / GRID_STEP).astype(np.intp)
        np.minimum(seg, self.array_table.shape[-1] - 1, out=seg)
        s = r - self.engine.grid[seg]
        c = np.take(self.array_table, seg, axis=-1)  # (4, columns, N), C-contiguous
        vals = c[0] * s  # ((c0 s + c1) s + c2) s + c3, in place: the float step's operations
        vals += c[1]
        vals *= s
        vals += c[2]
        vals *= s
        vals += c[3]
        cols, n, count = self.engine.columns, x.shape[0], x.shape[1]
        x_eq = vals[cols["x_eq"]]
        e = x - x_eq
        d = (valve + self.input_column) - vals[cols["v_eq"]]
        d = valve_effect(d, vals[cols["lam"]], np.sqrt, self.asymmetric, *self.authority)
        k_gain = vals[cols["K"]].reshape(n, 2, count)
        b_gain = vals[cols["B"]].reshape(n, 2, count)
        x = dynamics_arrays(e, d, self.shift_source, k_gain, b_gain)
        x += x_eq
        rho = rho + self.engine.alpha * ((100.0 + x[n - 2] / PC_PER_PERCENT) - rho)
        p0, p1 = self.output_offset
        return NonlinearPlant(x, rho, linkage, valve), x[n - 2] - p0, x[n - 1] - p1


def nonlinear_task(task: EngineTask, engine: NonlinearEngine, asymmetric: bool) -> EngineTask:
    """``task`` (an EngineTask, or a ThrottleTask whose profile gives the nominal valve schedule)
    with the nonlinear engine as its plant."""
    params = task.params
    if task.offset_table is None:  # the tracking task: about the trim at its power
        core = NonlinearPlantCore.at_trim(
            engine, task.operating_power, asymmetric, params.half_backlash, params.stiction, absolute=False
        )
        return dataclasses.replace(task, nonlinear=core)
    x, _, v = engine.trim(task.power)
    core = NonlinearPlantCore.at_trim(
        engine, float(task.power[0]), asymmetric, params.half_backlash, params.stiction, absolute=True
    )
    return dataclasses.replace(task, nonlinear=core, offset_table=v, x_start=x[0])


__all__ = ["PLANT_NAME", "NonlinearPlant", "NonlinearPlantCore", "nonlinear_engine_of", "nonlinear_task"]
