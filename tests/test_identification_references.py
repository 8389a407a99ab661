"""Identification checked against references the identifiers do not share.

* The instrumental-variable passes of the alpha-canonical fit against least squares, on Table I
  models simulated by scipy with white measurement (output) noise: the output-error setting IV
  is for, where least squares is biased (it assumes equation errors).
* DSR_e on random stable systems built by ``scipy.signal.zpk2ss`` (not the innovations form it
  estimates) with white and with coloured (ARMA) output noise: poles against the Cramer-Rao
  bound computed here by brute force, Markov parameters against the standard error of a
  least-squares FIR estimate; both bounds shrink as 1 / sqrt(samples).
* The pipeline on the nonlinear engine truth against the paper's Table II SEE, with the SEE
  computed here by scipy (eq 53 written out), and a wrong model that the bound rejects.
* The coverage of DSR_e's bootstrap intervals for the nozzle joint over 100 noise seeds, within
  a binomial band.
"""

from __future__ import annotations

import json
from importlib import resources

import numpy as np
import pytest
import scipy.signal
from conftest import dlsim, eq36, markov
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import linear_sum_assignment
from scipy.stats import binom, chi2

from ssme_envs.identification import dsr_e, identify
from ssme_envs.identification.engine_nonlinear_pipeline import run_nonlinear
from ssme_envs.identification.nozzle_uncertainty import dsr_e_uncertainty
from ssme_envs.identification.subspace import second_order_parameters
from ssme_envs.models import NonlinearEngine

TABLE = json.loads((resources.files("ssme_envs") / "models" / "data" / "engine_table1.json").read_text())
DT = TABLE["dt"]
LEVELS = tuple(entry["power_percent"] for entry in TABLE["models"])


