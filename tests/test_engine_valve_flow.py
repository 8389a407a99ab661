"""The nonlinear engine's valve effect (``ssme_envs.models.engine_valve_flow``): the valve authority
against its documented slope (integrated by scipy), one arithmetic on floats and arrays, the PRBS's
gains through it, and an engine without it stepping as the flow curve alone."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad

from ssme_envs.models.engine import POWER_LEVELS, TruthConfig, published_model
from ssme_envs.models.engine_nonlinear import NonlinearEngine, simulate_nonlinear
from ssme_envs.models.engine_valve_flow import (
    FLOW_AMPLITUDE,
    flow_characteristic,
    valve_authority,
    valve_effect,
)
from ssme_envs.signals import prbs, step_ramp_test_signal

losses = st.floats(0.0, 0.99)
travels = st.floats(1e-3, 0.1)
departures = st.floats(-0.5, 0.5, allow_subnormal=False)


@settings(max_examples=60, deadline=None)
@given(loss=losses, travel=travels, d=departures)
def test_authority_is_the_integral_of_its_documented_slope(loss, travel, d):
    """psi' = 1 - g + g (1 + (d/b)^2)^(-3/2): 1 at the trim, falling to 1 - g far from it."""
    slope = lambda s: 1.0 - loss + loss * (1.0 + (s / travel) ** 2) ** -1.5  # noqa: E731
    expected, _ = quad(slope, 0.0, d, epsabs=1e-15, epsrel=1e-12, limit=200)
    assert valve_authority(np.array(d), loss, travel) == pytest.approx(expected, rel=1e-9, abs=1e-15)


@settings(max_examples=40, deadline=None)
@given(loss=losses, travel=travels)
def test_authority_is_odd_monotone_with_unit_slope_at_the_trim(loss, travel):
    d = np.linspace(0.0, 0.5, 10001)
    psi = valve_authority(d, loss, travel)
    np.testing.assert_array_equal(valve_authority(-d, loss, travel), -psi)
    assert np.all(np.diff(psi) > 0)
    h = 1e-7 * travel
    slope = (valve_authority(np.array(h), loss, travel) - valve_authority(np.array(-h), loss, travel)) / (
        2 * h
    )
    assert slope == pytest.approx(1.0, rel=1e-9)
    far = 1e6 * travel
    assert valve_authority(np.array(far), loss, travel) / far == pytest.approx(1.0 - loss, abs=2e-6)


@settings(max_examples=80, deadline=None)
@given(
    d=st.lists(departures, min_size=1, max_size=6),
    lam=st.floats(0.7, 1.3),
    loss=losses,
    travel=travels,
    asymmetric=st.booleans(),
)
def test_floats_and_arrays_give_the_same_bits(d, lam, loss, travel, asymmetric):
    """The engine envs step one env on floats (math.sqrt) and a batch on arrays (np.sqrt)."""
    arrays = valve_effect(np.array(d), np.full(len(d), lam), np.sqrt, asymmetric, loss, travel)
    floats = [valve_effect(v, lam, math.sqrt, asymmetric, loss, travel) for v in d]
    assert arrays.tolist() == floats


@settings(max_examples=40, deadline=None)
@given(d=st.lists(departures, min_size=1, max_size=6), lam=st.floats(0.7, 1.3))
def test_no_authority_loss_is_the_flow_curve_alone_to_the_bit(d, lam):
    d = np.array(d)
    lam = np.full(d.size, lam)
    np.testing.assert_array_equal(valve_effect(d, lam, np.sqrt, True, 0.0, 0.02), flow_characteristic(d, lam))
    np.testing.assert_array_equal(valve_effect(d, lam, np.sqrt, False, 0.0, 0.02), d)


