"""The model-based controllers against references computed without them.

* The MPC in a scenario where its limits bind (the LQ servo asks for several times the valves'
  range): the requests it makes keep both limits, and its first move is the one an
  independently written QP (simulated prediction, cost and limits from the module doc, solved
  by scipy's SLSQP) gives.
* The LQ servo's Kalman filter: python-control's ``dlqe`` on the noise the class documents, a
  brute-force Riccati iteration, and the filter's error in a simulation of the code's own steps.
* The LQI gain: python-control's ``dlqr`` on the augmented model written here from the module
  doc (not with ``agents.lqi.augmented``), and the closed loop of the design model, integrators,
  gain and filter, by the code's own step functions, at each packaged power level.
"""

from __future__ import annotations

import functools
from unittest import mock

import control
import gymnasium as gym
import numpy as np
import pytest
import scipy.linalg
import scipy.optimize
from hypothesis import given, settings
from hypothesis import strategies as st

import agents.lqi
import agents.mpc
import ssme_envs  # noqa: F401  (registers the environments)
from agents.lqi import LQIServo, design_servo, servo_advance, servo_estimate, servo_feedback, servo_state
from agents.mpc import MPC
from agents.plants import linear_design
from ssme_envs.evaluation import make_env, rollout
from ssme_envs.models.engine import POWER_LEVELS, identified_model

TRACKING = "ssme_envs/EngineTracking-v0"
THROTTLE = "ssme_envs/EngineThrottle-v0"
NOZZLE = "ssme_envs/NozzleTVC-v0"
LAUNCHER = "ssme_envs/LauncherPitch-v0"

FEW = settings(deadline=None, max_examples=25)


# --------------------------------------------------------------------------------------------
# design models


@functools.cache
def design(env_id: str, source: str, power: float | None = None):
    return linear_design(gym.make(env_id), source, power=power)


# every kind of design model: the engine (4 states, 2 inputs, 2 outputs), the nozzle (stable
# oscillator) and the launcher (open-loop unstable rigid body), identified and truth
DESIGNS = [
    (env_id, source, None) for env_id in (TRACKING, NOZZLE, LAUNCHER) for source in ("identified", "truth")
]
# the packaged engine models: identified at every Table I level, and the published (linked) model
# where the linked range (65-109 %) holds it
PACKAGED = [(THROTTLE, "identified", float(p)) for p in POWER_LEVELS] + [
    (THROTTLE, "truth", float(p)) for p in POWER_LEVELS if p <= 109
]


def docstring_augmented(a, b, c, error_weight, rate_weight, integral_ratio):
    """The servo model of agents/lqi.py's module doc, written out: z = [x; u_(k-1); q] driven by
    du, with x+ = A x + B u_(k-1) + B du, u_k = u_(k-1) + du, q+ = q + r - C x (r = 0 about the
    target: an error integral, forward sum per sample, sign r - y), and the cost
    e' Qe e + du' R du + q' Qi q with Qe = error_weight I (e = -C x), R = rate_weight I,
    Qi = integral_ratio error_weight I; plus the 1e-6 rate_weight on u_(k-1) that the code's
    comment gives ("keeps the input modes detectable")."""
    n, m, p = a.shape[0], b.shape[1], c.shape[0]
    a_z = np.zeros((n + m + p, n + m + p))
    a_z[:n, :n], a_z[:n, n : n + m] = a, b  # x+ = A x + B u_(k-1) (+ B du)
    a_z[n : n + m, n : n + m] = np.eye(m)  # u_k = u_(k-1) (+ du)
    a_z[n + m :, :n], a_z[n + m :, n + m :] = -c, np.eye(p)  # q+ = q - C x
    b_z = np.zeros((n + m + p, m))
    b_z[:n], b_z[n : n + m] = b, np.eye(m)
    q_z = np.zeros_like(a_z)
    q_z[:n, :n] = error_weight * c.T @ c
    q_z[n : n + m, n : n + m] = 1e-6 * rate_weight * np.eye(m)
    q_z[n + m :, n + m :] = integral_ratio * error_weight * np.eye(p)
    return a_z, b_z, q_z, rate_weight * np.eye(m)


