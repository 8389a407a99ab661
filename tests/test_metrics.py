"""Saturation and limit-cycle metrics: hand-made trajectories, brute-force counts, simulated loops
(backlash under PI control, noise through a damped loop), and the env's own record of its
actuator through the evaluation harness."""

import math

import numpy as np
import pytest
import scipy.signal
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from agents import parse_controller
from ssme_envs.envs.catalogue import spec
from ssme_envs.evaluation import evaluate, layout_of
from ssme_envs.metrics import limit_cycle, saturation_fraction
from ssme_envs.models.engine import TruthConfig

DT = 0.04  # s, a sample time (the detector's periods scale with it)
# the engine's sensor noise (a fraction of full scale) in the observations' percent
SENSOR_NOISE = 100 * max(TruthConfig().sensor_noise)
SETTINGS = settings(max_examples=60, deadline=None, derandomize=True)


# ---- saturation -------------------------------------------------------------------------------


def test_saturation_fraction_by_hand():
    actions = np.array(
        [
            [1.0, -1.0, 0.3],
            [1.0, 0.0, 1.0],  # episode 3 has ended: its 1.0 does not count
            [0.5, 1.0, 1.0],
            [-1.0, 1.0, 1.0],
            [1.0 - 1e-7, 1.0, 1.0],  # within the tolerance: at the limit
            [0.99, 1.0, 1.0],  # 1 % short: not at the limit
            [-0.2, 1.0, 1.0],
            [1.0, 1.0, 1.0],
        ]
    )
    alive = np.zeros(actions.shape, dtype=bool)
    alive[:, 0] = True
    alive[:3, 1] = True  # ends after 3 steps
    alive[:1, 2] = True  # ends after 1
    fraction = saturation_fraction(actions, alive)
    np.testing.assert_allclose(fraction, [5 / 8, 2 / 3, 0.0])


def test_saturation_fraction_of_one_episode_and_another_limit():
    a = np.array([0.5, -0.5, 0.2, 0.49, 0.5])
    assert float(saturation_fraction(a, np.ones(5, dtype=bool), limit=0.5)) == pytest.approx(3 / 5)
    assert float(saturation_fraction(a, np.ones(5, dtype=bool))) == 0.0


@SETTINGS
@given(
    seed=st.integers(0, 2**32 - 1),
    steps=st.integers(1, 60),
    episodes=st.integers(1, 6),
    scale=st.floats(0.1, 3.0),
)
def test_saturation_fraction_equals_a_brute_force_count(seed, steps, episodes, scale):
    rng = np.random.default_rng(seed)
    # the env's clip: draws beyond full scale land exactly on it
    actions = np.clip(scale * rng.standard_normal((steps, episodes)), -1.0, 1.0)
    lengths = rng.integers(1, steps + 1, size=episodes)
    alive = np.arange(steps)[:, None] < lengths[None, :]
    expected = []
    for i in range(episodes):
        at_limit = sum(1 for k in range(lengths[i]) if actions[k, i] in (-1.0, 1.0))
        expected.append(at_limit / lengths[i])
    np.testing.assert_allclose(saturation_fraction(actions, alive), expected, rtol=0, atol=1e-15)


@pytest.mark.parametrize(
    ("actions", "alive", "kwargs", "error", "match"),
    [
        (np.zeros((3, 2)), np.ones((3, 1), dtype=bool), {}, ValueError, "same shape"),
        (np.zeros((3, 2)), np.ones((3, 2)), {}, TypeError, "boolean"),
        (np.full((3, 2), np.nan), np.ones((3, 2), dtype=bool), {}, ValueError, "NaN"),
        (np.zeros((3, 2)), np.array([[True, False]] * 3), {}, ValueError, "no alive step"),
        (np.zeros((3, 2)), np.ones((3, 2), dtype=bool), {"limit": 0.0}, ValueError, "limit"),
        (np.zeros((3, 2)), np.ones((3, 2), dtype=bool), {"tol": 1.0}, ValueError, "tol"),
    ],
)
def test_saturation_fraction_rejects_bad_input(actions, alive, kwargs, error, match):
    with pytest.raises(error, match=match):
        saturation_fraction(actions, alive, **kwargs)


