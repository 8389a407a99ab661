"""The main report's cost-over-zero tables: ratios, the causes printed for a controller above the
zero action, UNEXPLAINED when there is none, and none for the shipped report plan."""

import math

import numpy as np
import pytest

from ssme_envs.evaluation_result import ActuatorMetrics, ControllerMetrics, EvaluationResult, OutputMetrics
from ssme_envs.main_report import REPORT_PLAN, THROTTLE, cost_over_zero_tables, unexplained

NAN = math.nan


def _output(ise: float, cycles: float = 0.0, period: float = NAN, amplitude: float = NAN) -> OutputMetrics:
    return OutputMetrics(1.0, ise, 1.0, 0.0, NAN, NAN, NAN, cycles, period, amplitude, 3.0)


def _metrics(cost: float, ise: float = 1.0, at_limit: float = 0.0, cycles: float = 0.0,
             terminations: int = 0) -> ControllerMetrics:  # fmt: skip
    outputs = {
        "Pc": _output(ise, cycles, 0.33 if cycles else NAN, 1.3 if cycles else NAN),
        "MR": _output(ise),
    }
    actuators = {
        "OPOV": ActuatorMetrics(0.1, 1.0, 2.0, 0.0),
        "FPOV": ActuatorMetrics(0.1, 1.0, 2.0, at_limit),
    }
    return ControllerMetrics(8, -cost, 0.0, cost, cost, terminations, outputs, actuators)


def _result(rows: dict[str, ControllerMetrics], scenario: str = "made_up") -> EvaluationResult:
    result = EvaluationResult(THROTTLE)
    for name, m in rows.items():
        result.scenarios.setdefault(scenario, {})[name] = m
    return result


def _cause_lines(result: EvaluationResult) -> list[str]:
    return [line for line in cost_over_zero_tables({THROTTLE: result}) if line.startswith("- ")]


def test_ratio_cells_are_cost_over_zero():
    lines = cost_over_zero_tables({THROTTLE: _result({"zero": _metrics(40.0), "fast": _metrics(10.0)})})
    assert "| made_up | 40.000 | 0.25 |" in lines
    assert not [line for line in lines if line.startswith("- ")]  # nothing above 1.0


def test_a_limit_cycle_and_saturation_are_named():
    result = _result(
        {"zero": _metrics(50.0, ise=2.0), "wobbly": _metrics(150.0, ise=5.0, at_limit=0.18, cycles=1.0)}
    )
    (line,) = _cause_lines(result)
    assert line.startswith("- wobbly on made_up, 3.00x (Pc ISE 2.5x the zero action's, MR ISE 2.5x")
    assert "limit cycle in 100 % of episodes (0.33 s, +-1.3 % Pc)" in line
    assert "FPOV at its limit 18 % of the time" in line
    assert "UNEXPLAINED" not in line and unexplained(result) == []


def test_early_ends_are_named():
    (line,) = _cause_lines(_result({"zero": _metrics(50.0), "falls": _metrics(60.0, terminations=3)}))
    assert "ended early in 3 of 8 episodes" in line


def test_no_cause_is_unexplained_for_a_classical_controller_only():
    result = _result(
        {"zero": _metrics(50.0), "mystery": _metrics(55.0, at_limit=0.01), "ppo": _metrics(70.0)}
    )
    lines = _cause_lines(result)
    assert any(line.startswith("- mystery") and "**UNEXPLAINED**" in line for line in lines)
    assert any(line.startswith("- ppo") and "UNEXPLAINED" not in line for line in lines)
    assert unexplained(result) == [("made_up", "mystery")]


def test_a_written_cause_explains():
    result = _result({"zero": _metrics(50.0), "pi": _metrics(55.0)}, scenario="mission")
    (line,) = _cause_lines(result)
    assert "cross-coupling" in line and unexplained(result) == []


@pytest.mark.slow
def test_the_shipped_report_plan_has_no_unexplained_classical_controller():
    from agents import parse_controller
    from ssme_envs.evaluation import evaluate

    for env_id, (specs, scenarios) in REPORT_PLAN.items():
        names = [s for s in specs.split(",") if not s.startswith("ppo")]
        result = evaluate(env_id, {n: parse_controller(n, env_id) for n in names}, scenarios, episodes=4)
        assert unexplained(result) == [], env_id


def test_a_policys_fault_cause_comes_from_its_own_training_config():
    """The stuck valve's causes for the shipped policies were one written text, which called
    `ppo:identified` trained on the truth; now each is read from the policy's config.toml (the
    identified plant for that one) and a residual's names its base design's cost here."""
    import tomllib

    from agents.shipped import shipped_specs
    from ssme_envs.main_report import TRACKING

    result = EvaluationResult(TRACKING)
    rows = {"zero": _metrics(40.0), "lqi": _metrics(60.0)}
    rows |= {name: _metrics(50.0) for name in ("ppo", "ppo:identified", "ppo:residual")}
    result.scenarios["stuck_valve"] = rows
    lines = {
        line.split(" on ")[0][2:]: line
        for line in cost_over_zero_tables({TRACKING: result})
        if line[:2] == "- "
    }
    specs = shipped_specs(TRACKING)
    for name in ("ppo", "ppo:identified", "ppo:residual"):
        config = tomllib.loads((specs[name] / "config.toml").read_text())
        assert "fault" not in config.get("env_options", {})
        assert f"agents/policies/{specs[name].name}/config.toml" in lines[name]
        assert "never met a stuck valve" in lines[name]
    assert 'plant = "identified"' in lines["ppo:identified"]
    assert "plant" not in lines["ppo"].split("config.toml")[1]
    assert "a correction to `lqi`, which costs 1.50x the zero action here" in lines["ppo:residual"]