def documented_noise(a, b, c, input_limit, noise_std, process_ratio):
    """The filter's covariances as design_servo's doc and comments give them: process noise an
    input disturbance of process_ratio % of the input's range (plus a 1e-6 (max |B|)^2 floor on
    every state), measurement noise the sensor's, but no less than a quarter of what that
    disturbance moves the outputs by in one step (max |C B| per unit input)."""
    disturbance = process_ratio / 100.0 * input_limit
    process = disturbance**2 * (b @ b.T + 1e-6 * np.abs(b).max() ** 2 * np.eye(a.shape[0]))
    floor = 0.25 * disturbance * np.abs(c @ b).max()
    measurement = np.diag(np.maximum(np.asarray(noise_std, dtype=float), floor) ** 2)
    return process, measurement


def filter_gain(a, b, c, input_limit, noise_std, process_ratio):
    """(M, P, E, L): the measurement-update gain x_hat = x_pred + M (y - C x_pred) from
    python-control's dlqe (whose L = A M is the predictor's gain), the prediction covariance,
    the eigenvalues of A - L C, and L."""
    process, measurement = documented_noise(a, b, c, input_limit, noise_std, process_ratio)
    predictor, cov, eig = control.dlqe(a, np.eye(a.shape[0]), c, process, measurement)
    update = cov @ c.T @ np.linalg.inv(c @ cov @ c.T + measurement)
    return update, cov, np.asarray(eig), np.asarray(predictor)


def design_filter(d, process_ratio=10.0):
    return filter_gain(d.A, d.B, d.C, d.input_limit, d.noise_std, process_ratio)


def riccati_iteration(a, c, process, measurement, steps=4000):
    """The filter's Riccati difference equation run from P = process until it stops moving."""
    cov = process.copy()
    for _ in range(steps):
        gain = cov @ c.T @ np.linalg.inv(c @ cov @ c.T + measurement)
        new = a @ (cov - gain @ c @ cov) @ a.T + process
        new = 0.5 * (new + new.T)
        if np.allclose(new, cov, rtol=1e-13, atol=0.0):
            return new
        cov = new
    raise AssertionError("the Riccati iteration did not settle")


def matched(found: np.ndarray, expected: np.ndarray) -> np.ndarray:
    """``found`` reordered to pair with ``expected`` (nearest overall, Hungarian assignment)."""
    cost = np.abs(np.asarray(expected)[:, None] - np.asarray(found)[None, :])
    rows, cols = scipy.optimize.linear_sum_assignment(cost)
    return np.asarray(found)[cols[np.argsort(rows)]]


# --------------------------------------------------------------------------------------------
# 2. the Kalman filter


@FEW
@given(which=st.sampled_from(DESIGNS + PACKAGED), process_ratio=st.floats(0.5, 100.0))
def test_kalman_gain_is_python_controls_dlqe_on_the_documented_noise(which, process_ratio):
    d = design(*which)
    code = design_servo(d, process_ratio=process_ratio).kalman
    update, cov, eig, predictor = design_filter(d, process_ratio)
    np.testing.assert_allclose(code, update, rtol=1e-6, atol=1e-9 * np.abs(update).max())
    np.testing.assert_allclose(d.A @ code, predictor, rtol=1e-6, atol=1e-9 * np.abs(predictor).max())
    # the code filters (x_hat = x_pred + M (y - C x_pred), x_pred+ = A x_hat + B u): the filtered
    # error moves by (I - M C) A = A - M C A, the predicted one by A - A M C; both have the
    # eigenvalues of python-control's A - L C, inside the unit circle
    n = d.A.shape[0]
    for dynamics in (d.A - code @ d.C @ d.A, d.A - d.A @ code @ d.C):
        poles = np.linalg.eigvals(dynamics)
        np.testing.assert_allclose(matched(poles, eig), eig, atol=1e-7)
    assert np.abs(eig).max() < 1.0
    # and the prediction covariance is where the Riccati difference equation settles
    process, measurement = documented_noise(d.A, d.B, d.C, d.input_limit, d.noise_std, process_ratio)
    settled = riccati_iteration(d.A, d.C, process, measurement)
    np.testing.assert_allclose(cov, settled, rtol=1e-6, atol=1e-9 * np.abs(settled).max())
    assert code.shape == (n, d.C.shape[0])


