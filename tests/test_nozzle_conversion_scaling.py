"""J, b, k of a second-order model, and their bootstrap standard errors, in any units of torque and
angle: the conversion of the discrete model and the uncertainty must not lose digits when the
channels' sizes spread.

The reference systems are written here: a joint ``J x'' + b x' + k x = tau`` sampled with a
zero-order hold by ``scipy.signal.cont2discrete`` (dt 0.008 s), its input and output then put in
units ``10**k_u`` and ``10**k_y`` times smaller and its state in a basis ``10**k_x`` times larger,
``k_*`` in [-10, 20] (the J, b, k of the rescaled system are ``10**(k_u - k_y)`` times the
joint's). Measured on 3000 joints of the generator below, each once in its own units and once
rescaled: J, b, k come back within 1.4e-12 of the truth (median 5e-15) either way; the tolerance
1e-8 keeps 3.8 decades of margin. The former conversion (ss2tf, whose numerator subtracted
``poly(A)`` from ``poly(A - B C)``) was up to 8e-9 off in the joints' own units and more than
1e-8 off, up to "no static gain", for 42 % of the rescaled joints.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.signal
from hypothesis import example, given, settings
from hypothesis import strategies as st

from ssme_envs.identification.nozzle_uncertainty import dsr_e_uncertainty
from ssme_envs.identification.subspace import InnovationsModel, dsr_e, second_order_parameters, to_continuous

DT = 0.008
EXPONENTS = st.floats(-10.0, 20.0)
NOZZLE = (25.18, 376.53, 1.43e5)  # Table 1, linear row


@st.composite
def joints(draw) -> tuple[float, float, float]:
    """J in [1, 1e3] kg m^2, k in [1e3, 1e7] N m/rad with the natural frequency between 0.02 and
    2.5 rad per sample (below Nyquist, so the sampled joint determines it), b in [1e1, 1e5]
    N m s/rad with the damping ratio between 0.01 and 3; all log-uniform."""
    log_j = draw(st.floats(0.0, 3.0))
    log_k = draw(
        st.floats(max(3.0, log_j + 2 * math.log10(0.02 / DT)), min(7.0, log_j + 2 * math.log10(2.5 / DT)))
    )
    critical = math.log10(2.0) + (log_j + log_k) / 2  # b of damping ratio 1
    log_b = draw(st.floats(max(1.0, critical - 2.0), min(5.0, critical + math.log10(3.0))))
    return 10.0**log_j, 10.0**log_b, 10.0**log_k


def sampled_joint(inertia: float, friction: float, stiffness: float):
    """(Ad, Bd, Cd, Dd) of the joint, angle out, by scipy's zero-order hold."""
    ac = np.array([[0.0, 1.0], [-stiffness / inertia, -friction / inertia]])
    bc = np.array([[0.0], [1.0 / inertia]])
    ad, bd, cd, dd, _ = scipy.signal.cont2discrete((ac, bc, np.array([[1.0, 0.0]]), np.zeros((1, 1))), DT)
    return ad, bd, cd, dd


@settings(deadline=None, max_examples=25)
@given(joint=joints(), k_u=EXPONENTS, k_y=EXPONENTS, k_x=EXPONENTS)
@example(joint=NOZZLE, k_u=0.0, k_y=0.0, k_x=0.0)
@example(joint=NOZZLE, k_u=10.0, k_y=-1.0, k_x=0.0)  # torque in units 1e10 smaller: spread ~1e15
@example(joint=(20.0, 4.0 * math.sqrt(20.0 * 2e5), 2e5), k_u=15.0, k_y=-5.0, k_x=5.0)  # damping ratio 2
@example(joint=(20.0, 0.02 * math.sqrt(20.0 * 2e5), 2e5), k_u=-10.0, k_y=20.0, k_x=-7.0)  # 0.01
@example(joint=(20.0, 2.0 * math.sqrt(20.0 * 2e5), 2e5), k_u=20.0, k_y=-10.0, k_x=0.0)  # critical
def test_j_b_k_follow_the_units_of_torque_and_angle(joint, k_u, k_y, k_x):
    inertia, friction, stiffness = joint
    ad, bd, cd, dd = sampled_joint(*joint)
    s_u, s_y, s_x = 10.0**k_u, 10.0**k_y, 10.0**k_x
    model = InnovationsModel(ad, s_x * bd / s_u, s_y * cd / s_x, s_y * dd / s_u, np.zeros((2, 1)), DT)
    params = second_order_parameters(model)
    ratio = s_u / s_y
    for name, true in (("J", inertia), ("b", friction), ("k", stiffness)):
        assert params[name] == pytest.approx(true * ratio, rel=1e-8), name
    # and the unit-free figures: those of the joint itself
    omega_n = math.sqrt(stiffness / inertia)
    assert params["natural_frequency_hz"] == pytest.approx(omega_n / (2 * math.pi), rel=1e-8)
    assert params["damping_ratio"] == pytest.approx(friction / (2 * inertia * omega_n), rel=1e-8)


