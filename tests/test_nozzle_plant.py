"""Nozzle plant: Table 1 data, the normalization, RK4 against independent references, model.json."""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.signal
from scipy.integrate import solve_ivp

from ssme_envs.models.nozzle import (
    NozzleCore,
    NozzleModel,
    NozzleParameters,
    identified_nozzle,
    published_nozzle,
    recommended_substeps,
    rk4_floats,
    rk4_parameters,
    simulate_nozzle,
)
from ssme_envs.signals import prbs

# Table 1 of the VLS nozzle paper, transcribed: J, b, k, a, A, beta, gamma, n.
LINEAR_ROW = (25.18, 376.53, 1.43e5)
NONLINEAR_ROW = (22.92, 422.25, 2.97e5, 0.20, 0.35, 0.93, 1.86, 0.99)


def test_table_1_is_packaged():
    lin = published_nozzle("linear")
    assert (lin.J, lin.b, lin.k) == LINEAR_ROW and lin.is_linear
    bw = published_nozzle("bouc_wen")
    assert (bw.J, bw.b, bw.k, bw.a, bw.A, bw.beta, bw.gamma, bw.n) == NONLINEAR_ROW


def test_small_signal_stiffness_matches_linear_row_and_eq5():
    bw = published_nozzle("bouc_wen")
    assert bw.small_signal_stiffness == pytest.approx(0.2 * 2.97e5 + 0.8 * 2.97e5 * 0.35)
    assert bw.small_signal_stiffness == pytest.approx(1.43e5, rel=0.005)
    # eq 5: 0.03971 / (s^2 + 14.95 s + 5694) is (1/J) / (s^2 + b/J s + k/J) of the linear row
    j, b, k = LINEAR_ROW
    assert 1 / j == pytest.approx(0.03971, rel=1e-3)
    assert b / j == pytest.approx(14.95, rel=1e-3)
    assert k / j == pytest.approx(5694, rel=5e-3)  # 1.43e5 is rounded; 5694 needs k = 1.434e5


def _reference(params: NozzleParameters, tau: np.ndarray, dt: float) -> np.ndarray:
    """The paper's (unnormalized) equations in z, integrated by DOP853 sample by sample."""
    p = params

    def rhs(_t, s, torque):
        x, v, z = s
        accel = (torque - p.b * v - p.a * p.k * x - (1 - p.a) * p.k * z) / p.J
        return [v, accel, p.A * v - abs(z) ** p.n * (p.beta + p.gamma * np.sign(v * z)) * v]

    s, out = np.zeros(3), np.empty(tau.size)
    for i, torque in enumerate(tau):
        out[i] = s[0]
        s = solve_ivp(rhs, (0, dt), s, args=(torque,), method="DOP853", rtol=1e-12, atol=1e-15).y[:, -1]
    return out


def test_rk4_matches_reference_on_the_paper_equations():
    p = published_nozzle("bouc_wen")
    tau = prbs(300, amplitude=3000.0, n_inputs=1, n_bits=9, clock_samples=2)[:, 0]
    ref = _reference(p, tau, 0.008)
    assert np.max(np.abs(ref)) > np.radians(1.0)  # the test leaves the small-signal range
    for substeps, bound in ((4, 5e-4), (16, 5e-5)):
        err = np.max(np.abs(simulate_nozzle(p, tau, substeps=substeps) - ref)) / np.max(np.abs(ref))
        assert err < bound, (substeps, err)


def test_normalization_leaves_the_motion_unchanged():
    p = published_nozzle("bouc_wen")
    same = NozzleParameters.from_normalized(**p.normalized(), A=1.7)
    assert same.A == 1.7 and same.small_signal_stiffness == pytest.approx(p.small_signal_stiffness)
    tau = prbs(200, amplitude=3000.0, n_inputs=1, n_bits=9, clock_samples=2)[:, 0]
    np.testing.assert_allclose(_reference(same, tau, 0.008), _reference(p, tau, 0.008), rtol=1e-8, atol=1e-12)


def test_linear_joint_matches_exact_zoh_discretization():
    j, b, k = LINEAR_ROW
    dt = 0.008
    continuous = (
        np.array([[0, 1], [-k / j, -b / j]]),
        np.array([[0], [1 / j]]),
        np.array([[1, 0]]),
        np.zeros((1, 1)),
    )
    sys_d = scipy.signal.cont2discrete(continuous, dt)
    rng = np.random.default_rng(3)
    tau = rng.normal(0.0, 2000.0, 400)
    _, expected, _ = scipy.signal.dlsim((*sys_d[:4], dt), tau)
    got = simulate_nozzle(NozzleParameters.linear(j, b, k), tau, dt, substeps=8)
    # RK4 with h = 1 ms: global error of order (omega_n h)^4, a few 1e-6 of the peak
    np.testing.assert_allclose(got, expected[:, 0], rtol=0, atol=5e-6 * np.max(np.abs(expected)))