@pytest.mark.parametrize("which", [DESIGNS[0], DESIGNS[5], PACKAGED[0]], ids=str)
def test_the_code_s_filter_error_follows_the_dlqe_error_dynamics(which):
    # a brute-force run of servo_estimate / servo_advance on the design model itself, from a
    # wrong initial estimate, under random inputs: x - x_hat moves by A - M C A (M from dlqe)
    d = design(*which)
    servo = design_servo(d)
    update, *_ = design_filter(d)
    rng = np.random.default_rng(7)
    n, m = d.A.shape[0], d.B.shape[1]
    x = rng.normal(size=(3, n)) * 0.1 * d.input_limit * np.abs(d.B).max()
    state = servo_state(servo, 3)
    error, errors = None, []
    for _ in range(30):
        y = x @ d.C.T
        x_hat = servo_estimate(servo, state, y)
        if error is not None:
            expected = error @ (d.A - update @ d.C @ d.A).T
            np.testing.assert_allclose(x - x_hat, expected, rtol=1e-6, atol=1e-9 * np.abs(x).max())
        error = x - x_hat
        errors.append(np.abs(error).max())
        du = rng.uniform(-0.3, 0.3, size=(3, m)) * d.input_limit - state["u"] * 0.5
        u = servo_advance(servo, state, x_hat, y, np.zeros_like(y), du, d.input_limit)
        x = x @ d.A.T + u @ d.B.T
    assert errors[-1] < 0.1 * errors[0]  # and it dies out


# --------------------------------------------------------------------------------------------
# 3. the LQI gain


def dlqr_on_docstring_model(d, integral_ratio):
    a_z, b_z, q_z, r = docstring_augmented(d.A, d.B, d.C, d.error_weight, d.rate_weight, integral_ratio)
    gain, cost_to_go, poles = control.dlqr(a_z, b_z, q_z, r)
    return a_z, b_z, q_z, r, np.asarray(gain), np.asarray(cost_to_go), np.asarray(poles)


@FEW
@given(which=st.sampled_from(DESIGNS + PACKAGED), integral_ratio=st.floats(1e-3, 1.0))
def test_lqi_gain_is_dlqr_on_the_docstring_s_augmented_model(which, integral_ratio):
    d = design(*which)
    servo = design_servo(d, integral_ratio=integral_ratio)
    a_z, b_z, _, _, gain, cost_to_go, poles = dlqr_on_docstring_model(d, integral_ratio)
    np.testing.assert_allclose(servo.gain, gain, rtol=1e-6, atol=1e-8 * np.abs(gain).max())
    np.testing.assert_allclose(servo.cost_to_go, cost_to_go, rtol=1e-6, atol=1e-8 * np.abs(cost_to_go).max())
    closed = np.linalg.eigvals(a_z - b_z @ servo.gain)
    np.testing.assert_allclose(matched(closed, poles), poles, atol=1e-7)
    assert np.abs(closed).max() < 1.0


@pytest.mark.parametrize("which", PACKAGED, ids=lambda w: f"{w[1]}-{w[2]:g}")
def test_servo_closed_loop_at_each_packaged_power_level(which):
    d = design(*which)
    servo = design_servo(d)
    a_z, b_z, q_z, r, _, _, poles = dlqr_on_docstring_model(d, 0.02)
    # plant + integrators under the code's gain: Schur-stable, python-control's poles
    closed = np.linalg.eigvals(a_z - b_z @ servo.gain)
    assert np.abs(closed).max() < 1.0
    np.testing.assert_allclose(matched(closed, poles), poles, atol=1e-7)
    # the gain is optimal: the Riccati difference equation, run backwards, settles on it
    p_k = q_z.copy()
    for _ in range(3000):
        k_k = np.linalg.solve(r + b_z.T @ p_k @ b_z, b_z.T @ p_k @ a_z)
        p_k = q_z + a_z.T @ p_k @ (a_z - b_z @ k_k)
        p_k = 0.5 * (p_k + p_k.T)
    np.testing.assert_allclose(servo.gain, k_k, rtol=1e-6, atol=1e-8 * np.abs(k_k).max())
    # the whole loop, by the code's own steps (filter, feedback, integrators, prediction) on the
    # design model, r = 0 and far from the limits: a linear map of (x, x_pred, u, q) whose
    # eigenvalues are the regulator's and the filter's (the separation principle)
    n, m, p = d.A.shape[0], d.B.shape[1], d.C.shape[0]
    size = 2 * n + m + p
    h = 1e-9 * d.input_limit
    start = h * np.eye(size)
    state = servo_state(servo, size)
    x, state["x"], state["u"], state["q"] = np.split(start, [n, 2 * n, 2 * n + m], axis=1)
    y = x @ d.C.T
    zero = np.zeros_like(y)
    x_hat = servo_estimate(servo, state, y)
    du = servo_feedback(servo, state, x_hat, zero, zero)
    u = servo_advance(servo, state, x_hat, y, zero, du, d.input_limit)
    x_next = x @ d.A.T + u @ d.B.T
    loop = np.concatenate([x_next, state["x"], state["u"], state["q"]], axis=1).T / h
    _, _, filter_poles, _ = design_filter(d)
    expected = np.concatenate([poles, filter_poles])
    found = np.linalg.eigvals(loop)
    np.testing.assert_allclose(matched(found, expected), expected, atol=1e-6)
    assert np.abs(found).max() < 1.0


