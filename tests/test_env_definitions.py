"""The documented reward and observation definitions of the four envs, the engine faults and the
nozzle's actuator options, held to independent computations: the docstrings' formulas evaluated
here on the returned observations, and scipy simulations of the published models (Table I's
point model, the nozzle's linear joint) written in this file.

Tolerance. Observations are float32: each value carries a relative rounding error of at most
2**-24 (6e-8) of its own magnitude. A relation checked on observations (an error from a reference
and a measurement, an integral from the last integral and an error, a reward from squared
errors) combines at most three rounded values, so its float32 residue is below ~2e-7 of the
magnitudes involved. ``REL = 1e-5`` relative to those magnitudes leaves a margin of 50 while a
wrong definition (a weight, a unit factor of 100 or 180/pi, a dt, a sign, a missing clip) is off
by 1e-2 relative or more. Where a simulation here integrates differently from the env (scipy's
exact discretization against the env's RK4) the tolerance is stated at the test.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from importlib import resources

import gymnasium as gym
import numpy as np
import pytest
import scipy.signal
from conftest import dlsim, eq36
from hypothesis import assume, event, given, settings
from hypothesis import strategies as st

import ssme_envs  # noqa: F401  (registers the env ids)

REL = 1e-5  # see the module docstring
TINY = 1e-12  # absolute floor of the comparisons (values that round to zero)
DEG = 180.0 / math.pi
DATA = resources.files("ssme_envs") / "models" / "data"

TRACKING, THROTTLE = "ssme_envs/EngineTracking-v0", "ssme_envs/EngineThrottle-v0"
NOZZLE, LAUNCHER = "ssme_envs/NozzleTVC-v0", "ssme_envs/LauncherPitch-v0"

FEW = settings(deadline=None, max_examples=25, derandomize=True)


@dataclass(frozen=True)
class Layout:
    """Where the documented columns sit in an env's observation, and its documented constants."""

    measured: tuple[int, ...]
    reference: tuple[int, ...]
    error: tuple[int, ...]
    integral: tuple[int, ...]
    previous: tuple[int, ...]
    dt: float  # s per step
    integral_limit: float  # anti-windup bound of the error integrals
    # the worst cost of one step inside the envelope, from the docstrings' bounds: the largest
    # error the envelope and the reference allow (plus a margin for the sensor noise) and
    # action changes of 2 per component
    worst_step_cost: float


# EngineTracking / EngineThrottle: noise-free error <= 10 % (+0.1 % for noise), two channels
ENGINE = Layout((0, 1), (2, 3), (4, 5), (6, 7), (8, 9), 0.04, 100.0, 0.1 * 2 * 10.1**2 + 0.1 * 2 * 2.0**2)
# NozzleTVC: |angle| <= 6 deg, |reference| <= 3 deg (+0.1 deg for noise)
NOZZLE_LAYOUT = Layout((0,), (2,), (3,), (4,), (5,), 0.008, 10.0, 0.1 * 9.1**2 + 0.1 * 2.0**2)
# LauncherPitch: |attitude| <= 10 deg, |reference| <= 2 deg (the default amplitude; +0.1 deg)
LAUNCHER_LAYOUT = Layout((0,), (2,), (3,), (4,), (6,), 0.02, 10.0, 0.1 * 12.1**2 + 0.1 * 2.0**2)

_ENVS: dict[str, gym.Env] = {}


def env_of(env_id: str, **options) -> gym.Env:
    """One env per id and options for the whole module (making one costs more than an example)."""
    key = env_id + repr(sorted(options.items()))
    if key not in _ENVS:
        _ENVS[key] = gym.make(env_id, **options)
    return _ENVS[key]


def columns(obs: np.ndarray, index: tuple[int, ...]) -> np.ndarray:
    return obs[list(index)].astype(np.float64)


