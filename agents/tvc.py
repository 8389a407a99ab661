"""Hysteresis compensation for the nozzle: inverse Bouc-Wen feedforward on top of a linear loop."""

from __future__ import annotations

from typing import Any

import numpy as np

from agents.base import BatchController, by_kind, task_of
from agents.plants import nozzle_joint
from ssme_envs.envs.launcher_pitch import LauncherTask
from ssme_envs.envs.nozzle_tvc import NozzleTask

PATH_SUBSTEPS = 4  # RK4 steps per sample along the reference's path


def hysteresis_along(
    w: np.ndarray, x0: np.ndarray, x1: np.ndarray, beta: float, gamma: float, n: float
) -> np.ndarray:
    """The normalized Bouc-Wen state after the joint moves from x0 to x1 (rad): the law is
    rate-independent, ``dw/dx = 1 - |w|^n (beta + gamma sign(dx w))``, integrated over x by RK4."""
    h = (x1 - x0) / PATH_SUBSTEPS
    direction = np.sign(h)

    def slope(w: np.ndarray) -> np.ndarray:
        return 1.0 - np.abs(w) ** n * (beta + gamma * np.sign(direction * w))

    for _ in range(PATH_SUBSTEPS):
        k1 = slope(w)
        k2 = slope(w + 0.5 * h * k1)
        k3 = slope(w + 0.5 * h * k2)
        k4 = slope(w + h * k3)
        w = w + h / 6.0 * (k1 + 2.0 * (k2 + k3) + k4)
    return w


# whether the action is the nozzle joint's torque (the launcher's task composes a nozzle task, but
# its action is a deflection command to a servo)
TORQUE_LOOP: dict[type, bool] = {NozzleTask: True, LauncherTask: False}


class HysteresisCompensated(BatchController):
    """A nozzle loop (``base``, designed on the joint's linear stiffness) plus the torque the
    linear design leaves out: the joint's restoring torque is ``k_el x + k_hys w`` where the
    design assumes ``(k_el + k_hys) x``, so ``k_hys (w - x)`` is fed forward, with ``w`` the
    Bouc-Wen state the identified joint would have along the reference's path (noise-free, where
    the joint should be)."""

    name = "hysteresis"

    def __init__(self, env: Any, base: BatchController, design: str = "identified") -> None:
        super().__init__()
        task = task_of(env)
        if not by_kind(TORQUE_LOOP, task, self.name):
            raise TypeError(f"{self.name} compensates the NozzleTVC torque loop, not {type(task).__name__}")
        joint = nozzle_joint(task, design)
        norm = joint.normalized()
        self.k_hys = norm["k_hys"]
        self.shape = (norm["beta_n"], norm["gamma_n"], norm["n"])
        self.base = base
        self.design = base.design
        self.name = f"{base.name}+hysteresis"

    def initial_state(self, n: int) -> dict[str, np.ndarray]:
        return {"w": np.zeros(n), "r": np.zeros(n)}

    def reset(self, seed: int | None = None, num_envs: int = 1, envs: np.ndarray | None = None) -> None:
        self.base.reset(seed, num_envs, envs)
        super().reset(seed, num_envs, envs)

    def compute(self, obs: np.ndarray) -> np.ndarray:
        r = self.design.ports.read(obs)[1][:, 0]  # the reference, rad
        s = self.state
        s["w"] = hysteresis_along(s["w"], s["r"], r, *self.shape)
        s["r"] = r
        feedforward = self.k_hys * (s["w"] - r) / self.design.ports.input_scale
        return self.base.compute(obs) + feedforward[:, None]


__all__ = ["HysteresisCompensated", "hysteresis_along"]
