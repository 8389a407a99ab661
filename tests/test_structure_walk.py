"""The structure choice beyond the rank rule: the walk on refined scores and what it may choose.

The systems are ``conftest.random_system`` (random real and complex pole blocks behind a random
change of basis), simulated by ``scipy.signal.dlsim``; their observability indices come from a
rank computation on (A, C) (``test_identification_structures.observability_indices``). The
models are judged by their simulation of a fresh record, not by their structure.
"""

from __future__ import annotations

import numpy as np
from conftest import dlsim, eq36, random_system
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from test_identification_structures import observability_indices

from ssme_envs.identification import identify


def fresh_error(model, a, b, c, rng: np.random.Generator, samples: int = 2000) -> float:
    """Largest over outputs of the RMS simulation error on a fresh noise-free record, relative
    to the output's spread."""
    u = rng.standard_normal((samples, b.shape[1]))
    y = dlsim(a, b, c, u)
    got = dlsim(model.A, model.B, model.C, eq36(u, model.lam))
    return float(np.max(np.sqrt(np.mean((y - got) ** 2, axis=0)) / y.std(axis=0)))


def high_order_record(seed: int, noise: float, samples: int = 2000):
    """A SISO system of order 6-10 and a record of it under a Gaussian input, with white output
    noise of ``noise`` times the output's spread."""
    rng = np.random.default_rng(seed)
    order = int(rng.integers(6, 11))
    rng.integers(1, 2)  # the draw of an output count, kept so that the seeds name the same systems
    a, b, c = random_system(order, 1, 1, rng)
    u = rng.standard_normal((samples, 1))
    y = dlsim(a, b, c, u)
    return u, y + noise * y.std(axis=0) * rng.standard_normal(y.shape), (a, b, c), rng


@settings(max_examples=20, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1))
@example(seed=26)  # the walk on first scores stopped at 5 states of 10: 1.3e-2 of the spread
@example(seed=29)  # at 4 of 10 (refined scores level at 4 and 5 states): 2.6e-2
@example(seed=53)  # at 5 of 9: 7.9e-2
def test_a_nearly_noise_free_record_of_a_high_order_system_is_modelled_to_its_noise(seed):
    u, y, (a, b, c), rng = high_order_record(seed, 1e-6)
    model = identify(u, y, 1.0, uncertainty=False).model
    assert fresh_error(model, a, b, c, rng) < 1e-3, model.fit["structure"]


def test_a_set_is_not_chosen_for_what_refinement_makes_of_its_poor_estimate():
    # A 6-state, 2-output system at 1 % noise. (3, 2)'s instrumental-variable estimate, which is
    # what identify would return for it, simulates a fresh record 100 times worse than the true
    # (3, 3)'s (0.106 of the spread against 0.001); the choice stays near the true indices' error.
    # (This record keeps (3, 3) with or without the settling of refined scores; the test below
    # is one whose choice the settling decides.)
    rng = np.random.default_rng(85)
    order, m, p = int(rng.integers(1, 9)), int(rng.integers(1, 3)), int(rng.integers(1, 3))
    a, b, c = random_system(order, m, p, rng)
    assert (order, m, p) == (6, 1, 2) and observability_indices(a, c) == (3, 3)
    rng.random()  # the draw that chose the input's kind in the scan this record comes from
    u = rng.standard_normal((2000, m))
    y = dlsim(a, b, c, u)
    y = y + 0.01 * y.std(axis=0) * rng.standard_normal(y.shape)
    result = identify(u, y, 1.0, uncertainty=False)
    given_indices = identify(u, y, 1.0, indices=(3, 3), uncertainty=False)
    check = np.random.default_rng(1)
    error = fresh_error(result.model, a, b, c, check)
    assert error < 1.5 * fresh_error(given_indices.model, a, b, c, np.random.default_rng(1)) + 1e-4


def test_the_sets_whose_refined_score_is_not_counted_have_poorer_estimates():
    """An 8-state system, two inputs and two outputs, 1 % noise. Refined, (3, 4), (3, 5), (4, 4)
    and (4, 5) score better than the chosen (3, 6), but their own first scores are far from the
    best, and their instrumental-variable estimates, which identify would return, simulate a fresh
    record at least twice as badly as the chosen set's: the walk's settling gives them their first
    scores back (noted). Without it (3, 4) would be chosen (0.0088 of the spread against 0.0023)."""
    from ssme_envs.identification.structure_refined import NOT_COUNTED

    rng = np.random.default_rng(0)
    order, m = int(rng.integers(3, 9)), int(rng.integers(1, 3))
    a, b, c = random_system(order, m, 2, rng)
    assert (order, m) == (8, 2)
    u = rng.standard_normal((2000, m))
    y = dlsim(a, b, c, u)
    y = y + 0.01 * y.std(axis=0) * rng.standard_normal(y.shape)
    result = identify(u, y, 1.0, uncertainty=False)
    reverted = [cand.indices for cand in result.search.candidates if cand.note == NOT_COUNTED]
    assert len(reverted) >= 2
    chosen = fresh_error(result.model, a, b, c, np.random.default_rng(1))
    for indices in reverted:
        estimate = identify(u, y, 1.0, indices=indices, uncertainty=False).model
        assert fresh_error(estimate, a, b, c, np.random.default_rng(1)) > 2 * chosen, indices