def test_a_dead_step_may_hold_anything():
    actions = np.array([[1.0], [np.nan]])
    assert float(saturation_fraction(actions, np.array([[True], [False]]))[0]) == 1.0


# ---- limit cycles: synthetic signals ----------------------------------------------------------


def _zero_crossing_period(x: np.ndarray, dt: float) -> float | None:
    """Mean interval between the upward zero crossings of x less its mean, s."""
    x = x - x.mean()
    up = np.flatnonzero((x[:-1] < 0) & (x[1:] >= 0))
    return float(np.diff(up).mean() * dt) if len(up) > 2 else None


def _backlash_loop(kp, ki, tau, width, noise, seed, steps=2000, dt=DT):
    """Unit step response of PI control of 1 / (s (tau s + 1)) through a backlash (play) of total
    width, the sensor adding white noise; explicit Euler over 10 substeps. Returns the true output
    and the measured error."""
    rng = np.random.default_rng(seed)
    y = v = integral = out = 0.0
    ys, errors = np.empty(steps), np.empty(steps)
    for k in range(steps):
        e = 1.0 - (y + noise * rng.standard_normal())
        integral += ki * e * dt
        u = kp * e + integral
        if u > out + width / 2:
            out = u - width / 2
        elif u < out - width / 2:
            out = u + width / 2
        for _ in range(10):
            v += (out - v) / tau * dt / 10
            y += v * dt / 10
        ys[k], errors[k] = y, e
    return ys, errors


@SETTINGS
@given(
    kp=st.floats(2.0, 4.0),
    ki=st.floats(2.0, 4.0),
    tau=st.floats(0.15, 0.3),
    width=st.floats(0.01, 0.1),
    noise=st.floats(0.005, 0.025),
    seed=st.integers(0, 2**16),
)
def test_a_backlash_limit_cycle_is_found_with_its_period(kp, ki, tau, width, noise, seed):
    # PI on an integrating plant is stable here (kp > tau ki); the backlash makes it hunt with an
    # amplitude of about half its width and a period the width does not change
    ys, errors = _backlash_loop(kp, ki, tau, width, 0.0, seed)
    period = _zero_crossing_period(ys[1000:], DT)
    assume(period is not None)  # the loop has settled into a cycle (it may also stop in the play)
    alive = np.arange(len(ys)) >= 1000  # the cycle established, the approach left out
    found = limit_cycle(errors, alive, DT, settle=0.0)
    assert found.found
    assert found.period == pytest.approx(period, rel=0.03)
    # sine-equivalent amplitude: between a triangle's (0.82) and a square's (1.41) half swing
    assert 0.7 < found.amplitude / (np.ptp(ys[1000:]) / 2) < 1.45
    # sensor noise up to 2.5 % of the half play shortens the cycle but leaves it regular (more
    # dithers it into an irregular hunt)
    ys, errors = _backlash_loop(kp, ki, tau, width, noise * width / 2, seed)
    period = _zero_crossing_period(ys[1000:], DT)
    assume(period is not None)
    noisy = limit_cycle(errors, alive, DT, settle=0.0)
    assert noisy.found
    assert noisy.period == pytest.approx(period, rel=0.1)


