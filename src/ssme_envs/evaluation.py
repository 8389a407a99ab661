"""Evaluation harness: rollouts of any controller over named scenarios, and the metrics engineers read.

A controller is anything with ``reset(seed=..., num_envs=...)`` and ``act(observations)`` on a
batch (the protocol of the ``agents`` package). Each scenario is a set of env options; its
episodes run together in the env's native vector env, each one counted until its first end.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from ssme_envs.envs.inputs import positive_int
from ssme_envs.evaluation_result import ActuatorMetrics, ControllerMetrics, EvaluationResult, OutputMetrics
from ssme_envs.metrics import limit_cycle, saturation_fraction, step_metrics, step_response
from ssme_envs.models.linear import describe
from ssme_envs.robustness import cvar

NOISE_OFF = {"backlash": 5e-4, "stiction": 2e-4, "sensor_noise": 0.0}
LINEAR = {"asymmetric_gains": False, "backlash": 0.0, "stiction": 0.0, "sensor_noise": 0.0}

# name -> env options; the first of each env is its default scenario
SCENARIOS: dict[str, dict[str, dict[str, Any]]] = {
    "ssme_envs/EngineTracking-v0": {
        "pc_step": {"reference": "step", "reference_amplitude": (0.01, 0.0), "truth": NOISE_OFF},
        "mr_step": {"reference": "step", "reference_amplitude": (0.0, 0.01), "truth": NOISE_OFF},
        "both_steps": {"reference": "step", "reference_amplitude": 0.01, "truth": NOISE_OFF},
        "ramp": {"reference": "ramp", "truth": NOISE_OFF},
        "nominal": {"truth": LINEAR},  # random steps on the published linear model
        "valves": {"truth": NOISE_OFF},  # + lambda, backlash, stiction
        "noise": {},  # + sensor noise: the full truth
        "design_plant": {"plant": "identified", "truth": LINEAR},
        "stuck_valve": {"fault": {"kind": "stuck_valve", "time": 4.0, "index": 0}},
        "gain_loss": {"fault": {"kind": "gain_loss", "time": 4.0, "index": 1, "magnitude": 0.5}},
        "sensor_bias": {"fault": {"kind": "sensor_bias", "time": 4.0, "index": 0, "magnitude": 0.002}},
        "nonlinear": {"plant": "nonlinear"},  # the full truth's effects on the nonlinear engine
        "bucket": {"power": 67.0},  # the full truth in the max-q bucket, between the Table I levels
        "nonlinear_bucket": {"plant": "nonlinear", "power": 67.0},
    },
    "ssme_envs/EngineThrottle-v0": {
        "mission": {},
        "mission_noise_off": {"truth": NOISE_OFF},
        "mission_linear": {"truth": LINEAR},
        "mission_nonlinear": {"plant": "nonlinear"},  # scheduled on its own chamber pressure
    },
    "ssme_envs/NozzleTVC-v0": {
        "step": {"reference": "step", "sensor_noise": 0.0},
        "sine_sweep": {"reference": "sine_sweep"},
        "attitude": {"reference": "attitude"},
        "random_steps": {},
        "linear_plant": {"plant": "linear"},  # Table 1's linear row: random steps, no hysteresis
        "sine_sweep_linear": {"reference": "sine_sweep", "plant": "linear"},
        # the strong-hysteresis nozzle (yields within +-3 deg) and its small-signal linear joint
        "sine_sweep_strong": {"reference": "sine_sweep", "plant": "strong"},
        "sine_sweep_strong_linear": {"reference": "sine_sweep", "plant": "strong_linear"},
        "attitude_linear": {"reference": "attitude", "plant": "linear"},
        "gain_loss": {"fault": {"kind": "gain_loss", "time": 2.0, "magnitude": 0.5}},
    },
    "ssme_envs/LauncherPitch-v0": {
        "step": {"reference": "step", "sensor_noise": 0.0},
        "attitude": {"reference": "attitude"},
        "random_steps": {},
        "linear_nozzle": {"plant": "linear"},
        "sensor_bias": {"fault": {"kind": "sensor_bias", "time": 5.0, "magnitude": 0.002}},
    },
}


@dataclass(frozen=True)
class Layout:
    """Where an env's observations hold its outputs, references and errors, and their names."""

    outputs: tuple[str, ...]
    unit: str
    output_columns: tuple[int, ...]
    reference_columns: tuple[int, ...]
    error_columns: tuple[int, ...]
    actuators: tuple[str, ...]


