"""Values of user files that Python or numpy would read as numbers but are none: a JSON ``true`` is
an int to Python and 1.0 to numpy, ``"1.5"`` converts to 1.5 and ``null`` to NaN. Every model
loader refuses them with a ValueError naming the file and the key; the CLI exits 2 on one line."""

from __future__ import annotations

import json
import re
from fractions import Fraction
from importlib import resources
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ssme_envs.cli import main
from ssme_envs.envs.task import check_numbers, shown
from ssme_envs.models.linear import StateSpace, as_floats, check_dt, describe, finite_float
from ssme_envs.models.nozzle_joint import NozzleParameters
from ssme_envs.models.nozzle_model import NozzleModel
from ssme_envs.models.statespace import AlphaCanonicalModel
from ssme_envs.models.uncertainty import ParameterUncertainty

DATA = resources.files("ssme_envs") / "models" / "data"
ENGINE_FILES = [f"engine_identified_{power}.json" for power in (70, 80, 90, 100, 110)]
NOZZLE_FILES = ["nozzle_identified.json", "nozzle_strong_identified.json"]
Path_ = tuple[str | int, ...]


def _load(name: str) -> Any:
    return (NozzleModel if name.startswith("nozzle") else AlphaCanonicalModel).load


def _numeric_paths(value: Any, path: Path_ = ()) -> list[Path_]:
    """Where ``value`` holds a number (not a bool), ``fit`` (free provenance) left out."""
    if isinstance(value, dict):
        return [p for k, v in value.items() if k != "fit" for p in _numeric_paths(v, (*path, k))]
    if isinstance(value, list):
        return [p for i, v in enumerate(value) for p in _numeric_paths(v, (*path, i))]
    return [path] if isinstance(value, int | float) and not isinstance(value, bool) else []


def _set(doc: Any, path: Path_, value: Any) -> None:
    for key in path[:-1]:
        doc = doc[key]
    doc[path[-1]] = value


def _expected(path: Path_, flag: bool) -> list[str]:
    """Substrings the error for a boolean ``flag`` at ``path`` holds, besides the file's name."""
    keys = [k for k in path if isinstance(k, str)]
    indices = "".join(f"[{i}]" for i in path if isinstance(i, int))
    if keys == ["schema_version"]:  # the message of a wrong version, which names it as Python does
        return [f"unsupported schema_version {flag}"]
    if keys == ["observability_indices"]:
        return ["observability_indices must be a list of integers"]
    if keys[0] == "bouc_wen" and len(keys) == 2:  # the joint's own check names its parameter
        return [f"nozzle parameter {keys[1]} must be a finite number, got a boolean ({json.dumps(flag)})"]
    return [*keys[:-1], f"{keys[-1]}{indices}", f"a boolean ({json.dumps(flag)})"]


def _all_positions() -> list[tuple[str, Path_]]:
    out = []
    for name in (*ENGINE_FILES, *NOZZLE_FILES):
        out += [(name, path) for path in _numeric_paths(json.loads(DATA.joinpath(name).read_text()))]
    return out


POSITIONS = _all_positions()


def test_the_positions_cover_every_numeric_key_the_loaders_read():
    keys = {tuple(k for k in path if isinstance(k, str)) for _, path in POSITIONS}
    for matrix in ("A", "B", "C", "D", "K"):
        assert ("linear", matrix) in keys
    for key in ("A", "B", "C", "lambda", "dt", "observability_indices", "schema_version"):
        assert (key,) in keys
    for block in ((), ("linear",), ("bouc_wen",)):
        for key in ("covariance", "standard_errors", "samples"):
            assert (*block, "uncertainty", key) in keys
    assert {("bouc_wen", key) for key in ("J", "b", "k", "a", "A", "beta", "gamma", "n")} <= keys


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(position=st.sampled_from(POSITIONS), flag=st.booleans())
def test_a_boolean_at_any_numeric_key_of_a_packaged_model_is_refused_naming_file_and_key(
    tmp_path, position, flag
):
    name, path = position
    doc = json.loads(DATA.joinpath(name).read_text())
    _set(doc, path, flag)
    file = tmp_path / name
    file.write_text(json.dumps(doc))
    with pytest.raises(ValueError) as info:
        _load(name)(file)
    message = str(info.value)
    assert message.startswith(f"{file}: "), message
    for part in _expected(path, flag):
        assert part in message, (part, message)


@pytest.mark.parametrize("name", [ENGINE_FILES[3], NOZZLE_FILES[0]])
def test_the_packaged_models_copied_still_load(tmp_path, name):
    file = tmp_path / name
    file.write_text(DATA.joinpath(name).read_text())
    _load(name)(file)