# --------------------------------------------------------------------------------------------
# 1. the MPC with its limits active

RATE = 0.3  # the MPC's rate limit here, fraction of the input range per step
HORIZON = 10  # MPC's documented default
# large steps, small valve travel: the unconstrained servo asks for up to ~3 times full scale
LIMITED = {"reference_amplitude": 0.03, "action_scale": 0.01}


def _recording(module, log):
    """module.servo_advance that first logs the input asked for before its clip, action units."""

    def wrapped(s, state, x, y, r, du, limit):
        log.append(((state["u"] + du) / limit, du / limit))
        return servo_advance(s, state, x, y, r, du, limit)

    return mock.patch.object(module, "servo_advance", wrapped)


class SnapshotMPC(MPC):
    """The MPC, keeping a copy of its state before each step."""

    def initial_state(self, n):
        self.snapshots = []
        return super().initial_state(n)

    def compute(self, obs):
        self.snapshots.append({key: value.copy() for key, value in self.state.items()})
        return super().compute(obs)


@functools.cache
def limited_runs():
    env = make_env(TRACKING, "both_steps", 8, LIMITED)
    lqi_log, mpc_log = [], []
    with _recording(agents.lqi, lqi_log):
        lqi = rollout(env, LQIServo(env), "lqi")
    mpc = SnapshotMPC(env, rate_limit=RATE)
    assert mpc.horizon == HORIZON
    with _recording(agents.mpc, mpc_log):
        run = rollout(env, mpc, "mpc")
    task = env.task
    env.close()
    asked = {name: np.array([u for u, _ in log]) for name, log in (("lqi", lqi_log), ("mpc", mpc_log))}
    changes = np.array([du for _, du in mpc_log])
    return lqi, run, mpc, asked, changes, task


def test_mpc_keeps_its_limits_where_the_lq_servo_exceeds_them():
    lqi, run, mpc, asked, changes, _ = limited_runs()
    assert run.alive.all() and lqi.alive.all()
    # the unconstrained law asks for far more than the valves' range (measured 2.8)
    assert np.abs(asked["lqi"]).max() > 2.0
    assert mpc.failures == 0  # every step's QP solved: no fallback to the unconstrained law
    # what the MPC asks for, before any clip: within the range (OSQP's tolerance: measured 1.6e-7)
    assert np.abs(asked["mpc"]).max() <= 1.0 + 1e-6
    assert np.abs(changes).max() <= RATE + 1e-6
    # the requested actions (act() clips magnitudes, not changes): the rate limit holds at every
    # step, from the initial zero input
    requested = run.requested
    assert np.abs(requested).max() <= 1.0 + 1e-6
    assert np.abs(np.diff(requested, axis=0, prepend=0.0)).max() <= RATE + 1e-6
    # both limits were active
    assert np.abs(requested).max() >= 1.0 - 1e-3
    assert np.abs(np.diff(requested, axis=0, prepend=0.0)).max() >= RATE - 1e-3
    # and the LQ servo, limit-blind, moves faster than the MPC may, so the two differ
    assert np.abs(np.diff(lqi.requested, axis=0, prepend=0.0)).max() > RATE + 0.2
    assert np.abs(run.requested - lqi.requested).max() > 0.2


