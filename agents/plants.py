"""The linear design model of each env, with the units that map it onto the env's interface.

Each kind of task has its design model in :data:`DESIGNS`, looked up along the task's class
hierarchy (:func:`agents.base.by_kind`): the launcher's task is a nozzle task and the throttle
task an engine task, and each still gets its own entry whatever the order of the table.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.signal

from agents.base import DEG, Ports, by_kind, columns, task_of
from ssme_envs.envs.engine_throttle import ThrottleTask
from ssme_envs.envs.engine_tracking import EngineTask
from ssme_envs.envs.engine_tracking import design_model as engine_design_model
from ssme_envs.envs.launcher_pitch import LauncherTask
from ssme_envs.envs.nozzle_tvc import NozzleTask
from ssme_envs.models.linear import PlantMatrices, StateSpace
from ssme_envs.models.nozzle import NozzleParameters, identified_nozzle

DESIGN_SOURCES = ("identified", "truth")


@dataclass(frozen=True)
class LinearDesign(PlantMatrices):
    """A discrete linear plant ``x+ = A x + B u``, ``y = C x`` to design on, in model units.

    ``error_weight`` and ``rate_weight`` express the env's reward in model units: the cost of a
    step is ``error_weight |r - y|^2 + rate_weight |u_k - u_(k-1)|^2``.
    """

    plant: StateSpace
    ports: Ports
    input_limit: float  # |u| reachable with actions in [-1, 1], model units
    noise_std: np.ndarray  # (p,), measurement noise, model units
    error_weight: float
    rate_weight: float
    # feed a moving reference's ramp motion forward (off where the model leaves out dynamics that
    # the feedforward would drive: the launcher's nozzle servo)
    follow_ramps: bool = True


def check_source(source: str) -> str:
    if source not in DESIGN_SOURCES:
        raise ValueError(f"design source must be one of {DESIGN_SOURCES}, got {source!r}")
    return source


def nozzle_joint(task: NozzleTask, source: str) -> NozzleParameters:
    """The nozzle joint to design on: the identified model's (Bouc-Wen when identified, else
    linear), or the env's own plant."""
    return identified_nozzle(task.design).plant() if check_source(source) == "identified" else task.plant


def _oscillator(a1: float, a0: float, g: float, dt: float) -> StateSpace:
    """``x'' + a1 x' + a0 x = g u`` held over each sample (zero-order hold), output x."""
    a, b = np.array([[0.0, 1.0], [-a0, -a1]]), np.array([[0.0], [g]])
    c = np.array([[1.0, 0.0]])
    ad, bd, *_ = scipy.signal.cont2discrete((a, b, c, np.zeros((1, 1))), dt, method="zoh")
    return StateSpace(ad, bd, c, dt)


def _nozzle_second_order(task: NozzleTask, source: str) -> tuple[float, float, float]:
    joint = nozzle_joint(task, source)
    return joint.b / joint.J, joint.small_signal_stiffness / joint.J, 1.0 / joint.J


def _launcher_second_order(task: LauncherTask, source: str) -> tuple[float, float, float]:
    return 0.0, -task.instability, task.effectiveness


SECOND_ORDER: dict[type, Callable[[Any, str], tuple[float, float, float]]] = {
    NozzleTask: _nozzle_second_order,
    LauncherTask: _launcher_second_order,
}


def second_order(task: NozzleTask, source: str) -> tuple[float, float, float]:
    """(a1, a0, g) of the second-order design model ``x'' + a1 x' + a0 x = g u``: the nozzle
    (torque -> angle, the joint's small-signal stiffness) or the launcher's rigid body (deflection
    -> attitude, the servoed nozzle taken as ideal: its 15 Hz are far above the attitude loop's)."""
    return by_kind(SECOND_ORDER, task, "second-order model")(task, source)


# observation units per model unit: the models work in fractions and radians
UNIT_SCALE = {"%": 100.0, "deg": DEG}


def _ports(task: Any, outputs: tuple[str, ...], references: tuple[str, ...], input_scale: float,
           sign: float = 1.0) -> Ports:  # fmt: skip
    """Ports on the named columns of the task's observation layout, scaled by their unit."""
    observation = task.observation
    output_columns = columns(observation, *outputs)
    (unit,) = {observation.units[i] for i in output_columns}
    return Ports(output_columns, columns(observation, *references), sign * UNIT_SCALE[unit], input_scale)


def _design(plant: StateSpace, task: Any, ports: Ports, follow_ramps: bool = True) -> LinearDesign:
    """The design on ``plant`` read through ``ports``: the input limit is the action's full scale,
    the noise and the reward's weights the task's, in model units."""
    return LinearDesign(
        plant, ports, ports.input_scale, np.array(task.noise_std, dtype=float, ndmin=1),
        task.error_weight * ports.scale**2, task.rate_weight / ports.input_scale**2, follow_ramps,
    )  # fmt: skip


def _nozzle_design(task: NozzleTask, source: str, power: float | None) -> LinearDesign:
    ports = _ports(task, ("angle_deg",), ("ref_deg",), task.torque_limit)
    return _design(_oscillator(*second_order(task, source), task.dt), task, ports)


def _launcher_design(task: LauncherTask, source: str, power: float | None) -> LinearDesign:
    ports = _ports(task, ("attitude_deg",), ("ref_deg",), task.max_deflection)
    # through the 15 Hz servo the ramp feedforward costs: attitude cost 2.17 -> 3.62
    return _design(_oscillator(*second_order(task, source), task.dt), task, ports, follow_ramps=False)


def _engine_plant(model: Any) -> StateSpace:
    return StateSpace(model.A, model.B, model.C, model.dt)


def _engine_design(task: EngineTask, source: str, power: float | None) -> LinearDesign:
    ports = _ports(task, ("pc_pct", "mr_pct"), ("pc_ref_pct", "mr_ref_pct"), task.action_scale)
    return _design(_engine_plant(task.design_model(source)), task, ports)


def _throttle_design(task: ThrottleTask, source: str, power: float | None) -> LinearDesign:
    model = engine_design_model(100.0 if power is None else float(power), source)
    # the design model is about the operating point y_eq(P): its output y - y_eq(P) is minus the
    # observed error, and its reference 0
    ports = _ports(task, ("pc_err_pct", "mr_err_pct"), (), task.action_scale, sign=-1.0)
    return _design(_engine_plant(model), task, ports)


DESIGNS: dict[type, Callable[[Any, str, float | None], LinearDesign]] = {
    NozzleTask: _nozzle_design,
    LauncherTask: _launcher_design,
    EngineTask: _engine_design,
    ThrottleTask: _throttle_design,
}


def linear_design(env: Any, source: str = "identified", power: float | None = None) -> LinearDesign:
    """The design model of an ssme-envs env (scalar or native vector), from ``source``
    ("identified": what the identification pipeline produced; "truth": the env's own plant,
    its nonlinear effects left out). ``power`` (%): the throttle env's model at that level."""
    task = task_of(env)
    check_source(source)
    return by_kind(DESIGNS, task, "design model")(task, source, power)


__all__ = [
    "DESIGNS",
    "DESIGN_SOURCES",
    "SECOND_ORDER",
    "LinearDesign",
    "check_source",
    "linear_design",
    "nozzle_joint",
    "second_order",
]
