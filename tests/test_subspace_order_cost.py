"""DSR_e's BIC order scan screens its candidates by faster routes to the same quantities
(``subspace_screen``) and scores exactly only those near the smallest screened BIC
(``subspace_bic``): it must choose the order and return the model that scoring every candidate
exactly gives, bit for bit, and fall back to that where the screen cannot vouch for itself.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import dlsim, random_system

from ssme_envs.identification import subspace, subspace_bic
from ssme_envs.identification.subspace import dsr_e
from ssme_envs.identification.subspace_bic import _exact_scan, observability_pair, realize
from ssme_envs.identification.subspace_checks import prediction_criterion
from ssme_envs.identification.subspace_regression import input_matrices
from ssme_envs.identification.subspace_screen import (
    Spectra,
    screened_criterion,
    screened_input_matrices,
)


@pytest.fixture(autouse=True)
def _unstable_candidates_overflow():
    """As dsr_e around its passes: an unstable candidate's powers of A overflow, and it is refused."""
    with np.errstate(over="ignore", invalid="ignore"):
        yield


def noisy_record(seed: int, noise: float, samples: int = 2000):
    """A random stable system of order 1-6 with 1-2 inputs and outputs, white Gaussian inputs."""
    rng = np.random.default_rng(seed)
    n, m, p = int(rng.integers(1, 7)), int(rng.integers(1, 3)), int(rng.integers(1, 3))
    a, b, c = random_system(n, m, p, rng)
    u = rng.standard_normal((samples, m))
    y = dlsim(a, b, c, u)
    return u, y + noise * y.std(axis=0) * rng.standard_normal(y.shape)


def same_fit(first, second) -> bool:
    """Same order and horizons, and bit-identical model matrices and singular values."""
    matrices = [np.array_equal(getattr(first.model, x), getattr(second.model, x)) for x in "ABCDK"]
    horizons = (first.past_horizon, first.future_horizon) == (second.past_horizon, second.future_horizon)
    return (
        first.order == second.order
        and horizons
        and all(matrices)
        and np.array_equal(first.singular_values, second.singular_values)
    )


def pass_data(u: np.ndarray, y: np.ndarray, past: int = 12, future: int = 5):
    """Innovations, the SVD of Z and the candidate orders of one pass, as _identify_once has them."""
    e = subspace.arx_innovations(u, y, past)
    left, singular_values, _ = np.linalg.svd(subspace._projected_future(u, y, e, past, future, False))
    candidates = subspace._order_candidates(singular_values, min(10, future * y.shape[1]), False)
    return e, left, singular_values, candidates


@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize("noise", [0.01, 0.2])
def test_the_screened_scan_fits_as_the_exact_scan(monkeypatch, seed, noise):
    """dsr_e with the screened scan against dsr_e scoring every candidate exactly, through all its
    horizon refinements: the same order, horizons and model, bit for bit."""
    u, y = noisy_record(seed, noise)
    screened = dsr_e(u, y, 1.0)
    monkeypatch.setattr(subspace, "bic_order", _exact_scan)
    assert same_fit(screened, dsr_e(u, y, 1.0))


@pytest.mark.parametrize("seed", range(4))
def test_the_screen_agrees_with_the_exact_regression_and_criterion(seed):
    """Where the screen vouches for a candidate, its B, D, K and prediction criterion are those
    of input_matrices and prediction_criterion to round-off."""
    u, y = noisy_record(seed, 0.05)
    past = 12
    e, left, singular_values, candidates = pass_data(u, y, past)
    p = y.shape[1]
    drive, record = Spectra(np.hstack([u[past:], e])), Spectra(np.hstack([u, y])[:-1])
    vouched = 0
    for order in candidates:
        a, c = observability_pair(left, singular_values, order, p)
        try:
            screened = screened_input_matrices(a, c, u[past:], (y[past:] - e).T.reshape(-1), drive)
            exact = input_matrices(a, c, u[past:], y[past:], e)
        except ValueError:
            continue
        if screened is None:
            continue
        for found, expected in zip(screened, exact, strict=True):
            assert np.max(np.abs(found - expected)) <= 1e-9 * max(np.max(np.abs(expected)), 1.0)
        model = realize(left, singular_values, order, u, y, e, past, 1.0)
        criterion = screened_criterion((model.A, model.B, model.C, model.D, model.K), u, y, past, record)
        if criterion is not None:
            vouched += 1
            assert criterion == pytest.approx(prediction_criterion(model, u, y, past), abs=1e-10)
    assert vouched >= 1