@pytest.mark.parametrize("scale", [1e-300, 1e-150, 1e150, 1e300])
def test_to_continuous_follows_the_units_of_the_input(scale):
    # the former block logarithm squared an input matrix of 1e150 into inf
    ad, bd, cd, dd = sampled_joint(*NOZZLE)
    base = to_continuous(InnovationsModel(ad, bd, cd, dd, np.zeros((2, 1)), DT))
    ac, bc, cc, dc = to_continuous(InnovationsModel(ad, bd * scale, cd, dd, np.zeros((2, 1)), DT))
    np.testing.assert_allclose(ac, base[0], rtol=1e-14, atol=1e-14 * np.max(np.abs(base[0])))
    np.testing.assert_allclose(bc / scale, base[1], rtol=1e-14, atol=1e-14 * np.max(np.abs(base[1])))
    np.testing.assert_array_equal(cc, base[2])
    np.testing.assert_array_equal(dc, base[3])


@pytest.fixture(scope="module")
def nozzle_record():
    """1000 samples of the linear nozzle under a binary torque of 2000 N m, 5e-5 rad of noise."""
    tau = 2000.0 * np.repeat(np.sign(np.random.default_rng(99).standard_normal(500)), 2)
    ad, bd, cd, dd = sampled_joint(*NOZZLE)
    _, clean, _ = scipy.signal.dlsim((ad, bd, cd, dd, DT), tau[:, None])
    return tau, clean[:, 0] + 5e-5 * np.random.default_rng(3).standard_normal(tau.size)


@pytest.mark.parametrize(
    ("k_u", "k_y", "noise"),
    [(9, 0, "white"), (13, -3, "innovations"), (11, -2, "sieve")],  # torque over angle RMS: 9e13-9e20
)
def test_bootstrap_standard_errors_follow_the_units(nozzle_record, k_u, k_y, noise):
    """The record in N m and rad (spread 9e4, used as it is) against the same record with the
    torque and angle in other units (equilibrated by DSR_e). The bootstrap draws the same
    samples of the residual, so the replicates differ by round-off only: over 4 noise seeds,
    both noise models and five unit changes the standard errors agreed within 3e-11, the
    estimates and the noise level within 2e-14. The former residual, taken on the unscaled
    record, made them 3 to 19 % off (the noise level 3 %) at spread 9e13 and 11 to 20 times too
    large at 9e20, with the conversion already scale-safe."""
    tau, y = nozzle_record
    base = dsr_e_uncertainty(tau, y, DT, dsr_e(tau, y, DT, order=2), replicates=10, seed=2, noise=noise)
    s_u, s_y = 10.0**k_u, 10.0**k_y
    u_s, y_s = tau * s_u, y * s_y
    scaled = dsr_e_uncertainty(u_s, y_s, DT, dsr_e(u_s, y_s, DT, order=2), replicates=10, seed=2, noise=noise)
    ratio = s_u / s_y
    assert scaled.failed == base.failed == 0
    np.testing.assert_allclose(scaled.standard_errors, base.standard_errors * ratio, rtol=1e-9)
    np.testing.assert_allclose(scaled.estimate, base.estimate * ratio, rtol=1e-12)
    assert scaled.noise_std == pytest.approx(base.noise_std * s_y, rel=1e-12)