# label in the metrics -> the observation entries (output, reference, error) of each tracked
# output; their columns and unit, and the actuators' names, are read from the catalogue
_ENGINE_OUTPUTS = {"Pc": ("pc_pct", "pc_ref_pct", "pc_err_pct"), "MR": ("mr_pct", "mr_ref_pct", "mr_err_pct")}
TRACKED: dict[str, dict[str, tuple[str, str, str]]] = {
    "ssme_envs/EngineTracking-v0": _ENGINE_OUTPUTS,
    "ssme_envs/EngineThrottle-v0": _ENGINE_OUTPUTS,
    "ssme_envs/NozzleTVC-v0": {"angle": ("angle_deg", "ref_deg", "err_deg")},
    "ssme_envs/LauncherPitch-v0": {"attitude": ("attitude_deg", "ref_deg", "err_deg")},
}


@functools.cache
def layout_of(env_id: str) -> Layout:
    """The observation layout of ``env_id`` from its catalogue entry: the one place evaluation,
    results and reports look it up."""
    from ssme_envs.envs.catalogue import spec

    entry, tracked = spec(check_env_id(env_id)), TRACKED[env_id]
    observation = entry.observation
    output, reference, error = (
        tuple(observation.index(names[k]) for names in tracked.values()) for k in range(3)
    )
    (unit,) = {observation.units[i] for i in output}
    return Layout(tuple(tracked), unit, output, reference, error, tuple(entry.action_names))


class _Layouts(Mapping[str, Layout]):
    """The layout of each env of :data:`SCENARIOS`, read on first use (reading them imports every
    env's task module, which ``import ssme_envs.evaluation`` leaves to the first evaluation)."""

    def __getitem__(self, env_id: str) -> Layout:
        if env_id not in SCENARIOS:
            raise KeyError(env_id)
        return layout_of(env_id)

    def __iter__(self) -> Iterator[str]:
        return iter(SCENARIOS)

    def __len__(self) -> int:
        return len(SCENARIOS)


LAYOUTS: Mapping[str, Layout] = _Layouts()


def scenario_names(env_id: str) -> list[str]:
    check_env_id(env_id)
    return list(SCENARIOS[env_id])


def check_env_id(env_id: str) -> str:
    if env_id not in SCENARIOS:
        raise ValueError(f"unknown env {env_id!r}; choose one of {', '.join(SCENARIOS)}")
    return env_id


def check_scenarios(env_id: str, names: Sequence[str]) -> list[str]:
    """The scenario names, checked against the env's; ValueError listing the valid ones."""
    valid = SCENARIOS[check_env_id(env_id)]
    unknown = [name for name in names if name not in valid]
    if unknown:
        choices = ", ".join(valid)
        raise ValueError(f"unknown scenario {', '.join(unknown)} for {env_id}; choose from {choices}")
    check_distinct(names, "scenario")
    return list(names)


def check_distinct(names: Sequence[Any], what: str) -> None:
    """ValueError naming the first of ``names`` listed twice (its runs would be stored once)."""
    for i, name in enumerate(names):
        if name in names[:i]:  # by equality: unhashable entries are named by their own checks
            raise ValueError(f"{what} {name} is listed twice; list each once")


def make_env(
    env_id: str, scenario: str, num_envs: int, options: Mapping[str, Any] | None = None
) -> gym.vector.VectorEnv:
    """The native vector env of a scenario, with ``options`` (env keyword options) on top of the
    scenario's own."""
    check_scenarios(env_id, [scenario])
    import ssme_envs  # noqa: F401  (registers the environments)

    kwargs = {**SCENARIOS[env_id][scenario], **(options or {})}
    return gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", **kwargs)


@dataclass
class Rollout:
    """Episodes of one controller on one scenario, time-major: obs (T + 1, N, d), requested and
    applied actions (T, N, m), rewards (T, N), alive (T, N) (the step belongs to the first
    episode), dt (s)."""

    obs: np.ndarray
    requested: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    alive: np.ndarray
    dt: float


