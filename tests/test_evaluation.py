"""Evaluation harness: metrics against python-control and hand computations, the CLI's files and
errors."""

import json

import control
import numpy as np
import pytest
import scipy.signal
from hypothesis import given, settings
from hypothesis import strategies as st

from ssme_envs.cli import main
from ssme_envs.evaluation import LAYOUTS, Rollout, evaluate, metrics, step_metrics

TRACKING = "ssme_envs/EngineTracking-v0"


@pytest.mark.parametrize(
    "system",
    [
        ([1.0], [1.0, 0.6, 1.0]),  # underdamped: overshoot, ringing
        ([2.0], [0.5, 1.0]),  # first order
        ([1.0, 3.0], [1.0, 2.0, 3.0]),  # with a zero
    ],
)
def test_step_metrics_agree_with_python_control_step_info(system):
    t = np.linspace(0.0, 30.0, 3001)
    _, y = scipy.signal.step(system, T=t)
    ours = step_metrics(t, y)
    theirs = control.step_info(y, t)
    assert ours["rise_time"] == pytest.approx(theirs["RiseTime"], abs=1e-12)
    assert ours["settling_time"] == pytest.approx(theirs["SettlingTime"], abs=1e-12)
    assert ours["overshoot"] == pytest.approx(theirs["Overshoot"], abs=1e-9)


def test_metrics_by_hand():
    # 2 episodes x 10 steps of 0.1 s: constant error 0.5 %; episode 2 ends after 5 steps
    steps, dt = 10, 0.1
    obs = np.zeros((steps + 1, 2, 10))
    obs[:, :, 4] = 0.5
    actions = np.zeros((steps, 2, 2))
    actions[:, 0, 0] = [0, 1, 0, 1, 1, 1, 0, 0, 0, 0]  # 3 reversals: up, down, up, ..., down
    requested = actions.copy()
    requested[2, 0, 1] = 1.5
    alive = np.ones((steps, 2), dtype=bool)
    alive[5:, 1] = False
    rewards = np.full((steps, 2), -1.0)
    m = metrics(Rollout(obs, requested, actions, rewards, alive, dt), LAYOUTS[TRACKING])
    assert m["return_mean"] == pytest.approx(-7.5) and m["terminations"] == 1
    assert m["cost_cvar90"] == pytest.approx(10.0)  # the worst of two episodes
    pc = m["outputs"]["Pc"]
    assert pc["iae"] == pytest.approx((0.5 * 10 * dt + 0.5 * 5 * dt) / 2)
    assert pc["ise"] == pytest.approx((0.25 * 10 * dt + 0.25 * 5 * dt) / 2)
    times = np.arange(1, 11) * dt
    assert pc["itae"] == pytest.approx((0.5 * dt * times.sum() + 0.5 * dt * times[:5].sum()) / 2)
    assert m["actuators"]["OPOV"]["reversals"] == pytest.approx(3 / 2)
    # time at the limit counts the applied actions: OPOV sits at 1 for 4 of episode 1's 10 steps,
    # never in episode 2's 5; FPOV's request of 1.5 was never applied
    assert m["actuators"]["OPOV"]["time_at_limit"] == pytest.approx((4 / 10 + 0 / 5) / 2)
    assert m["actuators"]["FPOV"]["time_at_limit"] == 0.0


def test_steady_state_error_effort_and_travel_by_hand():
    # 2 episodes x 20 steps: constant Pc error 0.5 % in episode 1; episode 2 leaves after 10
    # steps with the error rising to 3 % on its last one: each is judged on its own last 10 %
    steps, dt = 20, 0.1
    obs = np.zeros((steps + 1, 2, 10))
    obs[1:, 0, 4] = 0.5
    obs[1:11, 1, 4] = 0.5
    obs[10, 1, 4] = -3.0  # step 10's observation (row 10), the last of episode 2
    actions = np.zeros((steps, 2, 2))
    actions[:, 0, 0] = 0.5
    actions[:4, 1, 1] = [0.2, -0.2, 0.2, -0.2]
    alive = np.ones((steps, 2), dtype=bool)
    alive[10:, 1] = False
    rewards = np.full((steps, 2), -1.0)
    rewards[:10, 1] = -2.0
    m = metrics(Rollout(obs, actions, actions, rewards, alive, dt), LAYOUTS[TRACKING])
    # episode 1: its last 2 steps at 0.5; episode 2: its last step (10 // 10 = 1) at 3
    assert m["outputs"]["Pc"]["steady_state_error"] == pytest.approx((0.5 + 3.0) / 2)
    assert m["outputs"]["MR"]["steady_state_error"] == 0.0
    assert m["return_std"] == pytest.approx(np.std([-20.0, -20.0]))
    # effort: the RMS over every alive step of every episode (20 + 10 of them)
    assert m["actuators"]["OPOV"]["effort_rms"] == pytest.approx(np.sqrt(20 * 0.25 / 30))
    assert m["actuators"]["FPOV"]["effort_rms"] == pytest.approx(np.sqrt(4 * 0.04 / 30))
    # travel: the summed |moves| per episode, the first from 0, averaged: OPOV 0.5 and 0
    assert m["actuators"]["OPOV"]["travel"] == pytest.approx(0.5 / 2)
    assert m["actuators"]["FPOV"]["travel"] == pytest.approx((0.2 + 0.4 + 0.4 + 0.4 + 0.2) / 2)


