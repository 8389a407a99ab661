"""Bouc-Wen fit and the nozzle pipeline: recovery, identifiability verdicts, the CLI, bad input."""

from __future__ import annotations

import json
import re
import warnings

import numpy as np
import pytest
import scipy.signal
from conftest import dlsim

from ssme_envs.cli import main
from ssme_envs.identification import nozzle_pipeline
from ssme_envs.identification.bouc_wen import NORMALIZED_NAMES, fit_bouc_wen
from ssme_envs.identification.nozzle_pipeline import (
    NozzleRecord,
    _finite_or_none,
    acquire,
    acquisition_bias,
    bench_experiment,
    bench_motion,
    identify_nozzle,
    read_nozzle_record,
    run_default,
    simulate_joint,
    strong_hysteresis_nozzle,
    validate_nozzle,
    validation_experiment,
    write_nozzle_record,
)
from ssme_envs.identification.nozzle_report import write_nozzle_report
from ssme_envs.identification.nozzle_uncertainty import dsr_e_uncertainty, regression_covariance
from ssme_envs.identification.subspace import dsr_e, second_order_parameters
from ssme_envs.models.nozzle import (
    IDENTIFIED_FILES,
    MAX_SUBSTEPS,
    NozzleModel,
    NozzleParameters,
    identified_nozzle,
    published_nozzle,
    recommended_substeps,
    simulate_nozzle,
)
from ssme_envs.signals import prbs


@pytest.fixture(scope="module")
def strong():
    truth = strong_hysteresis_nozzle()
    record = bench_experiment(truth, samples=2500)
    return truth, record, identify_nozzle(record)


def test_bench_experiment_matches_the_paper_setup():
    record = bench_experiment(published_nozzle(), samples=600)
    assert record.dt == 0.008 and record.tau.size == 600
    assert np.degrees(np.max(np.abs(record.beta))) == pytest.approx(3.0, rel=0.02)
    again = bench_experiment(published_nozzle(), samples=600)
    np.testing.assert_array_equal(record.beta, again.beta)
    other = bench_experiment(published_nozzle(), samples=600, seed=99)
    assert not np.array_equal(record.beta, other.beta)


def test_strong_hysteresis_is_recovered_and_predicts_unseen_data(strong):
    truth, _, ident = strong
    bw = ident.bouc_wen
    assert bw.determined, bw.reason
    assert bw.params.J == pytest.approx(truth.J, rel=0.05)
    norm = truth.normalized()
    for name in ("k_el", "k_hys", "n"):
        assert bw.normalized[name] == pytest.approx(norm[name], rel=0.05), name
    unseen = validation_experiment(truth, seed=123)
    figures = validate_nozzle(ident.model, unseen)
    assert figures["joint_fit_percent"] >= 95.0
    assert figures["joint_fit_percent"] > figures["dsr_e_fit_percent"] + 20  # the linear model cannot


def test_linear_range_record_leaves_hysteresis_undetermined(tmp_path):
    record = bench_experiment(published_nozzle(), samples=2000, range_deg=0.02)
    ident = identify_nozzle(record)
    assert not ident.bouc_wen.determined
    assert ident.bouc_wen.params is None and ident.model.bouc_wen is None
    assert "not determined by the data" in ident.bouc_wen.reason
    # the linear joint it falls back on still describes the record as well as the Bouc-Wen fit
    assert ident.bouc_wen.linear_fit_percent >= ident.bouc_wen.fit_percent - 0.5
    # the shape parameters the record hardly determines carry large standard errors (not the
    # round-off a pseudo-inverse gave them), no covariance is stored, and the report has no table
    for name in ("beta_n", "gamma_n", "n"):
        assert ident.bouc_wen.relative_std[name] > 0.5, name
    assert ident.model.bouc_wen_uncertainty is None and ident.model.linear_uncertainty is not None
    ident.model.save(tmp_path / "model.json")
    saved = json.loads((tmp_path / "model.json").read_text())
    assert saved["bouc_wen"] is None and "uncertainty" in saved["linear"]
    write_nozzle_report(tmp_path, ident, {"identification": record})
    report = (tmp_path / "report.md").read_text()
    assert "| parameter | value" not in report
    assert (
        "No Bouc-Wen parameters are reported: the hysteresis parameters are not determined by the data"
        in report
    )


