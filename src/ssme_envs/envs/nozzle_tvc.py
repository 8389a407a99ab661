"""Nozzle deflection tracking through a torque actuator and a hysteretic flexible joint."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import gymnasium as gym
import numpy as np

from ssme_envs.envs.references import Fault, check_reference, reference_signals, uniforms_needed, unit_normals
from ssme_envs.envs.tracking_env import TrackingEnv
from ssme_envs.models.nozzle import (
    DEFAULT_TORQUE_LIMIT,
    MAX_SUBSTEPS,
    NOZZLE_DT,
    NozzleModel,
    NozzleParameters,
    RK4Parameters,
    check_stable_substeps,
    identified_nozzle,
    integration_substeps,
    published_nozzle,
    rk4_arrays,
    rk4_floats,
    rk4_parameters,
)

DEG = 180.0 / math.pi
# RK4 substeps per sample by h * rate <= 0.25 (models.nozzle.recommended_substeps): 3 for Table 1,
# within 3e-4 of the motion (9e-4 deg on 3 deg, a sixth of the default sensor noise) where 4
# substeps give 2e-4 at a third more cost (experiments/results/nozzle_integration_accuracy.md).
# models.nozzle.integration_substeps adds RK4's stability rule (stiffness, damping and hysteresis
# rates at h * rate <= 1.3, half the stability limit) and refuses plants that need more than
# MAX_SUBSTEPS; the accuracy rule sets the count of Table 1's and the identified joints.
ENV_STEP_RATE = 0.25
NOZZLE_FAULTS = ("sensor_bias", "gain_loss")
OBS_NAMES = ("angle_deg", "rate_deg_s", "ref_deg", "err_deg", "err_int_deg_s", "prev_action")

# The step below runs on Python floats (one env) and on (N,) arrays (the vector env) with the
# same IEEE operations; only selection, clipping and the integrator's carrier differ.
FLOAT_OPS = SimpleNamespace(
    where=lambda cond, a, b: a if cond else b,
    clip=lambda x, lo, hi: min(max(x, lo), hi),
    integrate=lambda plant, tau, h, steps, p: rk4_floats(*plant, tau, h, steps, p),
)


def _integrate_in_place(plant: np.ndarray, tau: np.ndarray, h: float, steps: int, p: Any) -> np.ndarray:
    rk4_arrays(plant, tau, h, steps, p)
    return plant


ARRAY_OPS = SimpleNamespace(
    where=np.where, clip=lambda x, lo, hi: np.minimum(np.maximum(x, lo), hi), integrate=_integrate_in_place
)


def resolve_nozzle(plant: str | Path | NozzleParameters | NozzleModel) -> NozzleParameters:
    """The joint behind the env: ``"bouc_wen"`` (Table 1's hysteretic joint, the truth),
    ``"linear"`` (Table 1's linear row), ``"identified"`` (the packaged model identified from
    the bench test), a nozzle model.json path, or a parameter/model object."""
    if isinstance(plant, NozzleParameters):
        return plant
    if isinstance(plant, NozzleModel):
        return plant.plant()
    if plant in ("bouc_wen", "linear"):
        return published_nozzle(str(plant))
    if plant == "identified":
        return identified_nozzle().plant()
    if isinstance(plant, str | Path) and str(plant).endswith(".json"):
        return NozzleModel.load(plant).plant()
    raise ValueError(
        "plant must be 'bouc_wen', 'linear', 'identified', a nozzle model.json path or a model, "
        f"got {plant!r}"
    )


def _number(name: str, value: Any, low: float, high: float, low_open: bool = False) -> float:
    ok = isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
    if not ok or value > high or value < low or (low_open and value == low):
        bracket = "(" if low_open else "["
        raise ValueError(f"{name} must be a number in {bracket}{low:g}, {high:g}], got {value!r}")
    return float(value)


def episode_options(
    reference: str,
    amplitude_deg: float,
    max_amplitude_deg: float,
    sensor_noise: float,
    fault: dict | Fault | None,
    seconds: float,
    dt: float,
) -> dict[str, Any]:
    """The checked episode fields of a nozzle-driven task: horizon, reference, amplitude (rad),
    noise_std (rad) and fault."""
    check_reference(reference)
    amplitude = _number("reference_amplitude_deg", amplitude_deg, 0.0, max_amplitude_deg)
    parsed = Fault.parse(fault, 1, 1)
    if parsed is not None and parsed.kind not in NOZZLE_FAULTS:
        raise ValueError(f"unknown fault kind {parsed.kind!r}; choose one of {NOZZLE_FAULTS}")
    return {
        "horizon": round(_number("episode_seconds", seconds, 0.1, 3600.0) / dt),
        "reference": reference,
        "amplitude": np.array([math.radians(amplitude)]),
        "noise_std": _number("sensor_noise", sensor_noise, 0.0, 0.01),
        "fault": parsed,
    }


@dataclass(frozen=True)
class NozzleTask:
    """Everything a nozzle tracking episode needs, shared by the scalar and the vector env."""

    plant: NozzleParameters
    substeps: int
    horizon: int
    reference: str
    amplitude: np.ndarray  # (1,), rad
    noise_std: float  # rad
    fault: Fault | None
    torque_limit: float = DEFAULT_TORQUE_LIMIT  # N m, the action's full scale
    lag_gain: float = 1.0  # 1 - exp(-dt / lag): first-order actuator lag per step (1: none)
    max_torque_change: float = math.inf  # N m per step, the rate limit
    dt: float = NOZZLE_DT
    error_weight: float = 0.1
    rate_weight: float = 0.1
    envelope: float = math.radians(6.0)  # |angle| that ends an episode (twice the working range)
    integral_limit: float = 10.0  # deg s
    rk4_params: RK4Parameters = field(init=False, repr=False)  # floats, for both carriers
    fault_step: int = field(init=False)
    # largest reward loss of one step inside the envelope (with 1 deg for noise)
    step_cost_bound: float = field(init=False)

    n_actions = 1
    n_channels = 1

    @classmethod
    def build(
        cls,
        plant: str | Path | NozzleParameters | NozzleModel = "bouc_wen",
        reference: str = "random_steps",
        reference_amplitude_deg: float = 3.0,
        sensor_noise: float = 1e-4,
        fault: dict | Fault | None = None,
        episode_seconds: float = 4.0,
        actuator_lag: float = 0.0,
        rate_limit: float | None = None,
        substeps: int | None = None,
    ) -> NozzleTask:
        params = resolve_nozzle(plant)
        episode = episode_options(
            reference, reference_amplitude_deg, 3.0, sensor_noise, fault, episode_seconds, NOZZLE_DT
        )
        lag = _number("actuator_lag", actuator_lag, 0.0, 1.0)
        if rate_limit is not None:
            rate_limit = _number("rate_limit", rate_limit, 0.0, math.inf, low_open=True)
        envelope = math.radians(6.0)
        if substeps is None:
            substeps = integration_substeps(
                params, NOZZLE_DT, envelope, DEFAULT_TORQUE_LIMIT, ENV_STEP_RATE, sample="step"
            )
        elif not isinstance(substeps, int) or isinstance(substeps, bool) or not 1 <= substeps <= MAX_SUBSTEPS:
            raise ValueError(f"substeps must be an integer in 1-{MAX_SUBSTEPS}, got {substeps!r}")
        else:  # the caller's count: accuracy is theirs, stability is checked
            check_stable_substeps(params, substeps, NOZZLE_DT, envelope, DEFAULT_TORQUE_LIMIT)
        return cls(
            plant=params,
            substeps=substeps,
            **episode,
            lag_gain=1.0 if lag == 0 else -math.expm1(-NOZZLE_DT / lag),
            max_torque_change=math.inf if rate_limit is None else rate_limit * NOZZLE_DT,
            envelope=envelope,
        )

    def __post_init__(self) -> None:
        object.__setattr__(self, "rk4_params", rk4_parameters(self.plant.normalized()))
        object.__setattr__(
            self, "fault_step", round(self.fault.time / self.dt) if self.fault is not None else -1
        )
        if self.fault is not None and self.fault_step >= self.horizon:
            raise ValueError(
                f"fault time {self.fault.time:g} s is beyond the episode ({self.horizon * self.dt:g} s)"
            )
        bias = abs(self.fault.magnitude) if self.fault is not None and self.fault.kind == "sensor_bias" else 0
        error = DEG * (self.envelope + float(self.amplitude[0]) + bias) + 1.0
        object.__setattr__(self, "step_cost_bound", self.error_weight * error**2 + self.rate_weight * 2.0**2)

    @staticmethod
    def observation_space() -> gym.spaces.Box:
        high = np.array([20, 2000, 10, 30, 10, 1], dtype=np.float32)
        return gym.spaces.Box(-high, high, dtype=np.float32)

    @property
    def shared_references(self) -> None:
        return None

    @property
    def draw_size(self) -> int:
        """Uniform float32 numbers one episode consumes: sensor noise (an even count for the
        Box-Muller pairs), then the reference's."""
        length = self.horizon + 1
        return length + length % 2 + uniforms_needed(self.reference, length, 1, self.dt)

    def episodes(
        self, uniforms: np.ndarray, noise_out: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """References (1, horizon + 1, k) in rad and unit noise (1, horizon + 1, k) float32 of k
        episodes from their uniforms (draw_size, k) float32, as for the engine tasks."""
        length = self.horizon + 1
        uniforms = np.ascontiguousarray(uniforms, dtype=np.float32)
        pairs = length + length % 2
        noise = unit_normals(uniforms[:pairs])[:length][None]
        if noise_out is not None:
            noise_out[...] = noise
            noise = noise_out
        refs = reference_signals(
            self.reference, uniforms[pairs:].astype(np.float64), length, self.amplitude, self.dt
        )
        return refs, noise

    def zero_state(self, n: int) -> list:
        """[plant (3, n): angle, rate, hysteresis w; then each (n,): actuator torque, last
        measurement, error integral, previous action], at rest (the rate estimate starts from
        the rest angle)."""
        return [np.zeros((3, n))] + [np.zeros(n) for _ in range(4)]

    def initial_observation(self, ref: np.ndarray, draws: np.ndarray) -> np.ndarray:
        """Observations at reset (6, N) float32 from the first reference and noise rows (1, N)."""
        m = self._measure(0.0, np.asarray(draws[0], dtype=np.float64), 0, ARRAY_OPS)
        e = (ref[0] - m) * DEG
        zeros = np.zeros_like(m)
        return np.stack([m * DEG, zeros, ref[0] * DEG, e, zeros, zeros]).astype(np.float32)

    def _measure(self, x: Any, noise: Any, t: Any, ops: SimpleNamespace) -> Any:
        m = x + noise * self.noise_std
        fault = self.fault
        if fault is not None and fault.kind == "sensor_bias":
            m = ops.where(t >= self.fault_step, m + fault.magnitude, m)
        return m

    def step(self, state: list, a: Any, t: Any, ref: Any, noise: Any, ops: SimpleNamespace) -> tuple:
        """One step on floats (``FLOAT_OPS``) or (N,) arrays (``ARRAY_OPS``): action ``a`` in
        [-1, 1], ``t`` the step index after this step, ``ref`` (rad) and unit ``noise`` at t.
        Returns (state, observation values, reward, terminated)."""
        plant, torque, m_prev, integral, prev = state
        cmd = a * self.torque_limit
        fault = self.fault
        if fault is not None and fault.kind == "gain_loss":
            cmd = ops.where(t > self.fault_step, cmd * fault.magnitude, cmd)
        target = cmd if self.lag_gain == 1.0 else torque + self.lag_gain * (cmd - torque)
        if math.isinf(self.max_torque_change):
            torque = target
        else:
            limit = self.max_torque_change
            torque = torque + ops.clip(target - torque, -limit, limit)
        plant = ops.integrate(
            plant,
            torque,
            self.dt / self.substeps,
            self.substeps,
            self.rk4_params,
        )
        m, e, integral, reward, terminated = self._score(plant[0], a, prev, t, ref, noise, integral, ops)
        rate = (m - m_prev) * (DEG / self.dt)
        obs = (m * DEG, rate, ref * DEG, e, integral, a)
        return [plant, torque, m, integral, a], obs, reward, terminated

    def _score(self, x: Any, a: Any, prev: Any, t: Any, ref: Any, noise: Any, integral: Any,
               ops: SimpleNamespace) -> tuple:  # fmt: skip
        """What follows the tracked output x (rad) at step t: measurement m, error e (deg), error
        integral, reward, terminated (also for the launcher's attitude)."""
        m = self._measure(x, noise, t, ops)
        e = (ref - m) * DEG
        lim = self.integral_limit
        integral = ops.clip(integral + e * self.dt, -lim, lim)
        d = a - prev
        terminated = abs(x) > self.envelope
        reward = -self.error_weight * (e * e) - self.rate_weight * (d * d)
        reward = reward - (self.step_cost_bound * (self.horizon - t + 1)) * terminated
        return m, e, integral, reward, terminated

    def nonfinite_reward(self, t: Any) -> Any:
        """The reward of step ``t`` (an int or an int array) whose own reward came out NaN or
        infinite (the plant's state overflowed): the envelope penalty plus the worst cost of a
        step inside the envelope, ``-(horizon - t + 2) step_cost_bound``, finite."""
        return -self.step_cost_bound * (self.horizon - t + 2)

    def batch_step(
        self,
        state: list,
        acts: np.ndarray,
        t: np.ndarray,
        ref: np.ndarray,
        noise: np.ndarray,
        synced: bool,
    ) -> tuple:
        """N envs, one step: acts, ref, noise (1, N); observations (N, 6) float32, unclipped."""
        state, obs, reward, terminated = self.step(
            state, acts[0], t, ref[0], noise[0].astype(np.float64), ARRAY_OPS
        )
        return state, np.stack(obs, axis=1).astype(np.float32), reward, terminated


class NozzleTVCEnv(TrackingEnv):
    """Track a nozzle deflection command with the actuator torque (thrust-vector control).

    The plant is the movable nozzle of the VLS launcher's first stage: ``J x'' + b x' + F = tau``
    with the flexible joint's restoring torque F hysteretic (Bouc-Wen, Table 1 of the nozzle
    paper) by default, or linear, or any nozzle model.json; RK4 with ``substeps`` per 0.008 s step
    (3 for Table 1's joint: within 1e-3 deg of a fine-step simulation, tested). Angles in degrees.

    The substep count is computed once per plant
    (:func:`~ssme_envs.models.nozzle.integration_substeps`): the larger of an accuracy rule
    (``h omega_n <= 0.25``, hysteresis included) and a stability rule that keeps ``h * rate <=
    1.3`` (half of RK4's 2.61 limit for any eigenvalue in the left half-plane) for the stiffness
    ``sqrt(k/J)``, the damping ``b/J`` and the Bouc-Wen hysteresis rate
    (:func:`~ssme_envs.models.nozzle.stiff_rates`).
    A plant that needs more than 10,000 substeps per step is refused with a ValueError naming
    the rate and its parameters; so is a ``substeps`` argument below the stability rule's count.
    The actuator lag and rate limit act once per step, exactly: they need no substeps.

    ## Action Space
    ``Box(-1, 1, (1,), float32)``: the torque command as a fraction of the actuator's full scale
    (3e4 N m, about 4x the torque of a static 3 deg deflection). Optional first-order
    ``actuator_lag`` (s) and ``rate_limit`` (N m/s). Out-of-range actions are clipped; NaN or
    inf raises ValueError.

    ## Observation Space
    ``Box((6,), float32)``, finite bounds, clipped into them:

    | index | observation | unit | bound |
    |---|---|---|---|
    | 0 | measured angle (sensor noise ``sensor_noise`` rad) | deg | +-20 |
    | 1 | rate estimate (difference of measured angles) | deg/s | +-2000 |
    | 2 | reference | deg | +-10 |
    | 3 | tracking error (reference - measured) | deg | +-30 |
    | 4 | integral of the error (anti-windup at +-10) | deg s | +-10 |
    | 5 | previous action | - | +-1 |

    ## Rewards
    ``-0.1 e^2 - 0.1 (a_k - a_(k-1))^2`` with the error in degrees. Leaving the envelope (true
    angle beyond 6 deg) ends the episode with a penalty larger than the worst cost of all
    remaining steps, so ending early never pays.

    ## Starting State
    At rest: zero angle, rate, hysteresis state and torque.

    ## Episode End
    Termination on leaving the envelope; truncation after ``episode_seconds`` (4 s, 500 steps).
    ``step`` after either (or before the first ``reset``) raises
    :class:`~ssme_envs.envs.tracking_env.EpisodeOverError`: call ``reset``, which takes no options
    (None or ``{}``; else TypeError or ValueError), as in ``EngineTracking-v0``.

    Non-finite state: should the plant's state overflow or turn NaN anyway (the substep rule
    is meant to prevent it; its speed bounds are estimates), the step's reward comes out NaN or
    infinite and the step ends the episode instead of handing it out: ``terminated=True``,
    ``info == {"nonfinite": True}`` (otherwise the info is ``{}``), reward ``-(horizon - t + 2)
    * step_cost_bound`` (the envelope penalty plus the worst in-envelope step, finite), and the
    observation with NaN entries 0 and infinite ones at their bounds. It ends the episode
    rather than raising because one raising sub-env would stop a whole vector env (and a
    training run), while a terminated episode resets like any other; the native vector env
    and gymnasium's ``SyncVectorEnv`` give the same values and infos (``info["nonfinite"]``
    with its ``_nonfinite`` mask, under ``final_info`` in SAME_STEP autoreset mode).

    ## Arguments
    plant : "bouc_wen" (default), "linear", "identified", a nozzle model.json path or a model.
    reference : "random_steps" (default), "step", "ramp", "prbs", "sine_sweep", "attitude",
    "zero", "mixed" (each episode one of random_steps, step, ramp, sine_sweep, attitude: for
    training); reference_amplitude_deg (0-3, default 3). sensor_noise (rad, default 1e-4).
    fault : ``{"kind": "gain_loss", "time": 2.0, "magnitude": 0.5}`` or ``{"kind": "sensor_bias",
    "time": 2.0, "magnitude": 0.005}`` (rad). episode_seconds, actuator_lag, rate_limit, substeps
    (1-10,000; default the rule's count). render_mode : "human" or "rgb_array".
    """

    output_names = ("nozzle angle",)
    actuator_names = ("torque",)
    display_scale = DEG
    display_units = ("deg", "fraction of full scale")
    build_task: Callable[..., NozzleTask] = staticmethod(NozzleTask.build)

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        refs, noise, obs = self._draw_episode(seed, options)
        self._refs = refs[0].tolist()
        self._noise = noise[0].astype(np.float64).tolist()
        self._state = [(0.0, 0.0, 0.0), 0.0, 0.0, 0.0, 0.0]
        if self.render_mode:
            self._history = [[float(obs[0]) / DEG, self._refs[0], 0.0]]
        return obs, {}

    action_meaning = "the torque command"

    def _actuator_fraction(self) -> float:
        """The actuator's value for the rendered history, as a fraction of its full scale."""
        return self._state[1] / self.task.torque_limit

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        try:
            if len(action) != 1:
                raise ValueError
            a = float(action[0])
        except (TypeError, ValueError, IndexError):
            raise ValueError(f"action must be 1 number ({self.action_meaning}), got {action!r}") from None
        if not math.isfinite(a):
            raise ValueError(f"action must be finite, got {a} (NaN or inf)")
        self._check_running()
        a = min(max(a, -1.0), 1.0)
        t = self._t + 1
        self._state, obs, reward, terminated = self.task.step(
            self._state, a, t, self._refs[t], self._noise[t], FLOAT_OPS
        )
        self._t = t
        if self.render_mode:
            self._history.append([obs[0] / DEG, self._refs[t], self._actuator_fraction()])
            if self.render_mode == "human":
                self.render()
        out = np.array(obs, dtype=np.float32)
        np.minimum(np.maximum(out, self._low, out=out), self._high, out=out)
        info = {}
        if not math.isfinite(reward):  # the state overflowed or went NaN: end the episode (see Episode End)
            reward, terminated, info = self.task.nonfinite_reward(t), True, {"nonfinite": True}
            np.nan_to_num(out, copy=False, nan=0.0)
        terminated, truncated = bool(terminated), t >= self.task.horizon
        self._ended = "terminated" if terminated else "truncated" if truncated else ""
        return out, float(reward), terminated, truncated, info


__all__ = ["NozzleTVCEnv", "NozzleTask", "resolve_nozzle"]
