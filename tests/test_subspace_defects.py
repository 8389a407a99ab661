"""Two defects of DSR_e found by an audit, and their fixes.

1. Nearly collinear inputs: a noisy record whose inputs barely excite some input direction gave
   a model whose gain along it was noise, silently; now such a record is refused, naming the
   inputs. The limit follows the noise: a noise-free record identifies such directions exactly.
2. Given order: the first pass at the automatic horizons could fail or give an unstable model
   (the future horizon follows ``max_order``, not the order); it is now retried at other horizons.

The systems come from ``conftest.random_system`` (random pole blocks behind a random change of
basis), are simulated by ``scipy.signal.dlsim`` with white output noise, and the models are
compared with the true Markov parameters and frequency responses, computed here.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.linalg
from conftest import dlsim, markov, random_system
from hypothesis import example, given, settings
from hypothesis import strategies as st

from ssme_envs.identification.subspace import dsr_e
from ssme_envs.models.linear import spectral_radius

SAMPLES = 1000
SEEDS = st.integers(0, 2**32 - 1)
UNITS = st.floats(-30.0, 12.0)  # decimal exponents of the channels' units


def frequency_response(a, b, c, d=None, count: int = 32) -> np.ndarray:
    """``C (zI - A)^-1 B + D`` on the unit circle from 0 to Nyquist, shape (count, p, m)."""
    n = a.shape[0]
    d = np.zeros((c.shape[0], b.shape[1])) if d is None else d
    return np.array(
        [c @ scipy.linalg.solve(z * np.eye(n) - a, b) + d for z in np.exp(1j * np.linspace(0, np.pi, count))]
    )


def markov_error(a_hat, b_hat, c_hat, d_hat, a, b, c, count: int = 40) -> float:
    """Largest error of a model's Markov parameters ``C A^k B`` and feedthrough ``D`` against the
    truth's (no feedthrough), relative to the largest true Markov parameter."""
    truth = markov(a, b, c, count)
    error = max(np.max(np.abs(markov(a_hat, b_hat, c_hat, count) - truth)), np.max(np.abs(d_hat)))
    return float(error / np.max(np.abs(truth)))


def noisy(y: np.ndarray, noise: float, rng: np.random.Generator) -> np.ndarray:
    return y + noise * y.std(axis=0) * rng.standard_normal(y.shape)


# --- 1. nearly collinear inputs ------------------------------------------------------------------


def collinear_record(seed: int, m: int, delta: float, noise: float):
    """A system of order 2-4 with ``m`` inputs, the last of which is a combination of the others
    plus ``delta`` times independent noise: (system, u, y)."""
    rng = np.random.default_rng(seed)
    n, p = int(rng.integers(2, 5)), int(rng.integers(1, 3))
    a, b, c = random_system(n, m, p, rng)
    u = rng.standard_normal((SAMPLES, m))
    weights = rng.choice([-1.0, 1.0], m - 1) * rng.uniform(0.5, 2.0, m - 1)
    u[:, -1] = u[:, :-1] @ weights + delta * rng.standard_normal(SAMPLES)
    return (a, b, c), u, noisy(dlsim(a, b, c, u), noise, rng)