def test_fit_is_reproducible_for_any_worker_count():
    truth = strong_hysteresis_nozzle()
    tau = prbs(800, amplitude=2000.0, n_inputs=1, n_bits=9, clock_samples=2)[:, 0]
    x = simulate_nozzle(truth, tau, substeps=16) + 1e-5 * np.random.default_rng(1).standard_normal(tau.size)
    one = fit_bouc_wen(tau, x, 0.008, seed=5, workers=1, maxiter=4)
    two = fit_bouc_wen(tau, x, 0.008, seed=5, workers=2, maxiter=4)
    assert one.normalized == two.normalized


@pytest.mark.parametrize(
    ("tau", "x", "message"),
    [
        (np.r_[np.nan, np.ones(299)], np.ones(300), "input 'torque' has NaN or inf at sample 0"),
        (np.ones(300), np.ones(299), "inputs have 300 samples but outputs have 299"),
        (np.r_[0.0, np.ones(99)], np.linspace(0, 1, 100), "needs at least 200"),
        (np.full(300, 5.0), np.linspace(0, 1, 300), "input 'torque' is constant"),
        (np.r_[np.zeros(150), np.ones(150)], np.linspace(0, 1, 300), "torque changes only 1 times"),
    ],
)
def test_bad_records(tau, x, message):
    with pytest.raises(ValueError, match=message):
        fit_bouc_wen(tau, x, 0.008, workers=1)


def test_cli_identifies_a_user_csv(tmp_path, capsys, strong):
    truth, record, _ = strong
    data, check = tmp_path / "bench.csv", tmp_path / "check.csv"
    write_nozzle_record(data, NozzleRecord(record.tau, record.beta, record.dt, "torque_Nm", "angle_rad"))
    unseen = validation_experiment(truth)
    write_nozzle_record(check, NozzleRecord(unseen.tau, unseen.beta, unseen.dt, "torque_Nm", "angle_rad"))
    out = tmp_path / "out"
    code = main(
        [
            "identify",
            "nozzle",
            "--data",
            str(data),
            "--validate",
            str(check),
            "--out",
            str(out),
            "--input",
            "torque_Nm",
            "--output",
            "angle_rad",
        ]
    )
    assert code == 0, capsys.readouterr().err
    model = NozzleModel.load(out / "model.json")
    assert model.input_name == "torque_Nm" and model.bouc_wen is not None
    assert model.fit["validation_record"]["joint_fit_percent"] >= 95.0
    report = (out / "report.md").read_text()
    for png in (
        "frequency_response.png",
        "hysteresis.png",
        "prediction_identification.png",
        "prediction_validation.png",
    ):
        assert png in report and (out / png).stat().st_size > 10_000


def _record_rows(tau_scale: float = 1.0, beta_scale: float = 1.0, spike: float | None = None) -> str:
    """A valid 400-sample record (square-wave torque, angle from rest), scaled; ``spike``: the angle
    at sample 5."""
    beta = 1e-4 * np.sin(np.arange(400) / 10) * beta_scale
    if spike is not None:
        beta[5] = spike
    return "t,tau,beta\n" + "".join(
        f"{0.008 * i!r},{1000.0 * tau_scale * (-1) ** (i // 3)!r},{float(beta[i])!r}\n" for i in range(400)
    )


