"""Controllers: designs checked against python-control and scipy, and the comparisons the
evaluation is for (LQI vs PI, MPC = LQI without active limits, hysteresis compensation)."""

import control
import gymnasium as gym
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import ssme_envs  # noqa: F401
from agents import CONTROLLERS, Controller, controller_names, make_controller, parse_controller
from agents.lqi import LQIServo, augmented, reference_step
from agents.mpc import MPC
from agents.pid import DecoupledPI, PlacedPID, placed_pid
from agents.tvc import hysteresis_along
from ssme_envs.evaluation import evaluate, make_env, rollout
from ssme_envs.models.nozzle import identified_nozzle

TRACKING = "ssme_envs/EngineTracking-v0"
NOZZLE = "ssme_envs/NozzleTVC-v0"


def test_lqi_gain_is_python_controls_dlqr_on_the_augmented_model():
    env = gym.make(TRACKING)
    servo = LQIServo(env)
    a, b, q, r = augmented(servo.design, 0.02)
    gain, _, _ = control.dlqr(a, b, q, r)
    np.testing.assert_allclose(servo.servo.gain, gain, rtol=1e-6, atol=1e-9)
    # the reference feedforward puts the design model at rest on the reference
    x_u = servo.servo.target @ np.array([0.01, -0.005])
    d = servo.design
    n = d.A.shape[0]
    np.testing.assert_allclose(d.A @ x_u[:n] + d.B @ x_u[n:], x_u[:n], atol=1e-12)
    np.testing.assert_allclose(d.C @ x_u[:n], [0.01, -0.005], atol=1e-12)


def test_the_ramp_target_is_a_motion_of_the_design_model():
    servo = LQIServo(gym.make(NOZZLE)).servo
    a, b, c = servo.A, servo.B, servo.C
    n, eye = a.shape[0], np.eye(a.shape[0])
    r, s = np.array([0.02]), np.array([1e-4])  # rad, rad per sample
    d, e = (servo.target @ s)[:n], servo.ramp_change @ s
    x0, u0 = np.split(servo.target @ r + servo.ramp @ s, [n])
    # x_k = x0 + k d, u_k = u0 + k e solves x_(k+1) = A x_k + B u_k with C x_k = r + k s
    np.testing.assert_allclose((a - eye) @ d + b @ e, 0.0, atol=1e-12)
    np.testing.assert_allclose(c @ d, s, rtol=1e-12)
    np.testing.assert_allclose((a - eye) @ x0 + b @ u0, d, atol=1e-12)
    np.testing.assert_allclose(c @ x0, r, rtol=1e-12)


def test_reference_step_feeds_ramps_forward_and_not_steps():
    state = {"r": np.full((3, 1), np.nan), "dr": np.zeros((3, 1))}
    # columns: a ramp, a step, a decelerating motion
    references = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 1.0], [2.0, 5.0, 1.5], [3.0, 5.0, 1.6]])
    seen = [reference_step(state, r[:, None]).ravel() for r in references]
    np.testing.assert_allclose(seen, [[0, 0, 0], [0, 0, 0], [1, 0, 0.5], [1, 0, 0.1]], atol=1e-15)


def test_placed_pid_puts_the_closed_loop_poles_where_asked():
    a1, a0, g = 18.0, 6000.0, 0.04
    kp, ki, kd = placed_pid(a1, a0, g, omega=60.0, damping=0.7)
    # x'' + a1 x' + a0 x = g (kp e + ki int e - kd x'), e = r - x:
    # s^3 + (a1 + g kd) s^2 + (a0 + g kp) s + g ki
    poles = np.sort_complex(np.roots([1.0, a1 + g * kd, a0 + g * kp, g * ki]))
    expected = np.sort_complex(np.roots(np.polymul([1.0, 60.0], [1.0, 2 * 0.7 * 60.0, 3600.0])))
    np.testing.assert_allclose(poles, expected, rtol=1e-9)


def test_controllers_follow_the_protocol_on_scalar_and_vector_envs():
    for name, (_, env_ids, _) in CONTROLLERS.items():
        for env_id in env_ids:
            env = gym.make(env_id)
            controller = make_controller(name, env, env_id)
            assert isinstance(controller, Controller)
            obs, _ = env.reset(seed=0)
            controller.reset(seed=0)
            action = controller.act(obs, {})
            assert action.shape == env.action_space.shape and action.dtype == np.float32
            assert env.action_space.contains(action)
    vec = make_env(TRACKING, "nominal", 3)
    obs, _ = vec.reset(seed=0)
    lqi = LQIServo(vec)
    lqi.reset(num_envs=3)
    assert lqi.act(obs).shape == (3, 2)
    with pytest.raises(ValueError, match="expected observations of shape"):
        lqi.act(obs[:2])