def test_engine_without_authority_loss_moves_as_the_flow_curve_alone():
    """An engine built with authority_loss=0 steps as one whose valve effect is phi alone (written
    here with the flow curve, not the engine's valve_effect); the default engine does not."""
    engine = NonlinearEngine(authority_loss=0.0)
    u = 1.5 * step_ramp_test_signal()
    ideal = TruthConfig.ideal()
    _, plain = simulate_nonlinear(engine, 90.0, u, ideal)
    x, rho, v_trim = engine.trim(90.0)
    by_hand = []
    for k in range(u.shape[0]):
        by_hand.append(x[0, -2:] - engine.nominal_outputs(90.0)[0])
        tab = engine.table(rho)
        flow = flow_characteristic((v_trim + u[k]) - tab["v_eq"], tab["lam"])
        e = x - tab["x_eq"]
        x = tab["x_eq"] + e @ engine.shift.T + np.einsum("nij,nj->ni", tab["K"], e[:, -2:])
        x = x + np.einsum("nij,nj->ni", tab["B"], flow)
        rho = engine.power_of(x)
    np.testing.assert_allclose(plain, np.array(by_hand), rtol=0, atol=1e-13)
    _, default = simulate_nonlinear(NonlinearEngine(), 90.0, u, ideal)
    assert np.abs(default - plain).max() > 0.1 * np.abs(plain).max()


@pytest.mark.parametrize("power", POWER_LEVELS)
def test_prbs_sees_table_one_lambda_through_the_authority_chord(power):
    """On a +-0.01 binary input the valve effect is affine: up and down gains phi(psi(+-a)) / a;
    with c = psi(a) / a, eq 36's lambda from them is 1 + (lambda - 1) s(c) / (c s(1)) (about
    0.91 (lambda - 1)), within 5 % of Table I's lambda at every level."""
    a, lam = FLOW_AMPLITUDE, published_model(power).lam
    u = prbs(127, a)[:, :1] * np.ones(2)
    effect = valve_effect(u, lam, np.sqrt)
    c = valve_authority(np.array(a)) / a
    s = lambda z: math.sqrt(1 + z * z) - 1  # noqa: E731
    up = c + (lam - 1) * s(c) / s(1.0)
    down = c - (lam - 1) * s(c) / s(1.0)
    np.testing.assert_allclose(effect, np.where(u > 0, up, down) * u, rtol=1e-12, atol=1e-18)
    apparent = 2 * up / (up + down)
    np.testing.assert_allclose(apparent - 1, (lam - 1) * s(c) / (c * s(1.0)), rtol=1e-12)
    assert np.all(np.abs(apparent / lam - 1) < 0.05)
    assert c == pytest.approx(0.8825, abs=1e-4)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"authority_loss": 1.0}, "authority_loss"),
        ({"authority_loss": -0.1}, "authority_loss"),
        ({"authority_loss": True}, "authority_loss"),
        ({"authority_loss": "0.5"}, "authority_loss"),
        ({"authority_travel": 0.0}, "authority_travel"),
        ({"authority_travel": math.inf}, "authority_travel"),
        ({"authority_travel": math.nan}, "authority_travel"),
        ({"authority_travel": 10**400}, "authority_travel must be a number > 0.*too large"),
        ({"authority_loss": np.bool_(False)}, "authority_loss"),
        ({"authority_loss": np.array([0.5])}, "authority_loss"),
        ({"authority_travel": -np.float32(0.01)}, "authority_travel"),
    ],
)
def test_bad_authority_is_refused(kwargs, match):
    with pytest.raises(ValueError, match=match):
        NonlinearEngine(**kwargs)


@pytest.mark.parametrize(
    "loss, travel", [(np.int64(0), np.float32(0.015)), (np.float64(0.7), 1), (-0.0, np.float16(0.02))]
)
def test_numpy_numbers_are_accepted_as_floats(loss, travel):
    engine = NonlinearEngine(authority_loss=loss, authority_travel=travel)
    assert type(engine.authority_loss) is float and type(engine.authority_travel) is float
    assert (engine.authority_loss, engine.authority_travel) == (float(loss) + 0.0, float(travel))
    assert math.copysign(1.0, engine.authority_loss) == 1.0