@pytest.mark.parametrize(
    ("content", "extra", "message"),
    [
        ("t,tau,beta\n0,1,0\n0.008,2,x\n", [], "column 'beta': 'x' is not a number"),
        ("t,torque,beta\n0,1,0\n0.008,2,1\n", [], "unknown column"),
        (
            "t,tau,beta\n" + "".join(f"{0.008 * i},{1.0},{0.001 * i}\n" for i in range(300)),
            [],
            "input 'tau' is constant",
        ),
        (
            "t,tau,beta\n" + "".join(f"{0.008 * i},{(-1) ** i},{0.001 * i}\n" for i in range(30)),
            [],
            "samples",
        ),
        ("t,tau,beta\n0,nan,0\n0.008,1,1\n", [], "NaN"),
        pytest.param(
            _record_rows(1e155, 1e155),
            [],
            "input 'tau' reaches 1e+158: its squares overflow float64",
            id="values-scaled-by-1e155",
        ),
        ("t,tau,beta\n0,1,0\n0.008,2,1\n", ["--normalization-a", "0"], "--normalization-a"),
        ("t,tau,beta\n0,1,0\n0.008,2,1\n", ["--workers", "0"], "--workers"),
    ],
)
def test_cli_bad_input_exits_2_with_one_line(tmp_path, capsys, content, extra, message):
    path = tmp_path / "bad.csv"
    path.write_text(content)
    code = main(["identify", "nozzle", "--data", str(path), "--out", str(tmp_path / "o"), *extra])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("error: ") and err.count("\n") == 1
    assert message in err, err


def test_bad_validation_record_is_refused_before_the_fit(tmp_path, capsys):
    rows = "".join(f"{0.008 * i},{1000.0 * (-1) ** (i // 3)},{1e-4 * np.sin(i / 10)}\n" for i in range(400))
    data, check = tmp_path / "data.csv", tmp_path / "check.csv"
    data.write_text("t,tau,beta\n" + rows)
    check.write_text("t,tau,beta\n" + rows.replace(",1000.0,", ",nan,", 1))
    code = main(
        ["identify", "nozzle", "--data", str(data), "--validate", str(check), "--out", str(tmp_path / "o")]
    )
    err = capsys.readouterr().err
    assert code == 2 and err.startswith(f"error: {check}: ") and "NaN" in err