def test_lqi_beats_decoupled_pi_on_the_nominal_engine():
    results = evaluate(TRACKING, {"pi": DecoupledPI, "lqi": LQIServo}, ["nominal"], episodes=20)
    pi, lqi = results["nominal"]["pi"]["cost_mean"], results["nominal"]["lqi"]["cost_mean"]
    assert lqi < 0.6 * pi  # measured 1.49 vs 3.29 over 100 episodes
    # backlash and stiction make the LQ servo's valves hunt (limit cycles): more reversals
    valves = evaluate(TRACKING, {"lqi": LQIServo}, ["valves"], episodes=20)
    assert valves["valves"]["lqi"]["actuators"]["OPOV"]["reversals"] > (
        2 * results["nominal"]["lqi"]["actuators"]["OPOV"]["reversals"]
    )


def test_the_lq_tracker_on_the_truth_is_cheaper_than_the_integrating_servo():
    # on the exact linear model the integral action only costs: the reward's LQ tracker (feedforward,
    # negligible integral weight) is the limit; measured 1.28 vs 1.47 over 50 episodes
    factories = {spec: parse_controller(spec, TRACKING) for spec in ("lq:truth", "lqi:truth")}
    results = evaluate(TRACKING, factories, ["nominal"], episodes=10)["nominal"]
    assert results["lq:truth"]["cost_mean"] < 0.95 * results["lqi:truth"]["cost_mean"]


def test_mpc_acts_as_the_lq_servo_when_no_limit_binds():
    # small references: neither the magnitude nor the rate limit is reached
    env = gym.make_vec(TRACKING, num_envs=4, vectorization_mode="vector_entry_point",
                       reference_amplitude=0.001, truth={"backlash": 0.0, "stiction": 0.0})  # fmt: skip
    mpc, lqi = rollout(env, MPC(env, horizon=15), "mpc"), rollout(env, LQIServo(env), "lqi")
    assert np.abs(mpc.actions).max() < 0.2
    np.testing.assert_allclose(mpc.actions, lqi.actions, atol=2e-4)
    # and on ramps, with the ramp feedforward in both
    env = gym.make_vec(TRACKING, num_envs=4, vectorization_mode="vector_entry_point", reference="ramp",
                       reference_amplitude=0.001, truth={"backlash": 0.0, "stiction": 0.0})  # fmt: skip
    mpc, lqi = rollout(env, MPC(env, horizon=15), "mpc"), rollout(env, LQIServo(env), "lqi")
    np.testing.assert_allclose(mpc.actions, lqi.actions, atol=2e-4)


def test_mpc_keeps_its_rate_limit():
    env = make_env(TRACKING, "both_steps", 8)
    run = rollout(env, MPC(env, rate_limit=0.2), "mpc")
    change = np.abs(np.diff(run.actions, axis=0))[run.alive[1:]]
    assert change.max() <= 0.2 + 1e-4 and np.abs(run.actions).max() <= 1.0


def test_hysteresis_path_integral_matches_the_bouc_wen_ode_in_time():
    p = identified_nozzle().plant().normalized()
    beta, gamma, n = p["beta_n"], p["gamma_n"], p["n"]
    t = np.linspace(0.0, 8.0, 801)
    x = 0.05 * np.sin(t) + 0.02 * np.sin(2.3 * t)

    def rhs(time, w):
        v = 0.05 * np.cos(time) + 0.046 * np.cos(2.3 * time)
        return v * (1 - np.abs(w) ** n * (beta + gamma * np.sign(v * w)))

    reference = solve_ivp(rhs, (0, 8), [0.0], t_eval=t, rtol=1e-10, atol=1e-13, max_step=0.01).y[0]
    w = np.zeros(1)
    path = [0.0]
    for k in range(1, len(t)):
        w = hysteresis_along(w, x[k - 1 : k], x[k : k + 1], beta, gamma, n)
        path.append(float(w[0]))
    assert np.max(np.abs(np.array(path) - reference)) < 1e-5 * np.max(np.abs(reference)) + 1e-9


def test_hysteresis_compensation_lowers_tracking_iae_on_the_bouc_wen_nozzle():
    factories = {name: parse_controller(name, NOZZLE) for name in ("lqi", "hysteresis")}
    pairs = {"sine_sweep": "sine_sweep_linear", "attitude": "attitude_linear"}
    results = evaluate(NOZZLE, factories, [*pairs, *pairs.values()], episodes=20)

    def change(scenario):
        iae = {name: results[scenario][name]["outputs"]["angle"]["iae"] for name in factories}
        return iae["hysteresis"] / iae["lqi"] - 1

    for hysteretic, linear in pairs.items():
        assert change(hysteretic) < -0.005, hysteretic  # measured -8.3 % (sweep), -1.3 % (attitude)
        # and more than on the linear joint, where there is no hysteresis to cancel
        assert change(hysteretic) < change(linear) - 0.01, hysteretic  # by 2.2 and 2.8 points


