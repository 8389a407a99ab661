"""The nonlinear engine truth as the engine envs' plant (``plant="nonlinear"``).

The envs' step is held to the model's own simulator (``simulate_nonlinear`` and
``NonlinearEngine.step``, einsum arithmetic the env does not use), to a finite-difference
Jacobian for the truth design model, and to the paper's operating points (``y_eq(P) = (P/100 - 1,
0)``); scalar env == native vector env == SyncVectorEnv bit for bit, as for the default plant.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from conftest import sync_equal
from gymnasium.vector import AutoresetMode

import ssme_envs  # noqa: F401  (registers the environments)
from ssme_envs.envs.task import FLOATS
from ssme_envs.models import NonlinearEngine, TruthConfig, published_model, simulate_nonlinear
from ssme_envs.models.engine_step import valves_arrays

TRACKING, THROTTLE = "ssme_envs/EngineTracking-v0", "ssme_envs/EngineThrottle-v0"
SHORT_PROFILE = [(0.0, 100.0), (3.0, 100.0), (6.0, 80.0), (10.0, 80.0)]  # 250 steps
QUIET = {"backlash": 0.0, "stiction": 0.0, "sensor_noise": 0.0}


def test_nonlinear_tracking_scalar_equals_vector_bit_for_bit():
    # truncations in step (every env at one step) over two episodes
    assert sync_equal(TRACKING, 3, 520, seed=11, action_scale_up=1.3, plant="nonlinear") >= 6
    # terminations at different steps (each env at its own step), a fault, same-step autoreset,
    # between the Table I levels, and the linear flow curve
    stuck = {"kind": "stuck_valve", "time": 1.0, "index": 1}
    ends = sync_equal(TRACKING, 5, 200, seed=4, action_scale_up=2.0, mode=AutoresetMode.SAME_STEP,
                      plant="nonlinear", power=67.0, action_scale=0.2, fault=stuck)  # fmt: skip
    assert ends >= 20
    linear_flow = {"asymmetric_gains": False}
    assert (
        sync_equal(TRACKING, 2, 255, seed=2, action_scale_up=1.0, plant="nonlinear", truth=linear_flow) == 2
    )


def test_nonlinear_throttle_scalar_equals_vector_bit_for_bit():
    ends = sync_equal(THROTTLE, 4, 520, seed=5, action_scale_up=1.0, plant="nonlinear", profile=SHORT_PROFILE,
                    action_scale=0.2, truth={"sensor_noise": 2e-4})  # fmt: skip
    assert ends >= 8


def test_tracking_env_steps_the_model_simulation():
    """Open loop at 85 % (between two Table I levels): the env's measured outputs are
    ``simulate_nonlinear``'s from the same commands, valves and noise off or on alike."""
    steps, scale = 120, 0.02
    env = gym.make(TRACKING, plant="nonlinear", power=85.0, truth={"sensor_noise": 0.0}, action_scale=scale)
    env.reset(seed=0)
    actions = np.random.default_rng(3).uniform(-1, 1, (steps, 2)).astype(np.float32)
    observed = np.array([env.step(a)[0][:2] for a in actions])
    commands = np.vstack([actions.astype(float) * scale, np.zeros((1, 2))])
    _, clean = simulate_nonlinear(NonlinearEngine(), 85.0, commands, TruthConfig(sensor_noise=0.0))
    assert np.ptp(clean[:, 0]) > 0.01  # the schedule moves by more than 1 % of power
    np.testing.assert_allclose(observed, 100.0 * clean[1:], rtol=0, atol=2e-6)  # % (float32 observations)


