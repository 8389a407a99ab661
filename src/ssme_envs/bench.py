"""Environment throughput, measured beside gymnasium's own classic-control envs in the same run.

Steps per second of each ssme-envs environment through ``gymnasium.make`` (single) and through
its native vector env at several sizes, with Pendulum-v1 (single) and CartPole-v1's native vector
env measured alongside. Machines are shared and noisy, so the two are timed in alternating
rounds and each rate is the best round's (as ``timeit`` does); the ratios are what to compare.
A round is one whole episode of the measured env (its registered step limit) from its reset, so
the vector rates include the reset of every episode. Each env, the references included, is stepped with
the zero action (our episodes then run to their time limit: the rates time steps) and with
uniform random actions (episodes end early and often: the rates include their resets).

Each native vector row also gives its floor: the plant's arithmetic alone (the plant core of
``models`` on N envs, without references, noise, rewards or observations), timed in the same
alternating rounds (an episode's steps, no reset).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence

import gymnasium as gym
import numpy as np

from ssme_envs.envs import catalogue

ENV_IDS = tuple(catalogue.ENVS)
VECTOR_SIZES = (1, 64, 1024, 4096)
SINGLE_ROUND_STEPS = 2000


ACTIONS = ("zero", "random")
_TABLE = 256  # random actions drawn beforehand and cycled: the draws are not the env's time


def _action_table(space: gym.spaces.Space, kind: str) -> np.ndarray:
    if kind == "zero":
        return np.zeros((1, *space.shape), dtype=space.dtype)
    space.seed(0)
    return np.stack([space.sample() for _ in range(_TABLE)])


def _single_stepper(env_id: str, kind: str = "zero") -> tuple[Callable[[int], float], Callable[[], None]]:
    env = gym.make(env_id)
    env.reset(seed=0)
    table = list(_action_table(env.action_space, kind))

    def run(steps: int) -> float:
        start = time.perf_counter()
        for k in range(steps):
            _, _, terminated, truncated, _ = env.step(table[k % len(table)])
            if terminated or truncated:
                env.reset()
        return time.perf_counter() - start

    return run, env.close


def _vector_stepper(
    env_id: str, num_envs: int, kind: str = "zero"
) -> tuple[Callable[[int], float], Callable[[], None]]:
    env = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point")
    env.reset(seed=0)
    table = list(_action_table(env.action_space, kind)[:16])

    def run(steps: int) -> float:
        start = time.perf_counter()
        env.reset()  # a round is an episode from its reset (not reseeded, as an autoreset)
        for k in range(steps):
            env.step(table[k % len(table)])
        return time.perf_counter() - start

    return run, env.close


def _race(ours: tuple, reference: tuple, steps: int, rounds: int, *others: tuple) -> list[float]:
    """Best seconds per step of ours, the reference and any ``others`` (steppers: run, close)
    over alternating rounds."""
    contestants = (ours, reference, *others)
    times = np.empty((rounds, len(contestants)))
    for r in range(rounds):
        times[r] = [run(steps) for run, _ in contestants]
    for _, close in contestants:
        close()
    return (times.min(axis=0) / steps).tolist()


def plant_floor(env_id: str, num_envs: int, steps: int = 50, rounds: int = 5) -> float:
    """Best seconds per step of the env's plant arithmetic alone on ``num_envs`` envs: the
    plant core the task steps (engine valves and dynamics; the nozzle's RK4 substeps; the
    launcher's servo samples of RK4 and body), at the zero command."""
    run, _ = _floor_stepper(env_id, num_envs)
    return min(run(steps) for _ in range(rounds)) / steps


def _floor_stepper(env_id: str, num_envs: int) -> tuple[Callable[[int], float], Callable[[], None]]:
    """A stepper (run, close) of the plant arithmetic of :func:`plant_floor`."""
    from ssme_envs.envs.engine_task import EngineTask
    from ssme_envs.envs.launcher_pitch import LauncherTask
    from ssme_envs.envs.nozzle_task import integrate
    from ssme_envs.envs.task import SYNCED

    task = catalogue.spec(env_id).build_task()
    n, zero, t = num_envs, np.zeros(num_envs), np.ones(num_envs, dtype=np.int64)
    if isinstance(task, EngineTask):
        plant = task.initial_plant(n)
        nominal = None if task.offsets is None else SYNCED.at(task.offsets, t)

        def step() -> None:
            task.plant_step(plant, zero, zero, t, nominal, SYNCED)

    elif isinstance(task, LauncherTask):
        joint = np.zeros((3, n))

        def step() -> None:
            task.plant_step(joint, zero, zero, zero, None, task.rk4_params, SYNCED)

    else:
        joint, h = np.zeros((3, n)), task.dt / task.substeps

        def step() -> None:
            integrate(joint, zero, h, task.substeps, task.rk4_params, SYNCED)

    def run(steps: int) -> float:
        start = time.perf_counter()
        for _ in range(steps):
            step()
        return time.perf_counter() - start

    return run, lambda: None


def run_benchmark(
    env_ids: Sequence[str] = ENV_IDS,
    sizes: Sequence[int] = VECTOR_SIZES,
    rounds: int = 5,
    progress: Callable[[str], None] | None = None,
    actions: Sequence[str] = ACTIONS,
) -> list[dict[str, float | str]]:
    """Rows {env, mode, actions, num_envs, steps_per_s, reference, reference_steps_per_s, ratio,
    floor_steps_per_s (vector rows; NaN for single), of_floor}; ``actions``: "zero" and/or
    "random"."""
    import ssme_envs  # noqa: F401  (registers the environments)
    from ssme_envs.evaluation import check_distinct

    if rounds < 1:
        raise ValueError(f"rounds must be >= 1, got {rounds}")
    for listed, what in ((env_ids, "env"), (sizes, "size"), (actions, "action kind")):
        check_distinct(listed, what)  # a repeat would be measured again and shown twice
    say = progress or (lambda _: None)
    rows: list[dict[str, float | str]] = []
    for env_id in env_ids:
        episode = gym.spec(env_id).max_episode_steps or 1000
        for kind in actions:
            say(f"{env_id} (single, {kind} actions) beside Pendulum-v1 ...")
            ours, ref = _race(
                _single_stepper(env_id, kind),
                _single_stepper("Pendulum-v1", kind),
                SINGLE_ROUND_STEPS,
                rounds,
            )
            rows.append(_row(env_id, "single", kind, 1, 1.0 / ours, "Pendulum-v1", 1.0 / ref, math.nan))
            for n in sizes:
                say(f"{env_id} native vector, N = {n}, {kind} actions, beside CartPole-v1's ...")
                reference = _vector_stepper("CartPole-v1", n, kind)
                floor_stepper = _floor_stepper(env_id, n)
                ours, ref, floor = _race(
                    _vector_stepper(env_id, n, kind), reference, episode, rounds, floor_stepper
                )
                rows.append(
                    _row(env_id, "vector", kind, n, n / ours, "CartPole-v1 vector", n / ref, n / floor)
                )
    return rows


def _row(
    env_id: str,
    mode: str,
    actions: str,
    n: int,
    rate: float,
    reference: str,
    reference_rate: float,
    floor: float,
) -> dict:
    return {
        "env": env_id,
        "mode": mode,
        "actions": actions,
        "num_envs": n,
        "steps_per_s": rate,
        "reference": reference,
        "reference_steps_per_s": reference_rate,
        "ratio": rate / reference_rate,
        "floor_steps_per_s": floor,
        "of_floor": rate / floor,
    }


def kernels_used() -> str:
    """A sentence naming what ran each compiled step: its kernel, or the reference where none is
    built (or ``SSME_ENVS_NO_KERNEL`` is set)."""
    from ssme_envs.envs import episode_draws, episode_streams, nozzle_compiled
    from ssme_envs.models import engine_step, nozzle_joint

    ran = {"compiled": "compiled kernel", "python": "Python reference"}
    batch = "compiled kernel" if engine_step.has_batch(engine_step.kernel()) else "numpy reference"
    draws = {"compiled": "compiled kernel", "python": "numpy generators (whole episodes)"}
    streams = {"compiled": "compiled cursors", "python": "numpy reference (from whole episodes)"}
    scoring = {"compiled": "compiled kernel", "python": "numpy reference"}
    return (
        f"The nozzle joint ran its {ran[nozzle_joint.KERNEL]}, "
        f"the engine's float step its {ran[engine_step.KERNEL]}, its batch step its {batch}; "
        f"the vector envs' episode draws their {draws[episode_draws.KERNEL]}, the nozzle's and "
        f"launcher's per-step streams their {streams[episode_streams.KERNEL]} and their batch "
        f"scoring its {scoring[nozzle_compiled.KERNEL]}."
    )


def format_table(rows: list[dict[str, float | str]]) -> str:
    """A markdown table of the benchmark rows."""
    lines = [
        "| env | mode | actions | N | steps/s | reference | reference steps/s | ratio | plant floor steps/s "
        "| of the floor |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        floor = "" if math.isnan(r["floor_steps_per_s"]) else f"{r['floor_steps_per_s']:,.0f}"
        of_floor = "" if math.isnan(r["of_floor"]) else f"{r['of_floor']:.0%}"
        lines.append(
            f"| {r['env']} | {r['mode']} | {r['actions']} | {r['num_envs']} | {r['steps_per_s']:,.0f} | "
            f"{r['reference']} | {r['reference_steps_per_s']:,.0f} | {r['ratio']:.2f}x | {floor} | "
            f"{of_floor} |"
        )
    return "\n".join(lines)


__all__ = [
    "ACTIONS",
    "ENV_IDS",
    "VECTOR_SIZES",
    "format_table",
    "kernels_used",
    "plant_floor",
    "run_benchmark",
]