def test_the_screen_refuses_what_it_cannot_vouch_for():
    """A singular regression (two identical inputs) and a predictor on the unit circle give None;
    powers of A that overflow (to inf, or to NaN before any power of C A^k does) raise, as
    input_matrices does."""
    rng = np.random.default_rng(0)
    a, c = np.diag([0.5, 0.8]), rng.standard_normal((1, 2))
    u = np.repeat(rng.standard_normal((500, 1)), 2, axis=1)
    e, target = rng.standard_normal((500, 1)), rng.standard_normal(500)
    assert screened_input_matrices(a, c, u, target, Spectra(np.hstack([u, e]))) is None
    for unstable in (1e3 * np.eye(2), 1e200 * np.array([[1.0, 1.0], [-1.0, 1.0]])):  # A^2 is NaN
        with pytest.raises(ValueError, match="unstable"):
            screened_input_matrices(unstable, c, u[:, :1], target, Spectra(np.hstack([u[:, :1], e])))
    y = rng.standard_normal((500, 1))
    on_circle = (np.eye(2), np.ones((2, 1)), c, np.zeros((1, 1)), np.zeros((2, 1)))
    assert screened_criterion(on_circle, u[:, :1], y, 10, Spectra(np.hstack([u[:, :1], y])[:-1])) is None


@pytest.mark.parametrize("seed", range(4))
def test_near_ties_are_settled_by_the_exact_scores(monkeypatch, seed):
    """With every candidate a contender (TIE_MARGIN infinite) all are scored exactly; with the
    screened criterion off by 1e-7 (far more than round-off) the margin still absorbs it: both
    give the exact scan's order and model."""
    u, y = noisy_record(seed, 0.05)
    e, left, singular_values, candidates = pass_data(u, y)
    expected = _exact_scan(left, singular_values, candidates, u, y, e, 12, 1.0)

    def check() -> None:
        order, model = subspace_bic.bic_order(left, singular_values, candidates, u, y, e, 12, 1.0)
        assert order == expected[0]
        assert all(np.array_equal(getattr(model, x), getattr(expected[1], x)) for x in "ABCDK")

    with monkeypatch.context() as patch:
        patch.setattr(subspace_bic, "TIE_MARGIN", math.inf)
        check()
    screened_criterion = subspace_bic.screened_criterion

    def off(*args) -> float | None:
        criterion = screened_criterion(*args)
        return None if criterion is None else criterion + 1e-7

    with monkeypatch.context() as patch:
        patch.setattr(subspace_bic, "screened_criterion", off)
        check()


@pytest.mark.parametrize(("margin", "chosen"), [(None, 0), (0.01, 1)])
def test_a_near_tie_within_half_the_margin_is_settled_by_the_exact_scores(monkeypatch, margin, chosen):
    """A near tie set up on a real record's candidates: two orders whose exact BICs differ by 0.02
    (every other order 10 or more above), screened with errors of 0.045 against the better one
    (just under half of TIE_MARGIN = 0.1), so that the screen ranks the worse first. The margin
    keeps the better one a contender and the exact scores choose it; with a margin of 0.01 the
    screen's ranking would decide (the second case: the check can fail)."""
    u, y = noisy_record(0, 0.05)
    e, left, singular_values, candidates = pass_data(u, y)
    m, p, count = u.shape[1], y.shape[1], y.shape[0] - 12
    pair = candidates[:2]  # the lowest orders realize on this record
    exact = {n: 1000.0 + 10.0 * (n not in pair) + 0.02 * (n == pair[1]) for n in candidates}
    error = {n: 0.045 if n == pair[0] else -0.045 for n in candidates}

    def screened(matrices, *args) -> float:
        n = matrices[0].shape[0]
        return (exact[n] + error[n] - subspace_bic._bic(count, 0.0, n, m, p)) / count

    monkeypatch.setattr(subspace_bic, "screened_criterion", screened)
    monkeypatch.setattr(subspace_bic, "_exact_bic", lambda model, *args: exact[model.n_states])
    if margin is not None:
        monkeypatch.setattr(subspace_bic, "TIE_MARGIN", margin)
    order, model = subspace_bic.bic_order(left, singular_values, candidates, u, y, e, 12, 1.0)
    assert order == pair[chosen] and model.n_states == order


def test_a_contender_failing_its_exact_scoring_falls_back_to_the_exact_scan(monkeypatch):
    """Should the screen's winner fail its exact realization, every candidate is scored exactly:
    the result is the exact scan's without that candidate."""
    u, y = noisy_record(3, 0.05)
    e, left, singular_values, candidates = pass_data(u, y)
    winner, _ = subspace_bic.bic_order(left, singular_values, candidates, u, y, e, 12, 1.0)

    def failing(left, singular_values, order, *args):
        if order == winner:
            raise ValueError("refused")
        return realize(left, singular_values, order, *args)

    monkeypatch.setattr(subspace_bic, "realize", failing)
    order, model = subspace_bic.bic_order(left, singular_values, candidates, u, y, e, 12, 1.0)
    expected = _exact_scan(left, singular_values, candidates, u, y, e, 12, 1.0)
    assert order == expected[0] != winner
    assert np.array_equal(model.A, expected[1].A) and np.array_equal(model.K, expected[1].K)
