"""LauncherPitch-v0: the body's discretization, the coupled trajectory against a fine reference,
the hysteresis through the servo, bad input. (Checkers and the vector env: test_nozzle_env.py.)"""

import itertools
import math

import gymnasium as gym
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import ssme_envs  # noqa: F401
from ssme_envs.envs.launcher_pitch import body_transition
from ssme_envs.models.nozzle import published_nozzle

LAUNCHER = "ssme_envs/LauncherPitch-v0"
MU_A, MU_C = 3.0, 12.0  # the documented defaults, 1/s^2


def _propagate(inputs: np.ndarray, h: float) -> np.ndarray:
    p00, p01, p10, p11, g0t, g0q, g1t, g1q = body_transition(MU_A, MU_C, h)
    theta = q = 0.0
    for d0, d1 in itertools.pairwise(inputs):
        theta, q = p00 * theta + p01 * q + g0t * d0 + g1t * d1, p10 * theta + p11 * q + g0q * d0 + g1q * d1
    return np.array([theta, q])


def test_body_transition_is_exact_for_constant_and_ramp_deflections():
    h, n = 0.002, 500
    t = n * h
    root = math.sqrt(MU_A)
    # theta'' = mu_a theta + mu_c d from rest, solved by hand
    constant = _propagate(np.full(n + 1, 0.01), h)
    expected = 0.01 * MU_C / MU_A * np.array([math.cosh(root * t) - 1.0, root * math.sinh(root * t)])
    np.testing.assert_allclose(constant, expected, rtol=1e-9)
    ramp = _propagate(np.arange(n + 1) * h, h)  # d(t) = t
    expected = MU_C / MU_A * np.array([math.sinh(root * t) / root - t, math.cosh(root * t) - 1.0])
    np.testing.assert_allclose(ramp, expected, rtol=1e-9)


def _pd(target: float, attitude: float, rate: float) -> float:
    """A PD attitude loop (deg in, action out): theta'' + 12 kd theta' + (12 kp - 3) theta =
    12 kp ref, 4 rad/s and 0.7 damping on the rigid body."""
    return float(np.clip((1.58 * (target - attitude) - 0.467 * rate) / 3.0, -1.0, 1.0))


def test_trajectory_agrees_with_a_fine_reference_simulation():
    env = gym.make(LAUNCHER, reference="zero", sensor_noise=0.0)
    obs, _ = env.reset(seed=0)
    feedforward, k_p, k_d = env.unwrapped.task.servo
    p = published_nozzle("bouc_wen").normalized()

    def rhs(_t, s, torque):
        x, v, w, theta, q = s
        accel = (torque - p["b"] * v - p["k_el"] * x - p["k_hys"] * w) / p["J"]
        w_rate = v * (1 - abs(w) ** p["n"] * (p["beta_n"] + p["gamma_n"] * np.sign(v * w)))
        return [v, accel, w_rate, q, MU_A * theta + MU_C * x]

    targets = np.repeat(np.random.default_rng(2).uniform(-2, 2, 10), 25)  # deg, held 0.5 s
    state = np.zeros(5)
    errors = []
    for target in targets:
        obs, _, terminated, _, _ = env.step(np.array([_pd(target, obs[0], obs[1])], dtype=np.float32))
        assert not terminated
        # the same loop on the reference: servo torque held over each 2 ms, DOP853 in between
        a = _pd(target, math.degrees(state[3]), math.degrees(state[4]))
        for _ in range(10):
            torque = np.clip(feedforward * a * math.radians(3) - k_p * state[0] - k_d * state[1], -3e4, 3e4)
            state = solve_ivp(
                rhs, (0, 0.002), state, args=(torque,), method="DOP853", rtol=1e-11, atol=1e-14
            ).y[:, -1]
        errors.append([obs[0] - math.degrees(state[3]), obs[5] - math.degrees(state[0])])
    # deg (measured 1.7e-5 attitude, 1.2e-4 nozzle, on motions of 2.1 deg and 3.1 deg)
    assert np.max(np.abs(errors), axis=0).tolist() < [1e-3, 1e-3]