def test_scheduled_lqi_flies_the_throttle_profile():
    throttle = "ssme_envs/EngineThrottle-v0"
    factories = {name: parse_controller(name, throttle) for name in ("zero", "scheduled")}
    results = evaluate(throttle, factories, ["mission"], episodes=2)
    assert results["mission"]["scheduled"]["cost_mean"] < 0.2 * results["mission"]["zero"]["cost_mean"]


def test_partial_resets_and_bad_arguments():
    nozzle = make_env(NOZZLE, "attitude", 4)
    obs, _ = nozzle.reset(seed=0)
    for controller in (make_controller("hysteresis", nozzle, NOZZLE), MPC(make_env(TRACKING, "nominal", 4))):
        with pytest.raises(ValueError, match=r"reset\(envs=\.\.\.\) needs indices"):
            controller.reset(envs=np.array([1]))
        controller.reset(num_envs=4)
        controller.reset(envs=np.array([1, 3]))  # two episodes restart, the batch stays whole
        batch = obs if controller.name != "mpc" else np.zeros((4, 10))
        assert controller.act(batch).shape[0] == 4
        with pytest.raises(ValueError, match="needs indices into the 4 envs"):
            controller.reset(envs=np.array([4]))
    with pytest.raises(ValueError, match="integral_ratio must be a positive number"):
        LQIServo(nozzle, integral_ratio=-1.0)
    with pytest.raises(ValueError, match="omega must be a positive number"):
        PlacedPID(nozzle, omega=0.0)
    with pytest.raises(ValueError, match="horizon must be a positive integer"):
        MPC(make_env(TRACKING, "nominal", 1), horizon=True)


def test_unknown_names_list_the_valid_ones():
    with pytest.raises(ValueError, match="choose from zero, pi, lqi, mpc"):
        parse_controller("lqr", TRACKING)
    with pytest.raises(ValueError, match="identified, truth"):
        parse_controller("lqi:paper", TRACKING)
    for spec in ("zero:", "ppo:", "lqi:"):
        with pytest.raises(ValueError, match="names nothing after ':'"):
            parse_controller(spec, TRACKING)
    for design in ("truth", "identified", "paper"):  # the baseline is designed on no model
        with pytest.raises(ValueError, match=f"'zero:{design}': the zero controller is designed on no model"):
            parse_controller(f"zero:{design}", TRACKING)
    assert "hysteresis" in controller_names(NOZZLE) and "hysteresis" not in controller_names(TRACKING)


def test_a_shipped_policy_name_that_is_also_a_run_directory_here_is_refused(tmp_path, monkeypatch):
    """``ppo:spread`` loaded the shipped policy while ./spread, a run of the user's, went unread."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "spread").mkdir()
    (tmp_path / "spread" / "policy.json").write_text("{}")
    with pytest.raises(ValueError, match=r"write ppo:\./spread for the run"):
        parse_controller("ppo:spread", NOZZLE)
    (tmp_path / "identified").mkdir()  # a directory that holds no policy: no ambiguity
    assert callable(parse_controller("ppo:identified", TRACKING))


def test_a_design_a_later_scenario_rules_out_fails_before_any_rollout():
    """The controllers were designed before the rollouts on the first scenario's env only: a
    design that a later scenario's env rules out (here a factory refusing the ramp reference)
    failed after the earlier scenarios had run. Now each is designed on every scenario's env first."""

    def picky(env):
        if env.task.reference == "ramp":
            raise ValueError("this design cannot follow a ramp")
        return make_controller("zero", env)

    said: list[str] = []
    factories = {"zero": parse_controller("zero", TRACKING), "picky": picky}
    with pytest.raises(ValueError, match=r"cannot follow a ramp \(designing picky on scenario 'ramp'\)$"):
        evaluate(TRACKING, factories, ["pc_step", "ramp"], 1, progress=said.append)
    assert said == []


def test_a_controller_the_options_rule_out_fails_before_any_rollout(tmp_path):
    """An engine plant of our own with dt 0.02 s: the controllers designed on the identified model
    (dt 0.04 s) cannot be; the error came after the controllers before it had run their episodes
    (a progress line, then the error); now every controller is designed once first."""
    import dataclasses

    from ssme_envs.models import identified_model

    path = tmp_path / "fast.json"
    dataclasses.replace(identified_model(100), dt=0.02).save(path)
    said: list[str] = []
    factories = {name: parse_controller(name, TRACKING) for name in ("zero", "lqi")}
    expected = r"^the identified design model has dt 0\.04 s but the env's plant 0\.02 s"
    with pytest.raises(ValueError, match=expected):
        evaluate(TRACKING, factories, ["nominal"], 1, options={"plant": str(path)}, progress=said.append)
    assert said == []