ENGINE_CASES = {
    "A-true": (("A", 2, 0), True, "not an engine model: A[2][0] is a boolean (true), not a number"),
    "B-false": (("B", 0, 1), False, "not an engine model: B[0][1] is a boolean (false), not a number"),
    "C-true": (("C", 1, 3), True, "not an engine model: C[1][3] is a boolean (true), not a number"),
    "lambda": (("lambda", 1), True, "not an engine model: lambda[1] is a boolean (true), not a number"),
    "dt": (("dt",), True, "not an engine model: dt must be a positive number of seconds, got a boolean"),
    "cov": (("uncertainty", "covariance", 1, 1), False, "uncertainty.covariance[1][1] is a boolean (false)"),
    "se": (("uncertainty", "standard_errors", 0), True, "uncertainty.standard_errors[0] is a boolean (true)"),
    "samples": (("uncertainty", "samples"), True, "uncertainty.samples is a boolean (true), not an integer"),
    "A-text": (("A", 0, 2), "1.5", "not an engine model: A[0][2] is text ('1.5'), not a number"),
    "B-null": (("B", 1, 0), None, "not an engine model: B[1][0] is null, not a number"),
    "se-text": (
        ("uncertainty", "standard_errors", 2),
        "0.1",
        "uncertainty.standard_errors[2] is text ('0.1'), not a number",
    ),
    "se-wrong": (("uncertainty", "standard_errors", 0), 1.0, "uncertainty.standard_errors [1.0, "),
}


NOZZLE_CASES = {
    "A": (("linear", "A", 0, 1), True, "linear.A[0][1] is a boolean (true), not a number"),
    "K": (("linear", "K", 1, 0), False, "linear.K[1][0] is a boolean (false), not a number"),
    "D-text": (("linear", "D", 0, 0), "0", "linear.D[0][0] is text ('0'), not a number"),
    "dt": (("linear", "dt"), True, "linear.dt must be a finite number, got a boolean (true)"),
    "k": (("linear", "k"), False, "linear.k must be a finite number, got a boolean (false)"),
    "bw-n": (("bouc_wen", "n"), True, "nozzle parameter n must be a finite number, got a boolean (true)"),
    "cov": (
        ("bouc_wen", "uncertainty", "covariance", 0, 0),
        True,
        "bouc_wen.uncertainty: uncertainty.covariance[0][0] is a boolean (true), not a number",
    ),
    "se": (
        ("linear", "uncertainty", "standard_errors", 1),
        True,
        "linear.uncertainty.standard_errors[1] is a boolean (true), not a number",
    ),
    "samples": (
        ("linear", "uncertainty", "samples"),
        False,
        "linear.uncertainty: uncertainty.samples is a boolean (false), not an integer",
    ),
}


@pytest.mark.parametrize(
    ("name", "path", "value", "message"),
    [(ENGINE_FILES[3], *case) for case in ENGINE_CASES.values()]
    + [(NOZZLE_FILES[0], *case) for case in NOZZLE_CASES.values()],
    ids=[f"engine-{key}" for key in ENGINE_CASES] + [f"nozzle-{key}" for key in NOZZLE_CASES],
)
def test_model_values_that_are_no_numbers(tmp_path, name, path, value, message):
    doc = json.loads(DATA.joinpath(name).read_text())
    _set(doc, path, value)
    file = tmp_path / name
    file.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=re.escape(f"{file}: {message}")):
        _load(name)(file)


def test_the_cli_refuses_a_boolean_in_a_plant_file_on_one_line(tmp_path, capsys):
    doc = json.loads(DATA.joinpath(ENGINE_FILES[3]).read_text())
    doc["A"][2][0] = True  # a structural 1 of the alpha-canonical form: read as 1.0 it was accepted
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    argv = ["evaluate", "--env", "ssme_envs/EngineTracking-v0", "--plant", str(bad), "--controllers", "lqi"]
    assert main([*argv, "--scenario", "noise", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: "), err
    assert f"{bad}: not an engine model: A[2][0] is a boolean (true), not a number" in err
    assert not (tmp_path / "out").exists()


# --- the helpers -----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ([[1.0, True]], "M[0][1] is a boolean (true), not a number"),
        (np.ones((2, 2), dtype=bool), "M[0][0] is a boolean (true), not a number"),
        ([np.array([1.0, 2.0]), [np.bool_(False), 1.0]], "M[1][0] is a boolean (false), not a number"),
        (np.array([[1.0, None]], dtype=object), "M[0][1] is null, not a number"),
        (np.array(["2.5"]), "M[0] is text ('2.5'), not a number"),
        (True, "M is a boolean (true), not a number"),
    ],
)
def test_as_floats_names_the_entry_that_is_no_number(value, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        as_floats(value, "M", "a matrix")


def test_as_floats_keeps_numbers_of_every_kind():
    got = as_floats([[1, 2.5], [np.float32(3), np.int64(4)]], "M", "a matrix")
    np.testing.assert_array_equal(got, [[1.0, 2.5], [3.0, 4.0]])
    assert as_floats(np.eye(2), "M", "a matrix").dtype == float


def test_scalars_and_the_classes_refuse_booleans():
    with pytest.raises(ValueError, match=re.escape("x must be a finite number, got a boolean (false)")):
        finite_float(np.bool_(False), "x")
    with pytest.raises(ValueError, match=re.escape("dt must be a positive number of seconds, got a boolean")):
        check_dt(True)
    with pytest.raises(ValueError, match=re.escape("A[0][0] is a boolean (true)")):
        StateSpace(A=[[True]], B=[[1.0]], C=[[1.0]], dt=0.1)
    with pytest.raises(ValueError, match=re.escape("uncertainty.covariance[0][0] is a boolean (true)")):
        ParameterUncertainty(("J",), [[True]])
    with pytest.raises(ValueError, match=re.escape("parameter J must be a finite number, got a boolean")):
        NozzleParameters(J=True, b=1.0, k=1.0)


def test_shown_is_describe_and_shows_long_integers_by_their_size_wherever_they_sit():
    assert shown is describe
    assert describe(10**400) == "an integer of about 401 digits"
    assert describe([1, -(10**5000)]) == "[1, an integer of about 5001 digits]"
    assert describe(10**19) == str(10**19)
    # reprlib.repr of an int past 4300 digits raised Python's own ValueError in place of the message
    with pytest.raises(ValueError, match=r"w must be one number or 2, got \[1, 2, an integer of about"):
        check_numbers("w", [1, 2, 10**5000], 2, 0.0, 1.0)


# Keys a loader does not know were dropped without a word: an engine file's "D" (the alpha-
# canonical engine has no feedthrough) made a model without it; a misspelt key lost its value.
@pytest.mark.parametrize(
    ("name", "where", "key", "message"),
    [
        ("engine_identified_100.json", (), "D", r"unknown key\(s\) 'D' .*no feedthrough D"),
        ("engine_identified_70.json", (), "lamda", r"unknown key\(s\) 'lamda'"),
        ("nozzle_identified.json", (), "bouc-wen", r"unknown key\(s\) 'bouc-wen'"),
        ("nozzle_identified.json", ("linear",), "j", r"linear: unknown key\(s\) 'j'"),
    ],
)
def test_an_unknown_key_is_refused_naming_it(tmp_path, name, where, key, message):
    doc = json.loads(DATA.joinpath(name).read_text())
    block = doc
    for step in where:
        block = block[step]
    block[key] = [[1.0, 0.0], [0.0, 1.0]]
    path = tmp_path / name
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=re.escape(str(path)) + ": " + message):
        _load(name)(path)


