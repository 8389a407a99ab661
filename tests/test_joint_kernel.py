"""The Bouc-Wen power and the nozzle joint's compiled RK4 kernel.

The power is checked against the C library's ``math.pow`` (an independent implementation); its
two Python carriers and the compiled kernel are held to the same bits, and so is the kernel's
RK4 against the Python reference that the rest of the package's tests exercise.
"""

from __future__ import annotations

import math
import sys
import types
import warnings
from fractions import Fraction

import numpy as np
import pytest
from conftest import random_rollout
from hypothesis import given, settings
from hypothesis import strategies as st

import ssme_envs  # noqa: F401  (registers the environments)
from ssme_envs.envs import launcher_pitch, launcher_servo, nozzle_task
from ssme_envs.models import nozzle_joint
from ssme_envs.models.joint_power import power_array, power_float, tables
from ssme_envs.models.nozzle_joint import NozzleParameters, rk4_parameters

LAUNCHER = "ssme_envs/LauncherPitch-v0"
compiled = pytest.mark.skipif(nozzle_joint._KERNEL is None, reason="the compiled kernel is not built here")

bases = st.floats(min_value=0.0, max_value=1e300, allow_nan=False, allow_infinity=False)
exponents = st.floats(min_value=0.05, max_value=5.0)
nozzles = st.builds(
    NozzleParameters,
    J=st.floats(5.0, 50.0),
    b=st.floats(0.0, 800.0),
    k=st.floats(2e4, 2e5),
    a=st.floats(0.1, 1.0),
    A=st.just(1.0),
    beta=st.floats(0.0, 150.0),
    gamma=st.floats(0.0, 150.0),
    n=st.floats(0.5, 2.0),
)
joint_states = st.tuples(st.floats(-0.05, 0.05), st.floats(-2.0, 2.0), st.floats(-0.05, 0.05))


@settings(max_examples=300, deadline=None)
@given(x=bases, n=exponents)
def test_power_is_within_a_few_ulps_of_the_c_library(x: float, n: float) -> None:
    if x == 0.0:
        assert power_float(x, n) == 0.0
        return
    y = n * math.log(x)
    if not -700.0 < y < 700.0:  # the result over- or underflows: its own test below
        return
    exact = math.pow(x, n)
    # a few ulps plus |y| ulps from rounding y = n log x (the module's bound)
    assert abs(power_float(x, n) - exact) <= 3.0 * (1.0 + abs(y)) * 2.0**-53 * exact


@settings(max_examples=200, deadline=None)
@given(xs=st.lists(bases, min_size=1, max_size=40), n=exponents)
def test_power_gives_the_same_bits_on_floats_and_on_arrays(xs: list[float], n: float) -> None:
    array = power_array(np.array(xs), n)
    assert [power_float(x, n) for x in xs] == array.tolist()


def test_power_keeps_inf_and_nan_and_saturates_at_the_ends() -> None:
    assert power_float(math.inf, 1.5) == math.inf
    assert math.isnan(power_float(math.nan, 1.5))
    out = power_array(np.array([math.inf, math.nan, 1e-300, 1e300]), 3.0)
    assert out[0] == math.inf and math.isnan(out[1]) and out[2] == 0.0 and out[3] == math.inf
    assert power_float(1.0, 0.99) == 1.0 and power_float(4.0, 0.5) == 2.0


@compiled
@settings(max_examples=300, deadline=None)
@given(x=bases, n=exponents)
def test_kernel_power_has_the_reference_bits(x: float, n: float) -> None:
    assert nozzle_joint._KERNEL.power(x, n) == power_float(x, n)


def test_the_inverse_table_is_the_correctly_rounded_quotient() -> None:
    """The reference reads 1/c from a table where the kernel divides: both are 1/c rounded once
    (checked here against exact rational arithmetic)."""
    inv_c = tables()[0]
    assert inv_c == tuple(float(1 / Fraction(1 + (i + 0.5) / 128)) for i in range(128))


@compiled
def test_the_kernel_refuses_an_inverse_table_it_would_not_compute() -> None:
    inv_c, log_c, exp2 = tables()
    off = (*inv_c[:5], math.nextafter(inv_c[5], 2.0), *inv_c[6:])
    with pytest.raises(ValueError, match=r"inv_c\[5\] is not 1.0 / c"):
        nozzle_joint._KERNEL.set_tables(off, log_c, exp2)
    assert nozzle_joint._KERNEL.power(1.04, 1.5) == power_float(1.04, 1.5)  # its tables kept


@compiled
@settings(max_examples=150, deadline=None)
@given(nozzle=nozzles, state=joint_states, tau=st.floats(-3e4, 3e4), steps=st.integers(1, 6))
def test_kernel_rk4_float_has_the_reference_bits(nozzle, state, tau, steps) -> None:
    for p in (
        rk4_parameters(nozzle.normalized()),
        rk4_parameters(nozzle.normalized())._replace(hysteretic=False),
    ):
        assert nozzle_joint._KERNEL.rk4_float(*state, tau, 0.002, steps, p) == nozzle_joint._rk4_floats_py(
            *state, tau, 0.002, steps, p
        )