def independent_first_move(a, b, c, ew, rw, limit, x_hat, u_prev, q, r):
    """The MPC's problem from its doc, written here: over HORIZON input changes du_0.. (action
    units w = du / limit), the servo's predicted cost (stage cost of z_1 .. z_(N-1), Riccati
    cost-to-go on z_N, rw |du|^2 each step) about the target at rest on r, subject to
    |u_k| <= 1 and |du_k| <= RATE in action units; solved by SLSQP. Returns u_0 / limit."""
    n, m, p = a.shape[0], b.shape[1], c.shape[0]
    square = np.block([[a - np.eye(n), b], [c, np.zeros((p, m))]])
    x_ss, u_ss = np.split(np.linalg.solve(square, np.concatenate([np.zeros(n), r])), [n])
    a_z, b_z, q_z, r_z = docstring_augmented(a, b, c, ew, rw, 0.02)
    terminal = scipy.linalg.solve_discrete_are(a_z, b_z, q_z, r_z)

    def cost(w):
        x, u, integral, total = x_hat.copy(), u_prev.copy(), q.copy(), 0.0
        for k, du in enumerate(w.reshape(HORIZON, m) * limit):
            u = u + du
            total += rw * du @ du
            x, integral = a @ x + b @ u, integral + r - c @ x  # simulated, not stacked
            z = np.concatenate([x - x_ss, u - u_ss, integral])
            total += z @ (q_z if k < HORIZON - 1 else terminal) @ z
        return total

    # the cost is quadratic in w: its exact gradient and Hessian by polarization
    size = HORIZON * m
    eye = np.eye(size)
    c0 = cost(np.zeros(size))
    plus, minus = np.array([cost(e) for e in eye]), np.array([cost(-e) for e in eye])
    g = 0.5 * (plus - minus)
    hess = np.diag(plus + minus - 2 * c0)
    for i in range(size):
        for j in range(i):
            hess[i, j] = hess[j, i] = (
                cost(eye[i] + eye[j]) - c0 - g[i] - g[j] - 0.5 * (hess[i, i] + hess[j, j])
            )
    probe = np.random.default_rng(3).uniform(-0.5, 0.5, size)
    assert np.isclose(c0 + g @ probe + 0.5 * probe @ hess @ probe, cost(probe), rtol=1e-9, atol=1e-12 * c0)
    cumulative = np.kron(np.tril(np.ones((HORIZON, HORIZON))), np.eye(m))  # u_k = u_prev + sum du
    level = np.tile(u_prev / limit, HORIZON)
    g_ineq = np.vstack([-cumulative, cumulative, -eye, eye])
    h_ineq = np.concatenate([1.0 - level, 1.0 + level, np.full(size, RATE), np.full(size, RATE)])
    result = scipy.optimize.minimize(
        lambda w: c0 + g @ w + 0.5 * w @ hess @ w,
        np.zeros(size),
        jac=lambda w: g + hess @ w,
        method="SLSQP",
        constraints=[{"type": "ineq", "fun": lambda w: h_ineq + g_ineq @ w, "jac": lambda w: g_ineq}],
        options={"ftol": 1e-12, "maxiter": 1000},
    )
    # SLSQP stops some 1e-5 short on the saturated states (its line search gives up, status 8):
    # from its active set, the exact optimum by the KKT equations, certified below
    w = certified_optimum(hess, g, g_ineq, h_ineq, h_ineq + g_ineq @ result.x < 1e-6)
    return u_prev / limit + w[:m], w  # the first move, and the whole plan


def certified_optimum(hess, g, g_ineq, h_ineq, active):
    """The minimizer of g'w + w'Hw/2 (H > 0) subject to G w + h >= 0 by a primal-dual active set
    search from ``active``: the KKT equations of the active constraints as equalities, dropping a
    negative multiplier or adding a violated constraint until neither is left; then the KKT
    conditions (stationarity, primal and dual feasibility, complementarity) hold to rounding."""
    size = len(g)
    active = active.copy()
    for _ in range(4 * len(h_ineq)):
        rows = g_ineq[active]
        kkt = np.block([[hess, -rows.T], [rows, np.zeros((len(rows), len(rows)))]])
        solution = np.linalg.lstsq(kkt, np.concatenate([-g, -h_ineq[active]]), rcond=None)[0]
        w, multipliers = solution[:size], solution[size:]
        slack = h_ineq + g_ineq @ w
        if len(multipliers) and multipliers.min() < -1e-10 * max(1.0, np.abs(multipliers).max()):
            active[np.flatnonzero(active)[np.argmin(multipliers)]] = False
        elif slack.min() < -1e-10:
            active[np.argmin(slack)] = True
        else:
            break
    else:
        raise AssertionError("the active-set search did not settle")
    stationarity = hess @ w + g - g_ineq[active].T @ multipliers
    assert np.abs(stationarity).max() <= 1e-9 * (np.abs(g).max() + np.abs(hess).max())
    assert slack.min() >= -1e-10 and (multipliers.min() if len(multipliers) else 0.0) >= -1e-9
    return w