def test_validation_needs_the_model_sample_time():
    model = identified_nozzle()
    tau = 3000.0 * (-1.0) ** (np.arange(400) // 5)
    record = NozzleRecord(tau, 1e-5 * np.arange(tau.size), 0.01, "tau", "beta")
    with pytest.raises(ValueError, match=r"sample time 0\.01 s differs from the model's 0\.008 s"):
        validate_nozzle(model, record)


@pytest.mark.slow
def test_cli_default_bench_reproduces_the_packaged_model(tmp_path, capsys):
    out = tmp_path / "nozzle"
    assert main(["identify", "nozzle", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "hysteresis determined" in printed
    made = json.loads((out / "model.json").read_text())
    from importlib import resources

    packaged = json.loads(
        (resources.files("ssme_envs") / "models" / "data" / "nozzle_identified.json").read_text()
    )
    # a regression pin: the packaged model must be what this default run produces (it was made by
    # it); the independent checks against the paper's Table 1 follow
    for key, value in packaged["bouc_wen"].items():
        if key != "uncertainty":
            assert made["bouc_wen"][key] == pytest.approx(value, rel=1e-6), key
    for block in ("linear", "bouc_wen"):
        np.testing.assert_allclose(
            made[block]["uncertainty"]["standard_errors"],
            packaged[block]["uncertainty"]["standard_errors"],
            rtol=1e-6,
        )
    for key in ("J", "b", "k"):
        assert made["linear"][key] == pytest.approx(packaged["linear"][key], rel=1e-9), key
    np.testing.assert_allclose(made["linear"]["A"], packaged["linear"]["A"], rtol=1e-9)
    # the paper's Table 1 nozzle: J within 1 %, small-signal stiffness within 1 %
    truth = published_nozzle("bouc_wen")
    assert made["bouc_wen"]["J"] == pytest.approx(truth.J, rel=0.01)
    k, a, big_a = made["bouc_wen"]["k"], made["bouc_wen"]["a"], made["bouc_wen"]["A"]
    assert a * k + (1 - a) * k * big_a == pytest.approx(truth.small_signal_stiffness, rel=0.01)
    report = (out / "report.md").read_text()
    assert "paper, linear row (Table 1) | 25.18 | 376.53" in report
    assert (out / "data" / "nozzle_identification.csv").exists()


def test_angle_offset_is_refused():
    record = bench_experiment(published_nozzle(), samples=600)
    with pytest.raises(ValueError, match="not at rest at zero"):
        fit_bouc_wen(record.tau, record.beta + 0.01, 0.008, workers=1)


# --- records with absurd values: angles past a quarter turn, values whose squares overflow --------


@pytest.mark.parametrize(
    ("tau_scale", "beta_scale", "spike", "message"),
    [
        (1.0, 1.0, 1e5, r"output 'beta' reaches 1e\+05 at sample 5, beyond \+-1\.571 rad \(90 deg\)"),
        (1.0, 1.0, -2.0, r"output 'beta' reaches -2 at sample 5, beyond"),
        (1.0, 1e6, None, r"output 'beta' reaches 9\.983 at sample 1, beyond"),  # beta in microrad
        (1e155, 1e155, None, r"input 'tau' reaches 1e\+158: its squares overflow float64"),
        (1.0, 1e160, None, r"output 'beta' reaches 1e\+156: its squares overflow float64"),
    ],
)
def test_read_nozzle_record_refuses_absurd_values_naming_the_column(
    tmp_path, tau_scale, beta_scale, spike, message
):
    path = tmp_path / "rec.csv"
    path.write_text(_record_rows(tau_scale, beta_scale, spike))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # refused before any arithmetic that would overflow
        with pytest.raises(ValueError, match=rf"^{re.escape(str(path))}: {message}"):
            read_nozzle_record(path)


def test_read_nozzle_record_keeps_angles_within_a_quarter_turn(tmp_path):
    path = tmp_path / "rec.csv"
    path.write_text(_record_rows(beta_scale=1.5e4))  # up to 1.5 rad
    record = read_nozzle_record(path)
    assert np.max(np.abs(record.beta)) == pytest.approx(1.5, rel=1e-3)


def test_cli_refuses_an_angle_spike_in_the_validation_record_before_the_fit(tmp_path, capsys, monkeypatch):
    """The spike (1e5 rad) once sent the validation's joint simulation into 9e5 RK4 substeps a
    sample, after the whole fit: it never ended."""

    def fit(*args, **kwargs):
        raise AssertionError("the fit ran")

    monkeypatch.setattr(nozzle_pipeline, "identify_nozzle", fit)
    data, check = tmp_path / "data.csv", tmp_path / "check.csv"
    data.write_text(_record_rows())
    check.write_text(_record_rows(spike=1e5))
    code = main(
        ["identify", "nozzle", "--data", str(data), "--validate", str(check), "--out", str(tmp_path / "o")]
    )
    err = capsys.readouterr().err
    assert (
        code == 2 and err.startswith(f"error: {check}: output 'beta' reaches 1e+05") and err.count("\n") == 1
    )
    assert not (tmp_path / "o").exists()


def test_simulate_joint_refuses_more_rk4_substeps_than_the_cap():
    joint = published_nozzle("bouc_wen")
    beta = np.zeros(20)
    beta[5] = 3e3  # rad: the joint's hysteresis rate grows with the amplitude
    record = NozzleRecord(1000.0 * (-1.0) ** np.arange(20), beta, 0.008)
    assert recommended_substeps(joint, 0.008, 3e3) > MAX_SUBSTEPS
    with pytest.raises(
        ValueError, match=r"up to 3000 rad needs \d+ RK4 substeps per 0\.008 s sample, more than 10000"
    ):
        simulate_joint(joint, record)
    record.beta[5] = 0.05
    assert np.all(np.isfinite(simulate_joint(joint, record)))


# --- uncertainty: J, b, k by the residual bootstrap, the Bouc-Wen regression covariance, model.json


def _zoh_joint(J: float, b: float, k: float, dt: float):
    """The linear joint J x'' + b x' + k x = tau sampled with a zero-order hold, by scipy."""
    a = np.array([[0.0, 1.0], [-k / J, -b / J]])
    b_in = np.array([[0.0], [1.0 / J]])
    ad, bd, cd, _, _ = scipy.signal.cont2discrete((a, b_in, np.array([[1.0, 0.0]]), np.zeros((1, 1))), dt)
    return ad, bd, cd


LINEAR_TRUTH = (25.18, 376.53, 1.43e5)  # Table 1, linear row
_TAU = 2000.0 * np.repeat(np.sign(np.random.default_rng(99).standard_normal(500)), 2)  # 1000 samples
_CLEAN = dlsim(*_zoh_joint(*LINEAR_TRUTH, 0.008), _TAU[:, None])[:, 0]


def _noisy_joint(seed: int) -> np.ndarray:
    return _CLEAN + 5e-5 * np.random.default_rng(seed).standard_normal(_CLEAN.size)


def _jbk(result) -> np.ndarray:
    params = second_order_parameters(result.model)
    return np.array([params["J"], params["b"], params["k"]])


@pytest.fixture(scope="module")
def bootstrap_runs():
    """20 noise seeds with bootstrap standard errors; 100 more seeds for the spread alone."""
    est, se = [], []
    for seed in range(20):
        y = _noisy_joint(seed)
        result = dsr_e(_TAU, y, 0.008, order=2)
        boot = dsr_e_uncertainty(_TAU, y, 0.008, result, replicates=25, seed=seed, workers=1)
        est.append(_jbk(result))
        se.append(boot.standard_errors)
    spread = np.array([_jbk(dsr_e(_TAU, _noisy_joint(s), 0.008, order=2)) for s in range(100, 200)])
    return np.array(est), np.array(se), np.vstack([est, spread]).std(axis=0, ddof=1)


def test_dsr_e_standard_errors_match_the_spread_over_noise_seeds(bootstrap_runs):
    _, se, spread = bootstrap_runs
    ratio = se.mean(axis=0) / spread
    assert np.all((ratio > 0.7) & (ratio < 1.4)), ratio


def test_dsr_e_intervals_cover_the_truth(bootstrap_runs):
    est, se, _ = bootstrap_runs
    hits = np.sum(np.abs(est - np.array(LINEAR_TRUTH)) <= 1.96 * se, axis=0)
    assert np.all(hits >= 15), hits  # of 20; 95 % expected


def test_bootstrap_is_reproducible_for_any_worker_count():
    y = _noisy_joint(3)
    result = dsr_e(_TAU, y, 0.008, order=2)
    runs = {w: dsr_e_uncertainty(_TAU, y, 0.008, result, replicates=10, seed=4, workers=w) for w in (2, 3)}
    np.testing.assert_array_equal(runs[2].replicates, runs[3].replicates)
    here = dsr_e_uncertainty(_TAU, y, 0.008, result, replicates=10, seed=4, workers=1)
    again = dsr_e_uncertainty(_TAU, y, 0.008, result, replicates=10, seed=4, workers=1)
    np.testing.assert_array_equal(here.covariance, again.covariance)
    # one BLAS thread in the workers, the caller's here: the same draws, round-off apart
    np.testing.assert_allclose(here.replicates, runs[2].replicates, rtol=1e-6)
    other = dsr_e_uncertainty(_TAU, y, 0.008, result, replicates=10, seed=5, workers=1)
    assert not np.allclose(other.replicates, here.replicates, rtol=1e-9)
    assert here.parameter_uncertainty().parameters == ("J", "b", "k")
    np.testing.assert_allclose(here.standard_errors, here.replicates.std(axis=0, ddof=1))


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"replicates": 5}, "replicates must be an integer >= 10"),
        ({"workers": 0}, "workers must be an integer >= 1"),
        ({"noise": "pink"}, "noise must be one of white, innovations"),
        ({"dt": 0.01}, r"sample time 0\.008 s differs from dt = 0\.01 s"),
        ({"order": 3}, "a second-order model is needed"),
        ({"y": np.r_[np.nan, np.zeros(999)]}, "y has NaN"),
    ],
)
def test_bootstrap_bad_arguments(change, message):
    y = _noisy_joint(1)
    result = dsr_e(_TAU, y, 0.008, order=change.pop("order", 2))
    kwargs = {"u": _TAU, "y": y, "dt": 0.008, "result": result, **change}
    with pytest.raises(ValueError, match=message):
        dsr_e_uncertainty(**kwargs)


