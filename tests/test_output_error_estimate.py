"""identify(method="oe"): the output-error estimate and its intervals.

The records come from systems built by scipy (``zpk2ss``) or by ``conftest.random_system`` (random
pole blocks behind a random basis) and simulated by ``scipy.signal.dlsim``; the checks compare with
the true Markov parameters, with an independent simulation of the estimate, and with the truth's
gains and offsets.
"""

from __future__ import annotations

import argparse

import numpy as np
import pytest
import scipy.signal
from conftest import random_system
from hypothesis import given, settings
from hypothesis import strategies as st

from ssme_envs.cli import build_parser
from ssme_envs.identification import identify
from ssme_envs.identification.arguments import METHODS
from ssme_envs.identification.covariance import markov_standard_errors

MARKOV = 8


def _markov(a: np.ndarray, b: np.ndarray, c: np.ndarray, count: int) -> np.ndarray:
    out, power = [], b
    for _ in range(count):
        out.append(c @ power)
        power = a @ power
    return np.array(out)


def _record(system: tuple, u: np.ndarray, noise: float, rng: np.random.Generator) -> np.ndarray:
    a, b, c = system
    y = scipy.signal.dlsim((a, b, c, np.zeros((c.shape[0], b.shape[1])), 1.0), u)[1]
    return y + noise * y.std(axis=0) * rng.standard_normal(y.shape)


def _slow_system() -> tuple:
    """Poles 0.9 and 0.56, a zero at -0.3: a slow mode, where the least-squares estimate that the
    IV passes often keep at 10 % output noise is biased."""
    a, b, c, _ = scipy.signal.zpk2ss([-0.3], [0.9, 0.56], 0.8)
    return a, b, c


def test_output_error_intervals_cover_the_truth_where_iv_kept_least_squares() -> None:
    """A random system with a slow mode (poles 0.90 and 0.56), where the IV passes keep the
    least-squares estimate in about 40 % of the seeds at 10 % output noise and its intervals
    cover about 40 % of the Markov parameters."""
    system = random_system(2, 1, 1, np.random.default_rng(1014))
    assert np.sort(np.abs(np.linalg.eigvals(system[0]))) == pytest.approx([0.56, 0.9], abs=0.01)
    want = _markov(*system, MARKOV)
    inside, inside_ls_kept, ls_kept = [], [], 0
    for seed in range(60):
        rng = np.random.default_rng(seed)
        u = rng.standard_normal((1000, 1))
        y = _record(system, u, 0.1, rng)
        kept_ls = identify(u, y, 1.0, indices=[2], asymmetric=False).model.uncertainty.method
        model = identify(u, y, 1.0, indices=[2], asymmetric=False, method="oe").model
        assert model.uncertainty.method.startswith("output error")
        markov, se = markov_standard_errors(model, MARKOV)
        hits = np.abs(markov - want) <= 1.96 * se
        inside.append(hits)
        if kept_ls.startswith("least squares"):
            ls_kept += 1
            inside_ls_kept.append(hits)
    assert ls_kept >= 10  # the case the method is for occurs
    assert 0.9 <= np.mean(inside) <= 0.99
    assert np.mean(inside_ls_kept) >= 0.85


def _simulation_cost(model, intercept: np.ndarray, u: np.ndarray, y: np.ndarray) -> float:
    """The criterion method "oe" minimizes, by an independent simulation (dlsim of the estimate)."""
    d = np.zeros((model.n_outputs, model.n_inputs))
    simulated = scipy.signal.dlsim((model.A, model.B, model.C, d, 1.0), u)[1].reshape(y.shape)
    return float(np.sum(((y - simulated - intercept) / y.std(axis=0)) ** 2))


@settings(max_examples=12, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    order=st.integers(1, 3),
    outputs=st.integers(1, 2),
    noise=st.sampled_from([0.02, 0.05]),
)
def test_the_oe_estimate_minimizes_the_simulation_error(
    seed: int, order: int, outputs: int, noise: float
) -> None:
    rng = np.random.default_rng(seed)
    system = random_system(order * outputs, 1, outputs, rng)
    u = rng.standard_normal((600, 1))
    y = _record(system, u, noise, rng)
    try:
        start = identify(u, y, 1.0, asymmetric=False)
        fit = identify(u, y, 1.0, asymmetric=False, method="oe")
    except ValueError as exc:  # a structure the record does not determine is refused, for both
        assert "method 'oe'" not in str(exc)
        return
    best = _simulation_cost(fit.model, fit.intercept, u, y)
    assert best <= _simulation_cost(start.model, start.intercept, u, y) * (1 + 1e-9)
    # no small move of one free parameter (lambda is held: asymmetric=False) lowers it
    theta = fit.model.parameter_vector()
    for k in range(theta.size - fit.model.n_inputs):
        for step in (-1e-4, 1e-4):
            moved = theta.copy()
            moved[k] += step * max(abs(theta[k]), 1e-2)
            other = fit.model.with_parameters(moved)
            if other.spectral_radius() < 1.0:
                assert _simulation_cost(other, fit.intercept, u, y) >= best * (1 - 1e-9)
    assert np.all(fit.model.lam == 1.0)
    names = fit.model.parameter_names()
    held = [names.index(f"lambda[{j}]") for j in range(fit.model.n_inputs)]
    assert np.all(fit.model.uncertainty.covariance[held] == 0.0)


