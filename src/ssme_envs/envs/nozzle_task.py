"""The nozzle tracking task: a torque actuator and a hysteretic flexible joint."""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, NamedTuple

import gymnasium as gym
import numpy as np

from ssme_envs.envs.faults import Fault
from ssme_envs.envs.nozzle_compiled import score_config, score_kernel, score_observe
from ssme_envs.envs.nozzle_plants import resolve_nozzle, rule_substeps
from ssme_envs.envs.plant_spread import PlantSpread, covered_joints, resolve_spread
from ssme_envs.envs.references import (
    StreamLayout,
    check_reference,
    normal_rows,
    reference_signals,
    uniforms_needed,
)
from ssme_envs.envs.task import (
    MAX_EPISODE_SECONDS,
    SYNCED,
    Blocks,
    Carrier,
    Observation,
    Uniforms,
    Value,
    check_number,
    envelope_penalty,
    shown,
)
from ssme_envs.models.nozzle import (
    DEFAULT_TORQUE_LIMIT,
    MAX_SUBSTEPS,
    NOZZLE_DT,
    NozzleModel,
    NozzleParameters,
    RK4Parameters,
    check_stable_substeps,
    rk4_arrays,
    rk4_floats,
    rk4_parameters,
)

DEG = 180.0 / math.pi
NOZZLE_FAULTS = ("sensor_bias", "gain_loss")
NOZZLE_OBSERVATION = Observation(
    names=("angle_deg", "rate_deg_s", "ref_deg", "err_deg", "err_int_deg_s", "prev_action"),
    units=("deg", "deg/s", "deg", "deg", "deg s", "-"),
    high=(20.0, 2000.0, 10.0, 30.0, 10.0, 1.0),
)


class NozzleState(NamedTuple):
    """A nozzle episode's state: plant (angle, rate, hysteresis w: a float tuple, or (3, N)),
    actuator torque, last measurement, error integral, previous action, and the episode's drawn
    joint (None: the task's own)."""

    plant: Any
    torque: Value
    m_prev: Value
    integral: Value
    prev: Value
    joint: RK4Parameters | None = None


def integrate(plant: Any, tau: Value, h: float, steps: int, p: RK4Parameters, ops: Carrier) -> Any:
    """``steps`` RK4 steps of the joint under the torque tau held: the plant core's float or
    (in place) array arithmetic, the same operations in the same order (on arrays, the
    carrier's restarting envs, whose state the vector env discards, may be left as they were)."""
    if ops.batched:
        rk4_arrays(plant, tau, h, steps, p, skip=ops.restarting)
        return plant
    return rk4_floats(*plant, tau, h, steps, p)


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
    amplitude = check_number("reference_amplitude_deg", amplitude_deg, 0.0, max_amplitude_deg)
    parsed = Fault.parse(fault, 1, 1, kinds=NOZZLE_FAULTS)
    return {
        "horizon": round(check_number("episode_seconds", seconds, 0.1, MAX_EPISODE_SECONDS) / dt),
        "reference": reference,
        "amplitude": np.array([math.radians(amplitude)]),
        "noise_std": check_number("sensor_noise", sensor_noise, 0.0, 0.01),
        "fault": parsed,
    }