def table1(power: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A, B, C, lambda of Table I at ``power``, read from the data file (not the package's loader)."""
    (entry,) = [e for e in TABLE["models"] if e["power_percent"] == power]
    return tuple(np.array(entry[key], dtype=float) for key in ("A", "B", "C", "lambda"))


# --- 1. IV against LS under white output noise -------------------------------------------------

IV_MARKOV = 11  # C A^k B, k = 0..10
OUTPUT_NOISE = 0.05  # white measurement noise, share of each output's RMS


def _output_error_record(power: int, samples: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Table I at ``power`` driven by a random +-0.01 binary input, simulated by scipy, with white
    noise of 5 % of each output's RMS added to the outputs (output error, not equation error)."""
    a, b, c, lam = table1(power)
    rng = np.random.default_rng(seed)
    u = 0.01 * rng.choice([-1.0, 1.0], size=(samples, 2))
    y = dlsim(a, b, c, eq36(u, lam))
    rms = np.sqrt(np.mean(y**2, axis=0))
    return u, y + OUTPUT_NOISE * rms * rng.standard_normal(y.shape)


def _markov_errors(power: int, samples: int, seeds) -> dict[str, np.ndarray]:
    """max |C A^k B - Table I's| / max |Table I's| over k = 0..10, per seed, for "ls" and "iv"."""
    a, b, c, _ = table1(power)
    truth = markov(a, b, c, IV_MARKOV)
    errors = {"ls": [], "iv": []}
    for seed in seeds:
        u, y = _output_error_record(power, samples, seed)
        for method in errors:
            model = identify(u, y, DT, indices=(2, 2), method=method, uncertainty=False).model
            got = markov(model.A, model.B, model.C, IV_MARKOV)
            errors[method].append(np.max(np.abs(got - truth)) / np.max(np.abs(truth)))
    return {method: np.array(values) for method, values in errors.items()}


def test_iv_removes_the_least_squares_bias_under_white_output_noise():
    """At 70 % power, 1000 samples, 20 seeds: measured mean errors LS 0.0157, IV 0.0038 (IV better
    on 20 of 20 seeds)."""
    errors = _markov_errors(70, 1000, range(20))
    assert errors["iv"].mean() < 0.5 * errors["ls"].mean(), errors
    assert np.sum(errors["iv"] < errors["ls"]) >= 16, errors


@pytest.mark.parametrize("power", LEVELS)
def test_iv_is_consistent_and_least_squares_is_not(power):
    """Eight times the samples: IV's error falls (measured 0.0040 -> 0.0013 at 70 %, 0.33x; 1 /
    sqrt(8) = 0.35), LS's stays at its bias (0.0151 -> 0.0152), and with the long record IV beats
    LS at every Table I level (mean errors at 8000 samples, LS / IV: 70 % 0.0152 / 0.0013, 80 %
    0.0057 / 0.0013, 90 % 0.0045 / 0.0013, 100 % 0.0057 / 0.0013, 110 % 0.0033 / 0.0013)."""
    seeds = range(100, 108)
    long = _markov_errors(power, 8000, seeds)
    assert long["iv"].mean() < 0.7 * long["ls"].mean(), long
    if power == 70:  # the level where the bias dominates the spread at 1000 samples
        short = _markov_errors(power, 1000, seeds)
        assert long["iv"].mean() < 0.6 * short["iv"].mean(), (short, long)
        assert long["ls"].mean() > 0.8 * short["ls"].mean(), (short, long)


# --- 2. DSR_e on systems that are not in innovations form -------------------------------------

# Output noise std, share of each output's noise-free RMS: white, coloured. The coloured noise,
# v_o = sigma_e (1 + 0.5 q^-1) / (1 - a_o q^-1) w_o with |a_o| 0.6-0.85, is strong and slow
# enough for its states to stand above the singular values' noise floor: with 10 % and |a_o| down
# to 0.3 they barely do, and the forced extra states then land anywhere (system poles 0.05 off
# at 16000 samples on some records).
DSR_NOISE = {False: 0.1, True: 0.3}
NOISE_ZERO = 0.5
DSR_MARKOV = 10  # D, CB, ..., C A^8 B
SHORT, LONG = 2000, 16000


def _random_system(seed: int, coloured: bool, weak: bool = False):
    """A random stable system from ``scipy.signal.zpk2ss``: 1-4 poles of radius 0.3-0.9 (at most
    one complex pair), 1-2 inputs, 1-2 outputs (the extra input and output columns random), a
    random feedthrough. With ``coloured`` also one real noise pole per output, |a| 0.6-0.85
    (``weak``: within +-0.8). All poles at least 0.2 apart (so that each is determined on its
    own). Returns a, b, c, d, the system's poles and the noise poles."""
    rng = np.random.default_rng(seed)
    m, p = int(rng.integers(1, 3)), int(rng.integers(1, 3))
    while True:
        poles = []
        for _ in range(int(rng.integers(0, 2))):
            pole = rng.uniform(0.4, 0.9) * np.exp(1j * rng.uniform(0.3, 2.5))
            poles += [pole, np.conj(pole)]
        poles += list(rng.uniform(-0.9, 0.9, int(rng.integers(1, 3))))
        if not coloured:
            noise = []
        elif weak:
            noise = list(rng.uniform(-0.8, 0.8, p))
        else:
            noise = list(rng.uniform(0.6, 0.85, p) * rng.choice([-1.0, 1.0], p))
        every = np.array(poles + noise)
        gaps = np.abs(every[:, None] - every[None, :]) + 9.0 * np.eye(every.size)
        if gaps.min() > 0.2 and np.abs(every).min() > 0.3:
            break
    a, b, c, _ = scipy.signal.zpk2ss([], np.array(poles), 1.0)
    a, b, c = np.real(a), np.real(b), np.real(c)
    n = a.shape[0]
    b = np.column_stack([b, rng.standard_normal((n, m - 1))])
    c = np.vstack([c, rng.standard_normal((p - 1, n))])
    d = 0.5 * rng.standard_normal((p, m))
    return a, b, c, d, np.array(poles), np.array(noise)


def _pole_standard_deviations(a, b, c, u, sigma, noise_poles):
    """Cramer-Rao standard deviation of each pole (|delta| of a complex one) for a record with
    input ``u`` and output noise of driving std ``sigma`` per output, white or (``noise_poles``)
    ARMA with the known filter. Brute force: the prediction-error gradient of the modal form
    ``y = D u + sum_i R_i / (z - lambda_i) u`` with each residue R_i a free p x m matrix (a larger
    model class than the true rank-one residues, so the bound is if anything loose), filtered by
    the inverse noise filter, gives the Fisher information. Returns the std of each of ``a``'s
    eigenvalues, in the order of ``np.linalg.eig``, and those eigenvalues."""
    samples, m = u.shape
    p = c.shape[0]
    lam, vec = np.linalg.eig(a)
    left = np.linalg.inv(vec)
    columns, blocks = [], []

    def on_output(o, signal):
        col = np.zeros((samples, p))
        col[:, o] = signal
        return col

    for i, pole in enumerate(lam):
        if pole.imag < -1e-12:
            continue
        residue = np.outer(c @ vec[:, i], left[i] @ b)
        first = np.column_stack([scipy.signal.lfilter([0, 1], [1, -pole], u[:, j]) for j in range(m)])
        second = np.column_stack(
            [scipy.signal.lfilter([0, 0, 1], [1, -2 * pole, pole * pole], u[:, j]) for j in range(m)]
        )
        d_pole = second @ residue.T  # d y / d lambda, (samples, p)
        start = len(columns)
        if abs(pole.imag) > 1e-12:  # the pair contributes 2 Re(...)
            columns += [2 * d_pole.real, -2 * d_pole.imag]
            blocks.append((i, slice(start, start + 2)))
            for o in range(p):
                for j in range(m):
                    columns += [on_output(o, 2 * first[:, j].real), on_output(o, -2 * first[:, j].imag)]
        else:
            columns.append(d_pole.real)
            blocks.append((i, slice(start, start + 1)))
            columns += [on_output(o, first[:, j].real) for o in range(p) for j in range(m)]
    columns += [on_output(o, u[:, j]) for o in range(p) for j in range(m)]
    psi = np.stack(columns, axis=-1)  # (samples, p, parameters)
    if noise_poles.size:
        for o in range(p):
            psi[:, o] = scipy.signal.lfilter([1, -noise_poles[o]], [1, NOISE_ZERO], psi[:, o], axis=0)
    psi /= sigma[None, :, None]
    covariance = np.linalg.inv(np.einsum("tok,tol->kl", psi, psi))
    std = np.empty(lam.size)
    for i, block in blocks:
        std[i] = np.sqrt(np.trace(covariance[block, block]))
        if abs(lam[i].imag) > 1e-12:  # the conjugate: the same std
            std[np.argmin(np.abs(lam - np.conj(lam[i])))] = std[i]
    return std, lam


def _noisy_record(seed: int, coloured: bool, weak: bool = False):
    """The system of ``_random_system`` driven by LONG samples of unit white noise, simulated by
    scipy, plus output noise of DSR_NOISE times each output's RMS: white, or ARMA(1, 1) through
    ``lfilter`` (``weak``: 10 % of the RMS, noise poles within +-0.8). Returns the system, u, y,
    the noise's std and that of its white source."""
    system = _random_system(seed, coloured, weak)
    a, b, c, d, _, noise_poles = system
    m, p = b.shape[1], c.shape[0]
    rng = np.random.default_rng([seed, 1])
    u = rng.standard_normal((LONG, m))
    _, clean, _ = scipy.signal.dlsim((a, b, c, d, 1.0), u)
    clean = clean.reshape(LONG, p)
    sigma_v = (0.1 if weak else DSR_NOISE[coloured]) * np.sqrt(np.mean(clean**2, axis=0))
    w = rng.standard_normal((LONG, p))
    if not coloured:
        return system, u, clean + sigma_v * w, sigma_v, sigma_v
    arma_var = (1 + NOISE_ZERO**2 + 2 * noise_poles * NOISE_ZERO) / (1 - noise_poles**2)
    sigma_e = sigma_v / np.sqrt(arma_var)  # the ARMA filter's output then has std sigma_v
    v = np.column_stack(
        [sigma_e[o] * scipy.signal.lfilter([1, NOISE_ZERO], [1, -noise_poles[o]], w[:, o]) for o in range(p)]
    )
    return system, u, clean + v, sigma_v, sigma_e


def _markov_with_d(a, b, c, d) -> np.ndarray:
    return np.concatenate([d[None], markov(a, b, c, DSR_MARKOV - 1)])


def _dsr_e_errors(seed: int, coloured: bool) -> tuple[dict, dict]:
    """DSR_e on the first SHORT and on all LONG samples of one record: per length the largest
    pole error over its Cramer-Rao std, the largest Markov error over the FIR standard error,
    and the RMS Markov error; at SHORT also the RMS Markov error averaged over the record's eight
    disjoint SHORT segments (a steadier 1x figure than one segment's)."""
    (a, b, c, d, poles, noise_poles), u, y, sigma_v, sigma_e = _noisy_record(seed, coloured)
    p = c.shape[0]
    truth = _markov_with_d(a, b, c, d)
    order = a.shape[0] + (p if coloured else 0)  # the innovations form's order: plus the noise's states

    def rms_error(model) -> float:
        return float(np.sqrt(np.mean((_markov_with_d(model.A, model.B, model.C, model.D) - truth) ** 2)))

    out = []
    for samples in (SHORT, LONG):
        model = dsr_e(u[:samples], y[:samples], 1.0, order=order).model
        found = np.linalg.eigvals(model.A)
        cost = np.abs(poles[:, None] - found[None, :])  # the noise poles found are left unmatched
        rows, cols = linear_sum_assignment(cost)
        std, eigenvalues = _pole_standard_deviations(a, b, c, u[:samples], sigma_e, noise_poles)
        std = std[[np.argmin(np.abs(eigenvalues - pole)) for pole in poles]]  # in the order of poles
        got = _markov_with_d(model.A, model.B, model.C, model.D)
        # least-squares FIR standard error with a unit white input: sigma_v / sqrt(samples)
        scaled = (got - truth) / (sigma_v[None, :, None] / np.sqrt(samples))
        out.append(
            {
                "pole_ratio": float(np.max(cost[rows, cols] / std[rows])),
                "markov_ratio": float(np.max(np.abs(scaled))),
                "markov_rms": rms_error(model),
            }
        )
    segments = [
        rms_error(dsr_e(u[s : s + SHORT], y[s : s + SHORT], 1.0, order=order).model)
        for s in range(0, LONG, SHORT)
    ]
    out[0]["segment_rms"] = float(np.mean(segments))
    return out[0], out[1]


# Bounds: pole error <= POLE_BOUND x its Cramer-Rao std, each Markov parameter <= MARKOV_BOUND x
# sigma_v / sqrt(samples) (the standard error of a least-squares FIR estimate from a unit white
# input, for white and for coloured noise of std sigma_v alike); both shrink as 1 / sqrt(samples).
# Measured on 200 random systems each (seeds 0-199), at 2000 / 16000 samples:
# - white: poles median 1.0, 99th percentile 3.1 / 3.3, largest 5.0 / 5.7 std; Markov up to 3.9.
# - coloured: poles median 1.8, 99th percentile 24 / 8.7, largest 38 / 23 std (DSR_e has to place
#   the noise's states too, and at 2000 samples they sometimes drag a system pole off: seed 73's
#   pair -0.268 +- 0.405j came out as -0.18 +- 0.17j); Markov up to 6.3. 1 of the 200 raised
#   (test_dsr_e_past_horizon_refinement_keeps_a_model).
# - the RMS Markov error at 16000 samples over its mean on the eight 2000-sample segments: at
#   most 0.73 (white), 0.69 (coloured); 1 / sqrt(8) = 0.35 expected.
POLE_BOUND = {False: 8.0, True: 50.0}
MARKOV_BOUND = 8.0
DSR_SETTINGS = settings(deadline=None, max_examples=8, derandomize=True)


@pytest.mark.parametrize("coloured", [False, True], ids=["white", "arma"])
@DSR_SETTINGS
@given(seed=st.integers(0, 2**32 - 1))
def test_dsr_e_recovers_a_system_with_output_noise(coloured, seed):
    short, long = _dsr_e_errors(seed, coloured)
    for errors in (short, long):
        assert errors["pole_ratio"] < POLE_BOUND[coloured], (short, long)
        assert errors["markov_ratio"] < MARKOV_BOUND, (short, long)
    assert long["markov_rms"] < short["segment_rms"], (short, long)


def test_dsr_e_past_horizon_refinement_keeps_a_model():
    """A record with weak ARMA noise (seed 107, 10 %, 16000 samples, order 3 + 2 noise states):
    the first pass (J = 12) identifies the system poles to 0.008 with a stable A; the automatic
    refinement to J = 42 gives A a pole at 1.016, whose unit responses over 16000 samples (1e110,
    finite) leave the B, D, K regression at rank 3 of 22. dsr_e raised a ValueError blaming the
    input; it now keeps the first pass."""
    (a, _, c, _, poles, _), u, y, _, _ = _noisy_record(107, coloured=True, weak=True)
    order = a.shape[0] + c.shape[0]

    def pole_error(model) -> float:
        cost = np.abs(poles[:, None] - np.linalg.eigvals(model.A)[None, :])
        rows, cols = linear_sum_assignment(cost)
        return float(np.max(cost[rows, cols]))

    try:  # a ValueError here is not the failure this xfail expects
        first_pass = dsr_e(u, y, 1.0, order=order, past_horizon=12).model
    except ValueError as error:
        pytest.fail(f"the first pass's horizon fails too: {error}")
    assert np.max(np.abs(np.linalg.eigvals(first_pass.A))) < 1.0
    assert pole_error(first_pass) < 0.02
    assert pole_error(dsr_e(u, y, 1.0, order=order).model) < 0.02  # the refinement raised here


def test_an_unstable_identified_a_is_named_as_such_not_blamed_on_the_input():
    """Seed 125's samples 2000-3999 in the coloured-noise setting: the first pass (J = 12) gives A
    a spurious pole beyond the unit circle. The error names it, not the (white) input. Both
    horizons are given (those of the automatic first pass, L = 5 for two outputs): with either
    left automatic, dsr_e retries other horizons and finds a stable model here."""
    (a, _, c, _, _, _), u, y, _, _ = _noisy_record(125, coloured=True)
    with pytest.raises(ValueError, match=r"the identified A is unstable \(spectral radius 1\.0"):
        dsr_e(
            u[2000:4000], y[2000:4000], 1.0, order=a.shape[0] + c.shape[0], past_horizon=12, future_horizon=5
        )


def test_the_same_record_with_automatic_horizons_is_retried_to_a_stable_model():
    """The record above with the horizons left automatic: the unstable first pass is retried at
    other horizons, and the model kept has a stable A and predictor (true spectral radius 0.89)."""
    (a, _, c, _, _, _), u, y, _, _ = _noisy_record(125, coloured=True)
    model = dsr_e(u[2000:4000], y[2000:4000], 1.0, order=a.shape[0] + c.shape[0]).model
    assert np.max(np.abs(np.linalg.eigvals(model.A))) < 1.0
    assert np.max(np.abs(np.linalg.eigvals(model.A - model.K @ model.C))) < 1.0


# --- 3. the pipeline on the nonlinear truth against Table II -----------------------------------


def _see(measured: np.ndarray, predicted: np.ndarray) -> np.ndarray:
    """Eq 53 per output: sum (z - y)^2 / sum y^2."""
    return np.sum((predicted - measured) ** 2, axis=0) / np.sum(measured**2, axis=0)


def _model_see(model, u, y, b_scale: float = 1.0) -> np.ndarray:
    """SEE of the model's simulation from the inputs alone (scipy, eq 36 on the input)."""
    return _see(y, dlsim(model.A, b_scale * model.B, model.C, eq36(u, model.lam)))


def _filter_see(model, u, y) -> np.ndarray:
    """SEE of the one-step state-variable filter (eq 50), written as the observer
    x(k+1) = A_o x + K y + B u*, prediction C x, with A = A_o + K C: C = H [0 I] is non-zero on
    the p states that A_o (a shift) does not feed, so there A = K C gives K, and A_o = A - K C
    must come out nilpotent."""
    support = np.flatnonzero(np.any(model.C != 0, axis=0))
    assert support.size == model.C.shape[0]
    k = model.A[:, support] @ np.linalg.inv(model.C[:, support])
    a_o = model.A - k @ model.C
    n, p, m = a_o.shape[0], model.C.shape[0], model.B.shape[1]
    np.testing.assert_allclose(np.linalg.matrix_power(a_o, n), 0.0, atol=1e-9)
    _, pred, _ = scipy.signal.dlsim(
        (a_o, np.hstack([k, model.B]), model.C, np.zeros((p, p + m)), DT), np.hstack([y, eq36(u, model.lam)])
    )
    return _see(y, pred)


@pytest.fixture(scope="module")
def nonlinear_results():
    engine = NonlinearEngine()
    return {r.power_percent: r for r in run_nonlinear(power_levels=LEVELS, engine=engine)}


RECORDS = {"validation_prbs": "prbs", "validation_low_frequency": "low_frequency"}


@pytest.mark.parametrize("power", LEVELS)
def test_nonlinear_pipeline_beats_table_ii(nonlinear_results, power):
    """Our model's and filter's SEE on the nonlinear truth's validation records below the paper's
    (Table II) at the same level, record and output. Measured: 1.2-90 times below (the figure 3
    model SEEs, calibrated to the paper's range, closest)."""
    result = nonlinear_results[power]
    model = result.identified.model
    for record, key in RECORDS.items():
        u, y = result.records[record].u, result.records[record].y
        ours = {"model": _model_see(model, u, y), "filter": _filter_see(model, u, y)}
        for kind, values in ours.items():
            paper = np.array([TABLE["table2_see"][key][kind][o][str(power)] for o in TABLE["output_names"]])
            assert np.all(values < paper), (record, kind, values, paper)
            # the pipeline reports the same SEE
            np.testing.assert_allclose(result.validation[record][kind]["see"], values, rtol=1e-8, atol=1e-12)


@pytest.mark.parametrize("power", LEVELS)
def test_nonlinear_figure3_model_see_in_the_papers_range(nonlinear_results, power):
    """The identified point models' SEE on the figure 3 test (as packaged: OPOV within +-0.02,
    FPOV within +-0.015), computed here by scipy from the record, lies in 0.01-0.2, the range of
    Table II against Rocketdyne's simulation. The truth's valve authority was calibrated for this
    (``ssme_envs.models.engine_valve_flow``); without it 5 of the 10 fell below 0.01."""
    result = nonlinear_results[power]
    record = result.records["validation_low_frequency"]
    values = _model_see(result.identified.model, record.u, record.y)
    assert np.all((values >= 0.01) & (values <= 0.2)), values
    assert np.abs(record.u).max() == pytest.approx(0.02)


def test_table_ii_bound_rejects_a_wrong_model(nonlinear_results):
    """B scaled by 1.3 (every Markov parameter 30 % off): SEE on the 100 % PRBS validation record
    0.089 (pc), 0.099 (mr), above the paper's 0.0781, 0.0538; the identified model's 0.0044, 0.0047."""
    result = nonlinear_results[100]
    u, y = result.records["validation_prbs"].u, result.records["validation_prbs"].y
    paper = np.array([TABLE["table2_see"]["prbs"]["model"][o]["100"] for o in TABLE["output_names"]])
    assert np.all(_model_see(result.identified.model, u, y) < paper)
    assert np.all(_model_see(result.identified.model, u, y, b_scale=1.3) > paper)


# --- 4. coverage of the nozzle joint's bootstrap intervals -------------------------------------

JOINT = (25.18, 376.53, 1.43e5)  # J, b, k: the VLS paper's Table 1, linear row
JOINT_DT = 0.008
COVERAGE_SEEDS = range(1000, 1050)


def _joint_record() -> tuple[np.ndarray, np.ndarray]:
    """The linear joint J x'' + b x' + k x = tau, zero-order hold by scipy, driven by a +-2000 N m
    random binary torque held two samples (1000 samples): the construction of
    tests/test_nozzle_identification.py's bootstrap test, written out again here."""
    j, b, k = JOINT
    a = np.array([[0.0, 1.0], [-k / j, -b / j]])
    b_in = np.array([[0.0], [1.0 / j]])
    ad, bd, cd, _, _ = scipy.signal.cont2discrete(
        (a, b_in, np.array([[1.0, 0.0]]), np.zeros((1, 1))), JOINT_DT
    )
    tau = 2000.0 * np.repeat(np.sign(np.random.default_rng(99).standard_normal(500)), 2)
    return tau, dlsim(ad, bd, cd, tau[:, None])[:, 0]


@pytest.mark.slow
def test_dsr_e_bootstrap_intervals_have_their_nominal_coverage():
    """50 noise seeds (white, 5e-5 rad), 25 bootstrap replicates each: the 95 % intervals
    est +- 1.96 se hold the truth on as many seeds as the binomial 99 % band for p = 0.95, n = 50
    allows (75-80 % coverage fails it with probability 0.8-0.95), and the z-scores' mean square
    lies in the chi-square 99 % band (the standard errors are the spread's). (The experiment
    experiments/nozzle_uncertainty_coverage.py runs the longer study.)"""
    tau, clean = _joint_record()
    z = []
    for seed in COVERAGE_SEEDS:
        y = clean + 5e-5 * np.random.default_rng(seed).standard_normal(clean.size)
        result = dsr_e(tau, y, JOINT_DT, order=2)
        boot = dsr_e_uncertainty(tau, y, JOINT_DT, result, replicates=25, seed=seed, workers=1)
        params = second_order_parameters(result.model)
        estimate = np.array([params["J"], params["b"], params["k"]])
        z.append((estimate - np.array(JOINT)) / boot.standard_errors)
    z = np.array(z)
    n = len(COVERAGE_SEEDS)
    low, high = binom.ppf(0.005, n, 0.95), binom.isf(0.005, n, 0.95)
    hits = np.sum(np.abs(z) <= 1.96, axis=0)
    assert np.all((hits >= low) & (hits <= high)), (hits, low, high)
    mean_square = np.mean(z**2, axis=0)
    band = chi2.ppf([0.005, 0.995], n) / n
    assert np.all((mean_square > band[0]) & (mean_square < band[1])), (mean_square, band)
