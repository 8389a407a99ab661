"""Pitch attitude of a launcher steered by its movable nozzle, the nozzle's dynamics in the loop."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, NamedTuple

import gymnasium as gym
import numpy as np

from ssme_envs.envs import nozzle_task
from ssme_envs.envs.faults import Fault
from ssme_envs.envs.launcher_servo import (
    body_transition,
    compiled_servo,
    nozzle_servo_gains,
    servo_batch,
    servo_floats,
)
from ssme_envs.envs.nozzle_compiled import score_config, score_kernel, score_observe
from ssme_envs.envs.nozzle_plants import ENV_STEP_RATE, resolve_nozzle
from ssme_envs.envs.nozzle_task import DEG, NozzleTask, episode_options, integrate
from ssme_envs.envs.plant_spread import covered_joints, resolve_spread
from ssme_envs.envs.task import SYNCED, Blocks, Carrier, Observation, Uniforms, Value, check_number
from ssme_envs.envs.tracking_env import TrackingEnv
from ssme_envs.models.nozzle import (
    MAX_SUBSTEPS,
    NozzleModel,
    NozzleParameters,
    RK4Parameters,
    integration_substeps,
)

LAUNCHER_DT = 0.02  # s, a 50 Hz attitude loop
SERVO_SUBSTEPS = 10  # nozzle servo and integration steps per attitude step: a 500 Hz servo
LAUNCHER_OBSERVATION = Observation(
    names=("attitude_deg", "rate_deg_s", "ref_deg", "err_deg", "err_int_deg_s", "nozzle_deg", "prev_action"),
    units=("deg", "deg/s", "deg", "deg", "deg s", "deg", "-"),
    high=(20.0, 200.0, 10.0, 30.0, 10.0, 20.0, 1.0),
)
OBS_NAMES = LAUNCHER_OBSERVATION.names  # the observation columns, kept for existing imports


class LauncherState(NamedTuple):
    """A launcher episode's state: the nozzle (angle, rate, hysteresis w: a float tuple, or
    (3, N)), attitude theta (rad), pitch rate q (rad/s), error integral, previous action, and
    the episode's drawn joint (None: the task's own)."""

    nozzle: Any
    theta: Value
    q: Value
    integral: Value
    prev: Value
    joint: RK4Parameters | None = None


def _from_nozzle(name: str, doc: str) -> property:
    """A read-only attribute of the launcher that is its nozzle task's."""
    return property(lambda self: getattr(self.nozzle, name), doc=doc)


