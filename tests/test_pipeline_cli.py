"""The pipeline's records, the packaged design models, and the `ssme-envs identify engine` command."""

from __future__ import annotations

import json
import subprocess
import sys
from importlib import resources

import numpy as np
import pytest

from ssme_envs.cli import main
from ssme_envs.identification.pipeline import (
    DEFAULT_SEED,
    EngineRecord,
    default_experiment,
    read_record,
    run_default,
    write_record,
)
from ssme_envs.models import POWER_LEVELS, AlphaCanonicalModel, identified_model


@pytest.fixture(scope="module")
def default_results():
    return run_default(seed=DEFAULT_SEED)


def test_packaged_design_models_are_what_the_pipeline_produces(default_results):
    for result in default_results:
        packaged = identified_model(result.power_percent)
        fresh = result.identified.model
        np.testing.assert_allclose(packaged.A, fresh.A, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(packaged.B, fresh.B, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(packaged.lam, fresh.lam, rtol=1e-9)
        assert packaged.observability_indices == fresh.observability_indices == (2, 2)
        assert packaged.fit["seed"] == DEFAULT_SEED
        assert packaged.uncertainty.method == fresh.uncertainty.method  # which estimate was kept
        np.testing.assert_allclose(
            packaged.fit["validation_low_frequency"]["model"]["see"],
            fresh.fit["validation_low_frequency"]["model"]["see"],
            rtol=1e-6,
        )
        # the structure search's record too: the candidates weighed, their scores and the margin
        # (BIC units: the output-error refined scores move by about 1e-3 with the BLAS thread count,
        # and by up to about 0.7 where a machine's rounding flips a stop of the refinement, whose
        # tolerance is 1e-3 of the cost; the stale records were 3-17 units off)
        kept, now = packaged.fit["structure"], fresh.fit["structure"]
        assert kept["chosen"] == list(now["chosen"]) and kept["criterion"] == now["criterion"]
        assert [(c["indices"], c["note"]) for c in kept["candidates"]] == [
            (list(c["indices"]), c["note"]) for c in now["candidates"]
        ]
        scores = [[c["criterion"] for c in record["candidates"]] for record in (kept, now)]
        np.testing.assert_allclose(*scores, rtol=0, atol=1.0)
        assert abs(kept["margin"] - now["margin"]) < 1.0


def test_design_models_are_close_to_the_truth(default_results):
    for result in default_results:
        lam_err = np.abs(result.identified.model.lam - result.published.lam)
        assert np.all(lam_err < 5e-3)
        see_model = result.validation["validation_low_frequency"]["model"]["see"]
        assert max(see_model) < 5e-3


def test_experiment_is_reproducible():
    a = default_experiment(100, seed=3)
    b = default_experiment(100, seed=3)
    c = default_experiment(100, seed=4)
    np.testing.assert_array_equal(a["identification"].y, b["identification"].y)
    assert not np.array_equal(a["identification"].y, c["identification"].y)


def test_csv_round_trip_and_column_errors(tmp_path):
    rec = default_experiment(90)["validation_prbs"]
    path = tmp_path / "rec.csv"
    write_record(path, rec)
    back = read_record(path)
    np.testing.assert_array_equal(back.u, rec.u)
    np.testing.assert_array_equal(back.y, rec.y)
    assert back.dt == pytest.approx(0.04)
    with pytest.raises(ValueError, match="unknown column"):
        read_record(path, inputs=("beta_opov", "valve_x"))


def _write(tmp_path, text):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("text", "extra", "message"),
    [
        ("t,beta_opov,beta_fpov,pc,mr\n0,1,2,3\n0.04,1,2,3,4\n", [], "line 2 has 4 fields"),
        ("t,beta_opov,beta_fpov,pc,mr\n0,1,2,3,x\n0.04,1,2,3,4\n", [], "column 'mr': 'x' is not a number"),
        ("beta_opov,beta_fpov,pc,mr\n1,2,3,4\n1,2,3,4\n", [], "no 't' column"),
        ("t,beta_opov,beta_fpov,pc,mr\n0,1,2,3,4\n0.04,1,2,3,4\n0.1,1,2,3,4\n", [], "not uniformly spaced"),
        ("t,beta_opov,beta_fpov,pc,mr\n0,1,2,3,4\n0.04,1,2,3,4\n", ["--dt", "0.1"], "disagrees"),
        ("t,a,b,c,d\n0,1,2,3,4\n0.04,1,2,3,4\n", [], "unknown column.*beta_opov"),
        ("t,beta_opov,beta_fpov,pc,mr\n0,1,2,3,nan\n0.04,1,2,3,4\n", [], "'mr' has NaN"),
    ],
)
def test_cli_bad_csv_exits_2_with_one_line(tmp_path, capsys, text, extra, message):
    path = _write(tmp_path, text)
    code = main(["identify", "engine", "--data", str(path), "--out", str(tmp_path / "o"), *extra])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith("error: ") and err.count("\n") == 1
    assert __import__("re").search(message, err), err


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["identify", "engine"], "--out"),
        (["identify", "turbopump", "--out", "x"], "invalid choice"),
        (["identify", "engine", "--out", "{out}", "--indices", "2,x"], "--indices"),
        (["identify", "engine", "--out", "{out}", "--data", "{missing}"], "no such file"),
        (["identify", "engine", "--out", "{out}", "--dt", "0.04"], "--dt needs --data"),
        (["identify", "engine", "--out", "{out}", "--rank-tol", "2"], "rank_tol"),
        (["frobnicate"], "invalid choice"),
    ],
)
def test_cli_usage_errors(tmp_path, capsys, argv, message):
    argv = [a.format(out=tmp_path / "o", missing=tmp_path / "absent.csv") for a in argv]
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith("error: ") and err.count("\n") == 1
    assert message in err