def test_regression_covariance_against_the_normal_equations():
    rng = np.random.default_rng(0)
    x = rng.standard_normal((200, 3)) * [1.0, 1e3, 1e-3]
    np.testing.assert_allclose(regression_covariance(x, 2.5), 2.5 * np.linalg.inv(x.T @ x), rtol=1e-9)
    # a parameter the residuals do not depend on, and two that only act together: infinite
    # variance, not the zero a pseudo-inverse gives; the determined one keeps its own
    loose = np.column_stack([x[:, 0], np.zeros(200), x[:, 1], 2.0 * x[:, 1]])
    cov = regression_covariance(loose, 2.5)
    assert np.isinf(cov[1, 1]) and np.isinf(cov[2, 2]) and np.isinf(cov[3, 3])
    kept = x[:, :2]  # the regression on what the data determine: x0 and the combination along x1
    assert cov[0, 0] == pytest.approx(2.5 * np.linalg.inv(kept.T @ kept)[0, 0], rel=1e-9)


def test_identification_carries_standard_errors_into_model_json_and_report(tmp_path, strong):
    _, record, ident = strong
    model = ident.model
    assert model.linear_uncertainty.parameters == ("J", "b", "k")
    assert np.all(np.isfinite(model.linear_uncertainty.standard_errors))
    assert np.all(model.linear_uncertainty.standard_errors > 0)
    bw = ident.bouc_wen
    assert model.bouc_wen_uncertainty.parameters == NORMALIZED_NAMES
    np.testing.assert_allclose(
        model.bouc_wen_uncertainty.standard_errors, [bw.standard_errors[n] for n in NORMALIZED_NAMES]
    )
    path = tmp_path / "model.json"
    model.save(path)
    doc = json.loads(path.read_text())
    assert doc["schema_version"] == 2
    assert doc["linear"]["uncertainty"]["parameters"] == ["J", "b", "k"]
    assert doc["bouc_wen"]["uncertainty"]["parameters"] == list(NORMALIZED_NAMES)
    back = NozzleModel.load(path)
    np.testing.assert_array_equal(back.linear_uncertainty.covariance, model.linear_uncertainty.covariance)
    np.testing.assert_array_equal(back.bouc_wen_uncertainty.covariance, model.bouc_wen_uncertainty.covariance)
    assert back.bouc_wen == model.bouc_wen and back.linear["J"] == model.linear["J"]
    write_nozzle_report(tmp_path, ident, {"identification": record})
    report = (tmp_path / "report.md").read_text()
    se = model.linear_uncertainty.standard_errors
    assert f"| standard error (bootstrap) | {se[0]:.2g} | {se[1]:.2g} | {se[2]:.2g} |" in report
    assert "| parameter | value | standard error | relative |" in report
    assert f"| k_hys | {bw.normalized['k_hys']:.6g} | {bw.standard_errors['k_hys']:.2g} |" in report