@dataclass(frozen=True)
class LauncherTask:
    """A launcher pitch episode: a rigid body around a nozzle task (its joint, episodes, noise,
    faults and scoring, at the attitude loop's 0.02 s with the servo's 10 samples per step) and
    a position servo inside it."""

    nozzle: NozzleTask
    instability: float = 3.0  # mu_a = (normal force slope x CP-CG arm) / pitch inertia, 1/s^2
    effectiveness: float = 12.0  # mu_c = thrust x gimbal-CG arm / pitch inertia, 1/s^2 per rad
    max_deflection: float = math.radians(3.0)  # rad, the action's full scale
    servo: tuple = field(init=False, repr=False)
    body: tuple = field(init=False, repr=False)
    # RK4 steps per servo sample (the torque held over it): the nozzle rule of
    # models.nozzle.integration_substeps for a 2 ms sample, 1 for Table 1's and the identified
    # joints; a plant that needs more than MAX_SUBSTEPS per attitude step is refused
    rk4_substeps: int = field(init=False, repr=False)
    # the compiled batch step's numbers of score and observation, the pitch rate given
    score_config: np.ndarray = field(init=False, repr=False, compare=False)

    observation: ClassVar[Observation] = LAUNCHER_OBSERVATION
    action_names: ClassVar[tuple[str, ...]] = ("nozzle deflection",)
    n_actions: ClassVar[int] = 1
    n_channels: ClassVar[int] = 1

    plant = _from_nozzle("plant", "The nozzle's joint (NozzleParameters).")
    design = _from_nozzle("design", "The bench test whose identified nozzle model designs for it.")
    substeps = _from_nozzle("substeps", "Servo samples per attitude step.")
    horizon = _from_nozzle("horizon", "Steps per episode.")
    dt = _from_nozzle("dt", "The attitude step, s.")
    reference = _from_nozzle("reference", "The kind of reference.")
    noise_std = _from_nozzle("noise_std", "Attitude sensor noise, rad.")
    fault = _from_nozzle("fault", "The fault (on the servo torque or the attitude sensor), or None.")
    fault_step = _from_nozzle("fault_step", "The step after which the fault acts (-1: none).")
    torque_limit = _from_nozzle("torque_limit", "The servo's torque limit, N m.")
    error_weight = _from_nozzle("error_weight", "Reward weight of the squared error (deg).")
    rate_weight = _from_nozzle("rate_weight", "Reward weight of the squared action change.")
    envelope = _from_nozzle("envelope", "The attitude (rad) that ends an episode.")
    step_cost_bound = _from_nozzle("step_cost_bound", "Largest reward loss of one step inside the envelope.")
    draw_size = _from_nozzle("draw_size", "Uniform float32 numbers one episode consumes.")
    plant_draw_size = _from_nozzle("plant_draw_size", "The last uniforms of a draw, which draw the joint.")
    shared_references = _from_nozzle("shared_references", "None: references are drawn per episode.")
    stream_layout = _from_nozzle("stream_layout", "Where a step's noise and reference lie in the draw.")
    rk4_params = _from_nozzle("rk4_params", "The joint's integrator parameters.")

    @classmethod
    def build_launcher(
        cls,
        plant: str | Path | NozzleParameters | NozzleModel = "bouc_wen",
        reference: str = "random_steps",
        reference_amplitude_deg: float = 2.0,
        sensor_noise: float = 1e-4,
        fault: dict | Fault | None = None,
        episode_seconds: float = 10.0,
        instability: float = 3.0,
        effectiveness: float = 12.0,
        plant_spread: float | str | None = None,
        uncertainty_scale: float = 1.0,
    ) -> LauncherTask:
        joint, design = resolve_nozzle(plant)
        nozzle = NozzleTask(
            plant=joint,
            design=design,
            substeps=SERVO_SUBSTEPS,
            **episode_options(
                reference, reference_amplitude_deg, 5.0, sensor_noise, fault, episode_seconds, LAUNCHER_DT
            ),
            dt=LAUNCHER_DT,
            envelope=math.radians(10.0),
            spread=resolve_spread(plant_spread, joint, plant, uncertainty_scale),
        )
        return cls(
            nozzle=nozzle,
            instability=check_number("instability", instability, 0.0, 100.0),
            effectiveness=check_number("effectiveness", effectiveness, 0.0, 1000.0, low_open=True),
        )

    def __post_init__(self) -> None:
        object.__setattr__(self, "servo", nozzle_servo_gains(self.plant))
        h = self.dt / self.substeps
        object.__setattr__(self, "body", body_transition(self.instability, self.effectiveness, h))
        rk4_substeps = max(
            integration_substeps(
                joint,
                h,
                2.0 * self.max_deflection,  # the nozzle's travel: twice the command range, as NozzleTVC's
                self.torque_limit,
                ENV_STEP_RATE,
                max_substeps=MAX_SUBSTEPS // self.substeps,
                sample="servo sample",
            )
            for joint in covered_joints(self.plant, self.nozzle.spread)
        )  # the worst joint the spread can draw sets the count
        object.__setattr__(self, "rk4_substeps", rk4_substeps)
        object.__setattr__(self, "score_config", score_config(self.nozzle, DEG, measured=False))

    @classmethod
    def observation_space(cls) -> gym.spaces.Box:
        return cls.observation.space()

    def episodes(
        self, uniforms: Uniforms, start: int, stop: int, out: Blocks | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The nozzle task's episodes: attitude references (rad) and unit noise of steps [start, stop)."""
        return self.nozzle.episodes(uniforms, start, stop, out)

    def nonfinite_reward(self, t: Any) -> Any:
        """As the nozzle task's :meth:`~ssme_envs.envs.nozzle_task.NozzleTask.nonfinite_reward`."""
        return self.nozzle.nonfinite_reward(t)

    def initial_state(self, n: int | None = None, plants: np.ndarray | None = None) -> LauncherState:
        """At rest on the reference trajectory: floats (``n`` None) or arrays of ``n`` envs; the
        nozzle's joint drawn from ``plants`` as the nozzle task does."""
        joint = self.nozzle.drawn_joint(n, plants)
        if n is None:
            return LauncherState((0.0, 0.0, 0.0), 0.0, 0.0, 0.0, 0.0, joint)
        return LauncherState(np.zeros((3, n)), *(np.zeros(n) for _ in range(4)), joint)

    @property
    def observes_restarts(self) -> bool:
        """As the nozzle task's :attr:`~ssme_envs.envs.nozzle_task.NozzleTask.observes_restarts`."""
        return score_kernel(measured=False) is not None

    def initial_observation(self, ref: np.ndarray, draws: np.ndarray) -> np.ndarray:
        """Observations at reset (7, N) float32 from the first reference and noise rows (1, N)."""
        m = self.nozzle.measure(0.0, np.asarray(draws[0], dtype=np.float64), 0, SYNCED)
        obs = np.zeros((7, m.size), dtype=np.float32)  # rows rounded to float32 as they are set
        obs[0], obs[2], obs[3] = m * DEG, ref[0] * DEG, (ref[0] - m) * DEG
        return obs

    def step(
        self, state: LauncherState, action: Sequence[Value], t: Any, ref: Sequence[Value],
        noise: Sequence[Value], ops: Carrier,
    ) -> tuple[LauncherState, tuple, Value, Any]:  # fmt: skip
        """One attitude step, as :class:`~ssme_envs.envs.task.TrackingTask` says: the nozzle
        command in [-1, 1] of 3 deg; returns (state, the 7 observation values, reward, terminated),
        on arrays as :meth:`NozzleTask.step` returns them."""
        nozzle, theta, q, integral, prev, joint = state
        a, ref = action[0], ref[0]
        drive = self.servo[0] * (a * self.max_deflection)
        fault, gain = self.fault, None
        if fault is not None and fault.kind == "gain_loss":  # times 1.0 before the fault: exact
            gain = ops.where(t > self.fault_step, fault.magnitude, 1.0)
        params = self.rk4_params if joint is None else joint
        nozzle, theta, q = self.plant_step(nozzle, theta, q, drive, gain, params, ops)
        if ops.batched and (kernel := score_kernel(measured=False)) is not None:  # the rest in one pass
            args = (theta, a, prev, t, ref, noise[0], integral, q, nozzle[0], ops.restarting)
            values, reward, terminated = score_observe(kernel, self.score_config, *args)
            return LauncherState(nozzle, theta, q, integral, prev, joint), values, reward, terminated
        m, e, integral, reward, terminated = self.nozzle.score(
            theta, a, prev, t, ref, noise[0], integral, ops
        )
        obs = (m * DEG, q * DEG, ref * DEG, e, integral, nozzle[0] * DEG, a)
        return LauncherState(nozzle, theta, q, integral, a, joint), obs, reward, terminated

    def plant_step(
        self, nozzle: Any, theta: Value, q: Value, drive: Value, gain: Value | None, params: RK4Parameters,
        ops: Carrier,
    ) -> tuple[Any, Value, Value]:  # fmt: skip
        """The plant over one attitude step: the servo's samples of torque ``clip(drive - k_p d -
        k_d d', -lim, lim)`` (times the fault's ``gain``; None: no fault), the joint's RK4 and the
        rigid body, from the nozzle (a float tuple, or (3, N) stepped in place), attitude theta
        (rad) and pitch rate q (rad/s). Returns (nozzle, theta, q). (The bench times it as the
        plant's floor.)"""
        lim = self.torque_limit
        h = self.dt / self.substeps
        rk4_steps = self.rk4_substeps
        rk4_h = h / rk4_steps  # h itself for one step
        kernel = compiled_servo(ops.batched)
        args = (drive, gain, self.servo, lim, self.body, rk4_h, rk4_steps, self.substeps, params)
        if not ops.batched:  # one env: the loop below on floats, without the carrier's calls
            if kernel is not None:
                x, v, w, theta, q = kernel.servo_float(*nozzle, theta, q, *args)
            else:  # the float integrator looked up where integrate looks it up (nozzle_task's)
                x, v, w, theta, q = servo_floats(*nozzle, theta, q, *args, nozzle_task.rk4_floats)
            return (x, v, w), theta, q
        if kernel is not None and (attitude := servo_batch(kernel, nozzle, theta, q, *args)):
            return nozzle, *attitude
        _, k_p, k_d = self.servo
        p00, p01, p10, p11, g0_theta, g0_q, g1_theta, g1_q = self.body
        for _ in range(self.substeps):
            d = nozzle[0]
            torque = ops.clip(drive - k_p * d - k_d * nozzle[1], -lim, lim)
            if gain is not None:
                torque = torque * gain
            # the body's share of the old deflection is taken before the nozzle moves (in place)
            theta_next = p00 * theta + p01 * q + g0_theta * d
            q_next = p10 * theta + p11 * q + g0_q * d
            nozzle = integrate(nozzle, torque, rk4_h, rk4_steps, params, ops)
            d = nozzle[0]
            theta, q = theta_next + g1_theta * d, q_next + g1_q * d
        return nozzle, theta, q

    def render_row(self, state: LauncherState, obs: Sequence[float], ref: Sequence[float]) -> list[float]:
        """The measured attitude (rad), its reference, the nozzle deflection as a fraction of 3 deg."""
        return [obs[0] / DEG, ref[0], state.nozzle[0] / self.max_deflection]


class LauncherPitchEnv(TrackingEnv):
    """Track a pitch attitude command on an aerodynamically unstable launcher with the nozzle.

    Pitch plane, rigid body, small angles: ``theta'' = mu_a theta + mu_c d`` with ``mu_a = 3
    1/s^2`` (centre of pressure ahead of the centre of mass: an unstable pole at 1.7 rad/s, the
    attitude doubles in 0.4 s) and ``mu_c = 12 1/s^2`` per rad of nozzle deflection d. These two
    numbers are illustrative (the order of a launcher near maximum dynamic pressure), not VLS
    data. The nozzle is the NozzleTVC plant (Table 1's Bouc-Wen joint by default) inside a 500 Hz
    position servo designed on its linear stiffness (15 Hz, 0.7 damping, stiffness
    feedforward; torque limit 3e4 N m): the servo does not see the joint's hysteresis, the
    attitude loop does. The body is integrated exactly with the deflection linear between servo
    samples, the nozzle by RK4 over each 2 ms servo sample with the servo's torque held: one RK4
    step for Table 1's and the identified joints, more where NozzleTVC's substep rule (accuracy
    and RK4 stability for the stiffness, damping and hysteresis rates) asks for them at 2 ms. A
    plant that needs more than 1,000 per servo sample (10,000 per attitude step) is refused
    with a ValueError naming the rate. The servo and the body are discrete, exact per sample:
    they add no rate to the RK4 bound.

    ## Action Space
    ``Box(-1, 1, (1,), float32)``: the nozzle deflection command as a fraction of 3 deg. Out-of-
    range actions are clipped; NaN or inf raises ValueError.

    ## Observation Space
    ``Box((7,), float32)``, finite bounds, clipped into them:

    | index | observation | unit | bound |
    |---|---|---|---|
    | 0 | measured attitude (sensor noise ``sensor_noise`` rad) | deg | +-20 |
    | 1 | pitch rate (rate gyro) | deg/s | +-200 |
    | 2 | attitude reference | deg | +-10 |
    | 3 | tracking error (reference - measured) | deg | +-30 |
    | 4 | integral of the error (anti-windup at +-10) | deg s | +-10 |
    | 5 | nozzle deflection | deg | +-20 |
    | 6 | previous action | - | +-1 |

    ## Rewards
    ``-0.1 e^2 - 0.1 (a_k - a_(k-1))^2`` with the error in degrees. Leaving the envelope (attitude
    beyond 10 deg: the vehicle is lost) ends the episode with a penalty larger than the worst cost
    of all remaining steps.

    ## Starting State
    At rest on the reference trajectory: zero attitude, rate and nozzle state.

    ## Episode End
    Termination on leaving the envelope; truncation after ``episode_seconds`` (10 s, 500 steps
    of 0.02 s). ``gymnasium.make`` also applies the registered limit of 500 steps: for longer
    episodes pass ``max_episode_steps`` too. ``step`` after either raises
    :class:`~ssme_envs.envs.tracking_env.EpisodeOverError` and ``reset`` takes no options, as in
    ``NozzleTVC-v0``. A step whose state overflows or turns NaN ends the episode with
    ``info == {"nonfinite": True}``, a finite reward and observation, as in ``NozzleTVC-v0``
    (alike in the native vector env and ``SyncVectorEnv``).

    ## Arguments
    plant : "bouc_wen" (default), "linear", "identified", "strong", "strong_linear",
    "strong_identified" (as NozzleTVC's), a nozzle model.json path or a model.
    reference : as NozzleTVC ("random_steps" by default); reference_amplitude_deg (0-5, default
    2). sensor_noise (rad, default 1e-4). fault : ``{"kind": "gain_loss", "time": 5.0,
    "magnitude": 0.5}`` (servo torque) or ``{"kind": "sensor_bias", "time": 5.0, "magnitude":
    0.005}`` (attitude, rad). episode_seconds; instability, effectiveness (mu_a, mu_c in
    1/s^2). render_mode : "human" or "rgb_array".
    plant_spread, uncertainty_scale : the nozzle joint drawn per episode, as NozzleTVC's (the
    servo's gains stay those of the nominal joint; the rigid body is not drawn).
    """

    output_names = ("pitch attitude",)
    display_scale = DEG
    display_units = ("deg", "fraction of 3 deg")
    build_task: Callable[..., LauncherTask] = staticmethod(LauncherTask.build_launcher)

    action_meaning = "the nozzle deflection command"


__all__ = [
    "LAUNCHER_OBSERVATION",
    "OBS_NAMES",
    "LauncherPitchEnv",
    "LauncherState",
    "LauncherTask",
    "body_transition",
    "nozzle_servo_gains",
]