def _deflection_error(plant: str, period: float) -> float:
    """Largest |command - deflection| (deg) over the second period of a 2 deg sine attitude
    reference tracked by the PD loop."""
    steps = round(2 * period / 0.02)
    env = gym.make(LAUNCHER, plant=plant, reference="zero", sensor_noise=0.0, episode_seconds=2 * period,
                   max_episode_steps=steps)  # fmt: skip
    obs, _ = env.reset(seed=0)
    worst = 0.0
    for k in range(1, steps + 1):
        action = _pd(2.0 * math.sin(2 * math.pi * k * 0.02 / period), obs[0], obs[1])
        obs, _, terminated, _, _ = env.step(np.array([action], dtype=np.float32))
        assert not terminated
        if k > steps // 2:
            worst = max(worst, abs(3.0 * action - float(obs[5])))
    return worst


def test_the_servo_leaves_a_rate_independent_deflection_error_on_the_hysteretic_joint():
    bouc_wen = [_deflection_error("bouc_wen", period) for period in (10.0, 20.0)]
    linear = [_deflection_error("linear", period) for period in (10.0, 20.0)]
    # the linear joint's error is its servo lag, which shrinks as the sine slows; the
    # hysteretic joint keeps most of its error (measured 7.3e-3 -> 5.7e-3 deg; linear 2.0e-3 -> 0.9e-3)
    assert linear[1] < 0.6 * linear[0]
    assert bouc_wen[1] > 0.6 * bouc_wen[0]
    assert bouc_wen[1] > 3.0 * linear[1]


def test_attitude_diverges_without_control_and_leaving_the_envelope_ends_the_episode():
    env = gym.make(LAUNCHER, reference="zero", sensor_noise=0.0)
    env.reset(seed=0)
    steps, terminated = 0, False
    while not terminated and steps < 500:
        obs, reward, terminated, _, _ = env.step(np.array([0.1], dtype=np.float32))  # 0.3 deg held
        steps += 1
    assert terminated and abs(obs[0]) > 10.0
    # with the nozzle settled at 0.3 deg: theta = (mu_c/mu_a) 0.3 deg (cosh(1.73 t) - 1) ~ 10 deg
    expected = math.acosh(1 + 10.0 / (MU_C / MU_A * 0.3)) / math.sqrt(MU_A)
    assert steps * 0.02 == pytest.approx(expected, abs=0.1)
    assert reward < -100.0  # the termination penalty


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"reference_amplitude_deg": 6.0}, "reference_amplitude_deg"),
        ({"instability": -1.0}, "instability"),
        ({"effectiveness": 0.0}, "effectiveness"),
        ({"fault": {"kind": "stuck_valve", "time": 1.0}}, "unknown fault kind 'stuck_valve'"),
        ({"plant": "steel"}, "plant must be"),
        ({"reference": "chirp"}, "unknown reference"),
    ],
)
def test_bad_options_name_the_option(options, message):
    with pytest.raises(ValueError, match=message):
        gym.make(LAUNCHER, **options)


def test_bad_actions():
    env = gym.make(LAUNCHER)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action must be finite"):
        env.step(np.array([np.inf], dtype=np.float32))
    with pytest.raises(ValueError, match="nozzle deflection command"):
        env.step(np.zeros(3, dtype=np.float32))
    vec = gym.make_vec(LAUNCHER, num_envs=2, vectorization_mode="vector_entry_point")
    vec.reset(seed=0)
    with pytest.raises(ValueError, match="action of env 1 must be finite"):
        vec.step(np.array([[0.0], [np.nan]], dtype=np.float32))


def test_render_rgb_array_shows_attitude_and_deflection():
    env = gym.make(LAUNCHER, render_mode="rgb_array")
    env.reset(seed=0)
    for _ in range(20):
        env.step(np.array([0.2], dtype=np.float32))
    image = env.render()
    assert image.ndim == 3 and image.shape[2] == 3 and image.std() > 0
    assert env.unwrapped._history[-1][2] == pytest.approx(0.2, abs=0.01)  # deflection settled at 0.6 deg
    env.close()