@compiled
@settings(max_examples=40, deadline=None)
@given(
    plants=st.lists(st.tuples(nozzles, joint_states, st.floats(-3e4, 3e4)), min_size=1, max_size=300),
    steps=st.integers(1, 4),
    shared=st.booleans(),
)
def test_kernel_rk4_batch_has_the_reference_bits(plants, steps, shared) -> None:
    """Per-nozzle parameters (drawn plants) or one joint for all, across the kernel's blocks."""
    norms = [nozzle.normalized() for nozzle, _, _ in plants]
    if shared:
        p = rk4_parameters(norms[0])
    else:
        p = rk4_parameters({key: np.array([norm[key] for norm in norms]) for key in norms[0]})
    state = np.array([s for _, s, _ in plants]).T.copy()
    tau = np.array([t for _, _, t in plants])
    for params in (p, p._replace(hysteretic=False)):
        kernel, reference = state.copy(), state.copy()
        nozzle_joint._KERNEL.rk4_batch(kernel, tau, 0.002, steps, params)
        nozzle_joint._rk4_arrays_py(reference, tau, 0.002, steps, params)
        assert np.array_equal(kernel, reference, equal_nan=True)
        one = rk4_parameters(norms[0])._replace(hysteretic=params.hysteretic)
        if shared:  # and each nozzle alone on floats
            alone = [nozzle_joint.rk4_floats(*s, t, 0.002, steps, one) for _, s, t in plants]
            assert np.array_equal(np.array(alone).T, kernel)


@compiled
@settings(max_examples=40, deadline=None)
@given(
    plants=st.lists(
        st.tuples(nozzles, joint_states, st.floats(-3e4, 3e4), st.booleans()), min_size=1, max_size=400
    ),
    shared=st.booleans(),
)
def test_skipped_nozzles_leave_the_others_bits_alone(plants, shared) -> None:
    """Nozzles named in skip (a vector env's restarting envs, whose state it discards) are left
    out of blocks where the kernel packs the others: every other nozzle gets the reference's
    bits, and each skipped one is either stepped or left exactly as it was."""
    norms = [nozzle.normalized() for nozzle, *_ in plants]
    if shared:
        p = rk4_parameters(norms[0])
    else:
        p = rk4_parameters({key: np.array([norm[key] for norm in norms]) for key in norms[0]})
    state = np.array([s for _, s, _, _ in plants]).T.copy()
    tau = np.array([t for _, _, t, _ in plants])
    skip = np.array([k for *_, k in plants])
    for params in (p, p._replace(hysteretic=False)):
        kernel, reference = state.copy(), state.copy()
        nozzle_joint._KERNEL.rk4_batch(kernel, tau, 0.002, 2, params, skip)
        nozzle_joint._rk4_arrays_py(reference, tau, 0.002, 2, params)
        assert np.array_equal(kernel[:, ~skip], reference[:, ~skip], equal_nan=True)
        stepped = (kernel == reference) | (np.isnan(kernel) & np.isnan(reference))
        kept = (kernel == state) | (np.isnan(kernel) & np.isnan(state))
        assert (stepped.all(axis=0) | kept.all(axis=0))[skip].all()


@compiled
def test_a_skip_row_of_the_wrong_kind_is_named() -> None:
    state, p = np.zeros((3, 4)), rk4_parameters(nozzle_joint.strong_nozzle().normalized())
    for bad in (np.zeros(4), np.zeros(3, dtype=bool), [True] * 4):
        with pytest.raises(TypeError, match="skip"):
            nozzle_joint._KERNEL.rk4_batch(state, 0.0, 0.002, 1, p, bad)


def test_rk4_arrays_takes_a_strided_state_through_the_reference_with_the_same_bits() -> None:
    p = rk4_parameters(
        NozzleParameters(J=20.0, b=250.0, k=1.6e5, a=0.15, beta=120.0, gamma=80.0, n=1.5).normalized()
    )
    wide = np.zeros((3, 8))
    wide[:, ::2] = [[0.01, -0.02, 0.0, 0.03], [0.3, -1.0, 0.0, 0.2], [0.01, 0.0, -0.01, 0.02]]
    strided, contiguous = wide[:, ::2], wide[:, ::2].copy()
    tau = np.array([100.0, -5e3, 0.0, 2e4])
    nozzle_joint.rk4_arrays(strided, tau, 0.002, 3, p)
    nozzle_joint.rk4_arrays(contiguous, tau, 0.002, 3, p)
    assert np.array_equal(strided, contiguous)
    assert not np.array_equal(contiguous, wide[:, 1::2])  # it moved


