"""Environment throughput, measured beside gymnasium's own classic-control envs in the same run.

Steps per second of each ssme-envs environment through ``gymnasium.make`` (single) and through
its native vector env at several sizes, with Pendulum-v1 (single) and CartPole-v1's native vector
env measured alongside; machines are shared and noisy, so the ratios are what to compare.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import gymnasium as gym

ENV_IDS = ("ssme_envs/EngineTracking-v0", "ssme_envs/EngineThrottle-v0")
VECTOR_SIZES = (1, 64, 1024, 4096)


def _single_rate(env_id: str, seconds: float) -> float:
    env = gym.make(env_id)
    env.reset(seed=0)
    action = env.action_space.sample()
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        for _ in range(500):
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()
        steps += 500
    rate = steps / (time.perf_counter() - start)
    env.close()
    return rate


def _vector_rate(env_id: str, num_envs: int, seconds: float) -> float:
    env = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point")
    env.reset(seed=0)
    actions = env.action_space.sample()
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        for _ in range(20):
            env.step(actions)
        steps += 20 * num_envs
    rate = steps / (time.perf_counter() - start)
    env.close()
    return rate


def run_benchmark(
    env_ids: Sequence[str] = ENV_IDS,
    sizes: Sequence[int] = VECTOR_SIZES,
    seconds: float = 2.0,
    progress: Callable[[str], None] | None = None,
) -> list[dict[str, float | str]]:
    """Rows {env, mode, num_envs, steps_per_s, reference, reference_steps_per_s, ratio}."""
    import ssme_envs  # noqa: F401  (registers the environments)

    say = progress or (lambda _: None)
    rows: list[dict[str, float | str]] = []
    say("Pendulum-v1 (single) ...")
    pendulum = _single_rate("Pendulum-v1", seconds)
    cartpole = {}
    for n in sizes:
        say(f"CartPole-v1 native vector, N = {n} ...")
        cartpole[n] = _vector_rate("CartPole-v1", n, seconds)
    for env_id in env_ids:
        say(f"{env_id} (single) ...")
        rate = _single_rate(env_id, seconds)
        rows.append(_row(env_id, "single", 1, rate, "Pendulum-v1", pendulum))
        for n in sizes:
            say(f"{env_id} native vector, N = {n} ...")
            rows.append(
                _row(env_id, "vector", n, _vector_rate(env_id, n, seconds), "CartPole-v1 vector", cartpole[n])
            )
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