@SETTINGS
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(120, 1200),
    cycles=st.floats(3.6, 40.0),
    noise=st.floats(0.0, 1 / 3),
    square=st.booleans(),
)
def test_a_periodic_signal_in_noise_is_found_with_its_period_and_amplitude(seed, n, cycles, noise, square):
    rng = np.random.default_rng(seed)
    window = n - n // 4  # after the default settle
    samples = window / cycles
    assume(samples >= 4)
    t = np.arange(n)
    wave = np.sin(2 * np.pi * t / samples + rng.uniform(0, 2 * np.pi))
    wave = np.sign(wave) if square else wave
    signal = 5.0 + 0.01 * t + wave + noise * rng.standard_normal(n)  # offset and drift detrended
    found = limit_cycle(signal, np.ones(n, dtype=bool), DT)
    assert found.found and found.tested
    assert found.period == pytest.approx(samples * DT, rel=0.05)
    # the sine of the same power: amplitude 1 for the sine, sqrt(2) for the square wave
    assert found.amplitude == pytest.approx(math.sqrt(2) if square else 1.0, rel=0.15)


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(10, 2000))
def test_white_noise_at_the_sensor_level_is_no_limit_cycle(seed, n):
    noise = SENSOR_NOISE * np.random.default_rng(seed).standard_normal(n)
    found = limit_cycle(noise, np.ones(n, dtype=bool), DT)
    assert not found.found and found.period is None and found.amplitude is None
    assert found.tested == (n - n // 4 >= 40)


@SETTINGS
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(60, 1500),
    decay=st.floats(math.log(3), 12.0),
    cycles=st.floats(1.0, 60.0),
    noise=st.floats(0.0, 0.1),
    oscillating=st.booleans(),
)
def test_a_decaying_response_is_no_limit_cycle(seed, n, decay, cycles, noise, oscillating):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / (n - n // 4)  # in analysed windows
    # the amplitude falls by e^decay >= 3 over the analysed window
    envelope = np.exp(-decay * t)
    shape = np.cos(2 * np.pi * cycles * t + rng.uniform(0, 2 * np.pi)) if oscillating else 1.0
    signal = envelope * shape + noise * rng.standard_normal(n)
    assert not limit_cycle(signal, np.ones(n, dtype=bool), DT).found


@SETTINGS
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(100, 1500),
    zeta=st.floats(0.3, 1.0),
    cycles=st.floats(8.0, 100.0),
    white=st.floats(0.0, 1.0),
)
def test_noise_through_a_damped_loop_is_no_limit_cycle(seed, n, zeta, cycles, white):
    # sensor noise filtered by a closed loop of damping zeta, seen over 8 or more of its periods
    # (the test two periods on separates it from a cycle), plus white noise on top
    rng = np.random.default_rng(seed)
    period = (n - n // 4) / cycles * DT
    assume(period >= 4 * DT)
    wn = 2 * np.pi / period / math.sqrt(max(1 - zeta**2, 1e-2))
    num, den, _ = scipy.signal.cont2discrete(([wn**2], [1, 2 * zeta * wn, wn**2]), DT)
    colored = scipy.signal.lfilter(num.ravel(), den, rng.standard_normal(n + 2000))[2000:]
    signal = SENSOR_NOISE * (colored + white * rng.standard_normal(n))
    assert not limit_cycle(signal, np.ones(n, dtype=bool), DT).found


def test_a_loop_ringing_on_its_noise_is_mostly_told_from_a_limit_cycle():
    # damping 0.05-0.1: the correlation one period on passes (0.5-0.7), two periods on it
    # mostly fails; such a loop oscillates all but persistently, so some are named
    rng = np.random.default_rng(0)
    named = []
    for _ in range(200):
        n = int(rng.integers(300, 1500))
        zeta, cycles = rng.uniform(0.05, 0.1), rng.uniform(20, 60)
        period = (n - n // 4) / cycles * DT
        wn = 2 * np.pi / period / math.sqrt(1 - zeta**2)
        num, den, _ = scipy.signal.cont2discrete(([wn**2], [1, 2 * zeta * wn, wn**2]), DT)
        ringing = scipy.signal.lfilter(num.ravel(), den, rng.standard_normal(n + 3000))[3000:]
        named.append(limit_cycle(ringing, np.ones(n, dtype=bool), DT).found)
    assert np.mean(named) < 0.35


def test_windows_follow_the_reference_and_the_episode():
    rng = np.random.default_rng(3)
    steps, end = 700, 650
    reference = np.where(np.arange(steps) < 400, 1.0, 2.0)
    signal = 0.05 * rng.standard_normal(steps)
    signal[400:410] += 20.0 * np.exp(-np.arange(10))  # the step's transient, left to the settle share
    signal[400:end] += np.sin(2 * np.pi * np.arange(end - 400) / 16)  # the cycle after the step
    signal[end:] = np.nan  # the episode has ended: never read
    alive = np.arange(steps) < end
    found = limit_cycle(signal, alive, DT, reference)
    assert found.found and found.period == pytest.approx(16 * DT, rel=0.03)
    # before the step: noise only, tested for periods up to a third of its last 300 samples
    before = limit_cycle(signal[:400], alive[:400], DT, reference[:400])
    assert before == (False, True, None, None, 0.0, 100 * DT)
    # a reference that changes too often leaves nothing long enough to test
    hopping = np.repeat(np.arange(steps // 20), 20).astype(float)
    assert not limit_cycle(signal, alive, DT, hopping).tested


@pytest.mark.parametrize(
    ("args", "kwargs", "error", "match"),
    [
        ((np.zeros(50), np.ones(49, dtype=bool), DT), {}, ValueError, "same shape"),
        ((np.zeros(50), np.ones(50), DT), {}, TypeError, "boolean"),
        ((np.full(50, np.nan), np.ones(50, dtype=bool), DT), {}, ValueError, "NaN"),
        ((np.zeros(50), np.ones(50, dtype=bool), 0.0), {}, ValueError, "dt"),
        ((np.zeros(50), np.ones(50, dtype=bool), DT, np.zeros(49)), {}, ValueError, "reference"),
        ((np.zeros(50), np.ones(50, dtype=bool), DT), {"settle": 1.0}, ValueError, "settle"),
        ((np.zeros(50), np.ones(50, dtype=bool), DT), {"min_samples": 4}, ValueError, "min_samples"),
    ],
)
def test_limit_cycle_rejects_bad_input(args, kwargs, error, match):
    with pytest.raises(error, match=match):
        limit_cycle(*args, **kwargs)


# ---- through the evaluation harness ------------------------------------------------------------


def _schedule(k: int) -> float:
    """A torque command that alternates fast enough to keep the nozzle in its envelope: +-1.3
    of full scale, every third one halved."""
    return 1.3 * math.sin(2 * math.pi * k / 4) * (0.5 if k % 3 == 0 else 1.0)


class _Schedule:
    """:func:`_schedule` for every episode, clipped to +-1 by the controller itself when ``clip``."""

    def __init__(self, clip: bool) -> None:
        self.clip = clip

    def reset(self, seed=None, num_envs=1, envs=None):
        self.k = 0

    def act(self, obs, info=None):
        a = _schedule(self.k)
        self.k += 1
        return np.full((len(obs), 1), min(max(a, -1.0), 1.0) if self.clip else a)


def test_time_at_limit_is_what_the_nozzle_applied():
    env_id = "ssme_envs/NozzleTVC-v0"
    controllers = {
        "zero": parse_controller("zero", env_id),
        "overdrive": lambda env: _Schedule(clip=False),
        "self_clipped": lambda env: _Schedule(clip=True),  # requests no more than full scale
    }
    result = evaluate(env_id, controllers, ["step"], episodes=2)
    # the env's own record of the torque it applied, a fraction of full scale
    torque = spec(env_id).observation.index("prev_action")
    for name in controllers:
        run = result.rollouts[("step", name)]
        lengths = run.alive.sum(axis=0)
        recount = np.mean([np.mean(np.abs(run.obs[1 : lengths[i] + 1, i, torque]) >= 1.0) for i in range(2)])
        at_limit = result["step"][name].actuators["torque"].time_at_limit
        assert at_limit == pytest.approx(recount, abs=1e-12)
        if name != "zero":  # and the schedule's share beyond full scale over each episode's steps
            beyond = [abs(_schedule(k)) >= 1.0 for k in range(len(run.alive))]
            assert at_limit == pytest.approx(np.mean([np.mean(beyond[:n]) for n in lengths]), abs=1e-12)
            assert at_limit > 0.3
            assert (np.abs(run.requested) > 1.0).any() == (name == "overdrive")
    assert result["step"]["zero"].actuators["torque"].time_at_limit == 0.0


class _IntegratingRelay:
    """OPOV moves a fixed step with the sign of the Pc error each sample (an integrating relay):
    the loop hunts."""

    def __init__(self, step: float, column: int) -> None:
        self.step, self.column = step, column

    def reset(self, seed=None, num_envs=1, envs=None):
        self.a = np.zeros((num_envs, 2))

    def act(self, obs, info=None):
        self.a[:, 0] += self.step * np.sign(obs[:, self.column])
        return self.a.copy()


def test_a_relay_limit_cycle_is_named_by_the_metrics():
    env_id = "ssme_envs/EngineTracking-v0"
    layout = layout_of(env_id)
    pc_error = layout.error_columns[layout.outputs.index("Pc")]
    result = evaluate(
        env_id, {"relay": lambda env: _IntegratingRelay(0.03, pc_error)}, ["pc_step"], episodes=4
    )
    run, pc = result.rollouts[("pc_step", "relay")], result["pc_step"]["relay"].outputs["Pc"]
    assert pc.limit_cycle_fraction == 1.0
    # the last third of each episode, well after its step
    tails = run.obs[-len(run.obs) // 3 :, :, pc_error]
    periods = [_zero_crossing_period(tails[:, i], run.dt) for i in range(4)]
    assert pc.limit_cycle_period == pytest.approx(np.median(periods), rel=0.1)
    assert 0.7 < pc.limit_cycle_amplitude / np.median(np.ptp(tails, axis=0) / 2) < 1.45


# cont2discrete's numerator of a strictly proper TF leads with a round-off zero, which scipy's
# normalize warns of as it drops it: the response is exact
@pytest.mark.filterwarnings("ignore::scipy.signal.BadCoefficients")
@settings(deadline=None, max_examples=30)
@given(
    at=st.integers(1, 60),
    size=st.floats(0.2, 2.0) | st.floats(-2.0, -0.2),
    base=st.floats(-1.0, 1.0),
    zeta=st.floats(0.2, 1.2),
    wn=st.floats(2.0, 8.0),
)
def test_step_response_windows_each_episode_at_its_reference_step(at, size, base, zeta, wn):
    """A rollout's output is a second-order step response (scipy, zero-order hold) that starts
    with the first observation of the new reference, offset by a baseline: its metrics are
    python-control's step_info of that response, normalized by the reference step; episodes with
    two reference steps or an early end do not count."""
    import control

    from ssme_envs.metrics import step_response

    dt, horizon = 0.04, 200
    system = scipy.signal.cont2discrete(([wn * wn], [1.0, 2 * zeta * wn, wn * wn]), dt)
    unit = np.ravel(scipy.signal.dstep((*system[:2], dt), n=horizon + 1 - at)[1][0])
    unit = np.concatenate([unit[1:], unit[-1:]])  # a sample after the step: the response has begun
    t = np.arange(1, horizon + 1) * dt  # the time of each step's observation (rows 1..T)
    r = np.zeros((horizon + 1, 3))
    r[at + 1 :] = size
    r[at + 30 :, 1] = 0.0  # episode 1: a second step
    y = np.full((horizon, 3), base)
    y[at:] = base + size * unit[: horizon - at, None]  # y row j is the observation of step j + 1
    y[:, 1] += 5.0
    alive = np.ones((horizon, 3), dtype=bool)
    alive[-1, 2] = False  # episode 2 ended before the horizon
    ours = step_response(t, y, r, alive)
    theirs = control.step_info(unit[: horizon - at], T=t[at:] - t[at], yfinal=1.0)
    assert ours["rise_time"] == pytest.approx(theirs["RiseTime"], abs=1e-9, nan_ok=True)
    assert ours["settling_time"] == pytest.approx(theirs["SettlingTime"], abs=1e-9, nan_ok=True)
    assert ours["overshoot"] == pytest.approx(theirs["Overshoot"], abs=1e-7)
