"""A fifth env from the task protocol alone: a toy task plus one catalogue entry."""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

import gymnasium as gym
import numpy as np

from ssme_envs.envs import catalogue
from ssme_envs.envs.references import unit_normals
from ssme_envs.envs.task import Blocks, Carrier, Observation, TrackingTask


class ToyState(NamedTuple):
    x: Any
    prev: Any


@dataclass(frozen=True)
class ToyTask:
    """A first-order lag ``x+ = 0.9 x + 0.1 a`` tracking a constant reference drawn per episode."""

    horizon: int = 50
    dt: float = 0.1
    observation: ClassVar[Observation] = Observation(
        ("x", "ref", "err", "prev"), ("-",) * 4, (2.0, 1.0, 3.0, 1.0)
    )
    action_names: ClassVar[tuple[str, ...]] = ("push",)
    n_actions: ClassVar[int] = 1
    n_channels: ClassVar[int] = 1
    shared_references: ClassVar[None] = None

    @classmethod
    def build(cls, episode_steps: int = 50) -> ToyTask:
        return cls(horizon=episode_steps)

    @property
    def draw_size(self) -> int:
        return 2 * ((self.horizon + 2) // 2) + 1  # noise (an even count), then the reference

    def episodes(self, uniforms: np.ndarray, start: int, stop: int, out: Blocks | None = None) -> tuple:
        pairs = self.draw_size - 1
        noise = unit_normals(np.ascontiguousarray(uniforms[:pairs], dtype=np.float32))[start:stop][None]
        refs = np.repeat(uniforms[pairs:].astype(np.float64) - 0.5, stop - start, axis=0)[None]
        if out is not None:  # the vector env's tables
            out[0][...], out[1][...] = refs, noise
        return refs, noise

    plant_draw_size: ClassVar[int] = 0

    def initial_state(self, n: int | None = None, plants: np.ndarray | None = None) -> ToyState:
        return ToyState(0.0, 0.0) if n is None else ToyState(np.zeros(n), np.zeros(n))

    def initial_observation(self, ref: np.ndarray, noise: np.ndarray) -> np.ndarray:
        zeros = np.zeros_like(ref[0])
        return np.stack([zeros, ref[0], ref[0], zeros]).astype(np.float32)

    def step(self, state: ToyState, action: Sequence, t: Any, ref: Sequence, noise: Sequence, ops: Carrier):
        a, r = action[0], ref[0]
        x = 0.9 * state.x + 0.1 * a
        m = x + 0.01 * noise[0]
        e = r - m
        reward = -(e * e) - 0.1 * ((a - state.prev) * (a - state.prev))
        return ToyState(x, a), (m, r, e, a), reward, abs(x) > 1.5

    def nonfinite_reward(self, t: Any) -> None:
        return None

    def render_row(self, state: ToyState, obs: Sequence[float], ref: Sequence[float]) -> list[float]:
        return [obs[0], ref[0], state.prev]


TOY = catalogue.EnvEntry("ssme_envs_test/Toy-v0", f"{__name__}:ToyTask", "build", 50, "none: a toy")


def test_a_toy_task_makes_checked_scalar_and_vector_envs():
    from gymnasium.utils.env_checker import check_env as gym_check
    from stable_baselines3.common.env_checker import check_env as sb3_check

    catalogue.register(TOY)
    try:
        assert isinstance(ToyTask(), TrackingTask)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            env = gym.make(TOY.id)
            gym_check(env.unwrapped, skip_render_check=True)
            sb3_check(env.unwrapped, warn=True)
        native = gym.make_vec(TOY.id, 3, vectorization_mode="vector_entry_point")
        sync = gym.make_vec(TOY.id, 3, vectorization_mode="sync")
        a, b = native.reset(seed=1), sync.reset(seed=1)
        np.testing.assert_array_equal(a[0], b[0])
        rng = np.random.default_rng(0)
        for _ in range(120):  # several episodes, the NEXT_STEP autoresets included
            actions = rng.uniform(-1, 1, (3, 1)).astype(np.float32)
            ours, theirs = native.step(actions), sync.step(actions)
            assert ours[4] == {}  # nothing to report: the toy has no non-finite guard
            for x, y in zip(ours[:4], theirs[:4], strict=True):
                np.testing.assert_array_equal(x, y)
        assert catalogue.spec(TOY.id).observation.names == ("x", "ref", "err", "prev")
        assert catalogue.spec(TOY.id).default_options == {"episode_steps": 50}
    finally:
        catalogue.ENVS.pop(TOY.id, None)
        gym.envs.registration.registry.pop(TOY.id, None)


@dataclass(frozen=True)
class ToyOwnArrays(ToyTask):
    """The toy with an ``episodes`` that leaves ``out`` alone and returns arrays of its own."""

    def episodes(self, uniforms: np.ndarray, start: int, stop: int, out: Blocks | None = None) -> tuple:
        return super().episodes(uniforms, start, stop)


def test_a_task_that_returns_its_own_arrays_is_copied_into_the_tables():
    from ssme_envs.envs.vector import TrackingVectorEnv

    envs = [
        type(task.__name__, (TrackingVectorEnv,), {"build_task": task.build})(num_envs=4)
        for task in (ToyTask, ToyOwnArrays)
    ]
    first = [env.reset(seed=3)[0] for env in envs]
    np.testing.assert_array_equal(*first)
    assert np.abs(first[0][:, 1]).max() > 0  # the references reached the observations
    rng = np.random.default_rng(1)
    for _ in range(80):
        actions = rng.uniform(-1, 1, (4, 1))
        for x, y in zip(*(env.step(actions)[:4] for env in envs), strict=True):
            np.testing.assert_array_equal(x, y)
