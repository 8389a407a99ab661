"""PI and PID loops: the SSME-style decoupled PI, and PID by pole placement for the nozzle and the
launcher's attitude."""

from __future__ import annotations

from typing import Any

import numpy as np

from agents.base import DEG, BatchController, by_kind, columns, task_of
from agents.lqi import schedule_levels, scheduled_tables
from agents.plants import linear_design, second_order
from ssme_envs.envs.launcher_pitch import LauncherTask
from ssme_envs.envs.nozzle_tvc import NozzleTask
from ssme_envs.models.linear import spectral_radius


def simc_pi(step: np.ndarray, dt: float) -> tuple[float, float]:
    """PI gains (Kc, Ki = Kc / tau_I) by Skogestad's SIMC rule from a unit step response
    sampled at dt: first order plus one sample of delay, tau from the 63 % time, tau_c = delay."""
    gain = float(step[-1])
    delay = dt
    t63 = float(np.argmax(np.abs(step) >= 0.632 * abs(gain))) * dt
    tau = max(t63 - delay, dt)
    kc = tau / (gain * 2.0 * delay)
    return kc, kc / min(tau, 8.0 * delay)


class DecoupledPI(BatchController):
    """Two PI loops in the style of the SSME's own controller: Pc error -> OPOV, MR error -> FPOV,
    each tuned by SIMC on its own channel of the design model (the cross-coupling ignored).
    Velocity form, so a saturated valve stops integrating (anti-windup)."""

    name = "pi"

    def __init__(self, env: Any, design: str = "identified") -> None:
        super().__init__()
        self.design = linear_design(env, design)
        self.errors = columns(task_of(env).observation, "pc_err_pct", "mr_err_pct")
        self.kc, self.ki = diagonal_simc(self.design)

    def initial_state(self, n: int) -> dict[str, np.ndarray]:
        return {"u": np.zeros((n, 2)), "e": np.zeros((n, 2))}

    def gains(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(Kc, Ki) of the two loops, (2,) or per env (N, 2)."""
        return self.kc, self.ki

    def compute(self, obs: np.ndarray) -> np.ndarray:
        e = obs[:, self.errors] / 100.0
        s, limit = self.state, self.design.input_limit
        kc, ki = self.gains(obs)
        s["u"] = np.clip(s["u"] + kc * (e - s["e"]) + ki * self.design.dt * e, -limit, limit)
        s["e"] = e
        return s["u"] / self.design.ports.input_scale


def diagonal_simc(design: Any) -> tuple[np.ndarray, np.ndarray]:
    """SIMC (Kc, Ki) of the loops Pc -> OPOV and MR -> FPOV from the design model's unit steps."""
    x = np.zeros((design.A.shape[0], 2))
    steps = []
    for _ in range(200):  # unit steps on both valves, one column each
        steps.append(design.C @ x)
        x = design.A @ x + design.B
    response = np.array(steps)  # (T, outputs, inputs)
    gains = [simc_pi(response[:, i, i], design.dt) for i in range(2)]
    return np.array([g[0] for g in gains]), np.array([g[1] for g in gains])


def coupled_radius(design: Any, kc: np.ndarray, ki: np.ndarray) -> float:
    """Spectral radius of the loop of both velocity-form PIs closed around the whole design model
    (cross-coupling included): state (x, u, previous error), e = -C x."""
    A, B, C = design.A, design.B, design.C
    m = B.shape[1]
    kp, kd = np.diag(kc + ki * design.dt), np.diag(kc)
    loop = np.block([
        [A - B @ kp @ C, B, -B @ kd],
        [-kp @ C, np.eye(m), -kd],
        [-C, np.zeros((m, m)), np.zeros((m, m))],
    ])  # fmt: skip
    return spectral_radius(loop)


class ScheduledPI(DecoupledPI):
    """The decoupled PI as an engineer schedules it for EngineThrottle: SIMC gains on each power
    level's model (the identified ones at 70-110 %, or the linked truth every 4 % over 65-109 %),
    each level's pair scaled down (x 0.8 per try) until the coupled loop on that level's whole
    model has a spectral radius below ``RADIUS``, interpolated linearly in the commanded power read
    from the reference (``P = 100 + Pc reference in %``), as the scheduled LQ servo is."""

    name = "pi_scheduled"
    RADIUS = 0.97  # each level's gains must give the coupled loop a spectral radius below this

    def __init__(self, env: Any, design: str = "identified") -> None:
        BatchController.__init__(self)
        self.levels = schedule_levels(design)
        levels = self.levels.tolist()
        designs = [linear_design(env, design, power=level) for level in levels]
        self.design = designs[0]
        task = task_of(env)
        self.errors = columns(task.observation, "pc_err_pct", "mr_err_pct")
        (self.power_reference,) = columns(task.observation, "pc_ref_pct")
        kcs, kis, self.detune = [], [], []
        for level, d in zip(levels, designs, strict=True):
            kc, ki = diagonal_simc(d)
            factor = 1.0
            while coupled_radius(d, factor * kc, factor * ki) >= self.RADIUS:
                factor *= 0.8
                if factor < 0.01:  # slower than this, the PI would barely act
                    raise ValueError(f"{self.name}: no detuning of the SIMC gains gives the coupled loop "
                                     f"at {level:g} % a spectral radius below {self.RADIUS}")  # fmt: skip
            kcs.append(factor * kc)
            kis.append(factor * ki)
            self.detune.append(factor)
        self.tables = {"kc": np.array(kcs), "ki": np.array(kis)}

    def gains(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        gains = scheduled_tables(self.levels, self.tables, 100.0 + obs[:, self.power_reference])
        return gains["kc"], gains["ki"]


def placed_pid(
    a1: float, a0: float, g: float, omega: float, damping: float = 0.7
) -> tuple[float, float, float]:
    """(Kp, Ki, Kd) of ``u = Kp e + Ki int(e) - Kd x'`` on ``x'' + a1 x' + a0 x = g u`` placing
    the closed-loop poles at ``(s + omega)(s^2 + 2 damping omega s + omega^2)``."""
    kd = (omega + 2 * damping * omega - a1) / g
    kp = (omega**2 + 2 * damping * omega**2 - a0) / g
    return kp, omega**3 / g, kd


# the closed-loop poles (rad/s) of each kind of task: the launcher's task, a nozzle task too, gets
# its own along the class hierarchy
OMEGA: dict[type, float] = {NozzleTask: 60.0, LauncherTask: 4.0}


class PlacedPID(BatchController):
    """PID by pole placement on the second-order design model: the nozzle (torque -> angle, on the
    joint's small-signal stiffness, poles at 60 rad/s) or the launcher's rigid body (deflection
    -> attitude, poles at 4 rad/s). Derivative on the measured rate, conditional integration."""

    name = "pid"

    def __init__(self, env: Any, design: str = "identified", omega: float | None = None) -> None:
        super().__init__()
        task = task_of(env)
        if omega is None:
            omega = by_kind(OMEGA, task, f"{self.name} design")
        if not (isinstance(omega, int | float) and omega > 0):
            raise ValueError(f"omega must be a positive number (rad/s), got {omega!r}")
        self.design = linear_design(env, design)
        self.kp, self.ki, self.kd = placed_pid(*second_order(task, design), omega)
        self.error, self.rate = columns(task.observation, "err_deg", "rate_deg_s")

    def initial_state(self, n: int) -> dict[str, np.ndarray]:
        return {"integral": np.zeros(n)}

    def compute(self, obs: np.ndarray) -> np.ndarray:
        e, rate = obs[:, self.error] / DEG, obs[:, self.rate] / DEG
        s, limit = self.state, self.design.input_limit
        u = self.kp * e + self.ki * s["integral"] - self.kd * rate
        free = np.abs(u) < limit
        s["integral"] = np.where(free, s["integral"] + e * self.design.dt, s["integral"])
        return (u / self.design.ports.input_scale)[:, None]


__all__ = [
    "OMEGA",
    "DecoupledPI",
    "PlacedPID",
    "ScheduledPI",
    "coupled_radius",
    "diagonal_simc",
    "placed_pid",
    "simc_pi",
]
