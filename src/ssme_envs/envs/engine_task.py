"""The engine tracking task: chamber pressure and mixture ratio on an SSME point model."""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, NamedTuple

import numpy as np

from ssme_envs.envs import engine_compiled
from ssme_envs.envs.engine_models import design_model, env_plant, episode_steps, resolve_plant, resolve_truth
from ssme_envs.envs.engine_nonlinear_plant import NonlinearPlantCore, nonlinear_engine_of, nonlinear_task
from ssme_envs.envs.faults import Fault
from ssme_envs.envs.references import (
    check_reference,
    normal_pairs,
    reference_signals,
    uniforms_needed,
)
from ssme_envs.envs.task import (
    MAX_EPISODE_SECONDS,
    Blocks,
    Carrier,
    Observation,
    Schedule,
    Uniforms,
    Value,
    check_number,
    check_numbers,
    envelope_penalty,
)
from ssme_envs.models import engine_step
from ssme_envs.models.engine import TruthConfig
from ssme_envs.models.engine_nonlinear import NonlinearEngine
from ssme_envs.models.engine_step import (
    StepParameters,
    pair_rows,
    pair_step_reference,
    step_arrays,
)
from ssme_envs.models.linked import LinkedEngineModel
from ssme_envs.models.statespace import AlphaCanonicalModel

ENGINE_OBSERVATION = Observation(
    names=("pc_pct", "mr_pct", "pc_ref_pct", "mr_ref_pct", "pc_err_pct", "mr_err_pct",
           "pc_err_int", "mr_err_int", "prev_opov", "prev_fpov"),
    units=("%", "%", "%", "%", "%", "%", "% s", "% s", "-", "-"),
    high=(50.0, 50.0, 50.0, 50.0, 100.0, 100.0, 100.0, 100.0, 1.0, 1.0),
)  # fmt: skip


class EnginePlant(NamedTuple):
    """The plant's state: x (n states), valve linkage and valve positions (2 each); lists of
    floats for one env, (n, N) and (2, N) arrays for a batch."""

    x: Any
    linkage: Any
    valve: Any


class EngineState(NamedTuple):
    """An engine episode's state: plant, error integrals, previous action (2 each), held command
    (the stuck valve's)."""

    plant: EnginePlant
    integral: tuple[Value, Value]
    prev: tuple[Value, Value]
    held: Value


