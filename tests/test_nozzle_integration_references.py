"""NozzleTVC-v0's RK4 substep rule judged by its purpose: the env's angle against an independent
integration of the documented joint, for joints across the range the envs accept.

The joint (NozzleTVC's docstring, Table 1's form of the nozzle paper, eqs 4-5):

    J x'' + b x' + a k x + (1 - a) k z = tau,    z' = A x' - |z|^n (beta + gamma sign(x' z)) x',

with the torque tau = action x 3e4 N m held over each 8 ms step (no actuator lag, no rate
limit), integrated here by scipy's ``solve_ivp`` (DOP853, or Radau with the analytic Jacobian
for the stiff joints near the refusal limit) restarted at every change of the torque: never the
package's RK4, its substep rule or its normalization.

The claims under test, and their units (an error is ``max_k |x_env(k) - x_ref(k)| / max_k
|x_ref(k)|``, relative to the motion, as in experiments/results/nozzle_integration_accuracy.md,
over the steps the env runs: until its episode ends, which the first step beyond the 6 deg
envelope does, and which the rule sizes for):

- nozzle_plants.py, of the env's own rule (``h * rate <= ENV_STEP_RATE = 0.25``): the linear and
  the strong joints within 3e-4 of the motion (ENV_CLAIM); Table 1's Bouc-Wen joint on any
  torque within half the default sensor noise on a 3 deg motion (BOUC_WEN_CLAIM: 3e-4 held only
  on the PRBS test it was first measured on), ten seeded joints drawn around it within the sensor
  noise (DRAWN_CLAIM); a drawn joint can do worse: the kink of the Bouc-Wen law at velocity
  reversals sets RK4's error there, which the rule's rate (the natural frequency) does not count.
  NozzleTVC's docstring says the same.
- nozzle_substeps.recommended_substeps, at its default ``step_rate = 0.2``: "about 2e-4" on the
  +-3 deg PRBS test (RULE_CLAIM, read as < 2.5e-4), within BOUC_WEN_CLAIM on other torques.

The angle is the observation's (noise off), float32 in degrees: a relative rounding of 6e-8, far
below both claims. A non-finite state shows as ``info["nonfinite"]`` (the observation is
sanitized), which no comparison here may see.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

import ssme_envs  # noqa: F401  (registers the env ids)
from ssme_envs.models.nozzle import (
    MAX_SUBSTEPS,
    NozzleParameters,
    published_nozzle,
    recommended_substeps,
    strong_nozzle,
)

NOZZLE, LAUNCHER = "ssme_envs/NozzleTVC-v0", "ssme_envs/LauncherPitch-v0"
DT = 0.008  # s, the env step (NozzleTVC docstring)
FULL_SCALE = 3.0e4  # N m, the action's full scale (NozzleTVC docstring)
ENV_CLAIM = 3e-4  # relative to the motion, the env's rule at h * rate <= 0.25 (nozzle_plants.py)
RULE_CLAIM = 2.5e-4  # "about 2e-4", recommended_substeps at step_rate 0.2, on the PRBS test
# Where the Bouc-Wen law's kink at velocity reversals sets RK4's error (a rate the rule does not
# count), the docs bound it by the env's default sensor noise (1e-4 rad) on a 3 deg motion, not
# by a figure measured on the env: Table 1's joint within half of it on any torque, joints drawn
# around it within all of it (a drawn joint can do worse; the seeded ten below do not)
SENSOR_NOISE_ON_3_DEG = 1e-4 / math.radians(3.0)  # 1.9e-3 of the motion
BOUC_WEN_CLAIM = 0.5 * SENSOR_NOISE_ON_3_DEG
DRAWN_CLAIM = SENSOR_NOISE_ON_3_DEG
FEW = settings(max_examples=6, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])

TABLE1 = published_nozzle("bouc_wen")
TABLE1_LINEAR = published_nozzle("linear")
STRONG = strong_nozzle()
STRONG_LINEAR = NozzleParameters.linear(STRONG.J, STRONG.b, 1.6e5)  # its stiffness at rest: a k + (1-a) k A


# ------------------------------------------------------------------ the independent reference


def joint_rhs(p: NozzleParameters) -> tuple[Callable, Callable]:
    """The documented joint in Table 1's form (state x, x', z), and its Jacobian where sign(x' z)
    is fixed (for Radau)."""
    el, hys = p.a * p.k, (1.0 - p.a) * p.k

    def rhs(_t: float, s: np.ndarray, tau: float) -> list[float]:
        x, v, z = s
        c = p.beta + math.copysign(p.gamma, v * z) if v * z != 0.0 else p.beta
        return [v, (tau - p.b * v - el * x - hys * z) / p.J, p.A * v - abs(z) ** p.n * c * v]

    def jac(_t: float, s: np.ndarray, tau: float) -> list[list[float]]:
        _, v, z = s
        c = p.beta + math.copysign(p.gamma, v * z) if v * z != 0.0 else p.beta
        dz_dz = -p.n * abs(z) ** (p.n - 1.0) * math.copysign(1.0, z) * c * v if z != 0.0 else 0.0
        return [[0.0, 1.0, 0.0], [-el / p.J, -p.b / p.J, -hys / p.J], [0.0, p.A - abs(z) ** p.n * c, dz_dz]]

    return rhs, jac


def reference_angles(p: NozzleParameters, torques: np.ndarray, stiff: bool = False) -> np.ndarray:
    """x (rad) at the end of each step from rest, torques[k] (N m) held over step k; one
    ``solve_ivp`` per run of equal torques, evaluated at the step ends."""
    rhs, jac = joint_rhs(p)
    options = (
        {"method": "Radau", "jac": jac, "rtol": 1e-9, "atol": 1e-13}
        if stiff
        else {"method": "DOP853", "rtol": 1e-11, "atol": 1e-14}
    )
    state, out, k = np.zeros(3), [], 0
    while k < len(torques):
        end = k + 1
        while end < len(torques) and torques[end] == torques[k]:
            end += 1
        times = DT * np.arange(end - k + 1)
        sol = solve_ivp(rhs, (0.0, times[-1]), state, args=(float(torques[k]),), t_eval=times, **options)
        assert sol.success, sol.message
        out.extend(sol.y[0, 1:])
        state = sol.y[:, -1]
        k = end
    return np.array(out)


def test_the_reference_is_converged():
    """The reference's own error is far below the claims: DOP853 at rtol 1e-11 against 1e-13
    (and Radau at rtol 1e-9), across velocity reversals of Table 1's joint."""
    torques = FULL_SCALE * piecewise(np.random.default_rng(0), 120, 0.17)
    fine = reference_angles(TABLE1, torques)
    rhs, _ = joint_rhs(TABLE1)
    state, finer = np.zeros(3), []
    for tau in torques:
        state = solve_ivp(rhs, (0, DT), state, args=(tau,), method="DOP853", rtol=1e-13, atol=1e-16).y[:, -1]
        finer.append(state[0])
    scale = np.max(np.abs(finer))
    assert scale > math.radians(1.0)
    assert np.max(np.abs(fine - finer)) < 1e-8 * scale
    assert np.max(np.abs(reference_angles(TABLE1, torques, stiff=True) - finer)) < 1e-7 * scale


# ------------------------------------------------------------------ torques (fractions of full scale)


def piecewise(
    rng: np.random.Generator, steps: int, level: float, hold: tuple[int, int] = (1, 9)
) -> np.ndarray:
    """Uniform levels in +-level held 1-8 steps, as float32 actions (what the env receives)."""
    out: list[float] = []
    while len(out) < steps:
        out += [rng.uniform(-level, level)] * int(rng.integers(*hold))
    return np.array(out[:steps], dtype=np.float32).astype(np.float64)


def bang_bang(rng: np.random.Generator, steps: int) -> np.ndarray:
    """+-1 (the torque limit), one step of +1 then alternating holds of 1 or 2 steps."""
    out, sign = [1.0], -1.0
    while len(out) < steps:
        out += [sign] * int(rng.integers(1, 3))
        sign = -sign
    return np.array(out[:steps])


@functools.cache
def prbs_3deg(p: NozzleParameters, seed: int, steps: int) -> np.ndarray:
    """A random binary sequence clocked every 2 steps (16 ms), scaled so that the reference's
    peak is 3 deg: the test of experiments/nozzle_integration_accuracy.py."""
    unit = np.repeat(np.random.default_rng(seed).choice([-1.0, 1.0], steps // 2 + 1), 2)[:steps]
    level = 0.05
    for _ in range(2):  # the joint is not linear: rescale on the reference (to within 0.1 %)
        level *= math.radians(3.0) / np.max(np.abs(reference_angles(p, FULL_SCALE * level * unit)))
    out = (np.float32(level) * unit).astype(np.float64)
    out.setflags(write=False)
    return out


def static_level(p: NozzleParameters, degrees: float) -> float:
    """The torque (fraction of full scale) that holds the joint at ``degrees`` after loading from
    rest: a k x plus the hysteretic (1 - a) k z, z at most its saturation (beta + gamma)^(-1/n)."""
    x = math.radians(degrees)
    z_max = (p.beta + p.gamma) ** (-1.0 / p.n) if p.beta + p.gamma > 0 and p.a < 1 else math.inf
    return min(1.0, (p.a * p.k * x + (1.0 - p.a) * p.k * min(p.A * x, z_max)) / FULL_SCALE)


def signal(p: NozzleParameters, kind: str, seed: int, steps: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    if kind == "bang":
        return bang_bang(rng, steps)
    return piecewise(rng, steps, static_level(p, 2.0))


# ------------------------------------------------------------------ the env and the comparison


def env_angles(
    p: NozzleParameters, actions: np.ndarray, substeps: int | None = None
) -> tuple[np.ndarray, int]:
    """The env's true angle (rad, the noise-free observation) after each step until the episode
    ends, and the substeps it ran. Asserts no step came out non-finite."""
    options = {} if substeps is None else {"substeps": substeps}
    env = gym.make(NOZZLE, plant=p, sensor_noise=0.0, reference="zero", **options)
    env.reset(seed=0)
    angles = []
    for a in actions:
        obs, _, terminated, truncated, info = env.step(np.array([a], dtype=np.float32))
        assert "nonfinite" not in info and np.all(np.isfinite(obs)), (len(angles), info)
        angles.append(math.radians(float(obs[0])))
        if terminated or truncated:
            break
    return np.array(angles), env.unwrapped.task.substeps


def relative_error(angles: np.ndarray, ref: np.ndarray) -> float:
    """max |x_env - x_ref| / max |x_ref| over the steps the env ran (the one that leaves the
    envelope included: the rule sizes for the travel within it), up to the first beyond the
    observation's 20 deg bound (clipped there)."""
    shown = np.abs(ref[: len(angles)]) < math.radians(19.0)
    n = len(angles) if shown.all() else int(np.argmin(shown))
    assert n > 0, "the first step already passes the observation's bound"
    return float(np.max(np.abs(angles[:n] - ref[:n])) / np.max(np.abs(ref[:n])))


def run_and_compare(p: NozzleParameters, actions: np.ndarray, substeps: int | None = None,
                    stiff: bool = False) -> tuple[float, int]:  # fmt: skip
    angles, count = env_angles(p, actions, substeps)
    ref = reference_angles(p, FULL_SCALE * np.clip(actions[: len(angles)], -1.0, 1.0), stiff)
    assert np.all(np.isfinite(ref))
    return relative_error(angles, ref), count


def horizon(count: int, steps: int = 200) -> int:
    """Steps to run: fewer for joints that need many substeps (pure-Python RK4: ~5 us each)."""
    return max(25, min(steps, 30_000 // count))


# ------------------------------------------------------------------ 1. the documented accuracy


@pytest.mark.parametrize(
    "plant", [TABLE1, TABLE1_LINEAR, STRONG_LINEAR], ids=["table1", "linear", "strong_linear"]
)
def test_recommended_substeps_meet_about_2e_4_on_the_documented_prbs_test(plant):
    """recommended_substeps' claim in its own regime: its count at step_rate 0.2 for a 3 deg
    motion (4 for all three), run through the env (substeps=), on six +-3 deg PRBS tests of 300
    steps. (The strong nozzle's count at 0.2, 10, is below the env's stability rule's 24: refused,
    so only the env's count is tested for it.) Measured: Table 1 1.3e-4 to 2.4e-4; the linear
    joints <= 9e-5."""
    substeps = recommended_substeps(plant, DT, math.radians(3.0))
    errors = [run_and_compare(plant, prbs_3deg(plant, seed, 300), substeps)[0] for seed in range(6)]
    assert max(errors) < RULE_CLAIM, errors


def test_recommended_substeps_beyond_the_prbs_test_meet_the_bouc_wen_claim():
    """At step_rate 0.2 (4 substeps for Table 1), random piecewise-constant torques and bang-bang
    at the torque limit: up to 7.1e-4 (not 2e-4: the Bouc-Wen error is set by the velocity
    reversals, and not monotone in the count: one seed gives 2.6e-4 at 3 substeps, 7.1e-4 at 4)."""
    substeps = recommended_substeps(TABLE1, DT, math.radians(3.0))
    errors = [run_and_compare(TABLE1, signal(TABLE1, kind, seed, 200), substeps)[0]
              for kind in ("piecewise", "bang") for seed in range(8)]  # fmt: skip
    assert max(errors) < BOUC_WEN_CLAIM, errors
    assert max(errors) > RULE_CLAIM, errors  # the PRBS figure is not the bound on other torques


def test_the_envs_count_for_table_1_meets_the_bouc_wen_claim():
    """The env's 3 substeps on Table 1's joint: six +-3 deg PRBS tests (2.3e-4 to 3.5e-4), random
    piecewise-constant torques (1.1e-4 to 5.5e-4) and bang-bang at the torque limit (up to
    7.2e-4): within BOUC_WEN_CLAIM."""
    errors = [run_and_compare(TABLE1, prbs_3deg(TABLE1, seed, 300))[0] for seed in range(6)]
    errors += [run_and_compare(TABLE1, signal(TABLE1, kind, seed, 200))[0]
               for kind in ("piecewise", "bang") for seed in range(8)]  # fmt: skip
    assert max(errors) <= BOUC_WEN_CLAIM, errors


@pytest.mark.parametrize(
    "plant", [TABLE1_LINEAR, STRONG_LINEAR, STRONG], ids=["linear", "strong_linear", "strong"]
)
@pytest.mark.parametrize("kind", ["piecewise", "bang"])
def test_the_envs_count_meets_3e_4_on_the_other_presets(plant, kind):
    """The env's default count, random torques within the working range and bang-bang at the
    torque limit, four seeds each: the linear joints (their count, 3, set by the accuracy rule)
    and the strong nozzle (24, set by the stability rule; the accuracy rule alone asks for 16).
    Measured: linear <= 1e-4, strong_linear <= 2.1e-4, strong <= 5e-5."""
    for seed in range(4):
        error, _ = run_and_compare(plant, signal(plant, kind, seed, 200))
        assert error <= ENV_CLAIM, (seed, error)


# ------------------------------------------------------------------ drawn joints


def spread_factor() -> st.SearchStrategy[float]:
    """exp(s z), s = 0.5 (plant_spread's largest), z in its +-3 truncation."""
    return st.floats(-3.0, 3.0).map(lambda z: math.exp(0.5 * z))


def linear_joint(base: NozzleParameters, f: list[float]) -> NozzleParameters:
    """``base`` (linear) with J, b, k times the factors f."""
    return NozzleParameters.linear(base.J * f[0], base.b * f[1], base.k * f[2])


def bouc_wen_joint(base: NozzleParameters, f: list[float], n: float) -> NozzleParameters:
    """``base`` with J, b, the elastic and the hysteretic stiffness (a k, (1 - a) k), beta and
    gamma times the factors f, and the exponent n."""
    k_el, k_hys = base.a * base.k * f[2], (1.0 - base.a) * base.k * f[3]
    k = k_el + k_hys
    return NozzleParameters(J=base.J * f[0], b=base.b * f[1], k=k, a=k_el / k, A=base.A,
                            beta=base.beta * f[4], gamma=base.gamma * f[5], n=n)  # fmt: skip


LINEAR_JOINTS = st.builds(
    linear_joint,
    st.sampled_from([TABLE1_LINEAR, STRONG_LINEAR]),
    st.lists(spread_factor(), min_size=3, max_size=3),
)
STRONG_JOINTS = st.builds(
    bouc_wen_joint, st.just(STRONG), st.lists(spread_factor(), min_size=6, max_size=6), st.floats(1.0, 2.5)
)
TABLE1_JOINTS = st.builds(
    bouc_wen_joint, st.just(TABLE1), st.lists(spread_factor(), min_size=6, max_size=6), st.floats(0.7, 2.5)
)
KINDS = st.sampled_from(["piecewise", "bang"])
SEEDS = st.integers(0, 2**32 - 1)


def built_count(p: NozzleParameters) -> int:
    """The env's count for p; a refused joint (more than MAX_SUBSTEPS) is not drawn."""
    try:
        env = gym.make(NOZZLE, plant=p)
    except ValueError as exc:
        assert "RK4 substeps" in str(exc)
        assume(False)
    return env.unwrapped.task.substeps


def accepted(p: NozzleParameters, substeps: int) -> bool:
    """Whether the env takes ``substeps`` for ``p`` (it refuses fewer than its stability rule)."""
    try:
        gym.make(NOZZLE, plant=p, substeps=substeps)
    except ValueError as exc:
        assert "too few" in str(exc)
        return False
    return True


def check_waste(p: NozzleParameters, actions: np.ndarray, count: int, error: float) -> None:
    """2. Not wasteful: with half the substeps (where the env accepts them) the error grows and
    is no longer far inside the claim. A rule wasteful by a factor F would leave, at half its
    count, about ENV_CLAIM (2 / F)^4 (RK4's 4th order; (2 / F)^2 at Bouc-Wen's reversals):
    ENV_CLAIM / 10 catches F >= 3.6 (F >= 6.3 at second order)."""
    half = count // 2
    if half < 1 or not accepted(p, half):
        return
    half_error, _ = run_and_compare(p, actions, half)
    assert half_error > error, (count, error, half_error)
    assert half_error > ENV_CLAIM / 10, (count, error, half_error)


def check_drawn(joint: NozzleParameters, kind: str, seed: int, claim: float) -> None:
    """The env's count on ``joint``: finite, within ``claim``, and not wasteful (check_waste)."""
    count = built_count(joint)
    actions = signal(joint, kind, seed, horizon(count))
    error, _ = run_and_compare(joint, actions)
    assert error <= claim
    check_waste(joint, actions, count, error)


@FEW
@given(joint=LINEAR_JOINTS, kind=KINDS, seed=SEEDS)
def test_drawn_linear_joints_meet_the_claim_and_need_their_count(joint, kind, seed):
    """Linear joints around Table 1's and the strong nozzle's (J, b, k each within plant_spread's
    largest factors): finite, within ENV_CLAIM at the env's count, and worse at half of it.
    Measured: <= 1e-4 at the count; 3e-4 to 8e-3 at half."""
    check_drawn(joint, kind, seed, ENV_CLAIM)


@FEW
@given(joint=STRONG_JOINTS, kind=KINDS, seed=SEEDS)
def test_drawn_strongly_hysteretic_joints_meet_the_claim(joint, kind, seed):
    """Joints around the strong nozzle (plant_spread's factors on J, b, a k, (1 - a) k, beta,
    gamma; n in [1, 2.5]): finite and within ENV_CLAIM at the env's count (which the stability
    rule sets for most of them; measured <= 1.5e-4)."""
    check_drawn(joint, kind, seed, ENV_CLAIM)


@FEW
@given(joint=TABLE1_JOINTS, kind=KINDS, seed=SEEDS)
def test_drawn_table_1_like_joints_stay_finite_and_need_their_count(joint, kind, seed):
    """Joints around Table 1's (factors as above, n in [0.7, 2.5]): the trajectory stays finite
    (run_and_compare) and halving the count costs accuracy. (How accurate the count is on such
    joints: the seeded ten below, within DRAWN_CLAIM; a drawn joint can exceed that.)"""
    check_drawn(joint, kind, seed, math.inf)


def seeded_table1_joints(count: int) -> list[NozzleParameters]:
    """``count`` joints of TABLE1_JOINTS' distribution from a seeded generator."""
    rng = np.random.default_rng(0)
    return [bouc_wen_joint(TABLE1, np.exp(0.5 * rng.uniform(-3, 3, 6)).tolist(), float(rng.uniform(0.7, 2.5)))
            for _ in range(count)]  # fmt: skip


def test_seeded_table_1_like_joints_meet_the_drawn_claim():
    """10 seeded joints around Table 1's (J, b, a k, (1-a) k, beta, gamma times exp(0.5 z), |z| <=
    3; n in [0.7, 2.5]): up to 1.43e-3 (J=45.6, n=0.76, 4 substeps, bang-bang; it would need 10 for
    3e-4), below the default sensor noise on a 3 deg motion."""
    worst = []
    for i, joint in enumerate(seeded_table1_joints(10)):
        count = built_count(joint)
        worst.append(max(run_and_compare(joint, signal(joint, kind, i, horizon(count)))[0]
                         for kind in ("piecewise", "bang")))  # fmt: skip
    assert max(worst) <= DRAWN_CLAIM, worst


# ------------------------------------------------------------------ joints near the refusal limit

NEAR_LIMIT = {
    # overdamped: b / J = 1.5e6 1/s sets the stability rule's count
    "linear_overdamped": NozzleParameters.linear(2.5e-4, 376.53, 1.43e5),
    # nearly elasto-plastic: yields at 7e-5 rad, the hysteresis rate sets the count
    "bouc_wen_plastic": NozzleParameters(
        J=20.0, b=250.0, k=1.6e5, a=0.15, A=1.0, beta=1e6, gamma=2e6 / 3, n=1.5
    ),
}


@pytest.mark.parametrize("name", list(NEAR_LIMIT))
@pytest.mark.parametrize("kind", ["piecewise", "bang"])
def test_joints_near_the_refusal_limit_are_accurate_and_finite(name, kind):
    """Joints whose count is within 12 % of MAX_SUBSTEPS: 25 steps (bang-bang leaves the envelope
    at once on the overdamped one, at 11 deg: that one step is compared) against Radau, finite
    and within the claim. Measured: 2e-8 to 4e-8, the observation's float32 rounding."""
    p = NEAR_LIMIT[name]
    actions = signal(p, kind, 3, 25)
    angles, count = env_angles(p, actions)
    assert 0.88 * MAX_SUBSTEPS < count <= MAX_SUBSTEPS
    ref = reference_angles(p, FULL_SCALE * actions[: len(angles)], stiff=True)
    assert relative_error(angles, ref) <= ENV_CLAIM


# ------------------------------------------------------------------ 3. the launcher's nozzle


def servo_gains(p: NozzleParameters) -> tuple[float, float, float]:
    """LauncherPitch's documented servo: tau = k_ff d_cmd - k_p d - k_d d', designed on the
    small-signal stiffness k = a k + (1 - a) k A so that J d'' + (b + k_d) d' + (k + k_p) d has
    15 Hz and 0.7 damping (gains floored at 0), k_ff = k + k_p."""
    k = p.a * p.k + (1.0 - p.a) * p.k * p.A
    omega = 2.0 * math.pi * 15.0
    k_p = max(p.J * omega**2 - k, 0.0)
    k_d = max(2.0 * 0.7 * p.J * omega - p.b, 0.0)
    return k + k_p, k_p, k_d


def test_launcher_nozzle_deflection_on_the_strong_joint_against_joint_and_servo():
    """LauncherPitch-v0 on the strong nozzle (whose rule takes 4 RK4 steps per 2 ms servo sample:
    the Table 1 and linear joints, one step each, are test_launcher_env.py's and
    test_env_definitions.py's): the deflection column against the joint integrated here, the
    servo torque (clipped at +-3e4 N m) computed from the state at each 2 ms sample and held over
    it, d_cmd = action x 3 deg; 1 s of random piecewise-constant commands, the deflection up to
    6 deg. Measured: 7.4e-6 (2.1e-4 with one RK4 step per sample: this checks the servo and the
    joint in the launcher's loop more than the launcher's count)."""
    p = STRONG
    k_ff, k_p, k_d = servo_gains(p)
    rhs, _ = joint_rhs(p)
    actions = piecewise(np.random.default_rng(0), 50, 1.0, hold=(2, 8))
    env = gym.make(LAUNCHER, plant="strong", sensor_noise=0.0, reference="zero")
    env.reset(seed=0)
    state, got, expected = np.zeros(3), [], []
    for a in actions:
        obs, _, terminated, _, info = env.step(np.array([a], dtype=np.float32))
        assert "nonfinite" not in info
        for _ in range(10):
            tau = min(
                max(k_ff * a * math.radians(3.0) - k_p * state[0] - k_d * state[1], -FULL_SCALE), FULL_SCALE
            )
            state = solve_ivp(rhs, (0.0, 0.002), state, args=(tau,), method="DOP853", rtol=1e-11,
                              atol=1e-14).y[:, -1]  # fmt: skip
        got.append(math.radians(float(obs[5])))
        expected.append(state[0])
        if terminated:
            break
    assert len(got) >= 40  # the attitude stayed inside its envelope for most of the second
    error = np.max(np.abs(np.array(got) - expected)) / np.max(np.abs(expected))
    assert np.max(np.abs(expected)) > math.radians(2.0)  # past the strong joint's 1.7 deg yield
    assert error <= ENV_CLAIM, error
