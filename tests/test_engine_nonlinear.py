"""The nonlinear engine truth: its linearization, its asymmetric gains, its runs.

Expected values come from Table I (``published_model``) or from computations written out here
(finite differences, eq 36 branch by branch), never from the code under test.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import eq36, markov

from ssme_envs.identification.engine_nonlinear_pipeline import nonlinear_experiment, run_nonlinear
from ssme_envs.identification.pipeline import identify_record
from ssme_envs.models import (
    POWER_LEVELS,
    NonlinearEngine,
    TruthConfig,
    flow_characteristic,
    published_model,
    simulate,
    simulate_nonlinear,
)
from ssme_envs.signals import prbs, step_ramp_test_signal

MARKOV_COUNT = 11  # C A^k B for k = 0..10


@pytest.fixture(scope="module")
def engine() -> NonlinearEngine:
    return NonlinearEngine()


def _one_step(engine: NonlinearEngine, z: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The map (x, rho), v -> (x, rho) at the next sample, for one engine on flat vectors."""
    n = engine.layout.n
    x, rho = engine.step(z[None, :n], z[None, n], v[None])
    return np.concatenate([x[0], rho])


def _finite_difference_markov(engine: NonlinearEngine, power: float, h: float = 1e-6) -> np.ndarray:
    """Markov parameters of the central-difference Jacobian of the one-step map about the trim.

    The state is (x, rho); the output y = C x does not read rho. Steps: h in x and v
    (normalized units), 100 h in rho (% of power, the same Pc-equivalent size).
    """
    x0, rho0, v0 = engine.trim(power)
    z0 = np.concatenate([x0[0], rho0])
    size = z0.size
    jac_z = np.empty((size, size))
    for i in range(size):
        step = np.zeros(size)
        step[i] = h * (100.0 if i == size - 1 else 1.0)
        jac_z[:, i] = (_one_step(engine, z0 + step, v0[0]) - _one_step(engine, z0 - step, v0[0])) / (
            2 * step[i]
        )
    jac_v = np.empty((size, v0.shape[1]))
    for j in range(v0.shape[1]):
        step = np.zeros(v0.shape[1])
        step[j] = h
        jac_v[:, j] = (_one_step(engine, z0, v0[0] + step) - _one_step(engine, z0, v0[0] - step)) / (2 * h)
    c_aug = np.hstack([engine.C, np.zeros((engine.C.shape[0], 1))])
    return markov(jac_z, jac_v, c_aug, MARKOV_COUNT)


def test_table1_models_share_the_canonical_structure():
    """What the interpolation relies on: same indices, C = [0 I], A = A_o + K C at every level."""
    first = published_model(POWER_LEVELS[0])
    for power in POWER_LEVELS:
        model = published_model(power)
        assert model.observability_indices == first.observability_indices == (2, 2)
        np.testing.assert_array_equal(model.C, np.hstack([np.zeros((2, 2)), np.eye(2)]))
        assert model.alpha_canonical_residual() == 0.0


@pytest.mark.parametrize("power", [65.0, 70.0, 77.3, 90.0, 100.0, 108.9, 110.0])
def test_trim_is_an_equilibrium_at_its_own_power(engine, power):
    x, rho, v = engine.trim(power)
    x_next, rho_next = engine.step(x, rho, v)
    np.testing.assert_allclose(x_next, x, atol=1e-13)
    np.testing.assert_allclose(rho_next, power, atol=1e-10)
    np.testing.assert_allclose(engine.outputs(x)[0], [power / 100.0 - 1.0, 0.0], atol=1e-13)
    np.testing.assert_allclose(engine.power_of(x), power, atol=1e-10)


@pytest.mark.parametrize("tau", [0.0, 0.2])
@pytest.mark.parametrize("power", POWER_LEVELS)
def test_linearization_has_table1_markov_parameters(power, tau):
    """C A^k B of the finite-difference Jacobian equal Table I's to 1e-6 relative, k = 0..10."""
    engine = NonlinearEngine(tau=tau)
    ours = _finite_difference_markov(engine, power)
    model = published_model(power)
    expected = markov(model.A, model.B, model.C, MARKOV_COUNT)
    relative = np.linalg.norm(ours - expected, axis=(1, 2)) / np.linalg.norm(expected, axis=(1, 2))
    assert relative.max() < 1e-6, relative


def test_flow_characteristic_slope_and_chords():
    lam = np.array([0.7699, 1.1231])
    a = 0.01
    h = 1e-7
    slope = (flow_characteristic(np.full(2, h), lam) - flow_characteristic(np.full(2, -h), lam)) / (2 * h)
    np.testing.assert_allclose(slope, 1.0, rtol=1e-8)
    np.testing.assert_allclose(flow_characteristic(np.full(2, a), lam) / a, lam, rtol=1e-12)
    np.testing.assert_allclose(flow_characteristic(np.full(2, -a), lam) / -a, 2.0 - lam, rtol=1e-12)
    u = prbs(127, a)
    np.testing.assert_allclose(flow_characteristic(u, lam), eq36(u, lam), rtol=1e-12, atol=1e-17)
    d = np.linspace(-0.2, 0.2, 4001)[:, None] * np.ones(2)
    assert np.all(np.diff(flow_characteristic(d, lam), axis=0) > 0)  # monotone