@dataclass(frozen=True)
class NozzleTask:
    """Everything a nozzle tracking episode needs, shared by the scalar and the vector env."""

    plant: NozzleParameters
    design: str  # the bench test whose identified model the controllers design on (IDENTIFIED_FILES)
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
    spread: PlantSpread | None = None  # the joint drawn per episode (None: ``plant`` throughout)
    rk4_params: RK4Parameters = field(init=False, repr=False)  # floats, for both carriers
    fault_step: int = field(init=False)
    # largest reward loss of one step inside the envelope (with 1 deg for noise)
    step_cost_bound: float = field(init=False)
    # the compiled batch step's numbers of score and observation (nozzle_compiled.score_config)
    score_config: np.ndarray = field(init=False, repr=False, compare=False)

    observation: ClassVar[Observation] = NOZZLE_OBSERVATION
    action_names: ClassVar[tuple[str, ...]] = ("torque",)
    n_actions: ClassVar[int] = 1
    n_channels: ClassVar[int] = 1

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
        plant_spread: float | str | None = None,
        uncertainty_scale: float = 1.0,
    ) -> NozzleTask:
        params, design = resolve_nozzle(plant)
        spread = resolve_spread(plant_spread, params, plant, uncertainty_scale)
        joints = covered_joints(params, spread)
        episode = episode_options(
            reference, reference_amplitude_deg, 3.0, sensor_noise, fault, episode_seconds, NOZZLE_DT
        )
        lag = check_number("actuator_lag", actuator_lag, 0.0, 1.0)
        if rate_limit is not None:
            rate_limit = check_number("rate_limit", rate_limit, 0.0, math.inf, low_open=True)
        envelope = math.radians(6.0)
        if substeps is None:  # the worst joint the spread can draw (its corners) sets the count
            substeps = rule_substeps(joints, envelope)
        elif (
            not isinstance(substeps, int | np.integer)  # numpy's too, as the other integer options
            or isinstance(substeps, bool | np.bool_)
            or not 1 <= substeps <= MAX_SUBSTEPS
        ):
            raise ValueError(f"substeps must be an integer in 1-{MAX_SUBSTEPS}, got {shown(substeps)}")
        else:  # the caller's count: accuracy is theirs, stability is checked
            substeps = int(substeps)
            for joint in joints:
                check_stable_substeps(joint, substeps, NOZZLE_DT, envelope, DEFAULT_TORQUE_LIMIT)
        return cls(
            plant=params,
            design=design,
            substeps=substeps,
            **episode,
            lag_gain=1.0 if lag == 0 else -math.expm1(-NOZZLE_DT / lag),
            max_torque_change=math.inf if rate_limit is None else rate_limit * NOZZLE_DT,
            envelope=envelope,
            spread=spread,
        )

    def __post_init__(self) -> None:
        object.__setattr__(self, "rk4_params", rk4_parameters(self.plant.normalized()))
        fault_step = -1 if self.fault is None else self.fault.step(self.dt, self.horizon)
        object.__setattr__(self, "fault_step", fault_step)
        error = DEG * (self.envelope + float(self.amplitude[0]) + Fault.sensor_bias(self.fault)) + 1.0
        object.__setattr__(self, "step_cost_bound", self.error_weight * error**2 + self.rate_weight * 2.0**2)
        object.__setattr__(self, "score_config", score_config(self, DEG / self.dt, measured=True))

    @classmethod
    def observation_space(cls) -> gym.spaces.Box:
        return cls.observation.space()

    @property
    def shared_references(self) -> None:
        return None

    @property
    def plant_draw_size(self) -> int:
        """The last uniforms of an episode's draw, which draw its joint (0: a fixed joint)."""
        return 0 if self.spread is None else self.spread.draw_size

    @property
    def draw_size(self) -> int:
        """Uniform float32 numbers one episode consumes: sensor noise (an even count for the
        Box-Muller pairs), then the reference's, then the joint's (:attr:`plant_draw_size`)."""
        length = self.horizon + 1
        return (
            length + length % 2 + uniforms_needed(self.reference, length, 1, self.dt) + self.plant_draw_size
        )

    @property
    def stream_layout(self) -> StreamLayout | None:
        """Where a step's noise and reference lie in the draw, for the vector env to make each
        step's alone (:mod:`~ssme_envs.envs.episode_streams`): random_steps references only."""
        if self.reference != "random_steps":
            return None
        return StreamLayout.random_steps(self.horizon + 1, self.dt, float(self.amplitude[0]))

    def episodes(
        self, uniforms: Uniforms, start: int, stop: int, out: Blocks | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The steps [start, stop) of k episodes from their uniforms (draw_size, k) float32, as
        for the engine tasks: references (1, stop - start, k) in rad and unit noise (1, stop -
        start, k) float32, row s of the Box-Muller normals of the first draws; written into
        ``out`` where given."""
        length = self.horizon + 1
        pairs = length + length % 2
        refs_out, noise_out = (None, None) if out is None else out
        noise = normal_rows(uniforms, pairs // 2, start, stop, None if noise_out is None else noise_out[0])
        ref_uniforms = uniforms[pairs : pairs + uniforms_needed(self.reference, length, 1, self.dt)]
        refs = reference_signals(
            self.reference, ref_uniforms.astype(np.float64), length, self.amplitude, self.dt, start, stop,
            refs_out,
        )  # fmt: skip
        return refs, noise[None]

    def initial_state(self, n: int | None = None, plants: np.ndarray | None = None) -> NozzleState:
        """At rest (the rate estimate starts from the rest angle): floats (``n`` None) or arrays
        of ``n`` envs; with a spread, the joints drawn from ``plants`` (plant_draw_size, n or 1)."""
        joint = self.drawn_joint(n, plants)
        if n is None:
            return NozzleState((0.0, 0.0, 0.0), 0.0, 0.0, 0.0, 0.0, joint)
        return NozzleState(np.zeros((3, n)), *(np.zeros(n) for _ in range(4)), joint)

    def drawn_joint(self, n: int | None, plants: np.ndarray | None) -> RK4Parameters | None:
        """The integrator parameters of the episodes' drawn joints (None without a spread)."""
        if self.spread is None:
            return None
        if plants is None:  # the vector env's tables before any reset: the nominal joint
            nominal = self.rk4_params
            return nominal if n is None else RK4Parameters(
                *(v if isinstance(v, bool) else np.full(n, v) for v in nominal)
            )  # fmt: skip
        return self.spread.rk4(plants, self.rk4_params.hysteretic, n)

    @property
    def observes_restarts(self) -> bool:
        """Whether the batched step writes restarting envs' first observations (the compiled
        scoring does: :class:`~ssme_envs.envs.task.TrackingTask`)."""
        return score_kernel(measured=True) is not None

    def initial_observation(self, ref: np.ndarray, draws: np.ndarray) -> np.ndarray:
        """Observations at reset (6, N) float32 from the first reference and noise rows (1, N)."""
        m = self.measure(0.0, np.asarray(draws[0], dtype=np.float64), 0, SYNCED)
        obs = np.zeros((6, m.size), dtype=np.float32)  # rows rounded to float32 as they are set
        obs[0], obs[2], obs[3] = m * DEG, ref[0] * DEG, (ref[0] - m) * DEG
        return obs

    def measure(self, x: Value, noise: Value, t: Any, ops: Carrier) -> Value:
        """The sensor: x (rad) with noise and the sensor-bias fault."""
        m = x + noise * self.noise_std
        fault = self.fault
        if fault is not None and fault.kind == "sensor_bias":
            m = ops.where(t >= self.fault_step, m + fault.magnitude, m)
        return m

    def step(
        self, state: NozzleState, action: Sequence[Value], t: Any, ref: Sequence[Value],
        noise: Sequence[Value], ops: Carrier,
    ) -> tuple[NozzleState, tuple, Value, Any]:  # fmt: skip
        """One step, as :class:`~ssme_envs.envs.task.TrackingTask` says: the torque command in
        [-1, 1] of full scale, ``ref`` in rad. Returns (state, the 6 observation values, reward,
        terminated); on arrays with the compiled scoring, the values as a float32 table and the
        state's rows stepped in place (:mod:`~ssme_envs.envs.nozzle_compiled`)."""
        plant, torque, m_prev, integral, prev, joint = state
        a, ref = action[0], ref[0]
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
        params = self.rk4_params if joint is None else joint
        plant = integrate(plant, torque, self.dt / self.substeps, self.substeps, params, ops)
        if ops.batched and (kernel := score_kernel(measured=True)) is not None:  # the rest in one pass
            args = (plant[0], a, prev, t, ref, noise[0], integral, m_prev, None, ops.restarting)
            values, reward, terminated = score_observe(kernel, self.score_config, *args)
            return NozzleState(plant, torque, m_prev, integral, prev, joint), values, reward, terminated
        m, e, integral, reward, terminated = self.score(plant[0], a, prev, t, ref, noise[0], integral, ops)
        rate = (m - m_prev) * (DEG / self.dt)
        obs = (m * DEG, rate, ref * DEG, e, integral, a)
        return NozzleState(plant, torque, m, integral, a, joint), obs, reward, terminated

    def score(self, x: Value, a: Value, prev: Value, t: Any, ref: Value, noise: Value, integral: Value,
              ops: Carrier) -> tuple:  # fmt: skip
        """What follows the tracked output x (rad) at step t: measurement m, error e (deg), error
        integral, reward, terminated (also for the launcher's attitude)."""
        m = self.measure(x, noise, t, ops)
        e = (ref - m) * DEG
        lim = self.integral_limit
        integral = ops.clip(integral + e * self.dt, -lim, lim)
        d = a - prev
        terminated = abs(x) > self.envelope
        reward = -self.error_weight * (e * e) - self.rate_weight * (d * d)
        if ops.any(terminated):  # the penalty's passes only on the steps that need them
            reward = ops.charge(reward, terminated, functools.partial(envelope_penalty, self), t)
        return m, e, integral, reward, terminated

    def nonfinite_reward(self, t: Any) -> Any:
        """The reward of step ``t`` (an int or an int array) whose own reward came out NaN or
        infinite (the plant's state overflowed): the envelope penalty plus the worst cost of a
        step inside the envelope, ``-(horizon - t + 2) step_cost_bound``, finite."""
        return -self.step_cost_bound * (self.horizon - t + 2)

    def render_row(self, state: NozzleState, obs: Sequence[float], ref: Sequence[float]) -> list[float]:
        """The measured angle (rad), its reference, the torque as a fraction of full scale."""
        return [obs[0] / DEG, ref[0], state.torque / self.torque_limit]


__all__ = [
    "DEG",
    "NOZZLE_OBSERVATION",
    "NozzleState",
    "NozzleTask",
    "episode_options",
]
