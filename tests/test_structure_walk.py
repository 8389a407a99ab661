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
    # A 6-state, 2-output system at 1 % noise. Refined, (3, 2) simulates the held-out part as
    # well as the true (3, 3) with fewer parameters, but its own instrumental-variable estimate,
    # which is what identify returns, simulates a fresh record 100 times worse (0.106 of the
    # spread against 0.001 for the (3, 3) estimate).
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