def test_undetermined_standard_errors_are_written_as_null():
    assert _finite_or_none({"n": np.inf, "J": 0.5}) == {"n": None, "J": 0.5}


def test_version_1_model_without_uncertainty_still_loads(tmp_path):
    doc = identified_nozzle().to_dict()
    doc["schema_version"] = 1  # a version-1 file: no uncertainty blocks
    doc["linear"].pop("uncertainty")
    doc["bouc_wen"].pop("uncertainty")
    path = tmp_path / "m.json"
    path.write_text(json.dumps(doc))
    model = NozzleModel.load(path)
    assert model.linear_uncertainty is None and model.bouc_wen_uncertainty is None


def _with_uncertainty() -> dict:
    doc = identified_nozzle().to_dict()
    cov = np.diag([1e-6, 1e-3, 10.0])
    doc["linear"]["uncertainty"] = {
        "parameters": ["J", "b", "k"],
        "covariance": cov.tolist(),
        "standard_errors": np.sqrt(np.diag(cov)).tolist(),
        "method": "test",
        "samples": 7476,
    }
    cov7 = np.diag(np.arange(1.0, 8.0))
    doc["bouc_wen"]["uncertainty"] = {"parameters": list(NORMALIZED_NAMES), "covariance": cov7.tolist()}
    return doc