def rollout(env: gym.vector.VectorEnv, controller: Any, name: str, seed: int = 0) -> Rollout:
    """Run every sub-env of ``env`` for one episode under ``controller`` (reset with ``seed``)."""
    n = env.num_envs
    task = getattr(env, "task", None) or env.unwrapped.task
    obs, _ = env.reset(seed=seed)
    controller.reset(seed=seed, num_envs=n)
    observations, requested, applied, rewards, alive = [obs], [], [], [], []
    running = np.ones(n, dtype=bool)
    for k in range(task.horizon):
        action = np.asarray(controller.act(obs, {}), dtype=np.float64).reshape(n, -1)
        bad = ~np.isfinite(action).all(axis=1)
        if bad.any():
            raise ValueError(
                f"controller {name!r} returned a non-finite action {action[bad][0].tolist()} at step {k} "
                f"(episode {int(np.argmax(bad))})"
            )
        clipped = np.clip(action, -1.0, 1.0)
        obs, reward, terminated, truncated, _ = env.step(clipped.astype(np.float32))
        requested.append(action)
        applied.append(clipped)
        rewards.append(reward)
        alive.append(running.copy())
        observations.append(obs)
        running &= ~(terminated | truncated)
        if not running.any():
            break
    return Rollout(
        np.array(observations),
        np.array(requested),
        np.array(applied),
        np.array(rewards),
        np.array(alive),
        task.dt,
    )