@settings(deadline=None, max_examples=30, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(lam=st.floats(-5.0, 5.0, allow_nan=False), index=st.integers(0, 1))
def test_lambda_outside_zero_two_is_refused(tmp_path, lam, index):
    """u* = u + (lambda - 1)|u| gives lambda u above the operating point and (2 - lambda) u below:
    a lambda outside (0, 2) flips one side's gain, which no valve does."""
    doc = json.loads(DATA.joinpath("engine_identified_100.json").read_text())
    doc["lambda"][index] = lam
    path = tmp_path / "lam.json"
    path.write_text(json.dumps(doc))
    exact = Fraction(lam)  # eq 36 in exact arithmetic at u = -1 and +1: each side's gain
    if all((u + (exact - 1) * abs(u)) / u > 0 for u in (-1, 1)):
        assert AlphaCanonicalModel.load(path).lam[index] == lam
    else:
        with pytest.raises(ValueError, match=r"lambda must lie in \(0, 2\)"):
            AlphaCanonicalModel.load(path)


def test_negative_sample_count_is_refused(tmp_path):
    doc = json.loads(DATA.joinpath("engine_identified_90.json").read_text())
    doc["uncertainty"]["samples"] = -3
    path = tmp_path / "samples.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=r"uncertainty.samples must be >= 0, got -3"):
        AlphaCanonicalModel.load(path)


@pytest.mark.parametrize(
    "call",
    [
        lambda big: __import__("gymnasium").make("ssme_envs/EngineTracking-v0", power=big),
        lambda big: __import__("gymnasium").make("ssme_envs/NozzleTVC-v0", substeps=big),
        lambda big: __import__("gymnasium").make("ssme_envs/NozzleTVC-v0", plant_spread=big),
        lambda big: __import__("ssme_envs.metrics").metrics.limit_cycle(np.zeros(64), np.ones(64, bool), big),
    ],
)
def test_an_integer_of_thousands_of_digits_is_named_by_its_size(call):
    """Python refuses str() of an int past 4300 digits with a ValueError of its own; the messages
    name such a value by its size instead."""
    with pytest.raises(ValueError, match=r"an integer of about 5001 digits"):
        call(10**5000)


def test_an_unknown_key_in_an_uncertainty_block_is_refused(tmp_path):
    doc = json.loads(DATA.joinpath("engine_identified_80.json").read_text())
    doc["uncertainty"]["standard_error"] = [1.0]  # misspelt: it would have been dropped
    path = tmp_path / "u.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=r"uncertainty: unknown key\(s\) 'standard_error'"):
        AlphaCanonicalModel.load(path)


@pytest.mark.parametrize(
    ("name", "key"), [("engine_identified_100.json", "dt"), ("nozzle_identified.json", "J")]
)
def test_null_at_a_number_key_is_named_null(tmp_path, name, key):
    doc = json.loads(DATA.joinpath(name).read_text())
    (doc if name.startswith("engine") else doc["linear"])[key] = None
    path = tmp_path / name
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=rf"{key} must be a (finite|positive) number.*, got null$"):
        _load(name)(path)