def check_reset(layout: Layout, obs: np.ndarray) -> None:
    """At reset: errors = reference - measured, integrals and previous action zero."""
    meas, ref, err = (columns(obs, c) for c in (layout.measured, layout.reference, layout.error))
    assert np.all(np.abs(err - (ref - meas)) <= REL * (np.abs(ref) + np.abs(meas)) + TINY)
    assert np.all(columns(obs, layout.integral) == 0.0)
    assert np.all(columns(obs, layout.previous) == 0.0)


def check_step(
    layout: Layout, prev_obs: np.ndarray, obs: np.ndarray, reward: float, terminated: bool,
    action: np.ndarray, prev_action: np.ndarray, steps_left: int,
) -> None:  # fmt: skip
    """One step against the docstrings: error columns = reference - measured; integrals
    i_k = clip(i_(k-1) + e_k dt, -lim, lim); previous-action columns = the clipped action;
    reward = -0.1 sum e^2 - 0.1 |a_k - a_(k-1)|^2 (errors of the new observation, clipped actions),
    and on a terminating step a penalty larger than the worst cost of all remaining steps."""
    meas, ref, err = (columns(obs, c) for c in (layout.measured, layout.reference, layout.error))
    integral, last_integral = columns(obs, layout.integral), columns(prev_obs, layout.integral)
    assert np.all(np.abs(err - (ref - meas)) <= REL * (np.abs(ref) + np.abs(meas)) + TINY), (err, ref, meas)
    lim = layout.integral_limit
    expected_integral = np.clip(last_integral + err * layout.dt, -lim, lim)
    scale = np.abs(last_integral) + np.abs(err) * layout.dt
    assert np.all(np.abs(integral - expected_integral) <= REL * scale + TINY), (integral, expected_integral)
    np.testing.assert_array_equal(obs[list(layout.previous)], action.astype(np.float32))
    expected = -0.1 * np.sum(err**2) - 0.1 * np.sum((action - prev_action) ** 2)
    if not terminated:
        assert abs(reward - expected) <= REL * abs(expected) + TINY, (reward, expected)
    else:
        assert expected - reward > steps_left * layout.worst_step_cost, (reward, expected, steps_left)


def note(seen: dict) -> None:
    """What a drawn episode exercised, for ``--hypothesis-show-statistics``."""
    event("terminated" if seen["terminated"] else "truncated")
    event("clipped actions" if seen["clipped"] else "no clipped action")


def run_episode(env, layout: Layout, seed: int, policy, extra=None, horizon: int | None = None) -> dict:
    """Step ``env`` from ``reset(seed)`` to its end with ``policy(obs, k)`` (float32 actions,
    clipped here as the docstrings say the env clips them), checking every step; returns
    counts of what the episode exercised."""
    obs, _ = env.reset(seed=seed)
    check_reset(layout, obs)
    if extra is not None:
        extra(0, None, obs)
    horizon = env.spec.max_episode_steps if horizon is None else horizon  # the episode's steps
    prev_action = np.zeros(len(layout.previous))
    seen = {"steps": 0, "clipped": 0, "terminated": False, "saturated": 0}
    for k in range(1, horizon + 1):
        sent = np.asarray(policy(obs, k), dtype=np.float32)
        action = np.clip(sent.astype(np.float64), -1.0, 1.0)
        new, reward, terminated, truncated, _ = env.step(sent)
        check_step(layout, obs, new, reward, terminated, action, prev_action, horizon - k)
        if extra is not None:
            extra(k, obs, new)
        seen["steps"] = k
        seen["clipped"] += int(np.any(action != sent))
        seen["saturated"] += int(np.any(np.abs(columns(new, layout.integral)) == layout.integral_limit))
        assert truncated == (k == horizon)  # truncation after episode_seconds, not before
        obs, prev_action = new, action
        if terminated or truncated:
            seen["terminated"] = terminated
            break
    assert seen["terminated"] or seen["steps"] == horizon  # an episode ends only by its rules
    return seen