def test_uncertainty_blocks_round_trip(tmp_path):
    path = tmp_path / "m.json"
    path.write_text(json.dumps(_with_uncertainty()))
    model = NozzleModel.load(path)
    np.testing.assert_allclose(model.linear_uncertainty.standard_errors, np.sqrt([1e-6, 1e-3, 10.0]))
    assert model.bouc_wen_uncertainty.covariance[6, 6] == 7.0
    model.save(path)
    assert NozzleModel.load(path).to_dict() == model.to_dict()


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda d: d["linear"]["uncertainty"].pop("covariance"), "linear.uncertainty: uncertainty lacks"),
        (
            lambda d: d["linear"].update(uncertainty=[1, 2]),
            "linear.uncertainty: uncertainty must be an object",
        ),
        (lambda d: d["linear"]["uncertainty"].update(parameters=["J", "b", "zeta"]), "lacks: zeta"),
        (lambda d: d["linear"]["uncertainty"].update(covariance=[[1.0, 0.0], [0.0, 1.0]]), "has shape"),
        (lambda d: d["linear"]["uncertainty"]["covariance"][0].__setitem__(1, 0.5), "not symmetric"),
        (lambda d: d["linear"]["uncertainty"].update(standard_errors=[1.0, 2.0, 3.0]), "disagree"),
        (lambda d: d["linear"]["uncertainty"].update(standard_errors="small"), "list of numbers"),
        (lambda d: d["bouc_wen"]["uncertainty"]["parameters"].__setitem__(2, "k"), "lacks: k"),
        (lambda d: d["bouc_wen"]["uncertainty"].update(covariance=(-np.eye(7)).tolist()), "positive semi"),
        (lambda d: d.update(schema_version=3), "unsupported schema_version 3"),
    ],
)
def test_malformed_uncertainty_block(tmp_path, mutate, message):
    doc = _with_uncertainty()
    mutate(doc)
    path = tmp_path / "m.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=message) as err:
        NozzleModel.load(path)
    assert str(err.value).startswith(f"{path}: ")


@pytest.mark.parametrize("which", ["linear", "strong"])
def test_the_acquisition_bias_correction_recovers_the_joint(which):
    # A noise-free bench record of a linear joint: DSR_e's J, b, k carry the anti-alias filter's
    # bias (tens of noise standard errors); minus the bias simulated at the estimate they are the
    # joint's own to a small fraction of a noise standard error (under 1e-6 relative).
    # (the second joint: the strong-hysteresis nozzle's J, b, k, a faster and less damped mode)
    strong = strong_hysteresis_nozzle()
    truth = (
        published_nozzle("linear")
        if which == "linear"
        else NozzleParameters.linear(strong.J, strong.b, strong.k)
    )
    tau, angle = bench_motion(truth)
    tf = second_order_parameters(dsr_e(tau, acquire(angle, noise_std=0.0), 0.008, order=2).model)
    est = np.array([tf["J"], tf["b"], tf["k"]])
    want = np.array([truth.J, truth.b, truth.k])
    assert np.max(np.abs(est / want - 1)) > 3e-4  # the bias is there
    bias = acquisition_bias(tau, tuple(est))
    corrected = est - np.array([bias["J"], bias["b"], bias["k"]])
    np.testing.assert_allclose(corrected, want, rtol=2e-6)