@settings(deadline=None, max_examples=40)
@given(
    lengths=st.lists(st.integers(1, 40), min_size=1, max_size=6),
    seed=st.integers(0, 2**32 - 1),
)
def test_steady_state_error_is_each_episodes_own_tail_mean(lengths, seed):
    """Against a loop over the episodes: the mean |error| of the last max(1, n // 10) of each
    episode's n steps, averaged over the episodes."""
    rng = np.random.default_rng(seed)
    horizon, k = max(lengths), len(lengths)
    obs = rng.normal(size=(horizon + 1, k, 10))
    alive = np.arange(horizon)[:, None] < np.array(lengths)[None, :]
    zeros = np.zeros((horizon, k, 2))
    run = Rollout(obs, zeros, zeros, np.zeros((horizon, k)), alive, 0.04)
    tails = [np.abs(obs[1 + n - max(1, n // 10) : 1 + n, i, 4]).mean() for i, n in enumerate(lengths)]
    expected = np.mean(tails)
    assert metrics(run, LAYOUTS[TRACKING])["outputs"]["Pc"]["steady_state_error"] == pytest.approx(expected)


def test_a_nan_controller_is_named_with_its_step():
    class Broken:
        def reset(self, seed=None, num_envs=1, envs=None):
            self.k = 0

        def act(self, obs, info=None):
            self.k += 1
            out = np.zeros((len(obs), 2))
            if self.k > 7:
                out[1, 0] = np.nan
            return out

    with pytest.raises(ValueError, match=r"controller 'broken' returned a non-finite action .* at step 7"):
        evaluate(TRACKING, {"broken": lambda env: Broken()}, ["nominal"], episodes=2)


def test_evaluate_command_writes_results_and_plots(tmp_path, capsys):
    out = tmp_path / "ev"
    code = main(["evaluate", "--env", TRACKING, "--controllers", "pi,lqi,lqi:truth", "--scenario",
                 "pc_step,nominal", "--episodes", "3", "--out", str(out)])  # fmt: skip
    assert code == 0
    data = json.loads((out / "results.json").read_text())
    lqi = data["scenarios"]["pc_step"]["lqi"]
    assert {"return_mean", "return_std", "cost_cvar90", "outputs", "actuators"} <= set(lqi)
    assert lqi["outputs"]["Pc"]["rise_time"] > 0 and lqi["outputs"]["Pc"]["iae"] > 0
    assert (out / "pc_step.png").stat().st_size > 10_000 and (out / "nominal.png").exists()
    assert "| lqi:truth |" in (out / "results.md").read_text()


def test_evaluate_command_uses_its_seed(tmp_path):
    def costs(seed):
        out = tmp_path / str(seed)
        assert main(["evaluate", "--env", TRACKING, "--controllers", "lqi", "--scenario", "noise",
                     "--episodes", "2", "--seed", str(seed), "--out", str(out)]) == 0  # fmt: skip
        return json.loads((out / "results.json").read_text())["scenarios"]["noise"]["lqi"]["cost_mean"]

    assert costs(0) == costs(0) != costs(5)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--env", "CartPole-v1"], "unknown env 'CartPole-v1'; choose one of ssme_envs/EngineTracking-v0"),
        (["--env", TRACKING, "--controllers", "pi,lqr"], "unknown controller 'lqr'"),
        (["--env", TRACKING, "--scenario", "storm"], "unknown scenario storm .*choose from pc_step"),
        (["--env", TRACKING, "--episodes", "0"], "--episodes must be a positive integer"),
        (["--env", TRACKING, "--controllers", "lqi:paper"], "unknown design model 'paper'"),
    ],
)
def test_evaluate_command_rejects_bad_names(args, message, tmp_path, capsys):
    assert main(["evaluate", *args, "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "\n" not in err
    assert __import__("re").search(message, err), err


@pytest.mark.slow
def test_report_command_writes_one_report(tmp_path, capsys):
    out = tmp_path / "report"
    assert main(["report", "--out", str(out), "--episodes", "2"]) == 0
    text = (out / "report.md").read_text()
    for heading in ("LQI against decoupled PI", "Sim-to-real", "hysteresis compensation", "Table I"):
        assert heading in text
    for env in ("EngineTracking-v0", "EngineThrottle-v0", "NozzleTVC-v0", "LauncherPitch-v0"):
        assert (out / env / "results.json").exists()
    # every figure the report shows exists
    for figure in __import__("re").findall(r"!\[[^\]]*\]\(([^)]+)\)", text):
        assert (out / figure).exists(), figure


@pytest.mark.parametrize("episodes", [np.int64(2), np.int32(2)])
def test_numpy_integer_episode_counts_are_accepted(episodes):
    from agents import parse_controller

    result = evaluate(TRACKING, {"zero": parse_controller("zero", TRACKING)}, ["nominal"], episodes=episodes)
    assert result["nominal"]["zero"].episodes == 2