@pytest.mark.parametrize(
    ("env_id", "high", "n_actions"),
    [
        (TRACKING, (50, 50, 50, 50, 100, 100, 100, 100, 1, 1), 2),
        (THROTTLE, (50, 50, 50, 50, 100, 100, 100, 100, 1, 1), 2),
        (NOZZLE, (20, 2000, 10, 30, 10, 1), 1),
        (LAUNCHER, (20, 200, 10, 30, 10, 20, 1), 1),
    ],
)
def test_spaces_are_the_documented_tables(env_id, high, n_actions):
    """The observation Box is the docstring table's bounds (symmetric, float32) and the action
    Box is [-1, 1] of the documented size."""
    env = env_of(env_id)
    expected = np.array(high, dtype=np.float32)
    assert env.observation_space.dtype == np.float32
    np.testing.assert_array_equal(env.observation_space.high, expected)
    np.testing.assert_array_equal(env.observation_space.low, -expected)
    assert env.action_space.shape == (n_actions,) and env.action_space.dtype == np.float32
    assert np.all(env.action_space.low == -1.0) and np.all(env.action_space.high == 1.0)


# ---------------------------------------------------------------- hypothesis-drawn actions


def action_values(small: float = 1.0):
    """An action component: inside [-small, small], far out of range, or at and near the bounds."""
    return st.one_of(
        st.floats(-small, small).map(np.float32),  # float32 as the action space
        st.floats(-small, small).map(np.float32),
        st.floats(-1e4, 1e4).map(np.float32),
        st.sampled_from([-1.0, 1.0, 0.0, -1.0000001, 1.0000001, -3.0, 3.0]),
    )


def segments(n: int, small: float = 1.0, hold: int = 25):
    """Piecewise-constant action sequences: (action of n components, steps held) segments, cycled
    to the end of the episode (held actions make zero action changes, new ones nonzero)."""
    return st.lists(
        st.tuples(st.lists(action_values(small), min_size=n, max_size=n), st.integers(1, hold)),
        min_size=1,
        max_size=12,
    )


def piecewise(segs):
    """The action of step k (1, 2, ...) of the cycled segments."""
    table = [np.array(a, dtype=np.float32) for a, held in segs for _ in range(held)]
    return lambda k: table[(k - 1) % len(table)]


# ---------------------------------------------------------------- engine rewards and observations

THROTTLE_PROFILE = [(0.0, 100.0), (0.6, 104.0), (1.2, 85.0), (2.0, 95.0), (3.0, 95.0)]


def throttle_references(k: int, prev_obs, obs) -> None:
    """EngineThrottle's references follow the profile: Pc = P(t)/100 - 1 (in %: P - 100), MR 0."""
    times, powers = zip(*THROTTLE_PROFILE, strict=True)
    expected = np.interp(k * ENGINE.dt, times, powers) - 100.0
    assert abs(float(obs[2]) - expected) <= REL * abs(expected) + TINY, (k, obs[2], expected)
    assert obs[3] == 0.0


@FEW
@given(seed=st.integers(0, 2**31 - 1), segs=segments(2))
@pytest.mark.parametrize("env_id", [TRACKING, THROTTLE])
def test_engine_reward_and_observation_definitions(env_id, seed, segs):
    """EngineTracking-v0 and EngineThrottle-v0 (its docstring: 'As in EngineTracking-v0'): every
    step's reward, error, integral and previous-action columns from the observations alone, over
    whole episodes of drawn actions in and out of [-1, 1]; the throttle's references from its
    profile."""
    options = {"profile": THROTTLE_PROFILE} if env_id == THROTTLE else {}
    extra = throttle_references if env_id == THROTTLE else None
    actions = piecewise(segs)
    horizon = 75 if env_id == THROTTLE else 250  # the profile's 3 s; the default 10 s
    seen = run_episode(env_of(env_id, **options), ENGINE, seed, lambda obs, k: actions(k), extra, horizon)
    note(seen)