@dataclass(frozen=True)
class EngineTask:
    """Everything an engine tracking episode needs, shared by the scalar and the vector env."""

    params: StepParameters
    n_states: int
    dt: float
    horizon: int
    action_scale: float
    amplitude: np.ndarray
    reference: str
    noise_std: np.ndarray
    fault: Fault | None
    operating_power: float = 100.0  # %, the power level of the point model
    error_weight: float = 0.1
    rate_weight: float = 0.1
    envelope: float = 0.1  # tracking error (noise-free, normalized) that ends an episode (10 %)
    integral_limit: float = 100.0  # % s, anti-windup bound of the error integrals
    offset_table: np.ndarray | None = field(default=None, repr=False)  # (T + 1, m) added to commands
    # the nonlinear engine as the plant (plant="nonlinear"), or None: the point model
    nonlinear: NonlinearPlantCore | None = field(default=None, repr=False)
    own_plant: AlphaCanonicalModel | None = field(default=None, repr=False)  # plant= a model or file
    # the float core's operands in one tuple (one attribute read a step): pair_rows of K and B,
    # lambda - 1 of each valve, half the backlash, the stiction band
    rows: tuple = field(init=False, repr=False)
    noise_scale: tuple[float, float] = field(init=False, repr=False)  # noise_std as floats
    # noise_std as float64 arrays of one element: the batched step scales the float32 unit draws
    # by them straight into float64 (the products of the exact upcast, without an astype pass;
    # arrays, not numpy scalars, which numpy 1's value-based casting would leave float32)
    noise_scale_arrays: tuple = field(init=False, repr=False)
    offsets: Schedule | None = field(init=False, repr=False)  # offset_table for both carriers
    fault_step: int = field(init=False)  # the step after which the fault acts (-1: none)
    # largest reward loss of one step inside the envelope (errors and valve rates at their bounds)
    step_cost_bound: float = field(init=False)
    # the compiled float step's arguments after the commands and nominal valves (half the
    # backlash, stiction, engine_step.pair_table's table and width), None without the kernel
    kernel_args: tuple | None = field(init=False, repr=False)
    batch_args: engine_compiled.BatchArgs | None = field(init=False, repr=False, compare=False)

    observation: ClassVar[Observation] = ENGINE_OBSERVATION
    action_names: ClassVar[tuple[str, ...]] = ("OPOV", "FPOV")
    n_actions: ClassVar[int] = 2
    n_channels: ClassVar[int] = 2  # Pc, MR
    # the batched step takes the unit noise float32, as drawn (see noise_scale_arrays)
    scales_float32_noise: ClassVar[bool] = True

    @classmethod
    def build(
        cls,
        power: float = 100.0,
        plant: str | Path | AlphaCanonicalModel | NonlinearEngine = "truth",
        truth: TruthConfig | Mapping[str, Any] | None = None,
        reference: str = "random_steps",
        reference_amplitude: float | tuple[float, float] = 0.01,
        fault: Mapping[str, Any] | Fault | None = None,
        episode_seconds: float = 10.0,
        action_scale: float = 0.02,
    ) -> EngineTask:
        power = LinkedEngineModel.check_power(power)
        engine = nonlinear_engine_of(plant)
        if engine is not None:  # the point model's task with the nonlinear engine as its plant
            linear = cls.build(power=power, truth=truth, reference=reference, fault=fault,
                               reference_amplitude=reference_amplitude, episode_seconds=episode_seconds,
                               action_scale=action_scale)  # fmt: skip
            return nonlinear_task(linear, engine, resolve_truth(truth).asymmetric_gains)
        model = env_plant(plant, power)
        config = resolve_truth(truth)
        check_reference(reference)
        amplitude = check_numbers("reference_amplitude", reference_amplitude, 2, 0.0, 0.05)
        episode_seconds = check_number("episode_seconds", episode_seconds, 1.0, MAX_EPISODE_SECONDS)
        action_scale = check_number("action_scale", action_scale, 0.0, 0.2, low_open=True)
        noise = np.array(config.sensor_noise, dtype=float)  # two, checked by resolve_truth
        return cls(
            params=StepParameters.from_model(model, config),
            n_states=model.A.shape[0],
            dt=model.dt,
            horizon=episode_steps(model.dt, episode_seconds),
            action_scale=action_scale,
            amplitude=amplitude,
            reference=reference,
            noise_std=noise,
            fault=Fault.parse(fault, 2, 2),
            operating_power=power,
            # a plant of the user's own is its own "truth" design model
            own_plant=None if isinstance(plant, str) and plant in ("truth", "identified") else model,
        )

    def __post_init__(self) -> None:
        self._derive()
        self._compile()

    def _derive(self) -> None:
        """The fields derived from the others, but the compiled steps' arguments."""
        if self.nonlinear is not None:
            # the nonlinear engine's plant step and start, as instance attributes: the point
            # model's step path keeps its method lookups as they are
            object.__setattr__(self, "advance", self.nonlinear.advance)
            object.__setattr__(self, "initial_plant", self.nonlinear.initial_plant)
        k_rows, b_rows, lam = self.params.floats()
        pairs = pair_rows(self.params.shift_source, k_rows, b_rows)
        object.__setattr__(self, "rows", (pairs, *lam, self.params.half_backlash, self.params.stiction))
        object.__setattr__(self, "noise_scale", tuple(self.noise_std.tolist()))
        object.__setattr__(self, "noise_scale_arrays", tuple(np.full(1, s) for s in self.noise_scale))
        offsets = None if self.offset_table is None else Schedule.of(self.offset_table)
        object.__setattr__(self, "offsets", offsets)
        fault_step = -1 if self.fault is None else self.fault.step(self.dt, self.horizon)
        object.__setattr__(self, "fault_step", fault_step)
        error = 100.0 * (self.envelope + float(self.amplitude.max()) + Fault.sensor_bias(self.fault)) + 50.0
        object.__setattr__(
            self, "step_cost_bound", self.error_weight * 2 * error**2 + self.rate_weight * 2 * 2.0**2
        )

    def kernel_steps(self) -> tuple[list, bool]:
        """What the compiled steps read per step, ``[(lambda - 1 of both valves, pair rows)]``, and
        whether the steps follow a schedule (False: one step's, about zero nominal valves)."""
        pairs, g0, g1 = self.rows[:3]
        return [((g0, g1), pairs)], False

    def _compile(self) -> None:
        """``kernel_args`` and ``batch_args`` from :meth:`kernel_steps` (None without the kernel)."""
        kernel_args, batch_args = engine_compiled.compiled_args(self)
        object.__setattr__(self, "kernel_args", kernel_args)
        object.__setattr__(self, "batch_args", batch_args)

    def design_model(self, source: str = "identified") -> AlphaCanonicalModel:
        """The linear model a controller is designed on: :func:`design_model` at the env's power;
        ``"truth"`` on the nonlinear plant is its linearization about the trim at that power, on a
        plant given as a model (or model.json) that model. ValueError when the design model's
        sample time is not the plant's."""
        if source == "truth" and self.nonlinear is not None:
            return self.nonlinear.engine.linear_model(self.operating_power)
        if source == "truth" and self.own_plant is not None:
            return self.own_plant
        model = design_model(self.operating_power, source)
        # a design at another sample time acts at the wrong rate; a stamp's last bits do not
        if not math.isclose(model.dt, self.dt, rel_tol=1e-9):
            raise ValueError(
                f"the {source} design model has dt {model.dt:.12g} s but the env's plant {self.dt:.12g} s: "
                "design on 'truth' (the plant itself)"
            )
        return model

    @classmethod
    def observation_space(cls) -> Any:
        return cls.observation.space()

    @property
    def shared_references(self) -> np.ndarray | None:
        """References common to every episode, (horizon + 1, 2), or None when drawn per episode."""
        return None

    @property
    def draw_size(self) -> int:
        """Uniform float32 numbers one episode consumes: sensor noise, then the reference's."""
        return 2 * (self.horizon + 1) + uniforms_needed(self.reference, self.horizon + 1, 2, self.dt)

    def episodes(
        self, uniforms: Uniforms, start: int, stop: int, out: Blocks | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The steps [start, stop) of k episodes from their uniform draws, float32 (draw_size, k),
        episode axis last: references (2, stop - start, k) float64 and unit sensor noise (2,
        stop - start, k) float32, scaled by ``noise_std`` at each step. One float32 call to the
        generator per episode keeps the streams independent of how episodes are stepped; the
        steps are computed as episodes reach them, so that a reset costs the same whatever the
        episode's length. The noise of channel c, step s is row c (horizon + 1) + s of the
        Box-Muller normals of the first 2 (horizon + 1) uniforms. Written into ``out`` where
        given (:class:`~ssme_envs.envs.task.TrackingTask`)."""
        length = self.horizon + 1
        refs_out, noise_out = (None, None) if out is None else out
        noise = normal_pairs(uniforms, length, start, stop, noise_out)  # channel 0 cosines, 1 sines
        return self.references(uniforms[2 * length :], start, stop, refs_out), noise

    def references(
        self, uniforms: np.ndarray, start: int, stop: int, out: np.ndarray | None = None
    ) -> np.ndarray:
        """The references of k episodes from their uniforms (m, k): steps [start, stop), (2,
        stop - start, k), written into ``out`` where given."""
        length = self.horizon + 1
        return reference_signals(
            self.reference, uniforms.astype(np.float64), length, self.amplitude, self.dt, start, stop, out
        )

    # The plant: point model with valves (this class) or the linked model (the throttle task).
    @property
    def initial_outputs(self) -> np.ndarray:
        return np.zeros(2)

    def initial_plant(self, n: int | None) -> EnginePlant:
        if n is None:
            return EnginePlant([0.0] * self.n_states, (0.0, 0.0), (0.0, 0.0))
        return EnginePlant(np.zeros((self.n_states, n)), np.zeros((2, n)), np.zeros((2, n)))

    plant_draw_size: ClassVar[int] = 0  # the engine's plant is the same in every episode

    def initial_state(self, n: int | None = None, plants: np.ndarray | None = None) -> EngineState:
        """The state at reset: floats (``n`` None) or arrays of ``n`` envs (``plants``: unused)."""
        if n is None:
            return EngineState(self.initial_plant(n), (0.0, 0.0), (0.0, 0.0), 0.0)
        pair = lambda: (np.zeros(n), np.zeros(n))  # noqa: E731  (fresh arrays: written by column)
        return EngineState(self.initial_plant(n), pair(), pair(), np.zeros(n))

    def plant_step(
        self, plant: EnginePlant, c0: Value, c1: Value, t: Any, nominal: Any, ops: Carrier
    ) -> tuple[EnginePlant, Value, Value]:
        """The plant under the valve commands (c0, c1) of step t - 1 -> t: (plant, Pc, MR).
        ``nominal``: the commands' offsets of the step (the throttle's schedule) or None. (The
        bench times it as the plant's floor; :meth:`step` calls :meth:`advance` with its
        commands as they are.)"""
        return self.advance(plant, np.stack((c0, c1)) if ops.batched else (c0, c1), t, nominal, ops)

    def advance(
        self, plant: EnginePlant, command: Any, t: Any, nominal: Any, ops: Carrier
    ) -> tuple[EnginePlant, Value, Value]:
        """:meth:`plant_step` on the commands of both valves: a (2, N) array, or two floats."""
        if ops.batched:
            if self.batch_args is not None:  # compiled, stepped in place
                plant = engine_compiled.plant_step(self, plant, command, t)
            else:
                plant = EnginePlant(*step_arrays(*plant, command, self.params))
            return plant, plant.x[-2], plant.x[-1]
        x, linkage, valve = plant
        if self.kernel_args is not None:  # the reference's operations, compiled
            kernel = engine_step.kernel()
            x, linkage, valve = kernel.pair_step(x, linkage, valve, *command, 0.0, 0.0, *self.kernel_args, 0)
        else:  # gains about zero: |v - 0| is |v|, bit for bit
            pairs, g0, g1, half, stick = self.rows
            x, linkage, valve = pair_step_reference(
                x, linkage, valve, *command, 0.0, 0.0, half, stick, (g0, g1), pairs
            )
        return EnginePlant(x, linkage, valve), x[-2], x[-1]

    @staticmethod
    def valve_positions(plant: EnginePlant) -> Any:
        return plant.valve

    def step(
        self, state: EngineState, action: Sequence[Value], t: Any, ref: Sequence[Value],
        noise: Sequence[Value], ops: Carrier,
    ) -> tuple[EngineState, tuple, Value, Any]:  # fmt: skip
        """One step, as :class:`~ssme_envs.envs.task.TrackingTask` says: actions in [-1, 1]
        (OPOV, FPOV), the sensor noise in unit draws. Returns (state, the 10 observation values,
        reward, terminated)."""
        if ops.batched and self.batch_args is not None:  # these operations, compiled
            (plant, *rest), values, reward, terminated = engine_compiled.task_step(
                self, state, action, t, ref, noise
            )
            return EngineState(plant, *rest), values, reward, terminated
        plant, integral, prev, held = state
        a0, a1 = action[0], action[1]
        nominal = None
        if ops.batched:  # action is (2, N): one pass makes the commands of both valves
            cmd = action * self.action_scale
            if self.offsets is not None:  # the throttle's nominal valve schedule
                nominal = ops.at(self.offsets, t)
                cmd += nominal
            s0, s1 = self.noise_scale_arrays
        else:
            cmd = [a0 * self.action_scale, a1 * self.action_scale]
            if self.offsets is not None:
                nominal = ops.at(self.offsets, t)
                cmd = [nominal[0] + cmd[0], nominal[1] + cmd[1]]
            s0, s1 = self.noise_scale
        fault = self.fault
        if fault is not None and fault.kind != "sensor_bias":
            i, active = fault.index, t > self.fault_step
            if fault.kind == "stuck_valve":
                held = ops.where(t == self.fault_step + 1, cmd[i], held)
                cmd[i] = ops.where(active, held, cmd[i])
            else:  # gain_loss
                cmd[i] = ops.where(active, cmd[i] * fault.magnitude, cmd[i])
        plant, y0, y1 = self.advance(plant, cmd, t, nominal, ops)
        m = [y0 + noise[0] * s0, y1 + noise[1] * s1]
        if fault is not None and fault.kind == "sensor_bias":
            m[fault.index] = ops.where(t >= self.fault_step, m[fault.index] + fault.magnitude, m[fault.index])
        r0, r1 = ref[0], ref[1]
        e0, e1 = 100.0 * (r0 - m[0]), 100.0 * (r1 - m[1])
        lim = self.integral_limit
        i0 = ops.clip(integral[0] + e0 * self.dt, -lim, lim)
        i1 = ops.clip(integral[1] + e1 * self.dt, -lim, lim)
        d0, d1 = a0 - prev[0], a1 - prev[1]
        reward = -self.error_weight * (e0 * e0 + e1 * e1) - self.rate_weight * (d0 * d0 + d1 * d1)
        terminated = (abs(y0 - r0) > self.envelope) | (abs(y1 - r1) > self.envelope)
        if ops.any(terminated):  # the penalty's passes only on the (rare) steps that need them
            reward = ops.charge(reward, terminated, functools.partial(envelope_penalty, self), t)
        obs = (100.0 * m[0], 100.0 * m[1], 100.0 * r0, 100.0 * r1, e0, e1, i0, i1, a0, a1)
        return EngineState(plant, (i0, i1), (a0, a1), held), obs, reward, terminated

    def initial_observation(self, ref: np.ndarray, draws: np.ndarray) -> np.ndarray:
        """Observations at reset (10, N) float32 from the references and unit noise draws of
        step 0, (2, N) each."""
        m = self.initial_outputs[:, None] + draws * self.noise_std[:, None]
        fault = self.fault
        if fault is not None and fault.kind == "sensor_bias" and self.fault_step == 0:
            m[fault.index] = m[fault.index] + fault.magnitude
        zeros = np.zeros_like(m)
        obs = np.concatenate([100.0 * m, 100.0 * ref, 100.0 * (ref - m), zeros, zeros], axis=0)
        return obs.astype(np.float32)

    def nonfinite_reward(self, t: Any) -> None:
        """None: an engine step's values are passed on as they are (unstable plants are refused)."""
        return None

    def render_row(self, state: EngineState, obs: Sequence[float], ref: Sequence[float]) -> list[float]:
        """Measured Pc and MR, their references, the valve positions (normalized)."""
        valve = self.valve_positions(state.plant)
        return [obs[0] / 100.0, obs[1] / 100.0, *ref, valve[0], valve[1]]


__all__ = [
    "ENGINE_OBSERVATION",
    "EnginePlant",
    "EngineState",
    "EngineTask",
    "design_model",
    "resolve_plant",
    "resolve_truth",
]
