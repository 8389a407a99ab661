"""Table I as packaged, the alpha-canonical model type, and model.json validation."""

from __future__ import annotations

import json
import os
import re
import threading
import time

import numpy as np
import pytest

from ssme_envs.models import (
    AlphaCanonicalModel,
    AlphaStructure,
    asymmetric_gain,
    identified_model,
    published_model,
)
from ssme_envs.models.nozzle import NozzleModel, identified_nozzle
from ssme_envs.models.statespace_json import MAX_JSON_BYTES, MAX_MODEL_STATES

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


# --- model files: size, types and special files


def _wide_model(pairs: int) -> AlphaCanonicalModel:
    """An alpha-canonical model with indices (2, 1) * pairs: 3 pairs states, 2 pairs outputs,
    coupled outputs (H != I, so K is a triangular solve), small random free parameters."""
    indices = (2, 1) * pairs
    s = AlphaStructure.from_indices(indices)
    template = AlphaCanonicalModel(
        A=s.shift_matrix(),
        B=np.zeros((s.n_states, 2)),
        C=s.output_matrix(),
        dt=0.04,
        observability_indices=indices,
        lam=[1.0, 1.0],
        output_names=[f"y{k}" for k in range(s.n_outputs)],
    )
    values = np.random.default_rng(0).integers(-3, 4, template.parameter_vector().size) / 1000
    values[-2:] = 1.0
    return template.with_parameters(values)


def test_a_model_with_many_outputs_and_mixed_indices_loads_in_well_under_a_second(tmp_path):
    # 510 states, 340 outputs: the residual check took 43 s (K recomputed per entry), now 0.04 s
    model = _wide_model(170)
    assert model.n_states <= MAX_MODEL_STATES and not np.array_equal(model.H, np.eye(model.n_outputs))
    path = tmp_path / "wide.json"
    model.save(path)
    start = time.perf_counter()
    back = AlphaCanonicalModel.load(path)
    assert time.perf_counter() - start < 10.0
    np.testing.assert_array_equal(back.A, model.A)
    assert back.alpha_canonical_residual() < 1e-15
    doc = json.loads(path.read_text())
    # K[(0, 0), last output] is fixed at zero by eq 8 (index 2 > 1); H's last column is e_p
    doc["A"][model.structure.position(0, 0)][-1] += 0.5
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=r"not in alpha-canonical form .*violation of eqs 5-8: 0\.5"):
        AlphaCanonicalModel.load(path)


def test_a_model_file_with_more_states_than_the_cap_is_refused_before_building_them(tmp_path):
    doc = _doc()
    doc["A"] = [[0.0]] * (MAX_MODEL_STATES + 1)
    path = tmp_path / "huge.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(
        ValueError, match=rf"huge.json: A has {MAX_MODEL_STATES + 1} rows \(states\); .*at most"
    ):
        AlphaCanonicalModel.load(path)


ENGINE_BAD_TYPES = {
    "lambda-object": ("lambda", {"a": 1}, r"lambda must be a list of 2 finite gains"),
    "lambda-bigint": ("lambda", [1, 10**400], r"lambda must be .*: it holds an integer too large"),
    "dt-bigint": ("dt", 10**400, r"dt must be a positive number of seconds, got an integer of about 401"),
    "A-bigint": ("A", [[10**400, 0, 0, 0]] * 4, r"A must be a numeric matrix .*integer too large"),
    "version-true": ("schema_version", True, r"unsupported schema_version True"),
    "indices-bool": ("observability_indices", [True, 3], r"observability_indices must be a list of integers"),
}


@pytest.mark.parametrize(("key", "value", "message"), ENGINE_BAD_TYPES.values(), ids=ENGINE_BAD_TYPES)
def test_badly_typed_engine_values_are_value_errors_naming_file_and_key(tmp_path, key, value, message):
    doc = _doc()
    doc[key] = value
    path = tmp_path / "model.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=re.escape(f"{path}: ") + "(not an engine model: )?" + message):
        AlphaCanonicalModel.load(path)


def _nozzle_doc(section: str | None, key: str, value) -> dict:
    doc = identified_nozzle().to_dict()
    (doc if section is None else doc[section])[key] = value
    return doc


@pytest.mark.parametrize(
    ("section", "key", "value", "message"),
    [
        ("bouc_wen", "J", 10**400, r"nozzle parameter J must be a finite number, got an integer of about"),
        ("linear", "A", [[10**400]], r"linear.A must be a numeric matrix .*integer too large for a float"),
        ("linear", "dt", 10**400, r"linear.dt must be a finite number, got an integer of about 401 digits"),
        ("linear", "k", -(10**400), r"linear.k must be a finite number"),
        (None, "schema_version", True, r"unsupported schema_version True"),
    ],
    ids=["bw-J-bigint", "lin-A-bigint", "lin-dt-bigint", "lin-k-bigint", "version-true"],
)
def test_badly_typed_nozzle_values_are_value_errors_naming_file_and_key(
    tmp_path, section, key, value, message
):
    path = tmp_path / "nozzle.json"
    path.write_text(json.dumps(_nozzle_doc(section, key, value)))
    with pytest.raises(ValueError, match=re.escape(f"{path}: ") + message):
        NozzleModel.load(path)