def test_engine_integrals_saturate_at_the_documented_bound():
    """The anti-windup at +-100 % s, reached: a 5 % sensor bias on Pc from t = 0 with zero
    reference and small actions holds the Pc error near -5 % (inside the envelope, which is on
    the noise-free error) for 24 s; the recursion is checked at every step, clip included."""
    env = env_of(
        TRACKING,
        reference="zero",
        episode_seconds=24.0,
        max_episode_steps=600,
        fault={"kind": "sensor_bias", "time": 0.0, "index": 0, "magnitude": 0.05},
    )
    rng = np.random.default_rng(20240611)
    draws = rng.uniform(-0.3, 0.3, size=(600, 2)).astype(np.float32)
    layout = replace(ENGINE, worst_step_cost=0.1 * 2 * 15.1**2 + 0.8)  # the bias adds 5 % of error
    seen = run_episode(env, layout, 7, lambda obs, k: draws[k - 1])
    assert seen["steps"] == 600 and not seen["terminated"]
    assert seen["saturated"] >= 50  # -100 % s from about 20 s on


# ---------------------------------------------------------------- nozzle and launcher rewards


def nozzle_rate(k: int, prev_obs, obs) -> None:
    """The rate column: the difference of measured angles over 0.008 s (from the second step:
    see test_nozzle_first_rate_is_a_difference_of_measured_angles)."""
    if k >= 2:
        expected = (float(obs[0]) - float(prev_obs[0])) / NOZZLE_LAYOUT.dt
        scale = (abs(float(obs[0])) + abs(float(prev_obs[0]))) / NOZZLE_LAYOUT.dt + abs(expected)
        assert abs(float(obs[1]) - expected) <= REL * scale + TINY, (k, obs[1], expected)


@FEW
@given(seed=st.integers(0, 2**31 - 1), segs=segments(1, small=0.05, hold=10))
@pytest.mark.parametrize("plant", ["bouc_wen", "linear"])
def test_nozzle_reward_and_observation_definitions(plant, seed, segs):
    """NozzleTVC-v0: reward -0.1 e^2 - 0.1 (a_k - a_(k-1))^2 (deg), error, integral (+-10 deg s,
    dt 0.008 s), previous action and the rate estimate from the observations alone. The actions
    are a static feedforward of the reference with a little rate damping plus the drawn
    perturbations (some far out of range), so that episodes run long and some leave the envelope."""
    drawn = piecewise(segs)
    seen = run_episode(
        env_of(NOZZLE, plant=plant),
        NOZZLE_LAYOUT,
        seed,
        lambda obs, k: np.float32(0.25 / 3.0 * obs[2] - 0.001 * obs[1]) + drawn(k),
        nozzle_rate,
    )
    note(seen)


def test_nozzle_integral_saturates_at_the_documented_bound():
    """NozzleTVC's anti-windup at +-10 deg s, reached: a 0.05 rad sensor bias from t = 0, zero
    reference and zero torque (the nozzle stays at rest: no termination)."""
    env = env_of(NOZZLE, reference="zero", fault={"kind": "sensor_bias", "time": 0.0, "magnitude": 0.05})
    layout = replace(NOZZLE_LAYOUT, worst_step_cost=0.1 * 12.0**2 + 0.4)  # the bias adds 2.9 deg
    seen = run_episode(env, layout, 3, lambda obs, k: np.zeros(1, np.float32), nozzle_rate)
    assert seen["steps"] == 500 and seen["saturated"] >= 50  # -10 deg s after 3.5 s