def metrics(run: Rollout, layout: Layout) -> ControllerMetrics:
    """Per-output tracking, step and limit-cycle metrics (over episodes), actuator wear and time
    at the limits (of the applied actions), and the episode cost (minus the return): mean, std,
    CVaR 90 %."""
    alive = run.alive
    steps = alive.sum(axis=0)
    returns = (run.rewards * alive).sum(axis=0)
    costs = -returns
    t = np.arange(1, len(alive) + 1) * run.dt
    # the last 10 % (at least one) of each episode's own steps: an episode that ended early is
    # judged on how it ended, not on the zeros after its end
    tail = np.maximum(1, steps // 10)
    row = np.arange(len(alive))[:, None]
    in_tail = (row >= steps - tail) & (row < steps)
    outputs: dict[str, OutputMetrics] = {}
    step_rows = run.obs[1:]
    references = step_rows[:, :, list(layout.reference_columns)]  # (T, N, outputs)
    for i, name in enumerate(layout.outputs):
        e = np.abs(step_rows[:, :, layout.error_columns[i]]) * alive
        y = step_rows[:, :, layout.output_columns[i]]
        r = run.obs[:, :, layout.reference_columns[i]]
        outputs[name] = OutputMetrics(
            iae=float((e.sum(axis=0) * run.dt).mean()),
            ise=float(((e**2).sum(axis=0) * run.dt).mean()),
            itae=float(((t[:, None] * e).sum(axis=0) * run.dt).mean()),
            steady_state_error=float(((e * in_tail).sum(axis=0) / tail).mean()),
            **step_response(t, y, r, alive),
            **_limit_cycles(step_rows[:, :, layout.error_columns[i]], references, alive, run.dt),
        )
    change = np.diff(run.actions, axis=0, prepend=0.0)
    moving = np.abs(change) > 1e-3
    actuators: dict[str, ActuatorMetrics] = {}
    for j, name in enumerate(layout.actuators):
        # a reversal: a move against the previous move, holds in between not counted
        reversals = [
            np.count_nonzero(np.diff(np.sign(change[moving[:, i, j] & alive[:, i], i, j])))
            for i in range(alive.shape[1])
        ]
        actuators[name] = ActuatorMetrics(
            effort_rms=float(np.sqrt((run.actions[:, :, j] ** 2 * alive).sum() / alive.sum())),
            travel=float((np.abs(change[:, :, j]) * alive).sum(axis=0).mean()),
            reversals=float(np.mean(reversals)),
            time_at_limit=float(saturation_fraction(run.actions[:, :, j], alive).mean()),
        )
    return ControllerMetrics(
        episodes=int(alive.shape[1]),
        return_mean=float(returns.mean()),
        return_std=float(returns.std()),
        cost_mean=float(costs.mean()),
        cost_cvar90=cvar(costs, 0.9),
        terminations=int((steps < len(alive)).sum()),
        outputs=outputs,
        actuators=actuators,
    )


def _limit_cycles(err: np.ndarray, refs: np.ndarray, alive: np.ndarray, dt: float) -> dict[str, float]:
    """The limit-cycle fields of :class:`OutputMetrics` from the error (T, N), the references
    (T, N, k) (a change of any starts a new window) and alive (T, N); NaN where no episode gives
    them."""
    runs = [limit_cycle(err[:, i], alive[:, i], dt, refs[:, i]) for i in range(err.shape[1])]
    tested = [run for run in runs if run.tested]
    cycles = [run for run in tested if run.found]
    nan = float("nan")
    return {
        "limit_cycle_fraction": len(cycles) / len(tested) if tested else nan,
        "limit_cycle_period": float(np.median([c.period for c in cycles])) if cycles else nan,
        "limit_cycle_amplitude": float(np.median([c.amplitude for c in cycles])) if cycles else nan,
        "limit_cycle_longest_period": float(np.median([r.longest_period for r in tested])) if tested else nan,
    }


def check_factories(controllers: Any) -> None:
    """TypeError unless ``controllers`` maps names to factories (callables env -> controller)."""
    if not isinstance(controllers, Mapping):
        raise TypeError(
            "controllers must be a mapping of names to factories env -> controller, "
            f"got {type(controllers).__name__}"
        )
    for name, factory in controllers.items():
        if not isinstance(name, str) or not callable(factory):
            raise TypeError(
                f"controllers: {name!r} must name a factory env -> controller, got {describe(factory)}"
            )


def evaluate(
    env_id: str,
    controllers: Mapping[str, Callable[[Any], Any]],
    scenarios: Sequence[str] | None = None,
    episodes: int = 20,
    seed: int = 0,
    progress: Callable[[str], None] | None = None,
    options: Mapping[str, Any] | None = None,
) -> EvaluationResult:
    """Metrics of every controller on every scenario, with one rollout per pair for plotting.

    Parameters
    ----------
    env_id : str
        A registered env of :data:`SCENARIOS`.
    controllers : Mapping
        Names to factories ``env -> controller`` (a controller is designed on the scenario's env).
    scenarios : sequence of str, optional
        Scenario names (default: all of the env's).
    episodes : int
        Episodes per scenario, run together in the env's native vector env.
    seed : int
        Seed of the first episode; the same for every controller.
    progress : callable, optional
        Receives one line per finished pair.
    options : mapping, optional
        Env options added to every scenario's (e.g. ``{"plant_spread": 0.2}``: each episode on a
        plant of its own, see :mod:`ssme_envs.robustness`).

    Returns
    -------
    EvaluationResult
        ``result[scenario][controller]`` is a :class:`ControllerMetrics`; ``result.rollouts``
        holds the rollouts.
    """
    check_env_id(env_id)
    episodes = positive_int("episodes", episodes)
    check_factories(controllers)
    names = scenario_names(env_id) if scenarios is None else check_scenarios(env_id, scenarios)
    # every scenario's env made and every controller designed on it (a few ms each, designs are
    # cached) before any rollout: what the options rule out fails first, not midway through
    for scenario in names:
        try:
            env = make_env(env_id, scenario, 1, options)
        except ValueError as exc:
            raise ValueError(f"scenario {scenario!r}: {exc}") from None
        try:
            for name, factory in controllers.items():
                try:
                    factory(env)
                except ValueError as exc:
                    raise ValueError(f"{exc} (designing {name} on scenario {scenario!r})") from None
        finally:
            env.close()
    say = progress or (lambda _: None)
    layout = layout_of(env_id)
    result = EvaluationResult(env_id)
    total, done = len(names) * len(controllers), 0
    for scenario in names:
        for name, factory in controllers.items():
            start = time.perf_counter()
            env = make_env(env_id, scenario, episodes, options)
            run = rollout(env, factory(env), name, seed)
            env.close()
            scores = metrics(run, layout)
            result.add(scenario, name, scores, run)
            done += 1
            say(f"[{done}/{total}] {scenario} / {name}: cost {scores.cost_mean:.3f} "
                f"({time.perf_counter() - start:.1f} s)")  # fmt: skip
    return result


__all__ = [
    "LAYOUTS",
    "SCENARIOS",
    "TRACKED",
    "ActuatorMetrics",
    "ControllerMetrics",
    "EvaluationResult",
    "Layout",
    "OutputMetrics",
    "Rollout",
    "check_distinct",
    "check_env_id",
    "check_scenarios",
    "evaluate",
    "layout_of",
    "make_env",
    "metrics",
    "rollout",
    "scenario_names",
    "step_metrics",
]