@pytest.mark.parametrize("power", POWER_LEVELS)
def test_lambda_identified_from_a_prbs_record(engine, power):
    """lambda identified from the 0.01 PRBS record (pipeline's design, default valve effects and
    noise) is within 5 % of Table I's lambda."""
    record = nonlinear_experiment(power, engine=engine)["identification"]
    identified = identify_record(record).model.lam
    table = published_model(power).lam
    np.testing.assert_array_less(np.abs(identified / table - 1.0), 0.05)


def test_small_signals_follow_table1_and_large_ones_do_not(engine):
    """At 1e-5 travel the truth is Table I's symmetric model; at the figure 3 amplitude it is not."""
    u = step_ramp_test_signal()
    ideal = TruthConfig.ideal()
    for power in (70, 100):
        model = published_model(power)
        symmetric = TruthConfig(asymmetric_gains=False, backlash=0.0, stiction=0.0, sensor_noise=0.0)
        small = simulate_nonlinear(engine, power, 1e-3 * u, ideal)[1]
        linear = simulate(model, 1e-3 * u, symmetric)[1]
        assert np.abs(small - linear).max() < 1e-3 * np.abs(linear).max()
        large = simulate_nonlinear(engine, power, u, ideal)[1]
        with_lambda = simulate(model, u, ideal)[1]
        assert np.abs(large - with_lambda).max() > 0.05 * np.abs(with_lambda).max()


def test_batched_runs_equal_single_runs(engine):
    rng = np.random.default_rng(3)
    powers = np.array([66.0, 80.0, 93.5, 110.0])
    commands = 0.01 * np.sign(rng.standard_normal((4, 200, 2)))
    config = TruthConfig(backlash=1e-3, stiction=5e-4, sensor_noise=0.0)
    _, batched = simulate_nonlinear(engine, powers, commands, config)
    for i, power in enumerate(powers):
        _, single = simulate_nonlinear(engine, power, commands[i], config)
        np.testing.assert_allclose(batched[i], single, rtol=0, atol=1e-15)


def test_schedule_comes_from_the_state_not_the_command():
    """rho(k+1) = rho(k) + alpha (power implied by Pc(k+1) - rho(k)), whatever the valves do."""
    for tau in (0.0, 0.3):
        engine = NonlinearEngine(tau=tau)
        x, rho, v = engine.trim(np.array([75.0, 75.0]))
        v = v + np.array([[0.02, -0.01], [-0.02, 0.01]])
        for _ in range(5):
            x_prev_rho = rho
            x, rho = engine.step(x, rho, v)
            implied = 100.0 + 100.0 * x[:, 2]  # the Pc state of the (2, 2) structure
            alpha = 1.0 if tau == 0 else 1.0 - np.exp(-engine.dt / tau)
            np.testing.assert_allclose(rho, x_prev_rho + alpha * (implied - x_prev_rho), atol=1e-12)
        assert abs(rho[0] - rho[1]) > 1.0  # opposite valve moves, different engine states


def test_invalid_inputs_are_refused(engine):
    u = prbs(10)
    with pytest.raises(ValueError, match="power"):
        simulate_nonlinear(engine, 120.0, u)
    with pytest.raises(ValueError, match="commands"):
        simulate_nonlinear(engine, 90.0, u[:, :1])
    with pytest.raises(ValueError, match="rng"):
        simulate_nonlinear(engine, 90.0, u, TruthConfig())
    with pytest.raises(ValueError, match="tau"):
        NonlinearEngine(tau=-1.0)


def test_pipeline_identifies_and_validates_one_level(engine):
    (result,) = run_nonlinear(power_levels=(100,), engine=engine)
    assert result.power_percent == 100
    np.testing.assert_array_equal(result.published.A, published_model(100).A)
    for record in ("validation_prbs", "validation_low_frequency"):
        values = np.array([result.validation[record][kind]["see"] for kind in ("model", "filter")])
        assert np.all(np.isfinite(values)) and np.all(values > 0) and np.all(values < 1)
    assert result.identified.model.spectral_radius() < 1.0


@pytest.mark.parametrize("power", POWER_LEVELS)
def test_linear_model_is_table_one_at_its_levels(engine, power):
    """The engine's linearization about its trim (the envs' "truth" design model on this plant)
    is Table I's model at each Table I level, lambda included."""
    linear, table = engine.linear_model(power), published_model(power)
    np.testing.assert_allclose(linear.A, table.A, rtol=0, atol=1e-12)
    np.testing.assert_allclose(linear.B, table.B, rtol=0, atol=1e-12)
    np.testing.assert_allclose(linear.lam, table.lam, rtol=0, atol=1e-12)
    assert linear.observability_indices == table.observability_indices
    with pytest.raises(ValueError, match="power"):
        engine.linear_model(60.0)


def test_pipeline_report_section_states_the_amplitude_and_the_papers_numbers(engine, tmp_path):
    from ssme_envs.identification.engine_nonlinear_pipeline import nonlinear_into
    from ssme_envs.identification.report import markov_difference

    (tmp_path / "report.md").write_text("# Report\n")
    text = nonlinear_into(tmp_path).read_text()
    assert text.startswith("# Report\n\n## The nonlinear engine truth")
    assert "beta_opov within +-0.02, beta_fpov within +-0.015" in text  # step_ramp_test_signal's peaks
    assert "| filter | pc | 0.0123 / " in text  # Table II, 70 %, figure 3 test: the paper's number first
    assert markov_difference(published_model(90), published_model(90)) == 0.0
    shifted = published_model(90)
    shifted.B[:] *= 1.1  # every Markov parameter 10 % larger
    assert markov_difference(published_model(90), shifted) == pytest.approx(0.1, rel=1e-12)