@FEW
@given(seed=st.integers(0, 2**31 - 1), segs=segments(1, small=0.3))
@pytest.mark.parametrize("plant", ["bouc_wen", "linear"])
def test_launcher_reward_and_observation_definitions(plant, seed, segs):
    """LauncherPitch-v0: reward -0.1 e^2 - 0.1 (a_k - a_(k-1))^2 (deg), error, integral (+-10
    deg s, dt 0.02 s) and previous action from the observations alone, under an attitude PD law
    plus the drawn perturbations (some far out of range)."""
    drawn = piecewise(segs)
    seen = run_episode(
        env_of(LAUNCHER, plant=plant),
        LAUNCHER_LAYOUT,
        seed,
        lambda obs, k: np.float32((obs[3] - 0.3 * obs[1]) / 3.0) + drawn(k),
    )
    note(seen)


def test_launcher_integral_saturates_at_the_documented_bound():
    """LauncherPitch's anti-windup at +-10 deg s: a 0.05 rad attitude sensor bias from t = 0,
    zero reference and zero deflection (the vehicle stays at rest)."""
    env = env_of(LAUNCHER, reference="zero", fault={"kind": "sensor_bias", "time": 0.0, "magnitude": 0.05})
    seen = run_episode(env, LAUNCHER_LAYOUT, 3, lambda obs, k: np.zeros(1, np.float32))
    assert seen["steps"] == 500 and seen["saturated"] >= 300  # -10 deg s after 3.5 s of 10


def test_nozzle_first_rate_is_taken_from_the_rest_angle():
    """The docstring's rate column, 'difference of measured angles; at step 1 from the rest angle
    0': at the first step (angle_1 - 0) / 0.008 s, not from the angle observed at
    reset. A sensor bias from t = 0 makes the two differ: angle_0 = 0.05 rad (2.9 deg) at rest."""
    env = env_of(NOZZLE, reference="zero", fault={"kind": "sensor_bias", "time": 0.0, "magnitude": 0.05})
    first, _ = env.reset(seed=11)
    obs, *_ = env.step(np.zeros(1, np.float32))
    assert abs(float(first[0]) - np.degrees(0.05)) < 0.05  # the bias shows at reset
    expected = float(obs[0]) / NOZZLE_LAYOUT.dt
    assert abs(float(obs[1]) - expected) <= REL * abs(expected) + 1e-3


# ---------------------------------------------------------------- engine faults vs Table I


def table1(power: int = 100) -> tuple[np.ndarray, ...]:
    """A, B, C and lambda of Table I at ``power`` from the packaged data file."""
    doc = json.loads(DATA.joinpath("engine_table1.json").read_text())
    (entry,) = [m for m in doc["models"] if m["power_percent"] == power]
    assert doc["dt"] == ENGINE.dt
    return tuple(np.array(entry[key], dtype=float) for key in ("A", "B", "C", "lambda"))


IDEAL_VALVES = {"backlash": 0.0, "stiction": 0.0, "sensor_noise": 0.0}
FAULT_STEPS = 100