@settings(deadline=None, max_examples=20)
@given(
    seed=SEEDS,
    m=st.integers(2, 3),
    log_delta=st.floats(-6.0, -4.0),
    noise=st.floats(0.01, 0.3),
    data=st.data(),
)
@example(seed=3, m=2, log_delta=-6.0, noise=0.1, data=None).via("the audit's u1 = u0 + 1e-6 noise")
def test_nearly_collinear_noisy_inputs_are_refused_naming_the_inputs(seed, m, log_delta, noise, data):
    """Inputs whose last one repeats a combination of the others up to 1e-6..1e-4 of independent
    noise, with output noise of 1 to 30 % over 1000 samples: the gain along the unexcited
    direction is uncertain by 3 to 1e5 times the system's gain. The old code returned such
    models without a word (on the example, static gain [-8.1e4, 4.6e4] against the true
    [3.3, 0.51]); now they are refused, naming the inputs and the problem, in any units."""
    _, u, y = collinear_record(seed, m, 10.0**log_delta, noise)
    if data is not None:
        u = u * 10.0 ** np.array(data.draw(st.lists(UNITS, min_size=m, max_size=m), label="input units"))
        y = y * 10.0 ** np.array(data.draw(st.lists(UNITS, min_size=y.shape[1], max_size=y.shape[1])))
    with pytest.raises(ValueError, match="nearly collinear") as info:
        dsr_e(u, y, 1.0)
    message = str(info.value)
    assert all(f"u{i}" in message for i in range(m))
    assert "not determined by this record" in message
    assert "times less than the strongest" in message


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_limit_follows_the_noise_not_a_condition_number(seed):
    """The same inputs, u1 = w u0 + 1e-6 independent noise (input covariance condition number
    1e12 or more): without output noise the record determines the gain along u1 - u0 (the model's
    frequency response is right to 1e-6 of its peak), with 1 % output noise it does not and
    the record is refused (the old code refused neither)."""
    (a, b, c), u, y_clean = collinear_record(seed, 2, 1e-6, 0.0)
    result = dsr_e(u, y_clean, 1.0, order=a.shape[0])
    truth = frequency_response(a, b, c)
    found = frequency_response(result.model.A, result.model.B, result.model.C, result.model.D)
    assert np.max(np.abs(found - truth)) < 1e-6 * np.max(np.abs(truth))
    y_noisy = noisy(y_clean, 0.01, np.random.default_rng(seed))
    with pytest.raises(ValueError, match="inputs u0, u1 are nearly collinear"):
        dsr_e(u, y_noisy, 1.0, order=a.shape[0])


# --- 2. given order -------------------------------------------------------------------------------

NOISE = 0.1  # output noise, fraction of each output's standard deviation


def random_record(seed: int, inputs: int | None = None):
    """A system of order 4-10 with 1-2 inputs (or ``inputs``) and 1-2 outputs, white input,
    output noise ``NOISE``: (system, u, y)."""
    rng = np.random.default_rng(seed)
    n, m, p = int(rng.integers(4, 11)), int(rng.integers(1, 3)), int(rng.integers(1, 3))
    m = m if inputs is None else inputs
    a, b, c = random_system(n, m, p, rng)
    u = rng.standard_normal((SAMPLES, m))
    return (a, b, c), u, noisy(dlsim(a, b, c, u), NOISE, rng)


# Records of random_record on which the old first pass at the automatic horizons, order given,
# returned an unstable model (434: spectral radius 1.005, 369: 1.007, 271: 1.019) or failed with
# "the identified A is unstable" (124: 1.82, 287: 13.8).
REPRODUCERS = [434, 369, 271, 124, 287]
# Markov parameters' error relative to the largest: about NOISE / sqrt(SAMPLES) (3.2e-3) times a
# factor that stayed below 5.5 over the 31 of 500 records that the retry repaired (below 7.4 over
# the 96 of 2000 two-input records of the last test).
MARKOV_TOLERANCE = 10 * NOISE / np.sqrt(SAMPLES)


@pytest.mark.parametrize("seed", REPRODUCERS)
def test_given_order_on_a_failing_first_pass_gives_a_stable_accurate_model(seed):
    """On the reproducers (two outputs, order 9-10, future horizon 5 by default) the retry keeps
    a stable model and predictor whose Markov parameters are right to the noise's precision
    (errors 8e-3 to 1.6e-2 of the largest, tolerance 3.2e-2)."""
    (a, b, c), u, y = random_record(seed)
    result = dsr_e(u, y, 1.0, order=a.shape[0])
    model = result.model
    assert result.order == a.shape[0]
    assert spectral_radius(model.A) < 1.0
    assert spectral_radius(model.A - model.K @ model.C) < 1.0
    assert markov_error(model.A, model.B, model.C, model.D, a, b, c) < MARKOV_TOLERANCE


