"""DSR_e on records whose channels differ wildly in size: the poles, the transfer and every field of
the result must not depend on the channels' units.

The systems are built by scipy.signal (poles and zeros through ``zpk2ss``, further inputs and
outputs with random columns and rows of B, C, D, no innovations form) and simulated by
``scipy.signal.dlsim`` on a random binary input, with white output noise where stated. Each
channel is first brought to unit RMS, then multiplied by ``10**k`` with ``k`` drawn in
[-10, 30] per channel. Tolerances, from 1000 systems of the same generator with the channels
left at unit RMS: noise-free, the poles come within 2.4e-14 and the frequency response within
1.1e-14 of its peak (tolerances 1e-9; the failures they guard against are orders of magnitude
larger); with output noise of 1e-6 of each output's spread, within 2.8e-6 and 3.5e-7
(tolerances 1e-4 and 1e-5).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
import scipy.signal
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import linear_sum_assignment

from ssme_envs.identification.subspace import dsr_e

SAMPLES = 1500
EXPONENTS = st.floats(-10.0, 30.0)
SEEDS = st.integers(0, 2**32 - 1)


def random_system(rng: np.random.Generator, m: int, p: int):
    """A stable system of order 1-4 with poles at least 0.15 apart, radius at most 0.85:
    (A, B, C, D, poles). The first input and output see the zeros and poles drawn."""
    n = int(rng.integers(1, 5))
    poles: list[complex] = []
    while len(poles) < n:
        if n - len(poles) >= 2 and rng.random() < 0.6:
            radius, angle = rng.uniform(0.3, 0.85), rng.uniform(0.3, 2.8)
            new = [radius * np.exp(1j * angle), radius * np.exp(-1j * angle)]
        else:
            new = [complex(rng.uniform(-0.8, 0.85))]
        if all(abs(a - b) > 0.15 for a in new for b in poles):
            poles += new
    zeros = [rng.uniform(-0.9, 0.9)] if n > 1 and rng.random() < 0.5 else []
    if zeros and min(abs(zeros[0] - q) for q in poles) < 0.3:
        zeros = []  # a zero next to a pole would leave that mode barely visible
    a, b, c, _ = scipy.signal.zpk2ss(zeros, poles, 1.0)
    b = np.hstack([b, rng.standard_normal((n, m - 1))])
    c = np.vstack([c / np.linalg.norm(c), rng.standard_normal((p - 1, n))])
    d = rng.standard_normal((p, m))
    return a, b, c, d, np.array(poles, dtype=complex)


def unit_record(seed: int, m: int, p: int, noise: float):
    """System, and its record (u, y) with every channel at unit RMS, and the RMS values
    divided out (to express the true transfer in the record's units)."""
    rng = np.random.default_rng(seed)
    system = random_system(rng, m, p)
    a, b, c, d, _ = system
    u = np.where(rng.random((SAMPLES, m)) < 0.5, -1.0, 1.0)  # random binary input
    _, y, _ = scipy.signal.dlsim((a, b, c, d, 1.0), u)
    y = y.reshape(SAMPLES, p)
    y = y + noise * y.std(axis=0) * rng.standard_normal(y.shape)
    u_rms, y_rms = np.sqrt(np.mean(u**2, axis=0)), np.sqrt(np.mean(y**2, axis=0))
    return system, u / u_rms, y / y_rms, u_rms, y_rms


def pole_error(true: np.ndarray, found: np.ndarray) -> float:
    """Largest |found - true| after matching the poles one to one."""
    cost = np.abs(true[:, None] - found[None, :])
    rows, cols = linear_sum_assignment(cost)
    return float(np.max(cost[rows, cols]))


def frequency_response(a, b, c, d, count: int = 16) -> np.ndarray:
    """``C (zI - A)^-1 B + D`` on the unit circle from 0 to Nyquist, shape (count, p, m)."""
    n = a.shape[0]
    return np.array(
        [c @ scipy.linalg.solve(z * np.eye(n) - a, b) + d for z in np.exp(1j * np.linspace(0, np.pi, count))]
    )


def response_error(model, system, u_scale, y_scale) -> float:
    """Largest error of the model's response, each entry divided by its channels' scales
    (output over input), relative to the peak of the true response in unit-RMS units."""
    a, b, c, d, _ = system
    truth = frequency_response(a, b, c, d)
    found = frequency_response(model.A, model.B, model.C, model.D)
    return float(np.max(np.abs(found * u_scale / y_scale[:, None] - truth)) / np.max(np.abs(truth)))


@settings(deadline=None, max_examples=60)
@given(seed=SEEDS, m=st.integers(1, 2), p=st.integers(1, 2), data=st.data())
def test_noise_free_poles_order_and_response_do_not_depend_on_channel_scales(seed, m, p, data):
    system, u, y, u_rms, y_rms = unit_record(seed, m, p, noise=0.0)
    k_u = np.array(data.draw(st.lists(EXPONENTS, min_size=m, max_size=m), label="k_u"))
    k_y = np.array(data.draw(st.lists(EXPONENTS, min_size=p, max_size=p), label="k_y"))
    u_scale, y_scale = 10.0**k_u, 10.0**k_y
    result = dsr_e(u * u_scale, y * y_scale, 1.0)  # the order is found, not given
    poles = system[4]
    assert result.order == poles.size
    assert pole_error(poles, result.model.poles()) < 1e-9
    assert response_error(result.model, system, u_scale / u_rms, y_scale / y_rms) < 1e-9
    np.testing.assert_array_equal(result.model.K, 0.0)  # noise-free: no innovations


@settings(deadline=None, max_examples=40)
@given(seed=SEEDS, m=st.integers(1, 2), p=st.integers(1, 2), data=st.data())
def test_noisy_poles_and_response_are_as_good_as_at_unit_scales(seed, m, p, data):
    system, u, y, u_rms, y_rms = unit_record(seed, m, p, noise=1e-6)
    k_u = np.array(data.draw(st.lists(EXPONENTS, min_size=m, max_size=m), label="k_u"))
    k_y = np.array(data.draw(st.lists(EXPONENTS, min_size=p, max_size=p), label="k_y"))
    u_scale, y_scale = 10.0**k_u, 10.0**k_y
    poles = system[4]
    result = dsr_e(u * u_scale, y * y_scale, 1.0, order=poles.size)
    assert pole_error(poles, result.model.poles()) < 1e-4
    assert response_error(result.model, system, u_scale / u_rms, y_scale / y_rms) < 1e-5


@settings(deadline=None, max_examples=25)
@given(seed=SEEDS, k_u=EXPONENTS, k_y=EXPONENTS)
def test_one_output_every_field_follows_the_units(seed, k_u, k_y):
    """With one output a rescaled record gives the unit record's result in the new units, field
    by field: the same order and horizons, the same poles, singular values times the output's
    scale, the same transfer (D and the Markov parameters C A^j B times output over input scale)
    and the same noise model (C A^j K, output units per output unit). The basis-free
    quantities are compared, since the state basis may change by a scalar. Tolerances: over
    1500 draws the poles, the transfer and D agree within 4e-14, the singular values within
    7e-11 and the noise model (K of a 1e-4 noise record is poorly determined, and so sensitive to
    rounding) within 2.1e-8; before the equilibration the poles moved by up to 6e-4, and one
    draw in five changed the order or the past horizon."""
    _, u, y, _, _ = unit_record(seed, 1, 1, noise=1e-4)
    base = dsr_e(u, y, 1.0)
    u_scale, y_scale = 10.0**k_u, 10.0**k_y
    scaled = dsr_e(u * u_scale, y * y_scale, 1.0)
    assert (scaled.order, scaled.past_horizon, scaled.future_horizon) == (
        base.order,
        base.past_horizon,
        base.future_horizon,
    )
    assert pole_error(base.model.poles(), scaled.model.poles()) < 1e-9
    np.testing.assert_allclose(scaled.singular_values / y_scale, base.singular_values, rtol=1e-8, atol=0)

    def markov(model, gain):
        powers = [np.linalg.matrix_power(model.A, j) for j in range(20)]
        return np.array([model.C @ a_j @ gain for a_j in powers])

    transfer = markov(base.model, base.model.B)
    size = np.abs(transfer).max()
    ratio = y_scale / u_scale
    np.testing.assert_allclose(
        markov(scaled.model, scaled.model.B) / ratio, transfer, rtol=0, atol=1e-9 * size
    )
    np.testing.assert_allclose(scaled.model.D / ratio, base.model.D, rtol=0, atol=1e-9 * size)
    noise_model = markov(base.model, base.model.K)
    np.testing.assert_allclose(
        markov(scaled.model, scaled.model.K), noise_model, rtol=0, atol=1e-6 * np.abs(noise_model).max()
    )


@pytest.mark.parametrize("spread", [1e12, 1e20, 1e30])
def test_two_outputs_of_very_different_units(spread):
    """One input, two outputs, the second in units ``spread`` times smaller. Before the record
    was equilibrated, the second output's transfer came out 7e-5 off at 1e12, and at 1e20 and
    1e30 two of the four modes sank below the order selection's round-off floor (order 2)."""
    system, u, y, u_rms, y_rms = unit_record(0, 1, 2, noise=0.0)
    poles = system[4]
    assert poles.size == 4
    y_scale = np.array([1.0, spread])
    result = dsr_e(u, y * y_scale, 1.0)
    assert result.order == poles.size
    assert pole_error(poles, result.model.poles()) < 1e-9
    assert response_error(result.model, system, 1.0 / u_rms, y_scale / y_rms) < 1e-9


@settings(deadline=None, max_examples=10)
@given(seed=SEEDS, k=st.floats(-40.0, -12.0), channel=st.sampled_from(["u", "y"]))
def test_a_channel_in_tiny_units_is_data_not_a_constant(seed, k, channel):
    """A channel whose values are all below 1e-12 (units 1e12 to 1e40 times too large) varies
    as much as any other relative to its own size: it is identified, not refused as constant."""
    system, u, y, u_rms, y_rms = unit_record(seed, 1, 1, noise=0.0)
    u_scale, y_scale = (
        np.array([10.0**k if channel == "u" else 1.0]),
        np.array([10.0**k if channel == "y" else 1.0]),
    )
    result = dsr_e(u * u_scale, y * y_scale, 1.0)
    assert pole_error(system[4], result.model.poles()) < 1e-9
    assert response_error(result.model, system, u_scale / u_rms, y_scale / y_rms) < 1e-9


@settings(deadline=None, max_examples=30)
@given(seed=SEEDS, m=st.integers(1, 2), p=st.integers(1, 2), k=st.floats(-150.0, 150.0))
def test_a_record_of_any_size_identifies_as_at_unit_size(seed, m, p, k):
    """Every channel times the same 10**k, k in [-150, 150] (within the range whose squares stay
    finite, so accepted): the channels are balanced, and such a record used to be used unscaled,
    which beyond about 1e+-100 lost B and D's regression to round-off thresholds relative to one
    ("the inputs do not determine B and D"). Now its poles and response are as at unit size
    (noise 1e-6, order given; tolerances as above)."""
    system, u, y, u_rms, y_rms = unit_record(seed, m, p, noise=1e-6)
    scale = 10.0**k
    poles = system[4]
    result = dsr_e(u * scale, y * scale, 1.0, order=poles.size)
    assert pole_error(poles, result.model.poles()) < 1e-4
    ones_u, ones_y = np.full(m, scale), np.full(p, scale)
    assert response_error(result.model, system, ones_u / u_rms, ones_y / y_rms) < 1e-5