def test_batch_is_bitwise_equal_to_single_runs_and_per_nozzle_parameters():
    rng = np.random.default_rng(0)
    tau = rng.normal(0.0, 4000.0, (3, 400))
    params = [
        published_nozzle("bouc_wen"),
        published_nozzle("linear"),
        NozzleParameters(20, 300, 2e5, 0.3, 1, 5, 3, 1.2),
    ]
    batch = simulate_nozzle(params, tau)
    for i in range(3):
        np.testing.assert_array_equal(batch[i], simulate_nozzle(params[i], tau[i]))


def test_hysteresis_floor_changes_no_bit():
    # |w| is floored in |w|^n only to keep numpy's power off its slow path for exact zeros; the
    # trajectories from rest (w = 0 exactly at first) must equal those computed without it.
    floored = rk4_parameters(published_nozzle("bouc_wen").normalized())
    assert floored.w_floor > 0
    unfloored = floored._replace(w_floor=0.0)
    for torque in (0.0, 500.0, -2.0e4):
        a = b = (0.0, 0.0, 0.0)
        for _ in range(50):
            a = rk4_floats(*a, torque, 0.002, 4, floored)
            b = rk4_floats(*b, torque, 0.002, 4, unfloored)
            assert a == b


def test_torque_limit_saturates():
    p = published_nozzle("bouc_wen")
    tau = np.full(100, 5e4)
    np.testing.assert_array_equal(
        simulate_nozzle(p, tau, torque_limit=1e4), simulate_nozzle(p, np.full(100, 1e4), torque_limit=1e9)
    )
    core = NozzleCore(p, n=2)
    core.step(np.array([1e3, -1e3]))
    assert core.state[0, 0] == -core.state[0, 1] and core.state[0, 0] > 0
    core.reset(np.array([True, False]))
    assert core.state[0, 0] == 0 and core.state[0, 1] != 0


def test_recommended_substeps_grow_with_stiff_hysteresis():
    p = published_nozzle("bouc_wen")
    stiff = NozzleParameters(**{**p.to_dict(), "beta": 93.0, "gamma": 186.0})
    assert (
        recommended_substeps(stiff, 0.008, np.radians(3)) > recommended_substeps(p, 0.008, np.radians(3)) >= 4
    )


def test_recommended_substeps_refuse_an_overflowing_rate_and_tolerate_a_vanishing_one():
    p = published_nozzle("bouc_wen").to_dict()
    with pytest.raises(ValueError, match="overflows"):  # w_max = 1e10^(-100) underflows to 0
        recommended_substeps(NozzleParameters(**{**p, "beta": 1e10, "gamma": 0.0, "n": 0.01}), 0.008, 0.1)
    tiny = NozzleParameters(**{**p, "A": 1.0, "beta": 1e-300, "gamma": 0.0, "n": 0.01})  # w_max overflows
    omega = np.sqrt(tiny.small_signal_stiffness / tiny.J)  # the hysteresis rate vanishes
    assert recommended_substeps(tiny, 0.008, 0.1) == np.ceil(0.008 * omega / 0.2)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"J": 0.0}, "J must be positive"),
        ({"a": 1.5}, "a must be in"),
        ({"b": float("nan")}, "finite"),
        ({"beta": -3.0}, "beta \\+ gamma"),
        ({"gamma": -0.5}, "gamma must be >= 0"),
        ({"k": -1.0e5}, "k must be positive"),
        ({"b": -1.0}, "damping b must be >= 0"),
        ({"J": True}, "J must be a finite number"),
        ({"A": 1e3, "n": 200.0}, "not finite"),
    ],
)
def test_bad_parameters(kwargs, message):
    with pytest.raises(ValueError, match=message):
        NozzleParameters(**{**published_nozzle("bouc_wen").to_dict(), **kwargs})


def test_packaged_identified_model_loads_and_round_trips(tmp_path):
    model = identified_nozzle()
    assert model.linear["A"].shape == (2, 2) and model.bouc_wen is not None
    path = tmp_path / "m.json"
    model.save(path)
    back = NozzleModel.load(path)
    assert back.bouc_wen == model.bouc_wen
    np.testing.assert_array_equal(back.linear["A"], model.linear["A"])


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda d: d["linear"].pop("K"), "missing key"),
        (lambda d: d["linear"].update(B=[[1.0], [2.0], [3.0]]), "linear.B has shape"),
        (lambda d: d["bouc_wen"].update(zeta=1.0), "unknown key"),
        (lambda d: d["bouc_wen"].update(n=-1.0), "n must be positive"),
        (lambda d: d.update(schema="x"), "schema"),
        (lambda d: d["linear"].update(J="heavy"), "linear.J"),
        (lambda d: d["linear"].update(b=-1.0), "linear.b must be >= 0"),
        (lambda d: d["bouc_wen"].update(gamma=-0.1), "gamma must be >= 0"),
    ],
)
def test_malformed_nozzle_model(tmp_path, mutate, message):
    doc = identified_nozzle().to_dict()
    mutate(doc)
    path = tmp_path / "m.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=message):
        NozzleModel.load(path)
