"""Environment throughput, measured beside gymnasium's own classic-control envs in the same run.

Steps per second of each ssme-envs environment through ``gymnasium.make`` (single) and through
its native vector env at several sizes, with Pendulum-v1 (single) and CartPole-v1's native vector
env measured alongside. Machines are shared and noisy, so the two are timed in alternating
rounds and each rate is the best round's (as ``timeit`` does); the ratios are what to compare.
A round is one whole episode of the measured env (its registered step limit), so the vector
rates include the resets of every episode. Every env, the references included, is stepped with
the zero action: our episodes then run to their time limit, so the rates time steps, not the
resets of episodes cut short (a constant random torque drives the nozzle out of its envelope
within a few steps; what terminations cost depends on the policy).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import gymnasium as gym
import numpy as np

ENV_IDS = (
    "ssme_envs/EngineTracking-v0",
    "ssme_envs/EngineThrottle-v0",
    "ssme_envs/NozzleTVC-v0",
    "ssme_envs/LauncherPitch-v0",
)
VECTOR_SIZES = (1, 64, 1024, 4096)
SINGLE_ROUND_STEPS = 2000


def _single_stepper(env_id: str) -> tuple[Callable[[int], float], Callable[[], None]]:
    env = gym.make(env_id)
    env.reset(seed=0)
    action = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)

    def run(steps: int) -> float:
        start = time.perf_counter()
        for _ in range(steps):
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()
        return time.perf_counter() - start

    return run, env.close


def _vector_stepper(env_id: str, num_envs: int) -> tuple[Callable[[int], float], Callable[[], None]]:
    env = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point")
    env.reset(seed=0)
    actions = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)

    def run(steps: int) -> float:
        start = time.perf_counter()
        for _ in range(steps):
            env.step(actions)
        return time.perf_counter() - start

    return run, env.close


def _race(ours: tuple, reference: tuple, steps: int, rounds: int) -> tuple[float, float]:
    """Best seconds per step of ours and of the reference over alternating rounds."""
    times = np.empty((rounds, 2))
    for r in range(rounds):
        times[r] = reference[0](steps), ours[0](steps)
    ours[1]()
    reference[1]()
    best = times.min(axis=0) / steps
    return best[1], best[0]


def run_benchmark(
    env_ids: Sequence[str] = ENV_IDS,
    sizes: Sequence[int] = VECTOR_SIZES,
    rounds: int = 5,
    progress: Callable[[str], None] | None = None,
) -> list[dict[str, float | str]]:
    """Rows {env, mode, num_envs, steps_per_s, reference, reference_steps_per_s, ratio}."""
    import ssme_envs  # noqa: F401  (registers the environments)

    if rounds < 1:
        raise ValueError(f"rounds must be >= 1, got {rounds}")
    say = progress or (lambda _: None)
    rows: list[dict[str, float | str]] = []
    for env_id in env_ids:
        episode = gym.spec(env_id).max_episode_steps or 1000
        say(f"{env_id} (single) beside Pendulum-v1 ...")
        ours, ref = _race(_single_stepper(env_id), _single_stepper("Pendulum-v1"), SINGLE_ROUND_STEPS, rounds)
        rows.append(_row(env_id, "single", 1, 1.0 / ours, "Pendulum-v1", 1.0 / ref))
        for n in sizes:
            say(f"{env_id} native vector, N = {n}, beside CartPole-v1's ...")
            ours, ref = _race(_vector_stepper(env_id, n), _vector_stepper("CartPole-v1", n), episode, rounds)
            rows.append(_row(env_id, "vector", n, n / ours, "CartPole-v1 vector", n / ref))
    return rows


def _row(env_id: str, mode: str, n: int, rate: float, reference: str, reference_rate: float) -> dict:
    return {
        "env": env_id,
        "mode": mode,
        "num_envs": n,
        "steps_per_s": rate,
        "reference": reference,
        "reference_steps_per_s": reference_rate,
        "ratio": rate / reference_rate,
    }


def format_table(rows: list[dict[str, float | str]]) -> str:
    """A markdown table of the benchmark rows."""
    lines = [
        "| env | mode | N | steps/s | reference | reference steps/s | ratio |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['env']} | {r['mode']} | {r['num_envs']} | {r['steps_per_s']:,.0f} | {r['reference']} | "
            f"{r['reference_steps_per_s']:,.0f} | {r['ratio']:.2f}x |"
        )
    return "\n".join(lines)


__all__ = ["ENV_IDS", "VECTOR_SIZES", "format_table", "run_benchmark"]
