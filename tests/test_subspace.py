"""DSR_e subspace identification: expected values come from the true systems and from scipy."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.signal
from conftest import dlsim, markov
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import linear_sum_assignment

from ssme_envs.identification.subspace import (
    InnovationsModel,
    dsr_e,
    second_order_parameters,
    to_continuous,
)

# 3rd order, poles 0.85 and 0.6 +- 0.4j; two outputs, up to two inputs.
A3 = np.array([[0.85, 0.0, 0.0], [0.0, 0.6, 0.4], [0.0, -0.4, 0.6]])
B3 = np.array([[1.0, 0.5], [0.5, -1.0], [1.0, 1.0]])
C3 = np.array([[1.0, 0.5, 0.3], [0.2, 1.0, -0.5]])
K3 = np.array([[0.5, 0.1], [0.2, 0.4], [-0.1, 0.3]])


def innovations_record(a, b, c, d, k, u, e):
    """The true innovations-form system, step by step from the zero state."""
    x = np.zeros(a.shape[0])
    y = np.empty((u.shape[0], c.shape[0]))
    for t in range(u.shape[0]):
        y[t] = c @ x + d @ u[t] + e[t]
        x = a @ x + b @ u[t] + k @ e[t]
    return y


def worst_pole_error(true: np.ndarray, found: np.ndarray) -> float:
    """Largest |found - true| / |true| after matching poles one to one."""
    cost = np.abs(true[:, None] - found[None, :])
    rows, cols = linear_sum_assignment(cost)
    return float(np.max(cost[rows, cols] / np.abs(true[rows])))


def markov_with_d(a, b, c, d, count):
    return np.concatenate([d[None], markov(a, b, c, count)])


@pytest.fixture(scope="module")
def noisy_record():
    rng = np.random.default_rng(7)
    samples = 5000
    u = np.sign(rng.standard_normal((samples, 2)))  # random binary (PRBS-like) input
    e = 0.3 * rng.standard_normal((samples, 2))
    y = innovations_record(A3, B3, C3, np.zeros((2, 2)), K3, u, e)
    return u, y, e


def test_noise_free_siso_second_order():
    a = np.array([[1.6, -0.8], [1.0, 0.0]])
    b = np.array([[1.0], [0.0]])
    c = np.array([[0.2, 0.3]])
    u = np.random.default_rng(0).standard_normal((400, 1))
    y = dlsim(a, b, c, u)
    result = dsr_e(u, y, dt=0.1)
    assert result.order == 2
    s = result.singular_values / result.singular_values[0]
    assert s[2] < 1e-10 < s[1]
    assert worst_pole_error(np.linalg.eigvals(a), result.model.poles()) < 1e-9
    model = result.model
    expected = markov_with_d(a, b, c, np.zeros((1, 1)), 20)
    np.testing.assert_allclose(
        markov_with_d(model.A, model.B, model.C, model.D, 20), expected, rtol=0, atol=1e-10
    )
    np.testing.assert_array_equal(model.K, 0.0)
    assert model.dt == 0.1


def test_noise_free_mimo_third_order_with_feedthrough():
    d = np.array([[0.1, 0.0], [0.0, 0.2]])
    u = np.random.default_rng(1).standard_normal((400, 2))
    _, y, _ = scipy.signal.dlsim((A3, B3, C3, d, 1.0), u)
    result = dsr_e(u, y, dt=0.04)
    assert result.order == 3
    assert worst_pole_error(np.linalg.eigvals(A3), result.model.poles()) < 1e-9
    model = result.model
    np.testing.assert_allclose(
        markov_with_d(model.A, model.B, model.C, model.D, 15),
        markov_with_d(A3, B3, C3, d, 15),
        rtol=0,
        atol=1e-10,
    )
    np.testing.assert_allclose(model.simulate(u), y, rtol=0, atol=1e-9)


def test_noisy_third_order_two_outputs(noisy_record):
    u, y, _ = noisy_record
    result = dsr_e(u, y, dt=0.04)
    assert result.order == 3
    assert worst_pole_error(np.linalg.eigvals(A3), result.model.poles()) < 0.02
    # the automatic past horizon leaves (A - K C)^J negligible for the model found ...
    model = result.model
    rho = np.max(np.abs(np.linalg.eigvals(model.A - model.K @ model.C)))
    assert rho**result.past_horizon <= 2e-3
    # ... and for the true predictor too
    rho_true = np.max(np.abs(np.linalg.eigvals(A3 - K3 @ C3)))
    assert rho_true**result.past_horizon <= 1e-2
    # the Kalman gain: the model's predictor whitens the output about as well as the true one
    residual = y - model.simulate(u, y)
    assert np.all(np.std(residual[100:], axis=0) < 1.05 * 0.3)


def test_noisy_single_input():
    rng = np.random.default_rng(11)
    u = np.sign(rng.standard_normal((5000, 1)))
    e = 0.1 * rng.standard_normal((5000, 2))
    y = innovations_record(A3, B3[:, :1], C3, np.zeros((2, 1)), K3, u, e)
    result = dsr_e(u, y, dt=0.04)
    assert result.order == 3
    assert worst_pole_error(np.linalg.eigvals(A3), result.model.poles()) < 0.02


def test_explicit_order_and_horizons(noisy_record):
    u, y, _ = noisy_record
    result = dsr_e(u[:2000], y[:2000], dt=0.04, order=2, past_horizon=15, future_horizon=4)
    assert (result.order, result.past_horizon, result.future_horizon) == (2, 15, 4)
    assert result.model.A.shape == (2, 2)
    assert result.singular_values.shape == (10,)  # (L + 1) p rows of Z


def test_simulate_matches_true_system(noisy_record):
    u, y, e = noisy_record
    true = InnovationsModel(A3, B3, C3, np.zeros((2, 2)), K3, dt=0.04)
    # the Kalman predictor of the true system, started at the true (zero) state, returns y - e
    np.testing.assert_allclose(true.simulate(u, y), y - e, rtol=0, atol=1e-10)
    np.testing.assert_allclose(true.simulate(u), dlsim(A3, B3, C3, u), rtol=0, atol=1e-10)
    np.testing.assert_allclose(np.sort_complex(true.poles()), np.sort_complex(np.linalg.eigvals(A3)))


# J x'' + b x' + k x = tau, state (x, x'), sampled at 8 ms
INERTIA, FRICTION, STIFFNESS, DT = 25.18, 376.53, 1.43e5, 0.008


def continuous_plant(inertia=INERTIA, friction=FRICTION, stiffness=STIFFNESS):
    ac = np.array([[0.0, 1.0], [-stiffness / inertia, -friction / inertia]])
    bc = np.array([[0.0], [1.0 / inertia]])
    return ac, bc, np.array([[1.0, 0.0]]), np.zeros((1, 1))


def zoh_model(ac, bc, cc, dc):
    ad, bd, cd, dd, _ = scipy.signal.cont2discrete((ac, bc, cc, dc), DT, method="zoh")
    return InnovationsModel(ad, bd, cd, dd, np.zeros((2, 1)), DT)


def test_to_continuous_inverts_zoh():
    ac, bc, cc, dc = continuous_plant()
    back = to_continuous(zoh_model(ac, bc, cc, dc))
    for got, want in zip(back, (ac, bc, cc, dc), strict=True):
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9 * np.max(np.abs(want)))


def test_second_order_parameters_round_trip():
    params = second_order_parameters(zoh_model(*continuous_plant()))
    assert params["J"] == pytest.approx(INERTIA, rel=1e-6)
    assert params["b"] == pytest.approx(FRICTION, rel=1e-6)
    assert params["k"] == pytest.approx(STIFFNESS, rel=1e-6)
    assert abs(params["numerator_s_coefficient"]) < 1e-9 / INERTIA
    b2, _, b0 = params["numerator"]
    _, a1, a0 = params["denominator"]
    assert abs(b2) < 1e-9 / INERTIA
    assert (b0, a1, a0) == pytest.approx((1 / INERTIA, FRICTION / INERTIA, STIFFNESS / INERTIA), rel=1e-6)
    omega_n = math.sqrt(STIFFNESS / INERTIA)
    zeta = FRICTION / (2 * math.sqrt(STIFFNESS * INERTIA))
    assert params["natural_frequency_hz"] == pytest.approx(omega_n / (2 * math.pi), rel=1e-6)
    assert params["damping_ratio"] == pytest.approx(zeta, rel=1e-6)
    peak = omega_n * math.sqrt(1 - 2 * zeta**2) / (2 * math.pi)
    assert params["resonance_frequency_hz"] == pytest.approx(peak, rel=1e-6)
    # scipy's own magnitude peak of the continuous transfer function agrees
    freqs = np.linspace(0.9 * peak, 1.1 * peak, 20001) * 2 * math.pi
    _, response = scipy.signal.freqs([1 / INERTIA], [1, FRICTION / INERTIA, STIFFNESS / INERTIA], freqs)
    assert freqs[np.argmax(np.abs(response))] / (2 * math.pi) == pytest.approx(peak, rel=1e-4)


def test_printed_transfer_function():
    # 0.03971 / (s^2 + 14.95 s + 5694): the first two coefficients to ~1e-3. The constant term
    # is k/J = 5679.1 for k = 1.43e5 exactly; 5694 corresponds to k = 1.4339e5, which rounds
    # to the printed three significant digits of k (half a unit there is 3.5e-3 relative).
    params = second_order_parameters(zoh_model(*continuous_plant()))
    _, _, b0 = params["numerator"]
    _, a1, a0 = params["denominator"]
    assert b0 == pytest.approx(0.03971, rel=1e-3)
    assert a1 == pytest.approx(14.95, rel=1e-3)
    assert a0 == pytest.approx(5694, rel=3.5e-3)
    # and the printed transfer function gives back J, b, k to their printed digits
    printed = scipy.signal.tf2ss([0.03971], [1.0, 14.95, 5694.0])
    from_printed = second_order_parameters(zoh_model(*printed))
    assert from_printed["J"] == pytest.approx(INERTIA, rel=1e-3)
    assert from_printed["b"] == pytest.approx(FRICTION, rel=1e-3)
    assert from_printed["k"] == pytest.approx(STIFFNESS, rel=3.5e-3)


def test_noisy_second_order_plant_parameters():
    # identify the sampled plant from a noisy binary-input record, then J, b, k
    model = zoh_model(*continuous_plant())
    rng = np.random.default_rng(5)
    u = 100.0 * np.sign(rng.standard_normal((3000, 1)))
    clean = dlsim(model.A, model.B, model.C, u)
    y = clean + 0.05 * clean.std() * rng.standard_normal(clean.shape)
    result = dsr_e(u, y, dt=DT)
    assert result.order == 2
    params = second_order_parameters(result.model)
    for name, true in (("J", INERTIA), ("b", FRICTION), ("k", STIFFNESS)):
        assert params[name] == pytest.approx(true, rel=0.02), name


def test_to_continuous_rejects_negative_real_pole():
    model = InnovationsModel([[-0.5]], [[1.0]], [[1.0]], [[0.0]], [[0.0]], 0.1)
    with pytest.raises(ValueError, match="negative real axis"):
        to_continuous(model)


def test_second_order_parameters_rejects_wrong_models():
    mimo = InnovationsModel(A3, B3, C3, np.zeros((2, 2)), K3, 0.04)
    with pytest.raises(ValueError, match="single-input single-output"):
        second_order_parameters(mimo)
    third = InnovationsModel(A3, B3[:, :1], C3[:1], np.zeros((1, 1)), K3[:, :1], 0.04)
    with pytest.raises(ValueError, match="second-order"):
        second_order_parameters(third)


@pytest.fixture(scope="module")
def short_record():
    rng = np.random.default_rng(3)
    u = rng.standard_normal((300, 2))
    return u, dlsim(A3, B3, C3, u)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda u, y: (u, y[:-1]), "samples but outputs have"),
        (lambda u, y: (u[:, :, None], y), "shape"),
        (lambda u, y: (u, np.where(np.arange(300)[:, None] == 17, [0.0, np.nan], y)), "'y1'.*sample 17"),
        (lambda u, y: (np.where(np.arange(300)[:, None] == 5, [np.inf, 0.0], u), y), "'u0'.*sample 5"),
        (lambda u, y: (np.column_stack([u[:, 0], np.full(300, 2.0)]), y), "'u1' is constant"),
        (lambda u, y: (np.column_stack([u[:, 0], 3 * u[:, 0]]), y), "linearly dependent"),
        (lambda u, y: (u[:60], y[:60]), r"has 60 samples.*need at least \d+"),
        (lambda u, y: (u[:, :0], y), "at least one input"),
    ],
)
def test_bad_records(short_record, change, message):
    u, y = change(*short_record)
    with pytest.raises(ValueError, match=message):
        dsr_e(u, y, dt=0.04)


@pytest.mark.parametrize("samples", [0, 1])
def test_an_empty_or_one_sample_record_is_refused_by_name(samples):
    # an empty record used to fail in numpy's reduction ("zero-size array to reduction operation")
    with pytest.raises(ValueError, match=rf"^the record has {samples} samples: a record needs at least 2"):
        dsr_e(np.zeros((samples, 1)), np.zeros((samples, 1)), dt=0.04)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda u, y: (u + 1j * u, y), "u must be real numbers.*complex128"),
        (lambda u, y: (u, y > 0), "y must be real numbers.*bool"),
        (
            lambda u, y: (np.ma.masked_array(u, mask=np.arange(u.size).reshape(u.shape) == 7), y),
            "u has 1 masked",
        ),
    ],
)
def test_records_that_are_not_real_numbers_are_refused_as_identify_refuses_them(
    short_record, change, message
):
    """The records' kind is checked where every identifier reads them: DSR_e cut a complex record
    to its real part (with a warning) and read beneath a mask."""
    u, y = change(*short_record)
    with pytest.raises(ValueError, match=message):
        dsr_e(u, y, dt=0.04)


def test_static_system_has_no_state():
    u = np.random.default_rng(2).standard_normal((500, 1))
    with pytest.raises(ValueError, match="no dynamics"):
        dsr_e(u, 2.0 * u, dt=0.04)


def test_non_exciting_input():
    t = np.arange(600)
    u = np.sin(0.3 * t)[:, None]  # persistently exciting of order 2 only
    y = dlsim(A3, B3[:, :1], C3, u)
    with pytest.raises(ValueError, match="not persistently exciting"):
        dsr_e(u, y, dt=0.04)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"dt": 0.0}, "dt must be"),
        ({"dt": float("nan")}, "dt must be"),
        ({"dt": 0.04, "order": 0}, "order must be"),
        ({"dt": 0.04, "order": 2.5}, "order must be"),
        ({"dt": 0.04, "past_horizon": -1}, "past_horizon must be"),
        ({"dt": 0.04, "max_order": 0}, "max_order must be"),
        ({"dt": 0.04, "order": 9, "future_horizon": 2}, "order=9 needs future_horizon >= 5"),
    ],
)
def test_bad_arguments(short_record, kwargs, message):
    with pytest.raises(ValueError, match=message):
        dsr_e(*short_record, **kwargs)


def test_model_validation():
    with pytest.raises(ValueError, match="K has shape"):
        InnovationsModel(A3, B3, C3, np.zeros((2, 2)), K3[:, :1], 0.04)
    with pytest.raises(ValueError, match="dt must be"):
        InnovationsModel(A3, B3, C3, np.zeros((2, 2)), K3, -1.0)
    model = InnovationsModel(A3, B3, C3, np.zeros((2, 2)), K3, 0.04)
    with pytest.raises(ValueError, match="3 channels but the model has 2 inputs"):
        model.simulate(np.zeros((10, 3)))
    with pytest.raises(ValueError, match="y has shape"):
        model.simulate(np.zeros((10, 2)), np.zeros((9, 2)))


@settings(max_examples=12, deadline=None)
@given(exponent=st.floats(-10.0, 30.0))
def test_the_input_scale_only_scales_the_input_gains(exponent):
    """An input in other units (x 1e20 once read as 'the inputs do not determine B and D') gives
    the same poles and the same transfer once the scale is divided out. The record is a
    second-order filter run by scipy.signal.lfilter, with a little output noise. Tolerances:
    beyond about 1e12 between the channels' scales the projections lose digits (poles off by
    about 1e-5, within 1e-6 below)."""
    rng = np.random.default_rng(5)
    num, den, _ = scipy.signal.cont2discrete(([1.0], [1.0, 8.0, 400.0]), 0.01)
    u = rng.standard_normal(2000)
    y = scipy.signal.lfilter(np.squeeze(num), den, u) + 1e-4 * rng.standard_normal(2000)
    scale = 10.0**exponent
    base = dsr_e(u[:, None], y[:, None], 0.01, order=2).model
    scaled = dsr_e(scale * u[:, None], y[:, None], 0.01, order=2).model
    np.testing.assert_allclose(
        np.sort_complex(np.linalg.eigvals(scaled.A)), np.sort_complex(np.linalg.eigvals(base.A)), atol=1e-4
    )
    ours = scale * markov(scaled.A, scaled.B, scaled.C, 10)
    theirs = markov(base.A, base.B, base.C, 10)
    size = np.abs(theirs).max()  # D is zero up to the noise: compared on the transfer's scale
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-3 * size)
    np.testing.assert_allclose(scale * scaled.D, base.D, rtol=0, atol=1e-3 * size)


@pytest.mark.parametrize("samples", [200, 233])
def test_a_record_too_short_for_the_given_order_names_the_length_needed(samples):
    """Order 2 given, one input and output, horizons automatic: the future horizon is 10 (from
    max_order), and under 234 samples the capped past horizon (1) cannot hold 2 states: the error
    names the length (it used to name horizons the CLI does not set). The 234 comes from the
    horizon rules' constants worked by hand: 10 + 6 * 11 * 3 + 2 * (1 + 6 * 2)."""
    a, b, c = 0.5 * A3[:2, :2], B3[:2, :1], C3[:1, :2]
    rng = np.random.default_rng(0)
    u = rng.standard_normal((samples, 1))
    y = dlsim(a, b, c, u) + 0.01 * rng.standard_normal((samples, 1))
    with pytest.raises(ValueError, match=rf"^the record has {samples} samples; 2 states .* from 234 samples"):
        dsr_e(u, y, 0.008, order=2)
    longer = rng.standard_normal((234, 1))
    assert dsr_e(longer, dlsim(a, b, c, longer), 0.008, order=2).order == 2


def test_an_order_beyond_the_horizon_rule_names_the_horizons_not_the_length():
    """Order 44 on 2000 samples of one input and output: the automatic past horizon is capped by
    its rule (2 (L + 1) = 22 with L = 10), not by the record, so a longer record would not help:
    the error names the horizons to give (it said 'use a longer record')."""
    rng = np.random.default_rng(0)
    u = rng.standard_normal((2000, 1))
    y = dlsim(0.5 * A3[:2, :2], B3[:2, :1], C3[:1, :2], u) + 0.01 * rng.standard_normal((2000, 1))
    with pytest.raises(ValueError, match=r"^order=44 needs future_horizon >= 44 and past_horizon >= 23"):
        dsr_e(u, y, 0.008, order=44)