@settings(deadline=None, max_examples=80, derandomize=True)
@given(
    kind=st.sampled_from(["none", "gain_loss", "stuck_valve", "sensor_bias"]),
    index=st.integers(0, 1),
    gain=st.floats(0.0, 0.95),
    bias=st.floats(0.002, 0.05).flatmap(lambda m: st.sampled_from([m, -m])),
    fault_step=st.integers(0, FAULT_STEPS - 5),
    offset=st.floats(-0.45, 0.45),
    asymmetric=st.booleans(),
    seed=st.integers(0, 2**31 - 1),
    segs=segments(2, hold=8),
)
def test_engine_faults_against_table1_simulation(
    kind, index, gain, bias, fault_step, offset, asymmetric, seed, segs
):
    """EngineTracking-v0 at 100 % with backlash, stiction and noise off: the measured outputs
    (observation columns 0, 1, in %) equal 100 x Table I's model (scipy dlsim, x(k+1) = A x + B u,
    y = C x, the data file's A, B, C) under u = 0.02 x the clipped actions, through eq 36's gains
    when ``asymmetric_gains``, and:

    - gain_loss m on valve i at T: valve i's command times m from step round(T / dt) on;
    - stuck_valve on valve i at T: valve i holds the command of step round(T / dt) from then on;
    - sensor_bias b on output i at T: b added to output i from the observation at round(T / dt)
      (the reset observation when T rounds to 0).

    Tolerance: float32 observations (REL of the values) plus 1e-9 % for float64 operation order."""
    a, b, c, lam = table1()
    time = max(0.0, (fault_step + offset) * ENGINE.dt)
    f = round(time / ENGINE.dt)  # the offset stays within +-0.45 of a step: no half-way ties
    options = {"truth": {**IDEAL_VALVES, "asymmetric_gains": asymmetric}, "reference": "zero"}
    if kind == "gain_loss":
        options["fault"] = {"kind": kind, "time": time, "index": index, "magnitude": gain}
    elif kind == "stuck_valve":
        options["fault"] = {"kind": kind, "time": time, "index": index}
    elif kind == "sensor_bias":
        options["fault"] = {"kind": kind, "time": time, "index": index, "magnitude": bias}
    env = gym.make(TRACKING, **options)
    actions = piecewise(segs)
    sent = np.array([actions(k) for k in range(1, FAULT_STEPS + 1)])
    commands = 0.02 * np.clip(sent.astype(np.float64), -1.0, 1.0)  # rows j = 0.. act over [j dt, (j+1) dt]
    healthy = commands.copy()
    if kind == "gain_loss":
        commands[f:, index] *= gain
    elif kind == "stuck_valve":
        commands[f:, index] = commands[f, index]
    valves = eq36(commands, lam) if asymmetric else commands
    outputs = 100.0 * dlsim(a, b, c, np.vstack([valves, np.zeros((1, 2))]))  # y[k] after k commands
    if kind == "sensor_bias":
        outputs[f:, index] += 100.0 * bias
    obs, _ = env.reset(seed=seed)
    measured = [obs[:2]]
    for row in sent:
        obs, _, terminated, _, _ = env.step(row)
        measured.append(obs[:2])
        assert not terminated
    measured = np.array(measured, dtype=np.float64)
    tol = REL * np.abs(outputs) + 1e-9
    np.testing.assert_array_less(np.abs(measured - outputs), tol)
    # the comparison can tell the fault apart: without it the prediction is off (or the fault
    # happens to change nothing on these actions, which the draw is then not about)
    if kind != "none":
        unfaulted = 100.0 * dlsim(a, b, c, np.vstack([eq36(healthy, lam) if asymmetric else healthy,
                                                       np.zeros((1, 2))]))  # fmt: skip
        assume(np.any(np.abs(unfaulted - outputs) > 100 * (REL * np.abs(outputs) + 1e-9)))


# ---------------------------------------------------------------- nozzle actuator options vs scipy


def linear_joint() -> tuple[float, float, float]:
    """J, b, k of Table 1's linear row, from the packaged data file."""
    row = json.loads(DATA.joinpath("nozzle_table1.json").read_text())["linear"]
    return row["J"], row["b"], row["k"]


def joint_angles(torque: np.ndarray, dt: float = NOZZLE_LAYOUT.dt) -> np.ndarray:
    """Angles x_1..x_N (rad) of J x'' + b x' + k x = tau from rest, tau_k held over step k: the
    exact zero-order-hold discretization (scipy)."""
    j, b, k = linear_joint()
    system = (np.array([[0.0, 1.0], [-k / j, -b / j]]), np.array([[0.0], [1.0 / j]]),
              np.array([[1.0, 0.0]]), np.zeros((1, 1)))  # fmt: skip
    ad, bd, cd, dd, _ = scipy.signal.cont2discrete(system, dt, method="zoh")
    _, y, _ = scipy.signal.dlsim((ad, bd, cd, dd, dt), np.append(torque, 0.0))
    return y[1:, 0]


FULL_SCALE = 3.0e4  # N m, the documented full scale of the torque command


