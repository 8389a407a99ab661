"""Chamber pressure and mixture ratio tracking at one SSME power level."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from ssme_envs.envs.references import (
    Fault,
    check_reference,
    reference_signals,
    uniforms_needed,
    unit_normals,
)
from ssme_envs.envs.tracking_env import TrackingEnv
from ssme_envs.models.engine import (
    POWER_LEVELS,
    StepParameters,
    TruthConfig,
    check_stable_plant,
    identified_model,
    output_coupling,
    step_arrays,
    step_floats,
)
from ssme_envs.models.linked import LinkedEngineModel
from ssme_envs.models.statespace import AlphaCanonicalModel

OBS_NAMES = (
    "pc_pct", "mr_pct", "pc_ref_pct", "mr_ref_pct", "pc_err_pct", "mr_err_pct",
    "pc_err_int", "mr_err_int", "prev_opov", "prev_fpov",
)  # fmt: skip


def resolve_truth(truth: TruthConfig | Mapping[str, Any] | None) -> TruthConfig:
    """A TruthConfig from one, from a dict of its fields, or the default."""
    if truth is None:
        return TruthConfig()
    if isinstance(truth, TruthConfig):
        return truth
    if isinstance(truth, Mapping):
        unknown = sorted(set(truth) - set(TruthConfig.__dataclass_fields__))
        if unknown:
            raise ValueError(f"truth: unknown option(s) {', '.join(unknown)}")
        return TruthConfig(**truth)
    raise ValueError(f"truth must be a TruthConfig or a dict, got {type(truth).__name__}")


def resolve_plant(plant: str | Path | AlphaCanonicalModel, power: float) -> AlphaCanonicalModel:
    """The engine model behind an environment.

    ``"truth"``: the linked published model at ``power`` (Table I itself at 70-100 %);
    ``"identified"``: the packaged design model identified at ``power`` (70, 80, 90, 100, 110 %);
    a path to an engine model.json; or a model object.
    """
    if isinstance(plant, AlphaCanonicalModel):
        return plant
    if plant == "truth":
        return LinkedEngineModel().local_model(power)
    if plant == "identified":
        if power not in POWER_LEVELS:
            raise ValueError(f"plant='identified' exists at power {list(POWER_LEVELS)} %, got {power!r}")
        return identified_model(int(power))
    if isinstance(plant, str | Path) and str(plant).endswith(".json"):
        return AlphaCanonicalModel.load(plant)
    raise ValueError(f"plant must be 'truth', 'identified', a model.json path or a model, got {plant!r}")


def design_model(power: float, source: str = "identified") -> AlphaCanonicalModel:
    """The linear engine model a controller is designed on at ``power`` % (lambda and the valve
    effects left out): ``"identified"``, the packaged design model identified at the Table I
    level nearest to ``power``, or ``"truth"``, the published (linked) model at ``power``."""
    if source == "truth":
        return LinkedEngineModel().local_model(power)
    if source == "identified":
        return identified_model(int(min(POWER_LEVELS, key=lambda level: abs(level - power))))
    raise ValueError(f"design model source must be 'identified' or 'truth', got {source!r}")


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
    rows: tuple = field(init=False, repr=False)  # K, B, lambda - 1 as floats, for the scalar step
    noise_scale: tuple = field(init=False, repr=False)  # noise_std as floats, for the scalar step
    offset_table: np.ndarray | None = field(default=None, repr=False)  # (T + 1, m) added to commands
    command_offsets: list | None = field(init=False, repr=False)  # offset_table as floats
    offset_schedule: np.ndarray | None = field(init=False, repr=False)  # offset_table, (m, T + 1)
    fault_step: int = field(init=False)  # the step after which the fault acts (-1: none)
    # largest reward loss of one step inside the envelope (errors and valve rates at their bounds)
    step_cost_bound: float = field(init=False)

    @classmethod
    def build(
        cls,
        power: float = 100.0,
        plant: str | Path | AlphaCanonicalModel = "truth",
        truth: TruthConfig | Mapping[str, Any] | None = None,
        reference: str = "random_steps",
        reference_amplitude: float | tuple[float, float] = 0.01,
        fault: Mapping[str, Any] | Fault | None = None,
        episode_seconds: float = 10.0,
        action_scale: float = 0.02,
    ) -> EngineTask:
        power = LinkedEngineModel.check_power(power)
        model = resolve_plant(plant, power)
        if model.n_inputs != 2 or model.n_outputs != 2:
            raise ValueError(
                "plant must have 2 inputs (OPOV, FPOV) and 2 outputs (Pc, MR), "
                f"got {model.n_inputs} and {model.n_outputs}"
            )
        if output_coupling(model) is not None:
            raise ValueError(
                "plant couples its outputs (C = H [0 I] with H != I, indices "
                f"{list(model.observability_indices)}): the engine environments step models whose "
                "outputs are their last two states; identify with --indices 2,2"
            )
        check_stable_plant(model)
        config = resolve_truth(truth)
        check_reference(reference)
        try:
            amplitude = np.broadcast_to(np.asarray(reference_amplitude, dtype=float), (2,)).copy()
        except (TypeError, ValueError):
            raise ValueError(
                f"reference_amplitude must be one number or two, got {reference_amplitude!r}"
            ) from None
        if not np.all(np.isfinite(amplitude)) or np.any(amplitude < 0) or np.any(amplitude > 0.05):
            raise ValueError(
                f"reference_amplitude must be within 0-0.05 (normalized), got {reference_amplitude!r}"
            )
        if not (isinstance(episode_seconds, int | float) and 1.0 <= episode_seconds <= 3600.0):
            raise ValueError(f"episode_seconds must be within 1-3600 s, got {episode_seconds!r}")
        if not (isinstance(action_scale, int | float) and 0 < action_scale <= 0.2):
            raise ValueError(
                f"action_scale must be within (0, 0.2] normalized valve travel, got {action_scale!r}"
            )
        try:
            noise = np.broadcast_to(np.atleast_1d(np.asarray(config.sensor_noise, dtype=float)), (2,)).copy()
        except ValueError:
            raise ValueError(
                f"truth sensor_noise must be one number or two, got {config.sensor_noise!r}"
            ) from None
        return cls(
            params=StepParameters.from_model(model, config),
            n_states=model.A.shape[0],
            dt=model.dt,
            horizon=round(episode_seconds / model.dt),
            action_scale=float(action_scale),
            amplitude=amplitude,
            reference=reference,
            noise_std=noise,
            fault=Fault.parse(fault, 2, 2),
            operating_power=power,
        )

    def __post_init__(self) -> None:
        object.__setattr__(self, "rows", self.params.floats())
        object.__setattr__(self, "noise_scale", tuple(self.noise_std.tolist()))
        offsets = None if self.offset_table is None else self.offset_table.tolist()
        object.__setattr__(self, "command_offsets", offsets)
        schedule = None if self.offset_table is None else time_last(self.offset_table)
        object.__setattr__(self, "offset_schedule", schedule)
        object.__setattr__(
            self, "fault_step", round(self.fault.time / self.dt) if self.fault is not None else -1
        )
        if self.fault is not None and self.fault_step >= self.horizon:
            raise ValueError(
                f"fault time {self.fault.time:g} s is beyond the episode ({self.horizon * self.dt:g} s)"
            )
        bias = (
            abs(self.fault.magnitude) if self.fault is not None and self.fault.kind == "sensor_bias" else 0.0
        )
        error = 100.0 * (self.envelope + float(self.amplitude.max()) + bias) + 50.0
        object.__setattr__(
            self, "step_cost_bound", self.error_weight * 2 * error**2 + self.rate_weight * 2 * 2.0**2
        )

    n_actions = 2  # OPOV, FPOV
    n_channels = 2  # Pc, MR

    def design_model(self, source: str = "identified") -> AlphaCanonicalModel:
        """The linear model a controller is designed on: :func:`design_model` at the env's power."""
        return design_model(self.operating_power, source)

    @staticmethod
    def observation_space() -> gym.spaces.Box:
        return observation_space()

    def zero_state(self, n: int) -> list:
        """[plant state, error integrals, previous actions, held command] of n envs at reset."""
        return [self.initial_plant_arrays(n), np.zeros((2, n)), np.zeros((2, n)), np.zeros(n)]

    def initial_observation(self, ref: np.ndarray, draws: np.ndarray) -> np.ndarray:
        return initial_observation(self, ref, draws)

    def batch_step(self, *args: Any) -> tuple:
        return batch_step(self, *args)

    @property
    def shared_references(self) -> np.ndarray | None:
        """References common to every episode, (horizon + 1, 2), or None when drawn per episode."""
        return None

    # The plant: point model with valves (this class) or the linked model (the throttle task).
    @property
    def initial_outputs(self) -> np.ndarray:
        return np.zeros(2)

    def initial_plant_floats(self) -> list:
        return [[0.0] * self.n_states, [0.0, 0.0], [0.0, 0.0]]

    def initial_plant_arrays(self, n: int) -> list:
        return [np.zeros((self.n_states, n)), np.zeros((2, n)), np.zeros((2, n))]

    # ``nominal``: the command offsets of this step (the throttle's valve schedule) or None
    def plant_floats(self, plant: list, cmd: list, t: int, nominal: list | None) -> tuple[list, float, float]:
        x, linkage, valve = step_floats(*plant, cmd, self.params, self.rows)
        return [x, linkage, valve], x[-2], x[-1]

    def plant_arrays(
        self, plant: list, cmd: np.ndarray, t: np.ndarray, synced: bool, nominal: np.ndarray | None
    ) -> tuple[list, np.ndarray]:
        x, linkage, valve = step_arrays(*plant, cmd, self.params)
        return [x, linkage, valve], x[x.shape[0] - 2 :]

    @staticmethod
    def valve_positions(plant: list) -> list:
        return plant[-1]

    @property
    def draw_size(self) -> int:
        """Uniform float32 numbers one episode consumes: sensor noise, then the reference's."""
        return 2 * (self.horizon + 1) + uniforms_needed(self.reference, self.horizon + 1, 2, self.dt)

    def episodes(
        self, uniforms: np.ndarray, noise_out: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """References and sensor noise of k episodes from their uniform draws, float32 of shape
        (draw_size, k), episode axis last: references (2, horizon + 1, k) float64 and unit noise
        (2, horizon + 1, k) float32, scaled by ``noise_std`` at each step. One float32 call to
        the generator per episode keeps resets cheap (the vector env resets thousands at once),
        and an episode computed alone equals the same episode in a batch. ``noise_out``: an
        array to write the noise into."""
        length, k = self.horizon + 1, uniforms.shape[1]
        uniforms = np.ascontiguousarray(uniforms, dtype=np.float32)
        out = None if noise_out is None else noise_out.reshape(2 * length, k)
        noise = unit_normals(uniforms[: 2 * length], out).reshape(2, length, k)
        return self.references(uniforms[2 * length :]), noise

    def references(self, uniforms: np.ndarray) -> np.ndarray:
        """The references (2, horizon + 1, k) of k episodes from their uniforms (m, k)."""
        return reference_signals(
            self.reference, uniforms.astype(np.float64), self.horizon + 1, self.amplitude, self.dt
        )


# The environment step exists twice, like the engine step it calls: on floats for the scalar
# env and on (N, .) arrays for the vector env, with the same operations in the same order so that
# both give the same bits (tested against gymnasium's SyncVectorEnv).


def scalar_step(task: EngineTask, state: list, a0: float, a1: float, t: int, ref: list, noise: list):
    """One env, one step. ``state`` = [plant state, error integrals, previous action, held
    command]; ``t`` the step index after this step; ``ref``, ``noise`` the episode values at ``t``
    (noise as unit draws). Returns (state, observation list, reward, terminated)."""
    plant, integral, prev, held = state
    cmd = [a0 * task.action_scale, a1 * task.action_scale]
    nominal = None
    if task.command_offsets is not None:  # the throttle's nominal valve schedule
        nominal = task.command_offsets[t - 1]
        cmd = [nominal[0] + cmd[0], nominal[1] + cmd[1]]
    fault = task.fault
    if fault is not None and t > task.fault_step:
        i = fault.index
        if fault.kind == "stuck_valve":
            if t == task.fault_step + 1:
                held = cmd[i]
            cmd[i] = held
        elif fault.kind == "gain_loss":
            cmd[i] = cmd[i] * fault.magnitude
    plant, y0, y1 = task.plant_floats(plant, cmd, t, nominal)
    s0, s1 = task.noise_scale
    m0, m1 = y0 + noise[0] * s0, y1 + noise[1] * s1
    if fault is not None and fault.kind == "sensor_bias" and t >= task.fault_step:
        if fault.index == 0:
            m0 = m0 + fault.magnitude
        else:
            m1 = m1 + fault.magnitude
    e0, e1 = 100.0 * (ref[0] - m0), 100.0 * (ref[1] - m1)
    lim = task.integral_limit
    i0 = min(max(integral[0] + e0 * task.dt, -lim), lim)
    i1 = min(max(integral[1] + e1 * task.dt, -lim), lim)
    d0, d1 = a0 - prev[0], a1 - prev[1]
    reward = -task.error_weight * (e0 * e0 + e1 * e1) - task.rate_weight * (d0 * d0 + d1 * d1)
    terminated = abs(y0 - ref[0]) > task.envelope or abs(y1 - ref[1]) > task.envelope
    if terminated:
        reward = reward - task.step_cost_bound * (task.horizon - t + 1)
    obs = [100.0 * m0, 100.0 * m1, 100.0 * ref[0], 100.0 * ref[1], e0, e1, i0, i1, a0, a1]
    return [plant, [i0, i1], [a0, a1], held], obs, reward, terminated


def time_last(table: np.ndarray) -> np.ndarray:
    """A per-step table (T + 1, ...) as a schedule (..., T + 1): each entry's steps contiguous,
    so that gathering every env's step is one cache-friendly ``take``."""
    return np.ascontiguousarray(np.moveaxis(table, 0, -1))


def table_rows(schedule: np.ndarray, t: np.ndarray, synced: bool) -> np.ndarray:
    """The entries of a schedule (..., T + 1) that act on the step t - 1 -> t, batch axis last:
    (..., 1) when every env is at the same step, else (..., N)."""
    if synced:
        return schedule[..., t[0] - 1, None]
    return np.take(schedule, t - 1, axis=-1)


def batch_step(
    task: EngineTask,
    state: list,
    acts: np.ndarray,
    t: np.ndarray,
    ref: np.ndarray,
    noise: np.ndarray,
    synced: bool,
):
    """N envs, one step, as :func:`scalar_step` on state-major arrays: acts (2, N), ref (2, N)
    or (2, 1), noise (2, N), t (N,); ``synced`` when every env is at the same step. Returns
    (state, observations (N, 10) float32 before clipping, rewards (N,), terminated (N,))."""
    plant, previous_integral, prev, held = state
    cmd = acts * task.action_scale
    nominal = None
    if task.offset_schedule is not None:
        nominal = table_rows(task.offset_schedule, t, synced)
        cmd += nominal
    fault = task.fault
    if fault is not None:
        i, active = fault.index, t > task.fault_step
        if fault.kind == "stuck_valve":
            held = np.where(t == task.fault_step + 1, cmd[i], held)
            cmd[i] = np.where(active, held, cmd[i])
        elif fault.kind == "gain_loss":
            cmd[i] = np.where(active, cmd[i] * fault.magnitude, cmd[i])
    plant, y = task.plant_arrays(plant, cmd, t, synced, nominal)
    n = acts.shape[1]
    obs = np.empty((10, n))  # rows as in the observation table, filled in place
    m = obs[0:2]
    np.multiply(noise, task.noise_std[:, None], out=m)
    m += y
    if fault is not None and fault.kind == "sensor_bias":
        m[fault.index] = np.where(t >= task.fault_step, m[fault.index] + fault.magnitude, m[fault.index])
    e = np.subtract(ref, m, out=obs[4:6])
    e *= 100.0
    integral = e * task.dt
    integral += previous_integral
    np.maximum(integral, -task.integral_limit, out=integral)
    np.minimum(integral, task.integral_limit, out=integral)
    d = acts - prev
    e2, d2 = e * e, np.multiply(d, d, out=d)
    reward = (e2[0] + e2[1]) * -task.error_weight
    reward -= (d2[0] + d2[1]) * task.rate_weight
    miss = np.subtract(y, ref, out=e2)
    np.abs(miss, out=miss)
    terminated = np.maximum(miss[0], miss[1]) > task.envelope
    if terminated.any():
        reward = np.where(terminated, reward - task.step_cost_bound * (task.horizon - t + 1), reward)
    m *= 100.0
    np.multiply(ref, 100.0, out=obs[2:4])
    obs[6:8] = integral
    obs[8:10] = acts
    return [plant, integral, acts, held], obs.T.astype(np.float32), reward, terminated


def initial_observation(task: EngineTask, ref: np.ndarray, draws: np.ndarray) -> np.ndarray:
    """Observations at reset (10, N) float32 from the references and unit noise draws of step 0,
    (2, N) each."""
    m = task.initial_outputs[:, None] + draws * task.noise_std[:, None]
    fault = task.fault
    if fault is not None and fault.kind == "sensor_bias" and task.fault_step == 0:
        m[fault.index] = m[fault.index] + fault.magnitude
    zeros = np.zeros_like(m)
    obs = np.concatenate([100.0 * m, 100.0 * ref, 100.0 * (ref - m), zeros, zeros], axis=0)
    return obs.astype(np.float32)


def observation_space() -> gym.spaces.Box:
    high = np.array([50, 50, 50, 50, 100, 100, 100, 100, 1, 1], dtype=np.float32)
    return gym.spaces.Box(-high, high, dtype=np.float32)


def check_action_values(a0: float, a1: float) -> None:
    if not (math.isfinite(a0) and math.isfinite(a1)):
        raise ValueError(f"action must be finite, got {[a0, a1]} (NaN or inf)")


class EngineTrackingEnv(TrackingEnv):
    """Track chamber pressure (Pc) and mixture ratio (MR) with the OPOV and FPOV valves.

    The plant is an SSME point model (NASA TM-104422) at one power level, 0.04 s per step: by
    default the truth (the linked published model at ``power`` with the lambda gains of eq 36,
    valve backlash and stiction, sensor noise), or an identified design model, or any engine
    model.json. Quantities are deviations from the operating point; percentages are of the
    100 % point values (d Pc = 0.01 is 1 %).

    ## Action Space
    ``Box(-1, 1, (2,), float32)``: OPOV and FPOV valve commands; the valve deviation is
    ``action * action_scale`` (default 0.02 normalized valve travel). Out-of-range actions are
    clipped; NaN or inf raises ValueError.

    ## Observation Space
    ``Box((10,), float32)``, finite bounds, clipped into them:

    | index | observation | unit | bound |
    |---|---|---|---|
    | 0, 1 | measured Pc, MR deviation | % | +-50 |
    | 2, 3 | Pc, MR reference | % | +-50 |
    | 4, 5 | tracking errors (reference - measured) | % | +-100 |
    | 6, 7 | integrals of the errors (anti-windup at +-100) | % s | +-100 |
    | 8, 9 | previous action | - | +-1 |

    ## Rewards
    ``-0.1 (e_pc^2 + e_mr^2) - 0.1 |a_k - a_(k-1)|^2`` with errors in %: about -0.1 per step
    for 1 % errors. Leaving the envelope (a noise-free Pc or MR tracking error above 10 %) ends the
    episode with a penalty larger than the worst cost of all remaining steps, so ending early
    never pays.

    ## Starting State
    The operating point (zero deviations, valves at their nominal positions).

    ## Episode End
    Termination on leaving the envelope; truncation after ``episode_seconds`` (10 s, 250 steps).
    ``gymnasium.make`` also applies the registered limit of 250 steps: for longer episodes pass
    ``max_episode_steps`` too. ``step`` after ``terminated`` or ``truncated`` (or before the first
    ``reset``) raises :class:`~ssme_envs.envs.tracking_env.EpisodeOverError` (a ``ValueError``
    and an ``AssertionError``, as gymnasium's ``SyncVectorEnv`` refuses it in DISABLED autoreset
    mode): call ``reset``. (gymnasium's ``TimeLimit`` wrapper does not check: behind a limit
    shorter than the episode the env steps on.) ``reset`` takes no options: ``options`` must be
    None or ``{}``, else TypeError (not a dict) or ValueError (naming the unknown keys).

    ## Arguments
    power : 65-109 %, default 100. plant : "truth" (default), "identified" (at 70, 80, 90, 100 %), a
    model.json path or a model. truth : TruthConfig or dict (asymmetric_gains, backlash,
    stiction, sensor_noise), the effects added to the plant. reference : "random_steps"
    (default), "step", "ramp", "prbs", "sine_sweep", "attitude", "zero", "mixed" (each episode
    one of random_steps, step, ramp, sine_sweep, attitude); reference_amplitude (normalized,
    default 0.01).
    fault : e.g. ``{"kind": "stuck_valve", "time": 4.0, "index": 0}``, ``{"kind": "sensor_bias",
    "time": 4.0, "index": 0, "magnitude": 0.005}``, ``{"kind": "gain_loss", "time": 4.0,
    "index": 1, "magnitude": 0.5}``. episode_seconds, action_scale. render_mode : "human" or
    "rgb_array".
    """

    output_names = ("Pc", "MR")
    actuator_names = ("OPOV", "FPOV")
    build_task = staticmethod(EngineTask.build)

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        refs, noise, obs = self._draw_episode(seed, options)
        self._refs = refs.T.tolist()
        self._noise = noise.T.astype(np.float64).tolist()
        self._state = [self.task.initial_plant_floats(), [0.0, 0.0], [0.0, 0.0], 0.0]
        if self.render_mode:
            valve = self.task.valve_positions(self._state[0])
            self._history = [[obs[0] / 100.0, obs[1] / 100.0, *self._refs[0], valve[0], valve[1]]]
        return obs, {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        try:
            if len(action) != 2:
                raise ValueError
            a0, a1 = float(action[0]), float(action[1])
        except (TypeError, ValueError, IndexError):
            raise ValueError(f"action must be 2 numbers (OPOV, FPOV), got {action!r}") from None
        check_action_values(a0, a1)
        self._check_running()
        a0, a1 = min(max(a0, -1.0), 1.0), min(max(a1, -1.0), 1.0)
        t = self._t + 1
        self._state, obs, reward, terminated = scalar_step(
            self.task, self._state, a0, a1, t, self._refs[t], self._noise[t]
        )
        self._t = t
        if self.render_mode:
            valve = self.task.valve_positions(self._state[0])
            self._history.append([obs[0] / 100.0, obs[1] / 100.0, *self._refs[t], valve[0], valve[1]])
            if self.render_mode == "human":
                self.render()
        out = np.array(obs, dtype=np.float32)
        np.minimum(np.maximum(out, self._low, out=out), self._high, out=out)  # np.clip, without its overhead
        truncated = t >= self.task.horizon
        self._ended = "terminated" if terminated else "truncated" if truncated else ""
        return out, reward, terminated, truncated, {}


__all__ = ["EngineTask", "EngineTrackingEnv", "batch_step", "initial_observation", "scalar_step"]