def test_throttle_schedules_on_the_engines_own_chamber_pressure():
    """Zero action holds the paper's operating points; a held valve offset moves the engine off
    the commanded power, and the plant's schedule follows the engine, not the command."""
    env = gym.make(THROTTLE, plant="nonlinear", profile=SHORT_PROFILE, truth=QUIET)
    env.reset(seed=0)
    for _ in range(env.unwrapped.task.horizon):
        obs, *_ = env.step(np.zeros(2, np.float32))
    np.testing.assert_allclose(obs[[0, 1, 2, 3]], [-20.0, 0.0, -20.0, 0.0], atol=1e-4)  # y_eq(80 %)
    # the same run step by step with the model's own step (its einsum arithmetic), on the
    # absolute valve commands: the nominal schedule plus a held offset
    engine, task = NonlinearEngine(), env.unwrapped.task
    env.reset(seed=0)
    x, rho, v = engine.trim(100.0)
    linkage = v.T.copy()
    offset = np.array([0.3, -0.2], dtype=np.float32)
    gaps = []
    for t in range(1, 200):
        obs, *_ = env.step(offset)
        command = (engine.trim(task.power[t - 1])[2][0] + 0.02 * offset.astype(float))[:, None]
        linkage, valve = valves_arrays(linkage, linkage, command, 0.0, 0.0)
        x, rho = engine.step(x, rho, valve.T)
        plant = env.unwrapped._state.plant
        np.testing.assert_allclose(plant.x, x[0], rtol=0, atol=1e-12)
        assert plant.rho == pytest.approx(100.0 + 100.0 * x[0, -2], abs=1e-9)  # its own Pc, in %
        gaps.append(plant.rho - task.power[t])
    assert max(np.abs(gaps)) > 1.0  # % of power between the engine's schedule and the command


@pytest.mark.parametrize("power", [85.0, 100.0])
def test_truth_design_model_is_the_plants_linearization(power):
    """The tracking env's "truth" design model on the nonlinear plant: the Markov parameters of a
    central-difference Jacobian of the env's own plant step (floats) about its start."""
    env = gym.make(TRACKING, plant="nonlinear", power=power, truth=QUIET)
    task = env.unwrapped.task
    start = task.initial_plant(None)
    n, h = len(start.x), 1e-6

    def step(z: np.ndarray, u: np.ndarray) -> np.ndarray:
        plant = start._replace(x=z[:n].tolist(), rho=float(z[n]))
        nxt, _, _ = task.plant_step(plant, float(u[0]), float(u[1]), 1, None, FLOATS)
        return np.array([*nxt.x, nxt.rho])

    z0, u0 = np.array([*start.x, start.rho]), np.zeros(2)
    scale = np.r_[np.full(n, h), 100 * h]  # rho in % of power: the same size in Pc
    jac_z = np.column_stack([(step(z0 + e, u0) - step(z0 - e, u0)) / (2 * e.sum()) for e in np.diag(scale)])
    jac_u = np.column_stack([(step(z0, u0 + e) - step(z0, u0 - e)) / (2 * h) for e in np.diag([h, h])])
    c = np.zeros((2, n + 1))
    c[:, n - 2 : n] = np.eye(2)
    fd = np.array([c @ np.linalg.matrix_power(jac_z, k) @ jac_u for k in range(11)])
    design = task.design_model("truth")
    np.testing.assert_allclose(design.markov_parameters(11), fd, rtol=0, atol=1e-7)
    if power == 100.0:  # Table I's level: its published model
        np.testing.assert_allclose(design.markov_parameters(11), published_model(100).markov_parameters(11),
                                   rtol=0, atol=1e-12)  # fmt: skip
    from agents import make_controller

    assert make_controller("lqi:truth", env).act(env.reset(seed=0)[0][None], {}).shape == (1, 2)


def test_plant_options_and_bad_input():
    np.testing.assert_array_equal(gym.make(THROTTLE, plant="truth").reset(seed=1)[0],
                                  gym.make(THROTTLE).reset(seed=1)[0])  # fmt: skip
    assert gym.make(TRACKING, plant=NonlinearEngine(tau=0.1)).unwrapped.task.nonlinear.engine.tau == 0.1
    for env_id, kwargs, message in [
        (THROTTLE, {"plant": "identified"}, "plant must be 'truth', 'nonlinear'"),
        (TRACKING, {"plant": "nonlinear", "power": 120.0}, "power must be within 65-109"),
        (TRACKING, {"plant": "nonlinar"}, "'nonlinear'"),
    ]:
        with pytest.raises(ValueError, match=message):
            gym.make(env_id, **kwargs)