@settings(deadline=None, max_examples=15)
@given(seed=SEEDS)
@example(seed=434).via("first pass unstable, spectral radius 1.005")
@example(seed=124).via("first pass failed")
def test_given_order_always_gives_a_stable_model_and_predictor(seed):
    """Over random systems of order 4-10, DSR_e with the true order returns a model whose A and
    predictor A - K C are stable (the old code: an unstable model or an error on 31 of 500
    such records, all with two outputs)."""
    (a, _, _), u, y = random_record(seed)
    model = dsr_e(u, y, 1.0, order=a.shape[0]).model
    assert spectral_radius(model.A) < 1.0
    assert spectral_radius(model.A - model.K @ model.C) < 1.0


@settings(deadline=None, max_examples=15)
@given(seed=SEEDS, data=st.data())
@example(seed=271, data=None).via("two independent inputs; the old first pass was unstable")
def test_well_conditioned_two_input_records_are_identified_without_complaint(seed, data):
    """Two independent white inputs, each in any units (the outputs in one common unit: outputs
    in units less than 1e3 apart weigh by them, see ``dsr_e``): no collinearity refusal or
    warning, and a stable model whose Markov parameters are right to within 80 NOISE /
    sqrt(SAMPLES) (0.25) of the largest. The old code returned an unstable model or failed on 96 of 2000 such
    records (defect 2); the new one on none. The bound is loose because a stable first pass is
    kept as it is: at the default future horizon (5 for two outputs) its error reached 35
    NOISE / sqrt(SAMPLES) over those 2000 records, while the retried ones stayed below 7.4."""
    (a, b, c), u, y = random_record(seed, inputs=2)
    u_units, y_units = np.ones(2), np.ones(y.shape[1])
    if data is not None:
        u_units = 10.0 ** np.array(data.draw(st.lists(UNITS, min_size=2, max_size=2), label="input units"))
        y_units = np.full(y.shape[1], 10.0 ** data.draw(UNITS, label="output unit"))
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        model = dsr_e(u * u_units, y * y_units, 1.0, order=a.shape[0]).model
    assert spectral_radius(model.A) < 1.0
    # back to the simulation's units: B times the input units, C and D over the output units
    b_hat, c_hat, d_hat = model.B * u_units, model.C / y_units[:, None], model.D * u_units / y_units[:, None]
    assert markov_error(model.A, b_hat, c_hat, d_hat, a, b, c) < 8 * MARKOV_TOLERANCE


def test_a_longer_past_horizon_does_not_drop_a_slow_mode_the_record_shows():
    """A slow mode (pole 0.999) carrying a quarter of the output's variance, 2000 samples, 5 %
    noise (scipy's dlsim): the automatic past horizon's refinement went to a horizon where every
    order above 1 had an unstable predictor, and the order scan there returned order 1 (fresh-record
    error 0.40). A refined pass of another order is now kept only if its BIC on the record is no
    worse."""
    a, b, c = np.diag([0.999, 0.8, 0.3]), np.ones((3, 1)), np.array([[0.05, 1.0, 1.0]])
    rng = np.random.default_rng(2000)
    u, fresh_u = rng.normal(size=(2000, 1)), rng.normal(size=(3000, 1))
    clean = dlsim(a, b, c, u)
    y = clean + 0.05 * clean.std() * rng.normal(size=clean.shape)
    fresh = dlsim(a, b, c, fresh_u)
    model = dsr_e(u, y, 0.04).model
    error = np.linalg.norm(fresh - model.simulate(fresh_u)) / np.linalg.norm(fresh - fresh.mean())
    assert error < 0.1
    assert np.max(np.abs(np.linalg.eigvals(model.A))) > 0.99  # the slow mode is in the model


