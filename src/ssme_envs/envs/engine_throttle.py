"""The SSME over the mission throttle profile, on the linked full-range model."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ssme_envs.envs import engine_compiled
from ssme_envs.envs.engine_nonlinear_plant import nonlinear_engine_of, nonlinear_task
from ssme_envs.envs.engine_task import EnginePlant, EngineTask, resolve_truth
from ssme_envs.envs.engine_tracking import EngineTrackingEnv
from ssme_envs.envs.faults import Fault
from ssme_envs.envs.task import MAX_EPISODE_SECONDS, Carrier, Schedule, Value, real_number, shown
from ssme_envs.models import engine_step
from ssme_envs.models.engine import ENGINE_DT, TruthConfig
from ssme_envs.models.engine_nonlinear import NonlinearEngine
from ssme_envs.models.engine_step import (
    dynamics_arrays,
    pair_rows,
    pair_step_reference,
    valves_arrays,
)
from ssme_envs.models.linked import POWER_RANGE, LinkedEngineModel

# The mission profile of the paper's figure 2, compressed in time (the flight spends about
# 520 s; here 60 s): 100 %, up to 104 %, the 65-72 % bucket through max-q, back to 104 %, and the
# 3 g throttle-down as propellant is used. (time s, power %) breakpoints, linear in between.
MISSION_PROFILE: tuple[tuple[float, float], ...] = (
    (0.0, 100.0), (3.0, 100.0), (5.0, 104.0), (15.0, 104.0), (19.0, 67.0), (29.0, 67.0),
    (33.0, 104.0), (45.0, 104.0), (60.0, 67.0),
)  # fmt: skip


def _profile_points(profile: Any) -> np.ndarray:
    """The profile's (time s, power %) breakpoints as an (n, 2) float array, each entry checked
    first to be a finite real number (``np.asarray(dtype=float)`` reads True as 1, "5" and b"5" as
    5): ValueError naming the entry and its pair otherwise."""
    pairs = "profile must be a list of at least two (time s, power %) pairs"
    try:  # the entries as given (bools and strings kept), in the profile's shape
        raw = np.asarray(profile, dtype=object)
    except (TypeError, ValueError):
        raw = np.empty(0, dtype=object)
    if raw.ndim != 2 or raw.shape[1] != 2 or raw.shape[0] < 2:
        raise ValueError(pairs)
    for i, row in enumerate(raw.tolist()):
        for part, value in zip(("time", "power"), row, strict=True):
            number = real_number(value)
            if number is None:
                raise ValueError(
                    f"{pairs} of real numbers (not bools or strings), "
                    f"got {type(value).__name__} {shown(value)} as the {part} of pair {i}"
                )
            if not math.isfinite(number):  # an int beyond a float is inf here
                raise ValueError(f"profile {part} must be finite, got {shown(value)} in pair {i}")
    return np.asarray(profile, dtype=float)  # converted as before the checks: the same floats


def power_profile(profile: Sequence[tuple[float, float]], dt: float) -> np.ndarray:
    """Commanded power per sample, % (piecewise linear through the breakpoints)."""
    points = _profile_points(profile)
    if points[0, 0] != 0.0 or np.any(np.diff(points[:, 0]) <= 0):
        raise ValueError("profile times must start at 0 and increase")
    if points[:, 1].min() < POWER_RANGE[0] or points[:, 1].max() > POWER_RANGE[1]:
        raise ValueError(f"profile power must stay within {POWER_RANGE[0]:g}-{POWER_RANGE[1]:g} %")
    if points[-1, 0] > MAX_EPISODE_SECONDS:  # before the table of every sample is made
        raise ValueError(
            f"profile must end within {MAX_EPISODE_SECONDS:g} s (the longest episode), "
            f"got {points[-1, 0]:g} s"
        )
    t = np.arange(round(points[-1, 0] / dt) + 1) * dt
    return np.interp(t, points[:, 0], points[:, 1])


@dataclass(frozen=True)
class ThrottleTask(EngineTask):
    """An engine task whose plant is the linked model scheduled on the commanded power P(t)
    (``plant="truth"``; with ``plant="nonlinear"`` the nonlinear engine, ``nonlinear``, steps
    instead, and its own trim gives ``offset_table`` and ``x_start``; the linked tables stay
    unused):

    ``x(k+1) = A(P) x + B(P) u* + (I - A(P)) C^T c(P)``, ``y = C x``, with
    ``c(P) = y_eq(P) - G(P) u_eq(P)`` and ``u* = u + (lambda(P) - 1) |u - u_eq(P)|``. At a fixed
    power this is the local point model about its operating point; on the nominal schedule
    ``u = u_eq(P)`` its equilibrium output is ``y_eq(P)`` at every power.
    """

    power: np.ndarray = field(default=None)  # commanded power per step, %
    nominal_outputs: np.ndarray = field(default=None)  # (T + 1, 2), the references
    k_table: np.ndarray = field(default=None)  # (T + 1, n, p)
    b_table: np.ndarray = field(default=None)  # (T + 1, n, m)
    lam_table: np.ndarray = field(default=None)  # (T + 1, m), lambda - 1 (zero without the gains)
    state_offsets: np.ndarray = field(default=None)  # (T + 1, n), (I - A) C^T c(P)
    x_start: np.ndarray = field(default=None)  # (n,), the equilibrium at P(0) on the schedule
    # K, B, lambda - 1 and the state offsets of each step: as float tuples per step, and stacked
    # as rows time last, so that one gather fetches every parameter of every env's step
    schedule: Schedule = field(init=False, repr=False)
    schedule_parts: tuple = field(init=False, repr=False)  # (rows, shape) of each table in it

    def __post_init__(self) -> None:
        self._derive()
        tables = (self.k_table, self.b_table, self.lam_table, self.state_offsets)
        rows = [np.moveaxis(table, 0, -1).reshape(-1, table.shape[0]) for table in tables]
        ends = np.cumsum([len(block) for block in rows])
        parts = tuple(
            (slice(end - len(block), end), table.shape[1:])
            for end, block, table in zip(ends, rows, tables, strict=True)
        )
        # per step: pair_rows of K and B (the float core's) with each state's offset, lambda - 1
        shift = self.params.shift_source
        per_step = [
            (tuple((*row, o) for row, o in zip(pair_rows(shift, k, b), offset, strict=True)), lam)
            for k, b, lam, offset in zip(*(table.tolist() for table in tables), strict=True)
        ]
        object.__setattr__(self, "schedule", Schedule(per_step, np.ascontiguousarray(np.concatenate(rows))))
        object.__setattr__(self, "schedule_parts", parts)
        self._compile()

    def kernel_steps(self) -> tuple[list, bool]:
        """The rows of every step of the schedule (see :meth:`EngineTask.kernel_steps`)."""
        return [(lam, rows) for rows, lam in self.schedule.floats], True

    @classmethod
    def build_throttle(
        cls,
        profile: Sequence[tuple[float, float]] = MISSION_PROFILE,
        truth: TruthConfig | Mapping[str, Any] | None = None,
        fault: Mapping[str, Any] | Fault | None = None,
        action_scale: float = 0.02,
        plant: str | NonlinearEngine = "truth",
    ) -> ThrottleTask:
        engine = nonlinear_engine_of(plant)
        if engine is None and not (isinstance(plant, str) and plant == "truth"):
            raise ValueError(f"plant must be 'truth', 'nonlinear' or a NonlinearEngine, got {plant!r}")
        power = power_profile(profile, ENGINE_DT)
        if power.size < 2:
            raise ValueError("the profile is shorter than one 0.04 s step")
        base = EngineTask.build(
            truth=truth,
            fault=fault,
            action_scale=action_scale,
            reference="zero",
            episode_seconds=max(1.0, (power.size - 1) * ENGINE_DT),
        )
        config = resolve_truth(truth)
        linked = LinkedEngineModel()
        k, b, lam = linked.parameters(power)
        lam_minus_one = lam - 1.0 if config.asymmetric_gains else np.zeros_like(lam)
        u_nom, y_nom = linked.nominal_valves(power), linked.nominal_outputs(power)
        a, _, c = linked.state_matrices(power)
        eye = np.eye(a.shape[-1])
        gain = c @ np.linalg.solve(eye - a, b)
        offset_out = y_nom - (gain @ u_nom[..., None])[..., 0]
        offset = ((eye - a) @ c.T @ offset_out[..., None])[..., 0]
        x_start = np.linalg.solve(eye - a[0], b[0] @ u_nom[0] + offset[0])
        values = {f.name: getattr(base, f.name) for f in dataclasses.fields(base) if f.init}
        values.update(horizon=power.size - 1, reference="throttle", offset_table=u_nom)
        task = cls(
            **values,
            power=power,
            nominal_outputs=y_nom,
            k_table=k,
            b_table=b,
            lam_table=lam_minus_one,
            state_offsets=offset,
            x_start=x_start,
        )
        # on the nonlinear engine: its own trim gives the nominal valve schedule and the start
        return task if engine is None else nonlinear_task(task, engine, config.asymmetric_gains)

    @property
    def nominal_valves(self) -> np.ndarray:
        """The nominal valve schedule u_eq(P(t)), (T + 1, 2): the offset of the valve commands."""
        return self.offset_table

    @property
    def draw_size(self) -> int:
        return 2 * (self.horizon + 1)

    @property
    def shared_references(self) -> np.ndarray:
        return self.nominal_outputs

    def references(
        self, uniforms: np.ndarray, start: int, stop: int, out: np.ndarray | None = None
    ) -> np.ndarray:
        """The profile's references for every episode, a read-only view (2, stop - start, k), or
        written into ``out`` where given."""
        rows = self.nominal_outputs[start:stop].T[:, :, None]
        shared = np.broadcast_to(rows, (2, stop - start, uniforms.shape[1]))
        if out is None:
            return shared
        out[...] = shared
        return out

    # Plant state: [x (n), linkage (m), valve (m)], starting at the schedule's equilibrium. The
    # command of step t - 1 -> t is absolute (the schedule at t - 1 plus the action, faults
    # applied) and acts with that step's parameters.
    @property
    def initial_outputs(self) -> np.ndarray:
        return self.x_start[self.n_states - 2 :].copy()

    def initial_plant(self, n: int | None) -> EnginePlant:
        u0 = self.nominal_valves[0]
        if n is None:
            return EnginePlant(self.x_start.tolist(), tuple(u0.tolist()), tuple(u0.tolist()))
        u0 = np.repeat(u0[:, None], n, axis=1)
        return EnginePlant(np.repeat(self.x_start[:, None], n, axis=1), u0, u0.copy())

    def advance(
        self, plant: EnginePlant, command: Any, t: Any, nominal: Any, ops: Carrier
    ) -> tuple[EnginePlant, Value, Value]:
        """The linked model with the parameters of step t - 1 -> t (the plant core's float or
        array arithmetic, the same operations in the same order)."""
        x, linkage, valve = plant
        if ops.batched and self.batch_args is not None:  # the operations below, compiled
            x, linkage, valve = engine_compiled.plant_step(self, plant, command, t)
        elif ops.batched:
            half, stick, shift = self.params.half_backlash, self.params.stiction, self.params.shift_source
            rows = ops.at(self.schedule, t)
            k, b, lam, offset = (
                rows[part].reshape(*shape, rows.shape[-1]) for part, shape in self.schedule_parts
            )
            linkage, valve = valves_arrays(linkage, valve, command, half, stick)
            u_star = valve + lam * np.abs(valve - nominal)
            x = dynamics_arrays(x, u_star, shift, k, b)
            x += offset  # in place: the same sum, without a third (n, N) array
        elif self.kernel_args is not None:  # the reference's operations, compiled
            x, linkage, valve = engine_step.kernel().pair_step(
                x, linkage, valve, *command, *nominal, *self.kernel_args, t - 1
            )
        else:
            rows, lam = ops.at(self.schedule, t)
            valves = (*command, *nominal, *self.rows[3:])  # commands, nominals, backlash, stiction
            x, linkage, valve = pair_step_reference(x, linkage, valve, *valves, lam, rows)
        return EnginePlant(x, linkage, valve), x[-2], x[-1]


class EngineThrottleEnv(EngineTrackingEnv):
    """Fly the SSME through the mission throttle profile, tracking chamber pressure and mixture ratio.

    The plant is the full-range engine: the five Table I point models of NASA TM-104422 linked
    over 65-109 % power (:mod:`ssme_envs.models.linked`), with operating-point offsets, scheduled on the
    commanded power, with the lambda gains, valve backlash and stiction, and sensor noise of
    the truth. Outputs are normalized deviations from the 100 % point (d Pc = 0.01 per % of
    power); the references follow the profile: Pc = P/100 - 1, MR held at nominal.

    ## Action Space
    ``Box(-1, 1, (2,), float32)``: corrections to the nominal valve schedule. The valve commands
    are ``u_eq(P(t)) + action * action_scale`` (default 0.02 normalized valve travel), where
    ``u_eq`` is the schedule consistent with the point models' DC gains: zero action flies the
    profile open loop. Out-of-range actions are clipped; NaN or inf raises ValueError.

    ## Observation Space
    As in ``EngineTracking-v0`` (10 values: measured Pc and MR, references, errors, error
    integrals, previous action; errors in % of the 100 % values).

    ## Rewards
    As in ``EngineTracking-v0``: ``-0.1 (e_pc^2 + e_mr^2) - 0.1 |a_k - a_(k-1)|^2`` with errors in
    % of the 100 % values. An episode terminates when a tracking error exceeds 10 %, with a
    penalty larger than the cost of all remaining steps.

    ## Episode End
    Truncation at the end of the profile (default: the time-compressed mission, 60 s, 1500 steps).
    ``gymnasium.make`` also applies the registered limit of 1500 steps: for a longer profile pass
    ``max_episode_steps`` too. Faults act on the absolute valve commands (a stuck valve holds its
    position whatever the schedule). ``step`` after the episode ended raises
    :class:`~ssme_envs.envs.tracking_env.EpisodeOverError` and ``reset`` takes no options, as in
    ``EngineTracking-v0``.

    ## Arguments
    profile : list of (time s, power %) breakpoints within 65-109 % (default: the mission).
    plant : "truth" (default: the linked model scheduled on the commanded power, above) or
    "nonlinear" (or a ``NonlinearEngine``): the synthetic nonlinear engine of
    :mod:`ssme_envs.models.engine_nonlinear`, scheduled on the power implied by its own chamber
    pressure, never on the command; its own trim valve positions at the commanded power are the
    nominal schedule u_eq(P(t)), so zero action still holds the profile at steady state; it
    starts at its trim at the profile's first power. Controllers may still schedule on the
    commanded power (the reference).
    truth, fault, action_scale, render_mode : as in ``EngineTracking-v0``.
    """

    build_task = staticmethod(ThrottleTask.build_throttle)