@settings(deadline=None, max_examples=80, derandomize=True)
@given(
    option=st.sampled_from(["none", "actuator_lag", "rate_limit", "gain_loss", "sensor_bias"]),
    lag=st.floats(0.004, 0.2),
    rate=st.floats(1e4, 3e6),
    gain=st.floats(0.0, 0.95),
    bias=st.floats(0.002, 0.05).flatmap(lambda m: st.sampled_from([m, -m])),
    fault_step=st.integers(1, 100),
    offset=st.floats(-0.45, 0.45),
    seed=st.integers(0, 2**31 - 1),
    segs=segments(1, small=0.3, hold=15),
)
def test_nozzle_actuator_options_against_linear_joint(
    option, lag, rate, gain, bias, fault_step, offset, seed, segs
):
    """NozzleTVC-v0 on the linear joint, noise off, 50 RK4 substeps: the measured angle and rate
    columns equal an exact (scipy ZOH) simulation of J x'' + b x' + k x = tau (Table 1's linear
    row) driven by the torque computed here from the documented options, acting once per step:

    - actuator_lag T: a first-order lag T tau' = u - tau with the command u = 3e4 x clipped action
      held over the step, tau_k = e tau_(k-1) + (1 - e) u_k, e = exp(-0.008 / T), the value at the
      step's end held over the step;
    - rate_limit R (N m/s): tau_k = tau_(k-1) + clip(u_k - tau_(k-1), -R 0.008, R 0.008);
    - fault gain_loss m at T: the torque command times m from step round(T / dt) on;
    - fault sensor_bias b (rad) at T: b added to the measured angle from the observation at
      round(T / dt) on (from the second step: the first is test_nozzle_first_rate_...'s).

    Tolerance: RK4 with h omega_n = 0.012 per substep is within ~1e-8 of the exact motion; the
    float32 angles add 6e-8: 1e-5 of the largest angle."""
    dt = NOZZLE_LAYOUT.dt
    time = (fault_step + offset) * dt
    f = round(time / dt)  # within +-0.45 of a step: no half-way ties
    options = {"plant": "linear", "sensor_noise": 0.0, "reference": "zero", "substeps": 50}
    if option == "actuator_lag":
        options["actuator_lag"] = lag
    elif option == "rate_limit":
        options["rate_limit"] = rate
    elif option == "gain_loss":
        options["fault"] = {"kind": "gain_loss", "time": time, "magnitude": gain}
    elif option == "sensor_bias":
        options["fault"] = {"kind": "sensor_bias", "time": time, "magnitude": bias}
    env = gym.make(NOZZLE, **options)
    actions = piecewise(segs)
    obs, _ = env.reset(seed=seed)
    angles, rates, sent = [], [], []
    for k in range(1, 501):
        sent.append(actions(k))
        obs, _, terminated, truncated, _ = env.step(sent[-1])
        angles.append(float(obs[0]))
        rates.append(float(obs[1]))
        if terminated or truncated:
            break
    clipped = FULL_SCALE * np.clip(np.array(sent, dtype=np.float64)[:, 0], -1.0, 1.0)
    command = clipped.copy()  # row j acts over [j dt, (j + 1) dt]
    if option == "gain_loss":
        command[f:] *= gain
    torque = np.empty_like(command)
    tau, e = 0.0, math.exp(-dt / lag)
    for k, u in enumerate(command):
        if option == "actuator_lag":
            tau = e * tau + (1.0 - e) * u
        elif option == "rate_limit":
            tau = tau + min(max(u - tau, -rate * dt), rate * dt)
        else:
            tau = u
        torque[k] = tau
    motion = DEG * joint_angles(torque)
    x = np.concatenate([[0.0], motion])  # measured angles of the reset observation and steps 1..
    if option == "sensor_bias":
        x[f:] += DEG * bias
    tol = REL * np.max(np.abs(x)) + TINY
    np.testing.assert_array_less(np.abs(np.array(angles) - x[1:]), tol)
    np.testing.assert_array_less(np.abs(np.array(rates) - np.diff(x) / dt), 2 * tol / dt)
    # the option shows: without it the joint moves (or reads) otherwise, else the draw is not about it
    if option == "sensor_bias":
        assume(f <= len(sent))
    elif option != "none":
        plain = DEG * joint_angles(clipped)
        assume(np.max(np.abs(plain - motion)) > 100 * tol)