@pytest.mark.parametrize(
    ("zero", "cost", "cell"), [(40.0, 0.168, "0.0042"), (40.0, 2.6, "0.065"), (40.0, 10.0, "0.25")]
)
def test_small_ratios_keep_two_significant_digits(zero, cost, cell):
    """Two decimals printed the nozzle's ratio 0.0042 as 0.00."""
    lines = cost_over_zero_tables({THROTTLE: _result({"zero": _metrics(zero), "fast": _metrics(cost)})})
    assert f"| made_up | {zero:.3f} | {cell} |" in lines


def _nozzle(iae: dict[str, float], ended: int = 0) -> dict[str, ControllerMetrics]:
    """The nozzle table's three controllers with the given angle IAEs; ``ended`` PID episodes
    ended early."""
    return {
        c: ControllerMetrics(
            20,
            -1.0,
            0.0,
            1.0,
            1.0,
            ended if c == "pid" else 0,
            {"angle": OutputMetrics(v, 1.0, 1.0, 0.0, NAN, NAN, NAN, 0.0, NAN, NAN, 3.0)},
            {},
        )
        for c, v in iae.items()
    }


def test_the_nozzle_table_flags_early_ends_and_compares_each_scenario_with_its_own_twin():
    """The PID's IAE on the strong joint stood unflagged though most episodes ended early (the IAE
    stops there), and the sentence under the table named Table 1's linear row for the strong
    joint's twin and said the rest of the gain helps either joint where it cost the twin 83 %."""
    from ssme_envs.main_report import NOZZLE, nozzle_tables

    result = EvaluationResult(NOZZLE)
    result.scenarios["sine_sweep"] = _nozzle({"pid": 3.0, "lqi": 0.30, "hysteresis": 0.27})
    result.scenarios["sine_sweep_linear"] = _nozzle({"pid": 3.0, "lqi": 0.28, "hysteresis": 0.26})
    result.scenarios["sine_sweep_strong"] = _nozzle({"pid": 3.3, "lqi": 1.50, "hysteresis": 0.45}, ended=16)
    result.scenarios["sine_sweep_strong_linear"] = _nozzle({"pid": 3.7, "lqi": 0.25, "hysteresis": 0.50})
    lines = nozzle_tables(result)
    assert "| sine_sweep_strong | 3.3000 (16 of 20 ended early) | 1.5000 | 0.4500 | -70.0 % |" in lines
    assert any("the IAE understates the tracking" in line for line in lines)
    said = lines[-1]
    assert "sine_sweep_strong -170.0 (against sine_sweep_strong_linear)" in said
    assert "helps a joint without hysteresis too. On sine_sweep_strong_linear it adds to the cost" in said
    del result.scenarios["sine_sweep"], result.scenarios["sine_sweep_linear"]  # only a twin it costs
    assert nozzle_tables(result)[-1].endswith(
        "adds to the cost (its feedforward is the inverse of the identified Table 1 joint's hysteresis)."
    )


def test_the_ratio_standard_error_agrees_with_a_paired_bootstrap():
    """The learned / classical ratio's standard error (ratio estimator, paired episodes) against
    a bootstrap of the same episodes, resampled in pairs (seeded numpy)."""
    from types import SimpleNamespace

    from ssme_envs.report_costs import ratio_standard_error

    rng = np.random.default_rng(3)
    base = rng.gamma(2.0, 1.0, 400)
    costs = {"a": base * 1.1 + rng.normal(0.0, 0.3, 400), "b": base}
    result = EvaluationResult(THROTTLE)
    for name, c in costs.items():  # one step per episode, its reward minus the cost
        result.rollouts[("s", name)] = SimpleNamespace(rewards=-c[None, :], alive=np.ones((1, 400)))
    se = ratio_standard_error(result, "s", "a", "b")
    picks = rng.integers(0, 400, (4000, 400))
    boot = costs["a"][picks].mean(axis=1) / costs["b"][picks].mean(axis=1)
    assert se == pytest.approx(boot.std(), rel=0.1)
    assert ratio_standard_error(result, "s", "a", "missing") is None


def test_the_report_gives_each_envs_reward_from_its_docs():
    from ssme_envs.envs import catalogue
    from ssme_envs.main_report import reward_lines

    lines = reward_lines(dict.fromkeys(catalogue.ENVS))
    assert len(lines) == len(catalogue.ENVS)
    assert all("see the env's docs" not in line and "-0.1 " in line for line in lines)
    assert any(
        line.startswith("- ssme_envs/NozzleTVC-v0: ``-0.1 e^2 - 0.1 (a_k - a_(k-1))^2``") for line in lines
    )
