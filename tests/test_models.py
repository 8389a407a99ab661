"""Table I as packaged, the alpha-canonical model type, and model.json validation."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ssme_envs.models import AlphaCanonicalModel, asymmetric_gain, published_model

# Table I of NASA TM-104422 as printed: per power level, columns 3 and 4 of A (column by
# column), then B column by column, then lambda_1 and lambda_2. Transcribed from the paper.
TABLE_I = {
    70: "-0.2553 0.5044 1.0218 -0.7902 0.0416 -0.1108 -0.113 0.5812 "
    "0.3923 1.0558 0.2584 0.5902 0.0958 -0.2652 0.0788 -0.2697 0.8957 0.8403",
    80: "-0.1576 0.2587 0.8759 -0.5157 0.0257 -0.0545 -0.0666 0.4766 "
    "0.4068 0.9631 0.2574 0.6046 0.1564 -0.674 0.0384 -0.2307 1.1211 0.9279",
    90: "-0.1206 0.1434 0.8117 -0.4183 0.0155 -0.0275 -0.0478 0.4226 "
    "0.4223 0.9217 0.2518 0.6288 0.1546 -0.7302 0.021 -0.1779 0.9386 0.7699",
    100: "-0.1279 0.1994 0.7816 -0.5253 0.0212 -0.0508 -0.0565 0.475 "
    "0.3534 0.6831 0.2007 0.5043 0.0475 -0.6446 -0.0181 -0.1387 0.8594 0.9047",
    110: "-0.084 0.1082 0.728 -0.4164 0.0026 -0.0123 0.0181 0.333 "
    "0.2416 0.5112 0.1456 0.3593 0.0786 -0.575 -0.0243 -0.078 0.9704 1.1231",
}


@pytest.mark.parametrize("power", sorted(TABLE_I))
def test_packaged_table_matches_paper(power):
    v = np.array([float(x) for x in TABLE_I[power].split()])
    model = published_model(power)
    np.testing.assert_array_equal(model.A[:, 2], v[0:4])
    np.testing.assert_array_equal(model.A[:, 3], v[4:8])
    np.testing.assert_array_equal(model.B[:, 0], v[8:12])
    np.testing.assert_array_equal(model.B[:, 1], v[12:16])
    np.testing.assert_array_equal(model.lam, v[16:18])
    np.testing.assert_array_equal(model.A[:, :2], [[0, 0], [0, 0], [1, 0], [0, 1]])


@pytest.mark.parametrize("power", sorted(TABLE_I))
def test_published_models_are_stable_alpha_canonical(power):
    model = published_model(power)
    rho = max(abs(np.linalg.eigvals(model.A)))
    assert 0.55 < rho < 0.65  # the reading notes: spectral radius 0.55 to 0.65
    np.testing.assert_array_equal(model.C, np.hstack([np.zeros((2, 2)), np.eye(2)]))
    k = model.A[:, 2:]
    a_o = model.A - k @ model.C
    assert set(np.unique(a_o)) <= {0.0, 1.0}
    np.testing.assert_array_equal(a_o @ a_o, np.zeros((4, 4)))  # nilpotent, A_o^mu = 0 with mu = 2
    assert model.observability_indices == (2, 2)
    assert model.alpha_canonical_residual() == 0.0


def test_asymmetric_gain_is_eq36():
    u = np.array([[0.01, -0.01], [-0.02, 0.0], [0.0, 0.03]])
    lam = np.array([0.8594, 0.9047])
    expected = np.array(
        [[0.8594 * 0.01, (2 - 0.9047) * -0.01], [(2 - 0.8594) * -0.02, 0.0], [0.0, 0.9047 * 0.03]]
    )
    np.testing.assert_allclose(asymmetric_gain(u, lam), expected, rtol=1e-15)


def test_markov_parameters_and_dc_gain():
    model = published_model(100)
    expected = [model.C @ np.linalg.matrix_power(model.A, k) @ model.B for k in range(6)]
    np.testing.assert_allclose(model.markov_parameters(6), expected, rtol=1e-13, atol=1e-15)
    dc = sum(model.C @ np.linalg.matrix_power(model.A, k) @ model.B for k in range(400))
    np.testing.assert_allclose(model.dc_gain(), dc, rtol=1e-10)


def test_json_round_trip(tmp_path):
    model = published_model(80)
    path = tmp_path / "model.json"
    model.save(path)
    back = AlphaCanonicalModel.load(path)
    np.testing.assert_array_equal(back.A, model.A)
    np.testing.assert_array_equal(back.B, model.B)
    np.testing.assert_array_equal(back.lam, model.lam)
    assert back.observability_indices == (2, 2)
    assert json.loads(path.read_text())["schema"] == "ssme-envs/engine-model"


def _doc():
    return published_model(100).to_dict()


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda d: d.pop("B"), "missing key"),
        (lambda d: d.update(A=[[0, 1], [1, 0]]), "B has shape"),
        (lambda d: d["A"][0].__setitem__(0, float("nan")), "A contains NaN"),
        (lambda d: d.update(observability_indices=[3, 2]), "observability_indices"),
        (lambda d: d.update({"lambda": [1.0]}), "lambda"),
        (lambda d: d.update(dt=-0.04), "dt must be"),
        (lambda d: d.update(schema="something-else"), "schema"),
        (lambda d: d.update(A="not a matrix"), "A must be"),
        (lambda d: d.update(input_names=["a"]), "input names"),
        (lambda d: d.update(fit=5), "fit must be an object"),
        (lambda d: d.update(input_names=3), "input_names must be a list of strings"),
        (lambda d: d["A"][2].__setitem__(0, 0.5), "not in alpha-canonical form"),
    ],
)
def test_malformed_model_json_names_the_problem(tmp_path, mutate, message):
    doc = _doc()
    mutate(doc)
    path = tmp_path / "model.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=message):
        AlphaCanonicalModel.load(path)


def test_not_json_and_missing_file(tmp_path):
    path = tmp_path / "model.json"
    path.write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        AlphaCanonicalModel.load(path)
    with pytest.raises(ValueError, match="no such file"):
        AlphaCanonicalModel.load(tmp_path / "absent.json")
    path.write_text("[1, 2]")
    with pytest.raises(ValueError, match="expected a JSON object"):
        AlphaCanonicalModel.load(path)


def test_unknown_power_level():
    with pytest.raises(ValueError, match="no published model at 95"):
        published_model(95)


def test_nan_model_is_not_written(tmp_path):
    model = published_model(100)
    model.fit["see"] = [float("nan")]
    with pytest.raises(ValueError):
        model.save(tmp_path / "m.json")