@pytest.mark.parametrize("seed", range(6))
def test_a_short_record_is_not_held_to_the_capped_past_horizon(seed):
    """300 samples of a lightly damped 4-state system (poles 0.995 and 0.9 at angles 0.2 and 1.0
    rad, rotation blocks, scipy's dlsim), 5 % noise: the record capped the automatic past horizon
    at 7, whose innovations estimate left fresh-record errors of 0.20-0.33; a pass at the horizon
    rule's 22 is now tried and kept where its BIC on the record is lower (0.02-0.07)."""

    def block(radius: float, angle: float) -> np.ndarray:
        return radius * np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])

    shape_rng = np.random.default_rng(1)
    a = scipy.linalg.block_diag(block(0.995, 0.2), block(0.9, 1.0))
    b, c = shape_rng.normal(size=(4, 1)), shape_rng.normal(size=(1, 4))
    rng = np.random.default_rng(300 + seed)
    u, fresh_u = rng.normal(size=(300, 1)), rng.normal(size=(3000, 1))
    clean = dlsim(a, b, c, u)
    y = clean + 0.05 * clean.std() * rng.normal(size=clean.shape)
    fresh = dlsim(a, b, c, fresh_u)
    model = dsr_e(u, y, 0.04).model
    assert np.linalg.norm(fresh - model.simulate(fresh_u)) / np.linalg.norm(fresh - fresh.mean()) < 0.1


@pytest.mark.parametrize("seed", [68, 13, 36])
def test_the_short_record_pass_does_not_trade_a_stable_a_for_an_unstable_one(seed):
    """Slow real poles (0.97-0.9999), 250 samples, 30 % noise: the pass at the horizon rule's J
    had the lower record BIC with an unstable A (seed 68: |eig| 1.0109, fresh-record error 4e12)
    where the capped horizon's A is stable; it is refused as a refined pass turning A unstable is."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 4))
    a = np.diag(rng.uniform(0.97, 0.9999, n))
    if n > 1:
        a[0, 1] = rng.uniform(0.0, 0.5)
    b, c = rng.normal(size=(n, 1)), rng.normal(size=(1, n))
    u = rng.standard_normal((250, 1))
    clean = dlsim(a, b, c, u)
    y = clean + 0.3 * clean.std() * rng.standard_normal(clean.shape)
    assert spectral_radius(dsr_e(u, y, 1.0).model.A) < 1.0


@pytest.mark.parametrize("seed", range(3))
def test_a_noise_free_short_record_keeps_the_capped_horizon(seed):
    """A noise-free record gets no refinement, nor the short-record pass, whose BIC there would
    compare round-off residuals (a past horizon of 22 or 7 by the last bits)."""
    from ssme_envs.identification.subspace_horizons import default_future, default_past

    rng = np.random.default_rng(seed)
    a, b, c = random_system(3, 1, 1, rng)
    u = rng.standard_normal((300, 1))
    result = dsr_e(u, dlsim(a, b, c, u), 1.0)
    assert result.past_horizon == default_past(300, 1, 1, default_future(10, 1))
    assert result.order == 3


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), samples=st.sampled_from([250, 300]), noise=st.floats(0.2, 0.3))
def test_the_automatic_horizons_keep_a_stable_a_where_the_capped_pass_has_one(seed, samples, noise):
    """Slow real poles (0.97-0.9999) on short noisy records: whatever the automatic horizons try,
    they return a stable A wherever the record-capped pass alone gives one (the short-record pass
    broke it on about one such record in seven before it was held to the rule)."""
    from ssme_envs.identification.subspace_horizons import default_future, default_past

    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 4))
    a = np.diag(rng.uniform(0.97, 0.9999, n))
    b, c = rng.normal(size=(n, 1)), rng.normal(size=(1, n))
    u = rng.standard_normal((samples, 1))
    clean = dlsim(a, b, c, u)
    y = clean + noise * clean.std() * rng.standard_normal(clean.shape)
    capped = dsr_e(u, y, 1.0, past_horizon=default_past(samples, 1, 1, default_future(10, 1)))
    if spectral_radius(capped.model.A) < 1.0:
        assert spectral_radius(dsr_e(u, y, 1.0).model.A) < 1.0