# ---------------------------------------------------------------- launcher columns vs scipy


def test_launcher_columns_against_documented_model():
    """LauncherPitch-v0 on the linear joint, noise off: attitude, pitch rate and nozzle deflection
    columns (0, 1, 5) against a simulation of the documented model written here: a 500 Hz servo
    tau = clip(k_ff d_cmd - k_p d - k_d d', +-3e4 N m) held over each 2 ms sample, with k_ff =
    k + k_p and the closed loop J d'' + (b + k_d) d' + (k + k_p) d at 15 Hz and 0.7 damping, on the
    joint's exact ZOH discretization; the body theta'' = 3 theta + 12 d with d linear between the
    servo samples (scipy.signal.lsim, linear interpolation); d_cmd = action x 3 deg.

    Tolerance: the env integrates the joint by one RK4 step per 2 ms sample (h omega_n = 0.15,
    relative error ~1e-6 per sample) where the simulation is exact, and the unstable body
    (pole 1.7 rad/s) grows a difference by e^1.7 over the 1 s compared: 1e-4 of each column's
    largest value, still 100 times below a 1 % change of any constant."""
    rng = np.random.default_rng(5)
    steps, samples = 50, 10
    env = gym.make(LAUNCHER, plant="linear", sensor_noise=0.0, reference="zero")
    env.reset(seed=1)
    sent = np.concatenate([rng.uniform(-1.2, 1.2, (10, 1)), rng.uniform(-0.3, 0.3, (steps - 10, 1))])
    sent = sent.astype(np.float32)
    observed = np.array([env.step(a)[0] for a in sent], dtype=np.float64)

    j, b, k = linear_joint()
    omega, zeta = 2 * math.pi * 15.0, 0.7
    k_p, k_d = j * omega**2 - k, 2 * zeta * j * omega - b
    k_ff = k + k_p
    h = LAUNCHER_LAYOUT.dt / samples
    system = (np.array([[0.0, 1.0], [-k / j, -b / j]]), np.array([[0.0], [1.0 / j]]),
              np.eye(2), np.zeros((2, 1)))  # fmt: skip
    ad, bd, *_ = scipy.signal.cont2discrete(system, h, method="zoh")
    state = np.zeros(2)
    deflection = [0.0]
    for a in np.clip(sent[:, 0].astype(np.float64), -1.0, 1.0):
        for _ in range(samples):
            tau = min(max(k_ff * a * math.radians(3.0) - k_p * state[0] - k_d * state[1], -3e4), 3e4)
            state = ad @ state + bd[:, 0] * tau
            deflection.append(state[0])
    times = h * np.arange(len(deflection))
    body = (np.array([[0.0, 1.0], [3.0, 0.0]]), np.array([[0.0], [12.0]]), np.eye(2), np.zeros((2, 1)))
    _, y, _ = scipy.signal.lsim(body, np.array(deflection), times, interp=True)
    expected = DEG * np.column_stack([y[samples::samples, 0], y[samples::samples, 1],
                                      np.array(deflection)[samples::samples]])  # fmt: skip
    got = observed[:, [0, 1, 5]]
    tol = 1e-4 * np.max(np.abs(expected), axis=0)
    assert np.all(np.abs(got - expected) < tol), (np.abs(got - expected).max(axis=0), tol)
    assert np.max(np.abs(expected[:, 0])) > 0.5  # the attitude moved (deg): the check has teeth
