"""Monte-Carlo evaluation (``evaluate --monte-carlo``) and the spread-tuned LQ servo."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import ssme_envs  # noqa: F401  (registers the environments)
from agents import LQIServo
from agents.robust import RobustLQI, design_task
from ssme_envs.cli import main
from ssme_envs.models.nozzle import identified_nozzle
from ssme_envs.robustness import spread_envs, summarize

NOZZLE = "ssme_envs/NozzleTVC-v0"


@settings(max_examples=50, deadline=None)
@given(arrays(np.float64, st.integers(1, 300), elements=st.floats(0, 1e6)))
def test_summary_is_mean_worst_and_the_mean_of_the_worst_tenth(costs):
    row = summarize(costs)
    ranked = sorted(costs.tolist())
    count = -(-len(ranked) // 10)  # the worst tenth, rounded up: ceil(N / 10)
    tail = ranked[len(ranked) - count :]
    assert row.mean == pytest.approx(sum(ranked) / len(ranked), rel=1e-12, abs=1e-9)
    assert row.worst == ranked[-1]
    assert row.cvar == pytest.approx(sum(tail) / len(tail), rel=1e-12, abs=1e-9)
    assert row.mean <= row.cvar + 1e-9 and row.cvar <= row.worst + 1e-9


def test_monte_carlo_writes_the_table_from_the_drawn_plants(tmp_path):
    """Three drawn plants: robustness.json's mean is results.json's cost (the same rollouts), the
    drawn plants change the LQ servo's cost, and the zero action's (which never moves the joint)
    not; the command is recorded."""
    out = tmp_path / "mc"
    args = ["evaluate", "--env", NOZZLE, "--controllers", "zero,lqi", "--scenario", "step",
            "--monte-carlo", "3", "--plant-spread", "0.3", "--out", str(out)]  # fmt: skip
    assert main(args) == 0
    robust = json.loads((out / "robustness.json").read_text())
    results = json.loads((out / "results.json").read_text())["scenarios"]["step"]
    rows = robust["scenarios"]["step"]
    assert robust["plant_spread"] == 0.3 and rows["lqi"]["plants"] == 3
    for name in ("zero", "lqi"):
        assert rows[name]["mean"] == pytest.approx(results[name]["cost_mean"], rel=1e-12)
    text = (out / "robustness.md").read_text()
    nominal = {line.split("|")[1].strip(): float(line.split("|")[2]) for line in text.splitlines()
               if line.startswith("| zero") or line.startswith("| lqi")}  # fmt: skip
    assert nominal["zero"] == pytest.approx(rows["zero"]["mean"], abs=6e-4)  # the table's 3 decimals
    assert abs(nominal["lqi"] / rows["lqi"]["mean"] - 1) > 1e-3
    assert text.startswith(f"# Robustness on {NOZZLE}") and "3 plants drawn with relative spread 0.3" in text


def test_the_nominal_mean_is_in_the_json_and_a_repeated_row_is_said(tmp_path):
    """robustness.md's nominal-plant column had no source in robustness.json; and two controllers
    with the same episode costs (the report's `robust` and `lqi` on the nozzle) stood as two equal
    rows without a word."""
    from agents import parse_controller
    from ssme_envs.evaluation import evaluate
    from ssme_envs.robustness import write_robustness

    lqi = parse_controller("lqi", NOZZLE)
    factories = {"zero": parse_controller("zero", NOZZLE), "lqi": lqi, "twin": lqi}
    drawn = evaluate(NOZZLE, factories, ["step"], 3, options={"plant_spread": 0.3})
    nominal = evaluate(NOZZLE, factories, ["step"], 3)
    text = write_robustness(tmp_path, drawn, nominal, 0.3, "the command").read_text()
    rows = json.loads((tmp_path / "robustness.json").read_text())["scenarios"]["step"]
    for name in factories:
        assert rows[name]["nominal_mean"] == nominal["step"][name].cost_mean
    assert "`twin` gives every episode the cost `lqi` gives it, to the bit" in text
    assert "`lqi` gives every episode" not in text and "`zero` gives every episode" not in text


def test_plant_option_reaches_both_runs_and_uncertainty_draws_from_the_identified_model(tmp_path):
    """``--plant identified --plant-spread uncertainty``: the drawn run is evaluate() with those env
    options, the nominal run evaluate() on the identified plant alone (not the scenario's own)."""
    from agents import parse_controller
    from ssme_envs.evaluation import evaluate

    out = tmp_path / "mc"
    args = ["evaluate", "--env", NOZZLE, "--controllers", "lqi", "--scenario", "step", "--monte-carlo", "3",
            "--plant", "identified", "--plant-spread", "uncertainty", "--out", str(out)]  # fmt: skip
    assert main(args) == 0
    robust = json.loads((out / "robustness.json").read_text())
    assert robust["plant_spread"] == "uncertainty"
    factories = {"lqi": parse_controller("lqi", NOZZLE)}
    drawn = evaluate(
        NOZZLE, factories, ["step"], 3, 0, options={"plant": "identified", "plant_spread": "uncertainty"}
    )
    nominal = evaluate(NOZZLE, factories, ["step"], 3, 0, options={"plant": "identified"})
    default = evaluate(NOZZLE, factories, ["step"], 3, 0)
    assert robust["scenarios"]["step"]["lqi"]["mean"] == drawn["step"]["lqi"].cost_mean
    text = (out / "robustness.md").read_text()
    row = next(line for line in text.splitlines() if line.startswith("| lqi"))
    assert float(row.split("|")[2]) == pytest.approx(nominal["step"]["lqi"].cost_mean, abs=6e-4)
    assert drawn["step"]["lqi"].cost_mean != nominal["step"]["lqi"].cost_mean  # plants were drawn
    assert nominal["step"]["lqi"].cost_mean != default["step"]["lqi"].cost_mean  # the plant replaced


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--env", "ssme_envs/EngineTracking-v0", "--monte-carlo", "2"], "has one plant in every episode"),
        (["--env", NOZZLE, "--monte-carlo", "2", "--episodes", "3"], "give --episodes or --monte-carlo"),
        (["--env", NOZZLE, "--plant-spread", "0.1"], "--plant-spread applies with --monte-carlo"),
        (["--env", NOZZLE, "--monte-carlo", "0"], "--monte-carlo must be a positive integer"),
        (["--env", NOZZLE, "--monte-carlo", "2", "--plant-spread", "0.9"], "plant_spread must be in"),
        (["--env", NOZZLE, "--plant", "nope"], "scenario 'step': plant must be one of"),
        (["--env", NOZZLE, "--monte-carlo", "2", "--plant-spread", "0"], "must be above 0 to draw plants"),
        (["--env", NOZZLE, "--monte-carlo", "2", "--plant-spread", "-0"], "must be above 0 to draw plants"),
        (["--env", NOZZLE, "--monte-carlo", "2", "--plant-spread", ""], "must be a number or 'uncertainty'"),
        (["--env", NOZZLE, "--monte-carlo", "100000000000"], "--monte-carlo 100000000000 needs about"),
        (
            ["--env", "ssme_envs/EngineTracking-v0", "--plant", "identified"],
            "scenario 'bucket': plant='identified'",
        ),
    ],
)
def test_monte_carlo_errors_are_one_line(tmp_path, capsys, extra, message):
    assert main(["evaluate", *extra, "--controllers", "zero", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and message in err[0]


def test_spread_envs_are_those_whose_task_takes_the_option():
    assert spread_envs() == [NOZZLE, "ssme_envs/LauncherPitch-v0"]


def test_the_robust_family_holds_the_nominal_servo_and_tunes_on_the_design_model():
    """With R x 1 and the 10 % process ratio the tuned servo is the LQ servo, action for action;
    its ensemble is drawn around the identified joint (the design model), not the judged plant."""
    env = gym.make_vec(NOZZLE, num_envs=4, vectorization_mode="vector_entry_point", plant_spread=0.2)
    obs, _ = env.reset(seed=1)
    a, b = RobustLQI(env, "identified", 1.0, 10.0), LQIServo(env, "identified")
    a.reset(seed=1, num_envs=4)
    b.reset(seed=1, num_envs=4)
    for _ in range(50):
        act = a.act(obs, {})
        np.testing.assert_array_equal(act, b.act(obs, {}))
        obs, *_ = env.step(act.astype(np.float32))
    ensemble = design_task(env.unwrapped.task, "identified")
    design = identified_nozzle("table1").plant().normalized()
    np.testing.assert_allclose(ensemble.spread.mean, list(design.values()), rtol=1e-15)
    assert ensemble.plant != env.unwrapped.task.plant


def test_tuning_all_candidates_in_one_env_scores_each_as_on_an_env_of_its_own(monkeypatch):
    """The robust servo's tuning runs every candidate in one vector env; each candidate's CVaR
    equals the one of its own rollout on an env of the ensemble alone (the same seeds), to the bit,
    and the tuned candidate is the one of least CVaR."""
    import itertools

    import agents.robust as robust
    from ssme_envs.envs.vector import TrackingVectorEnv
    from ssme_envs.evaluation import rollout
    from ssme_envs.robustness import cvar, episode_costs

    monkeypatch.setattr(robust, "DESIGN_PLANTS", 12)
    monkeypatch.setattr(robust, "RATE_FACTORS", (0.5, 1.0, 4.0))
    monkeypatch.setattr(robust, "_TUNED", {})
    task = gym.make(NOZZLE, reference="step").unwrapped.task
    ensemble = design_task(task, "identified")
    alone = type("Alone", (TrackingVectorEnv,), {"build_task": staticmethod(lambda: ensemble)})
    scores = {}
    for factor, process in itertools.product(robust.RATE_FACTORS, robust.PROCESS_RATIOS):
        env = alone(12)
        servo = RobustLQI(env, "identified", factor, process)
        scores[factor, process] = cvar(episode_costs(rollout(env, servo, "robust", robust.DESIGN_SEED)))
    assert len(set(scores.values())) > 1  # the candidates differ, so the choice means something
    factor, process, score = robust._tuned(task, "identified")
    assert score == scores[factor, process] == min(scores.values())