def _assert_same_json(made, packaged, where="model"):
    """Equal JSON documents, numbers to 1e-6 relative (the fit's last bits may differ between
    CPUs, as in the pin of the default bench's model above)."""
    if isinstance(packaged, dict):
        assert set(made) == set(packaged), where
        for key, value in packaged.items():
            _assert_same_json(made[key], value, f"{where}.{key}")
    elif isinstance(packaged, list):
        assert len(made) == len(packaged), where
        for i, (a, b) in enumerate(zip(made, packaged, strict=True)):
            _assert_same_json(a, b, f"{where}[{i}]")
    elif isinstance(packaged, float) and not isinstance(made, bool):
        assert made == pytest.approx(packaged, rel=1e-6, abs=1e-300), where
    else:
        assert made == packaged, where


@pytest.mark.slow
def test_the_strong_nozzle_design_model_is_what_its_pipeline_produces(tmp_path):
    """experiments/make_design_models.py's run for the strong nozzle (the default bench test of
    the "strong" truth) reproduces the packaged nozzle_strong_identified.json."""
    from importlib import resources

    model = run_default(truth="strong")[0].model
    model.save(tmp_path / "model.json")
    made = json.loads((tmp_path / "model.json").read_text())
    packaged = json.loads(
        (resources.files("ssme_envs") / "models" / "data" / IDENTIFIED_FILES["strong"]).read_text()
    )
    _assert_same_json(made, packaged)


@pytest.mark.slow
@pytest.mark.parametrize("scale", [1e-300, 1e140])
def test_cli_identifies_a_record_in_extreme_torque_units_quietly(tmp_path, capsys, strong, scale):
    """The strong joint's bench record with the torque in units of 1/scale N m: exit 0, nothing on
    stderr, the frequency-response figure written (it went through scipy's transfer-function
    coefficients, which overflowed at 1e-300, a LinAlgError, and gave BadCoefficients and divide
    warnings at 1e140), and J, b, k in the new units: the unscaled fit's times scale, to 1e-6."""
    _, record, ident = strong
    data = tmp_path / "scaled.csv"
    write_nozzle_record(data, NozzleRecord(record.tau * scale, record.beta, record.dt, "tau", "beta"))
    out = tmp_path / "out"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code = main(["identify", "nozzle", "--data", str(data), "--out", str(out)])
    captured = capsys.readouterr()
    assert code == 0 and captured.err == "", captured.err
    assert not caught, [str(w.message) for w in caught]
    # work that grows with the record says its stages (a 200,000-sample record ran past two
    # minutes behind one line): the bootstrap with its expected time, then the joint fit
    assert re.search(r"^DSR_e: [\d.e+-]+ s; the standard errors of J, b, k: 100 bootstrap records "
                     r"\(up to about [\d.e+-]+ s\)$", captured.out, re.M)  # fmt: skip
    assert re.search(r"^the Bouc-Wen joint: evolutionary search, then least squares on all 2500 samples$",
                     captured.out, re.M)  # fmt: skip
    assert (out / "frequency_response.png").stat().st_size > 10_000
    linear = NozzleModel.load(out / "model.json").linear
    for name in ("J", "b", "k"):
        assert linear[name] == pytest.approx(ident.model.linear[name] * scale, rel=1e-6), name


@pytest.mark.parametrize("scale", [1e-13, 1e-300])
def test_an_angle_that_barely_moves_is_refused_by_name(strong, scale):
    """The strong joint's record with its angle times 1e-13 or 1e-300 (largest |angle| below a
    picoradian): no nozzle motion; at 1e-300 the joint fit's filtered derivatives underflowed (a
    divide-by-zero warning, then 'does not show a mass-spring response')."""
    _, record, _ = strong
    with pytest.raises(
        ValueError, match=r"^angle moves by at most [\d.e+-]+ rad, below 1e-12 rad: .* in rad\?$"
    ):
        fit_bouc_wen(record.tau, record.beta * scale, record.dt, workers=1)