def test_a_kernel_that_differs_from_the_reference_is_refused(monkeypatch) -> None:
    """A build that fused or reordered operations (one ulp off) is not used, with a warning."""
    monkeypatch.delenv("SSME_ENVS_NO_KERNEL", raising=False)
    real = nozzle_joint._KERNEL or types.SimpleNamespace(set_tables=lambda *a: None)
    fake = types.ModuleType("ssme_envs.models._joint_kernel")
    fake.set_tables = real.set_tables
    fake.power = lambda x, n: math.nextafter(power_float(x, n), math.inf)
    fake.rk4_float = nozzle_joint._rk4_floats_py
    fake.rk4_batch = nozzle_joint._rk4_arrays_py
    fake.servo_float = fake.servo_batch = lambda *args: None
    monkeypatch.setitem(sys.modules, "ssme_envs.models._joint_kernel", fake)
    monkeypatch.setattr(sys.modules["ssme_envs.models"], "_joint_kernel", fake, raising=False)
    with pytest.warns(RuntimeWarning, match="differs from its reference"):
        assert nozzle_joint._load_kernel() is None
    fake.power = power_float  # the same bits: taken
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert nozzle_joint._load_kernel() is fake


@compiled
@settings(max_examples=6, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    options=st.sampled_from(
        [
            {},
            {"plant": "strong", "fault": {"kind": "gain_loss", "time": 0.3, "magnitude": 0.5}},
            {"plant_spread": 0.3},
            {"plant": "linear"},
        ]
    ),
    batched=st.booleans(),
)
def test_launcher_gives_the_same_bits_with_and_without_the_kernels_servo(seed, options, batched):
    """The kernel's servo loop against the Python loop over the Python integrators."""
    with_kernel = random_rollout(LAUNCHER, seed, batched, 120, 6, **options)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(launcher_pitch, "compiled_servo", lambda batched: None)
        patch.setattr(nozzle_task, "rk4_floats", nozzle_joint._rk4_floats_py)
        patch.setattr(nozzle_task, "rk4_arrays", nozzle_joint._rk4_arrays_py)
        reference = random_rollout(LAUNCHER, seed, batched, 120, 6, **options)
    assert len(with_kernel) == len(reference)
    assert all(np.array_equal(a, b) for a, b in zip(with_kernel, reference, strict=True))


def test_a_substituted_integrator_gets_the_python_servo_loop(monkeypatch) -> None:
    monkeypatch.setattr(nozzle_task, "rk4_floats", lambda *args: nozzle_joint._rk4_floats_py(*args))
    assert launcher_servo.compiled_servo(batched=False) is None
    assert launcher_servo.compiled_servo(batched=True) is nozzle_joint._KERNEL


@compiled
def test_a_kernel_that_reads_one_joint_for_every_nozzle_is_refused(monkeypatch) -> None:
    """The import check holds the per-nozzle joints (drawn plants) apart from the shared one: a
    kernel that steps every nozzle of a batch with the first one's joint is not used."""
    monkeypatch.delenv("SSME_ENVS_NO_KERNEL", raising=False)
    real = nozzle_joint._KERNEL

    def first_joint_for_all(state, tau, h, steps, p, skip=None):
        if isinstance(p.n, np.ndarray):
            p = p._replace(**{k: v[0] for k, v in p._asdict().items() if isinstance(v, np.ndarray)})
        real.rk4_batch(state, tau, h, steps, p, skip)

    fake = types.ModuleType("ssme_envs.models._joint_kernel")
    fake.set_tables, fake.power, fake.rk4_float = real.set_tables, real.power, real.rk4_float
    fake.servo_float, fake.servo_batch = real.servo_float, real.servo_batch
    fake.rk4_batch = first_joint_for_all
    monkeypatch.setitem(sys.modules, "ssme_envs.models._joint_kernel", fake)
    monkeypatch.setattr(sys.modules["ssme_envs.models"], "_joint_kernel", fake, raising=False)
    with pytest.warns(RuntimeWarning, match="differs from its reference"):
        assert nozzle_joint._load_kernel() is None
    fake.rk4_batch = real.rk4_batch
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert nozzle_joint._load_kernel() is fake


def test_a_build_of_an_older_source_is_refused(monkeypatch) -> None:
    """A kernel without the calls this source makes (a stale build) warns and is not used."""
    monkeypatch.delenv("SSME_ENVS_NO_KERNEL", raising=False)
    stale = types.ModuleType("ssme_envs.models._joint_kernel")
    stale.rk4_float, stale.rk4_batch = nozzle_joint._rk4_floats_py, nozzle_joint._rk4_arrays_py
    monkeypatch.setitem(sys.modules, "ssme_envs.models._joint_kernel", stale)
    monkeypatch.setattr(sys.modules["ssme_envs.models"], "_joint_kernel", stale, raising=False)
    with pytest.warns(RuntimeWarning, match="differs from its reference"):
        assert nozzle_joint._load_kernel() is None


@pytest.mark.parametrize("base", [-1e-3, -2.0, -math.inf])
def test_a_negative_base_is_refused_by_name(base: float) -> None:
    with pytest.raises(ValueError, match="takes x >= 0"):
        power_float(base, 1.5)
    with pytest.raises(ValueError, match="takes x >= 0"):
        power_array(np.array([0.1, base]), 1.5)
    if nozzle_joint._KERNEL is not None:
        with pytest.raises(ValueError, match="takes x >= 0"):
            nozzle_joint._KERNEL.power(base, 1.5)