@FEW
@given(pick=st.integers(0, 10**6), binding=st.booleans())
def test_mpc_first_move_is_the_independent_qp_s(pick, binding):
    _, run, mpc, asked, changes, task = limited_runs()
    steps, episodes = run.requested.shape[:2]
    first = asked["mpc"]
    if binding:  # the first move on a limit: the QP's constraints decide it
        on_limit = np.argwhere(
            (np.abs(first).max(axis=2) > 1 - 1e-3) | (np.abs(changes).max(axis=2) > RATE - 1e-3)
        )
        k, i = on_limit[pick % len(on_limit)]
    else:
        k, i = divmod(pick % (steps * episodes), episodes)
    # the design model: the packaged identified model at the env's 100 %; the weights: the
    # reward -0.1 (|e|^2 in %) - 0.1 |a_k - a_(k-1)|^2 with u = action_scale a
    model = identified_model(100)
    a, b, c = (np.asarray(model.A, float), np.asarray(model.B, float), np.asarray(model.C, float))
    scale = LIMITED["action_scale"]
    ew, rw = 0.1 * 100.0**2, 0.1 / scale**2
    assert (mpc.design.error_weight, mpc.design.rate_weight, mpc.design.input_limit) == pytest.approx(
        (ew, rw, scale)
    )
    np.testing.assert_allclose(mpc.design.A, a, rtol=1e-12)
    # what the MPC saw at step k: the observation (outputs and references in %) and its state
    observation = task.observation
    obs = run.obs[k, i].astype(np.float64)
    y = obs[[observation.index("pc_pct"), observation.index("mr_pct")]] / 100.0
    r = obs[[observation.index("pc_ref_pct"), observation.index("mr_ref_pct")]] / 100.0
    refs = run.obs[max(k - 2, 0) : k + 1, i][
        :, [observation.index("pc_ref_pct"), observation.index("mr_ref_pct")]
    ]
    increments = np.diff(refs, axis=0)
    assert len(increments) < 2 or not np.any(increments[0] * increments[1] > 0)  # a step: no ramp
    snapshot = mpc.snapshots[k]
    x_pred, u_prev, q = snapshot["x"][i], snapshot["u"][i], snapshot["q"][i]
    update, *_ = filter_gain(a, b, c, scale, task.noise_std, 10.0)
    x_hat = x_pred + update @ (y - c @ x_pred)
    expected, _ = independent_first_move(a, b, c, ew, rw, scale, x_hat, u_prev, q, r)
    np.testing.assert_allclose(first[k, i], expected, atol=1e-4)


def test_a_design_model_no_controller_can_stabilize_is_refused_by_name():
    """The nozzle's identified design (two states, one input, one output) with B zeroed, and with a
    third state, unstable (1.05) and out of the input's reach but seen by the output: the LQ servo
    cannot be designed on either. A scipy Riccati error about Schur forms (or "Failed to find a
    finite solution") was the CLI's message; now the cause is named."""
    import dataclasses

    d = design(NOZZLE, "identified")
    zero_b = dataclasses.replace(d, plant=dataclasses.replace(d.plant, B=np.zeros_like(d.B)))
    with pytest.raises(ValueError, match=r"^the design model's B is zero: its inputs move nothing"):
        design_servo(zero_b)
    a = scipy.linalg.block_diag(d.A, [[1.05]])
    b = np.vstack([d.B, [[0.0]]])
    c = np.hstack([d.C, np.ones((d.C.shape[0], 1))])
    unreachable = dataclasses.replace(d, plant=dataclasses.replace(d.plant, A=a, B=b, C=c))
    with pytest.raises(ValueError, match=r"^cannot design the LQ servo's gain on this design model: .*"
                                         r"out of the inputs' reach\?$"):  # fmt: skip
        design_servo(unreachable)