@pytest.mark.parametrize(
    ("load", "section"),
    [(AlphaCanonicalModel.load, None), (NozzleModel.load, "linear"), (NozzleModel.load, "bouc_wen")],
    ids=["engine", "nozzle-linear", "nozzle-bouc-wen"],
)
def test_an_uncertainty_covariance_past_float_range_is_a_value_error_naming_it(tmp_path, load, section):
    doc = identified_model(100).to_dict() if section is None else identified_nozzle().to_dict()
    block = doc["uncertainty"] if section is None else doc[section]["uncertainty"]
    block["covariance"][0][0] = 10**400
    path = tmp_path / "model.json"
    path.write_text(json.dumps(doc))
    where = "uncertainty" if section is None else f"{section}.uncertainty"
    with pytest.raises(
        ValueError, match=re.escape(f"{path}: {where} holds an integer too large for a float")
    ):
        load(path)


@pytest.mark.parametrize("load", [AlphaCanonicalModel.load, NozzleModel.load], ids=["engine", "nozzle"])
@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[" * 100_000 + "]" * 100_000, "nested too deeply to read as JSON"),
        ('{"a":' * 100_000 + "1" + "}" * 100_000, "nested too deeply to read as JSON"),
        ('{"dt": 1' + "0" * 5000 + "}", r"a number in it is too long to read \(Exceeds the limit"),
    ],
    ids=["deep-lists", "deep-objects", "5001-digits"],
)
def test_unreadable_json_is_a_value_error_naming_the_file(tmp_path, load, text, message):
    path = tmp_path / "model.json"
    path.write_text(text)
    with pytest.raises(ValueError, match=re.escape(f"{path}: ") + message):
        load(path)


def _unblock_fifo_after(path, seconds: float) -> None:
    """Open ``path`` for writing after ``seconds``: a loader blocked opening it then reads end of
    file (and fails the test) instead of hanging it."""

    def run() -> None:
        time.sleep(seconds)
        try:
            os.close(os.open(path, os.O_WRONLY | os.O_NONBLOCK))
        except OSError:
            pass  # no reader waiting on it: the loader did not block

    threading.Thread(target=run, daemon=True).start()


@pytest.mark.parametrize("load", [AlphaCanonicalModel.load, NozzleModel.load], ids=["engine", "nozzle"])
def test_special_files_are_refused_naming_the_path(tmp_path, load):
    fifo = tmp_path / "x.json"
    os.mkfifo(fifo)
    _unblock_fifo_after(fifo, 5.0)
    with pytest.raises(
        ValueError, match=re.escape(f"{fifo}: not valid JSON: it is a FIFO (named pipe), not a regular file")
    ):
        load(fifo)
    link = tmp_path / "device.json"
    link.symlink_to(os.devnull)  # a device behind a link; /dev/zero would read forever
    for path in (os.devnull, link):
        with pytest.raises(ValueError, match=re.escape(f"{path}: not valid JSON: it is a character device")):
            load(path)
    directory = f"{tmp_path}: not valid JSON: it is a directory, not a regular file"
    with pytest.raises(ValueError, match=re.escape(directory)):
        load(tmp_path)
    big = tmp_path / "big.json"
    with big.open("wb") as file:
        file.truncate(MAX_JSON_BYTES + 1)  # sparse: no disk used
    with pytest.raises(ValueError, match=re.escape(f"{big}: larger than 64 MiB, too large for a model file")):
        load(big)


@pytest.mark.parametrize(
    ("load", "model", "key"),
    [
        (AlphaCanonicalModel.load, lambda: identified_model(100), "dt"),
        (AlphaCanonicalModel.load, lambda: identified_model(100), "method"),  # inside "uncertainty"
        (NozzleModel.load, identified_nozzle, "J"),  # inside "linear"
    ],
    ids=["engine-top", "engine-nested", "nozzle-nested"],
)
def test_a_key_given_twice_is_refused_naming_it(tmp_path, load, model, key):
    """JSON keeps the last of a repeated key silently, where other readers keep the first: a
    model.json with one is refused, naming the key, at any depth (the text written here by hand
    from the saved file: the key's first occurrence repeated in front of it)."""
    path = tmp_path / "model.json"
    model().save(path)
    text = path.read_text()
    start = text.index(f'"{key}":')
    value = start + len(json.dumps(key)) + 1
    value += len(text[value:]) - len(text[value:].lstrip())
    i = json.JSONDecoder().raw_decode(text, value)[1]  # the end of the key's value
    duplicate = tmp_path / "twice.json"
    duplicate.write_text(text[:start] + text[start:i] + "," + text[start:])
    with pytest.raises(ValueError, match=rf"twice\.json: key '{key}' appears twice in one object"):
        load(duplicate)
    load(path)