def test_a_constant_output_offset_is_estimated_apart_from_the_dynamics() -> None:
    rng = np.random.default_rng(3)
    system = _slow_system()
    u = rng.standard_normal((800, 1))
    y = _record(system, u, 0.05, rng)
    plain = identify(u, y, 1.0, indices=[2], method="oe")
    shifted = identify(u, y + 0.37, 1.0, indices=[2], method="oe")
    assert shifted.intercept - plain.intercept == pytest.approx([0.37], abs=1e-6)
    np.testing.assert_allclose(
        shifted.model.markov_parameters(MARKOV), plain.model.markov_parameters(MARKOV), rtol=1e-5, atol=1e-7
    )


@pytest.mark.parametrize("binary", [False, True])
def test_the_asymmetric_gain_is_estimated_within_its_interval(binary: bool) -> None:
    """lambda of a Gaussian input (from the |u| lags) and of a binary one (from the mean shift it
    causes; no output offset is then estimated beside it): within 3 standard errors, over seeds."""
    system, lam = _slow_system(), 1.25
    z = []
    for seed in range(12):
        rng = np.random.default_rng(seed)
        u = rng.standard_normal((1000, 1))
        if binary:
            u = np.sign(u)
        u_star = u + (lam - 1.0) * np.abs(u)  # eq 36, written here
        y = _record(system, u_star, 0.05, rng)
        fit = identify(u, y, 1.0, indices=[2], method="oe")
        names = fit.model.parameter_names()
        var = fit.model.uncertainty.covariance[names.index("lambda[0]"), names.index("lambda[0]")]
        z.append((fit.model.lam[0] - lam) / np.sqrt(var))
        if binary:
            assert fit.intercept == pytest.approx([0.0])
    assert np.max(np.abs(z)) < 3.5
    assert np.mean(np.abs(z) < 1.96) >= 0.75


def test_oe_refuses_a_record_whose_starting_estimate_is_unstable() -> None:
    rng = np.random.default_rng(0)
    u = rng.standard_normal((300, 1))
    system = (np.array([[1.02]]), np.array([[1.0]]), np.array([[1.0]]))
    y = _record(system, u, 0.01, rng)
    assert identify(u, y, 1.0, indices=[1]).model.spectral_radius() > 1.0  # iv gives it
    with pytest.raises(ValueError, match=r"method 'oe' simulates the model.*unstable.*use method 'iv'"):
        identify(u, y, 1.0, indices=[1], method="oe")


def test_the_command_line_offers_the_library_methods_and_defaults() -> None:
    import inspect

    parser = build_parser()
    engine = _subparser(_subparser(parser, "identify"), "engine")
    options = {action.dest: action for action in engine._actions}
    assert tuple(options["method"].choices) == METHODS
    defaults = inspect.signature(identify).parameters
    for name in ("method", "max_index", "rank_tol"):
        assert options[name].default == defaults[name].default


def test_the_max_index_help_gives_the_walks_largest_order() -> None:
    """The CLI's help writes the walk's bound as a number (it does not import identification)."""
    from ssme_envs.identification.structure import MAX_WALK_ORDER

    engine = _subparser(_subparser(build_parser(), "identify"), "engine")
    (option,) = [a for a in engine._actions if a.dest == "max_index"]
    assert f"to {MAX_WALK_ORDER} states in all" in option.help


def _subparser(parser: argparse.ArgumentParser, name: str) -> argparse.ArgumentParser:
    (commands,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return commands.choices[name]


def test_oe_on_an_exact_record_gives_the_system_and_a_finite_covariance_without_caveat() -> None:
    rng = np.random.default_rng(5)
    a, b, c = random_system(4, 2, 2, rng)
    u = np.sign(rng.standard_normal((800, 2)))
    y = scipy.signal.dlsim((a, b, c, np.zeros((2, 2)), 1.0), u)[1]
    model = identify(u, y, 1.0, method="oe").model
    np.testing.assert_allclose(model.markov_parameters(MARKOV), _markov(a, b, c, MARKOV), atol=1e-8)
    assert np.all(np.isfinite(model.uncertainty.covariance))
    assert "not white" not in model.uncertainty.method