def test_cli_rank_deficient_and_constant_records(tmp_path, capsys):
    rec = default_experiment(100)["identification"]
    for name, u in (
        ("dup", np.column_stack([rec.u[:, 0], rec.u[:, 0]])),
        ("const", np.column_stack([rec.u[:, 0], np.full(rec.u.shape[0], 0.01)])),
    ):
        path = tmp_path / f"{name}.csv"
        write_record(path, EngineRecord(u, rec.y, rec.dt))
        assert main(["identify", "engine", "--data", str(path), "--out", str(tmp_path / name)]) == 2
        err = capsys.readouterr().err
        assert "linearly dependent" in err or "is constant" in err


def test_cli_identifies_a_user_record(tmp_path, capsys):
    records = default_experiment(80)
    data, check = tmp_path / "id.csv", tmp_path / "val.csv"
    # user column names, and a file without a t column
    rec = records["identification"]
    write_record(data, EngineRecord(rec.u, rec.y, rec.dt, ("opov", "fpov"), ("p_c", "mixture")))
    val = records["validation_low_frequency"]
    np.savetxt(
        check, np.column_stack([val.u, val.y]), delimiter=",", header="opov,fpov,p_c,mixture", comments=""
    )
    out = tmp_path / "out"
    code = main(
        [
            "identify",
            "engine",
            "--data",
            str(data),
            "--out",
            str(out),
            "--inputs",
            "opov,fpov",
            "--outputs",
            "p_c,mixture",
            "--validate",
            str(check),
            "--dt",
            "0.04",
        ]
    )
    assert code == 0, capsys.readouterr().err
    model = AlphaCanonicalModel.load(out / "model.json")
    assert model.input_names == ("opov", "fpov") and model.output_names == ("p_c", "mixture")
    assert model.observability_indices == (2, 2)
    assert max(model.fit["validation_record"]["model"]["see"]) < 5e-3
    report = (out / "report.md").read_text()
    for png in ("structure_search.png", "identification.png", "validation.png"):
        assert png in report and (out / png).stat().st_size > 10_000


def test_cli_default_run_writes_tables_and_figures(tmp_path, capsys):
    out = tmp_path / "default"
    assert main(["identify", "engine", "--out", str(out)]) == 0
    report = (out / "report.md").read_text()
    assert "Table I: published vs identified" in report
    assert "0.0441 / " in report  # the paper's filter SEE for Pc at 100 %, beside ours
    assert "truth we chose" in report
    for p in POWER_LEVELS:
        assert (out / f"engine_{p}_low_frequency.png").exists()
        saved = json.loads((out / f"model_{p}.json").read_text())
        packaged = json.loads(
            (resources.files("ssme_envs") / "models" / "data" / f"engine_identified_{p}.json").read_text()
        )
        np.testing.assert_allclose(saved["A"], packaged["A"], rtol=1e-9, atol=1e-12)
    assert "5 power levels" in capsys.readouterr().out


def test_console_script_reports_errors_without_traceback(tmp_path):
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "ssme_envs.cli",
            "identify",
            "engine",
            "--out",
            str(tmp_path),
            "--data",
            str(tmp_path / "none.csv"),
        ],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 2
    assert proc.stderr.strip().startswith("error: ") and "Traceback" not in proc.stderr


def test_cli_validate_scores_a_model_and_rejects_malformed_json(tmp_path, capsys):
    rec = default_experiment(110)["validation_low_frequency"]
    data = tmp_path / "lowfreq.csv"
    write_record(data, rec)
    model_path = tmp_path / "model.json"
    identified_model(110).save(model_path)
    argv = [
        "validate",
        "engine",
        "--model",
        str(model_path),
        "--data",
        str(data),
        "--out",
        str(tmp_path / "v"),
    ]
    assert main(argv) == 0
    assert "lowfreq.csv: model SEE" in capsys.readouterr().out
    assert (tmp_path / "v" / "lowfreq.png").exists()
    broken = json.loads(model_path.read_text())
    broken["B"] = broken["B"][:3]
    model_path.write_text(json.dumps(broken))
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "B has shape (3, 2)" in err and err.count("\n") == 1


def test_a_rerun_replaces_the_earlier_run_whole(tmp_path, capsys):
    """Two validations into one --out: the second's files only, no figure left from the first."""
    model_path = tmp_path / "model.json"
    identified_model(110).save(model_path)
    records = default_experiment(110)
    for name, key in (("lowfreq", "validation_low_frequency"), ("prbs", "validation_prbs")):
        write_record(tmp_path / f"{name}.csv", records[key])
    out = tmp_path / "v"
    argv = ["validate", "engine", "--model", str(model_path), "--out", str(out), "--data"]
    assert main([*argv, str(tmp_path / "lowfreq.csv"), str(tmp_path / "prbs.csv")]) == 0
    assert {"lowfreq.png", "prbs.png"} <= {p.name for p in out.iterdir()}
    assert main([*argv, str(tmp_path / "prbs.csv")]) == 0
    assert "replaced the earlier run in" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == [
        ".ssme-envs-run",
        "prbs.png",
        "report.md",
        "response_bands.png",
    ]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lowfreq.csv", "model.json", "prbs.csv", "v"]
