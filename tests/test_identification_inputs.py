"""Identification on records a user may bring: a PRBS with jitter or a few odd samples, structures
that do not fit the record, and model files that claim impossible structures."""

from __future__ import annotations

import functools
import json
import math
import re
import warnings

import numpy as np
import pytest
from conftest import dlsim, eq36, markov, random_system
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from ssme_envs.identification import identify
from ssme_envs.identification.covariance import markov_standard_errors
from ssme_envs.models import AlphaCanonicalModel, published_model
from ssme_envs.models.statespace_json import engine_model_from_dict, engine_model_to_dict
from ssme_envs.signals import prbs


def _record(jitter: float, changed: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Table I's 100 % model (scipy's simulation, eq 36 on the input) driven by a +-0.01 PRBS
    whose magnitude jitters by up to ``jitter`` of it, with ``changed`` samples shrunk."""
    rng = np.random.default_rng(seed)
    u = prbs(1016, amplitude=0.01) * (1.0 + jitter * rng.uniform(-1.0, 1.0, (1016, 2)))
    rows = rng.choice(1016, changed, replace=False)
    u[rows, rng.integers(0, 2, changed)] *= rng.uniform(0.0, 1.0, changed)
    truth = published_model(100)
    return u, dlsim(truth.A, truth.B, truth.C, eq36(u, truth.lam))


@settings(max_examples=15, deadline=None)
@given(
    jitter=st.one_of(st.just(0.0), st.floats(1e-6, 0.3)),
    changed=st.integers(0, 20),
    seed=st.integers(0, 2**16),
)
def test_lambda_survives_jitter_and_odd_samples_on_a_prbs(jitter, changed, seed):
    # A 1e-6 jitter or one sample at 0.009 on a +-0.01 PRBS used to fit lambda from |u| lags
    # collinear with the intercept: lambda 7.4 or 19.5 for Table I's 0.86.
    u, y = _record(jitter, changed, seed)
    result = identify(u, y, 0.04, indices=(2, 2))
    np.testing.assert_allclose(result.model.lam, published_model(100).lam, rtol=0.02)


@pytest.mark.parametrize(("jitter", "changed"), [(1e-6, 0), (0.0, 1), (0.02, 5)])
def test_the_structure_search_too(jitter, changed):
    u, y = _record(jitter, changed, seed=3)
    # sensor noise as the truth's (1e-4): on exact data BIC rewards any extra state for the last
    # digits a jitter leaves unexplained
    y = y + np.random.default_rng(4).normal(0.0, 1e-4, y.shape)
    result = identify(u, y, 0.04)
    assert result.model.observability_indices == (2, 2)
    np.testing.assert_allclose(result.model.lam, published_model(100).lam, rtol=0.02)


def test_a_noisy_two_level_input_of_unequal_magnitude_is_refused():
    u, y = _record(0.0, 0, seed=1)
    u[:, 1] += 0.002 + np.random.default_rng(0).normal(0.0, 1e-5, 1016)
    with pytest.raises(ValueError, match="input 'u1' switches between two levels of different magnitude"):
        identify(u, y, 0.04, indices=(2, 2))


@settings(max_examples=10, deadline=None)
@given(offset=st.floats(0.01, 1.0), column=st.integers(0, 1), sign=st.sampled_from([-1.0, 1.0]))
def test_an_input_that_never_changes_sign_is_refused_as_such(offset, column, sign):
    """A valve given as a position rather than a deviation (the PRBS shifted by at least its
    amplitude, up or down): lambda acts about the operating point, so the record is refused
    naming the input and the remedies (it used to be called "two levels of different magnitude",
    and so was a ramp such as the t column). Without the asymmetric gains the same record of a
    symmetric plant identifies, the offset going to the intercept: Table I's 100 % Markov
    parameters (lambda = 1, scipy's simulation of the deviations) to 1e-6."""
    u, _ = _record(0.0, 0, seed=2)
    truth = published_model(100)
    y = dlsim(truth.A, truth.B, truth.C, u)
    shifted = u.copy()
    shifted[:, column] += sign * offset
    with pytest.raises(ValueError, match=rf"^input 'u{column}' never changes sign .* \(--symmetric\)$"):
        identify(shifted, y, 0.04, indices=(2, 2))
    model = identify(shifted, y, 0.04, indices=(2, 2), asymmetric=False, uncertainty=False).model
    np.testing.assert_allclose(model.markov_parameters(8), truth.markov_parameters(8), atol=1e-6)


def test_an_output_offset_that_drives_lambda_out_of_range_is_refused_by_name():
    """Outputs not given as deviations from the operating point: with a two-level input lambda
    is read from the outputs' means (eq 42), and an offset of 0.05 on Table I's 100 % record
    (scipy's simulation) gave lambda 4.4, written to a model.json its own loader refuses."""
    u, y = _record(0.0, 0, seed=2)
    with pytest.raises(
        ValueError, match=r"^input 'u0': the identified lambda is 4\.\d+, outside \(0, 2\).*offset"
    ):
        identify(u, y + 0.05, 0.04)


def test_a_lambda_out_of_range_on_an_unstable_plants_record_is_not_blamed_on_an_offset():
    """An open-loop record of an unstable plant (pole 1.05, a PRBS on both inputs, 1 % noise):
    lambda came out -2.9, and the refusal named an output offset as the likely cause; the
    outputs' means drift with the unstable mode, and the message now says that."""
    rng = np.random.default_rng(14)
    pole = rng.uniform(1.005, 1.06)
    u = prbs(500, amplitude=0.01)
    a, b = np.diag([pole, rng.uniform(0.3, 0.9)]), rng.normal(size=(2, 2))
    y = dlsim(a, b, np.eye(2), u)
    y = y + 0.01 * y.std(axis=0) * rng.standard_normal(y.shape)
    with pytest.raises(
        ValueError, match=r"lambda is .*, outside \(0, 2\).*the identified model is unstable"
    ) as info:
        identify(u, y, 0.04)
    assert "offset" not in str(info.value)


@settings(max_examples=10, deadline=None)
@given(offset=hnp.arrays(np.float64, 2, elements=st.floats(-0.002, 0.002)))
def test_an_output_offset_moves_lambda_as_the_steady_state_gain_says(offset):
    """With a two-level input of amplitude gamma, u* = u + (lambda - 1) gamma: an output offset c
    reads as the constant input G(1)^-1 c, G(1) = C (I - A)^-1 B the truth's steady-state gain
    (numpy's solve), so lambda moves by G(1)^-1 c / gamma (README: 0.001 on both outputs takes
    lambda_OPOV from 0.86 to 0.93)."""
    truth = published_model(100)
    u, y = _record(0.0, 0, seed=5)
    gain = truth.C @ np.linalg.solve(np.eye(truth.n_states) - truth.A, truth.B)
    expected = truth.lam + np.linalg.solve(gain, offset) / 0.01
    model = identify(u, y + offset, 0.04, indices=(2, 2), uncertainty=False).model
    np.testing.assert_allclose(model.lam, expected, atol=1e-6)


@settings(max_examples=12, deadline=None)
@given(offset=st.floats(-0.05, 0.05), method=st.sampled_from(["iv", "ls", "oe"]))
def test_an_identified_model_is_one_its_loader_takes(offset, method):
    """Whatever offset the outputs carry, identify refuses by name or returns a model that
    model.json round-trips (lambda in (0, 2))."""
    u, y = _record(0.0, 0, seed=5)
    y = y + offset + np.random.default_rng(6).normal(0.0, 1e-4, y.shape)
    try:
        model = identify(u, y, 0.04, indices=(2, 2), method=method).model
    except ValueError as exc:
        assert re.match(r"input 'u\d': the identified lambda is .*, outside \(0, 2\)", str(exc)), exc
        return
    back = engine_model_from_dict(AlphaCanonicalModel, json.loads(json.dumps(engine_model_to_dict(model))))
    np.testing.assert_array_equal(back.lam, model.lam)


@pytest.mark.parametrize("indices", [(9_999_999, 1), (200, 200), (2,), (2, 2, 2), (0, 2), (2.0, 2)])
def test_indices_that_the_record_cannot_fit_are_refused(indices):
    u, y = _record(0.0, 0, seed=2)
    with pytest.raises(ValueError, match=r"observability indices|the record has"):
        identify(u, y, 0.04, indices=indices)


def test_a_model_file_claiming_a_billion_states_is_refused_before_building_them():
    data = engine_model_to_dict(published_model(100))
    data = json.loads(json.dumps(data))
    data.pop("uncertainty", None)
    data["observability_indices"] = [1_000_000_000, 2]
    with pytest.raises(
        ValueError, match=r"observability_indices \[1000000000, 2\] need 2 outputs and 1000000002"
    ):
        engine_model_from_dict(AlphaCanonicalModel, data, "model.json")


@pytest.mark.parametrize("normalization", [1e20, 1e30])
def test_a_normalization_that_rounds_the_hysteresis_away_is_refused(normalization):
    from ssme_envs.identification.bouc_wen import _table1_form
    from ssme_envs.models.nozzle import published_nozzle

    normalized = published_nozzle("bouc_wen").normalized()
    assert _table1_form(normalized, 0.35).normalized() == pytest.approx(normalized, rel=1e-12)
    with pytest.raises(ValueError, match=re.escape(f"normalization A = {normalization:g} cannot hold")):
        _table1_form(normalized, normalization)


def test_a_model_file_with_a_non_finite_figure_names_where_it_is():
    from ssme_envs.models.statespace import dumps_compact

    with pytest.raises(ValueError, match=r"^fit\.dsr_e\.resonance_frequency_hz holds NaN or inf"):
        dumps_compact({"A": [[1.0]], "fit": {"dsr_e": {"resonance_frequency_hz": math.inf}}})
    with pytest.raises(ValueError, match=r"^A holds NaN or inf"):
        dumps_compact({"A": [[1.0, math.nan]]})
    assert json.loads(dumps_compact({"A": [[1.0, 2.5]], "fit": {"n": [1, {"k": 2}]}})) == {
        "A": [[1.0, 2.5]],
        "fit": {"n": [1, {"k": 2}]},
    }


@pytest.mark.parametrize("scale", [1e154, 1e200, 1e300])
@pytest.mark.parametrize("method", ["identify", "dsr_e"])
def test_values_whose_squares_overflow_are_refused_by_name(scale, method):
    """A library call (not only a record file) with an output whose squares overflow float64 is
    refused naming the channel, instead of turning into inf or NaN inside the regression."""
    from ssme_envs.identification.subspace import dsr_e

    u = prbs(300, 0.01)
    y = np.cumsum(u, axis=0)
    y[7, 1] = scale
    call = (lambda: identify(u, y, 0.04)) if method == "identify" else (lambda: dsr_e(u, y, 0.04))
    with pytest.raises(ValueError, match=r"output '[^']+' reaches .*: its squares overflow float64"):
        call()


# ---- identify's arguments, checked before any work (ssme_envs.identification.arguments) ----


@functools.cache
def _clean() -> tuple[np.ndarray, np.ndarray]:
    u, y = _record(0.0, 0, seed=2)
    u.flags.writeable = y.flags.writeable = False  # shared by the tests below
    return u, y


@pytest.fixture
def no_work(monkeypatch):
    """Makes any work past the argument checks fail loudly: an argument refused must be refused
    before the record is even read."""

    def refuse(*args, **kwargs):
        raise AssertionError("the record was read before the arguments were checked")

    monkeypatch.setattr("ssme_envs.identification.alpha_canonical.check_record", refuse)


def _refused(error: type[Exception], pattern: str, *args, **kwargs) -> str:
    """Calls identify, checks it raises ``error`` whose message matches ``pattern`` from its
    start, and returns the message."""
    with pytest.raises(error, match=pattern) as info:
        identify(*args, **kwargs)
    # the wrong kind of thing is a TypeError, and a ValueError for the callers that catch those
    assert isinstance(info.value, ValueError)
    return str(info.value)


@pytest.mark.parametrize(
    ("which", "pattern"),
    [
        ("u", r"^u needs at least one input column, got shape \(1016, 0\)"),
        ("y", r"^y needs at least one output column, got shape \(1016, 0\)"),
    ],
)
@pytest.mark.parametrize("indices", [None, (2, 2)])
def test_a_record_without_columns_is_refused_by_name(which, pattern, indices, no_work):
    # used to divide by zero in the structure search's instrument depth
    u, y = _clean()
    u, y = (u[:, :0], y) if which == "u" else (u, y[:, :0])
    _refused(ValueError, pattern, u, y, 0.04, indices=indices)


@settings(max_examples=25, deadline=None)
@given(samples=st.integers(0, 85), seed=st.integers(0, 2**16))
def test_a_record_too_short_for_the_search_is_refused_before_its_values_are_read(samples, seed):
    # an empty record used to fail in numpy's reduction ("zero-size array to reduction operation")
    rng = np.random.default_rng(seed)
    u, y = rng.normal(size=(samples, 2)), rng.normal(size=(samples, 2))
    _refused(ValueError, rf"^the record has {samples} samples; a structure search", u, y, 0.04)


@pytest.mark.parametrize("samples", [0, 1, 2])
def test_a_record_too_short_for_the_indices_is_refused_before_its_values_are_read(samples, no_work):
    u, y = np.zeros((samples, 2)), np.zeros((samples, 2))
    _refused(
        ValueError,
        rf"^the record has {samples} samples, observability indices \[2, 2\]",
        u,
        y,
        0.04,
        indices=(2, 2),
    )


# np.zeros of dtype object holds ints, numbers: objects that are not are the parametrized test's
_NOT_REAL = st.one_of(
    hnp.complex_number_dtypes(),
    hnp.boolean_dtypes(),
    hnp.unicode_string_dtypes(),
    hnp.byte_string_dtypes(),
    hnp.datetime64_dtypes(),
    hnp.timedelta64_dtypes(),
)


@settings(max_examples=30, deadline=None)
@given(dtype=_NOT_REAL, which=st.sampled_from(["u", "y"]))
def test_a_record_of_anything_but_real_numbers_is_refused_by_name(dtype, which):
    # a complex record used to lose its imaginary part with a mere ComplexWarning
    u, y = _clean()
    bad = np.zeros(u.shape, dtype=dtype)
    args = (bad, y) if which == "u" else (u, bad)
    _refused(TypeError, rf"^{which} must be real numbers .*, got {re.escape(str(dtype))}$", *args, 0.04)


@pytest.mark.parametrize(
    ("change", "shown"),
    [
        (lambda u: u + 1j * u, "complex128"),
        (lambda u: u > 0, "bool"),
        (lambda u: u.astype(str), "<U"),
        (lambda u: [[True, 0.5]] * len(u), "a list holding bools"),
        (lambda u: [[None, 0.5]] * len(u), "list of dtype object"),
        (lambda u: [["0.01", 0.5]] * len(u), "list of dtype <U"),
        (lambda u: None, "NoneType of dtype object"),
    ],
)
def test_the_envs_words_for_a_record_that_is_not_numbers(change, shown, no_work):
    u, y = _clean()
    _refused(
        TypeError,
        rf"^u must be real numbers \(an int or float array .*\), got {re.escape(shown)}",
        change(u),
        y,
        0.04,
    )


@settings(max_examples=15, deadline=None)
@given(data=st.data(), which=st.sampled_from(["u", "y"]))
def test_a_masked_record_is_refused_not_unmasked(data, which):
    u, y = _clean()
    mask = data.draw(hnp.arrays(bool, u.shape).filter(np.any))
    args = (np.ma.masked_array(u, mask=mask), y) if which == "u" else (u, np.ma.masked_array(y, mask=mask))
    _refused(ValueError, rf"^{which} has {int(mask.sum())} masked values? of 2032", *args, 0.04)


@pytest.mark.parametrize("name", ["asymmetric", "uncertainty"])
@pytest.mark.parametrize("value", ["no", "false", "", 0, 1, 1.0, None, [True], np.array([True])])
def test_a_flag_must_be_a_bool(name, value, no_work):
    # "no" and "false" used to be taken as true
    u, y = _clean()
    _refused(
        TypeError, rf"^{name} must be True or False, got {type(value).__name__} ", u, y, 0.04, **{name: value}
    )


@pytest.mark.parametrize("name", ["input_names", "output_names"])
@pytest.mark.parametrize(
    ("value", "error"),
    [
        ("ab", TypeError),  # used to name the channels 'a' and 'b'
        (b"ab", TypeError),
        ({"a", "b"}, TypeError),
        ({"a": 0, "b": 1}, TypeError),
        ((1, 2), TypeError),
        (("a", None), TypeError),
        ("a", TypeError),
        (("a",), ValueError),
        (("a", "b", "c"), ValueError),
        (("a", "a"), ValueError),
    ],
)
def test_channel_names_must_be_distinct_strings_one_per_column(name, value, error, no_work):
    u, y = _clean()
    column = "u" if name == "input_names" else "y"
    _refused(
        error,
        rf"^{name} must be 2 distinct str, one per column of {column}, got",
        u,
        y,
        0.04,
        **{name: value},
    )


@pytest.mark.parametrize(
    ("name", "value", "error", "pattern"),
    [
        ("max_index", 2.5, TypeError, "must be a positive integer"),
        ("max_index", "3", TypeError, "must be a positive integer"),
        ("max_index", True, TypeError, "must be a positive integer"),
        ("max_index", None, TypeError, "must be a positive integer"),
        ("max_index", 0, ValueError, "must be >= 1, got 0"),
        ("max_index", -3, ValueError, "must be >= 1, got -3"),
        ("rank_tol", "x", TypeError, r"must be in \(0, 1\), a finite real number, got str 'x'"),
        ("rank_tol", True, TypeError, r"must be in \(0, 1\)"),
        ("rank_tol", 0.1 + 0j, TypeError, r"must be in \(0, 1\)"),
        ("rank_tol", math.nan, ValueError, r"must be in \(0, 1\), a finite real number, got nan"),
        ("rank_tol", 1, ValueError, r"must be in \(0, 1\)"),
        ("rank_tol", 0.0, ValueError, r"must be in \(0, 1\)"),
        ("indices", 2, TypeError, "must be 2 observability indices"),
        ("indices", "22", TypeError, "must be 2 observability indices"),
        ("indices", {2, 3}, TypeError, "must be 2 observability indices"),
        ("indices", np.array([[2, 2]]), TypeError, "must be 2 observability indices"),
        ("indices", (True, 2), TypeError, "must be positive integers"),
        ("indices", ("2", 2), TypeError, "must be positive integers"),
        ("indices", (2,), ValueError, ": 1 observability indices given for 2 outputs"),
        ("indices", (0, 2), ValueError, "must be positive integers"),
        ("method", "IV", ValueError, "must be one of 'iv', 'ls', 'oe', got 'IV'"),
        ("method", ["iv"], ValueError, r"must be one of 'iv', 'ls', 'oe', got \['iv'\]"),
        ("method", None, ValueError, "must be one of 'iv', 'ls', 'oe', got None"),
        ("dt", "0.04", ValueError, "must be a positive number of seconds, got '0.04'"),
        ("dt", True, ValueError, "must be a positive number of seconds"),
    ],
)
def test_each_option_is_refused_by_name(name, value, error, pattern, no_work):
    # max_index=2.5, rank_tol="x" and indices=2 used to fail deep inside with Python's words
    u, y = _clean()
    options = {"dt": 0.04, name: value}
    _refused(error, rf"^{name}{'' if pattern.startswith(':') else ' '}{pattern}", u, y, **options)


@settings(max_examples=30, deadline=None)
@given(value=st.one_of(st.floats(), st.text(max_size=3), st.booleans(), st.none(), st.complex_numbers()))
def test_max_index_takes_integers_only(value):
    u, y = _clean()
    _refused(TypeError, r"^max_index must be a positive integer", u, y, 0.04, max_index=value)


@settings(max_examples=30, deadline=None)
@given(value=st.floats().filter(lambda v: not 0 < v < 1) | st.integers())
def test_rank_tol_outside_zero_one_is_refused(value):
    u, y = _clean()
    _refused(ValueError, r"^rank_tol must be in \(0, 1\)", u, y, 0.04, rank_tol=value)


def test_integer_lists_and_unmasked_records_give_the_float_arrays_model():
    """Integers are read as floats: an integer record, as an array or as lists, and a masked
    array without a masked value, give the float record's model to the last bit."""
    truth = published_model(100)
    u = np.rint(prbs(600, amplitude=1.0)).astype(np.int64)
    y = np.rint(1e4 * dlsim(truth.A, truth.B, truth.C, eq36(u.astype(float), truth.lam))).astype(np.int32)
    y = y + np.random.default_rng(0).integers(-3, 4, y.shape, dtype=np.int32)
    options = {"indices": np.array([2, 2]), "max_index": np.int64(4), "asymmetric": np.bool_(True)}
    reference = identify(u.astype(float), y.astype(float), 0.04, **options).model
    for args in ((u, y), (u.tolist(), y.tolist()), (np.ma.masked_array(u, mask=False), y)):
        model = identify(*args, 0.04, **options).model
        for field in ("A", "B", "C", "lam"):
            np.testing.assert_array_equal(getattr(model, field), getattr(reference, field))
        assert model.observability_indices == (2, 2)


@settings(max_examples=15, deadline=None)
@given(
    input_scale=st.sampled_from([1e-30, 1e-10, 1e-4, 1.0, 1e4, 1e12]),
    output_scale=st.sampled_from([1e-30, 1e-10, 1.0, 1e8, 1e12]),
    seed=st.integers(0, 2**32 - 1),
)
def test_a_record_in_other_units_gives_the_same_model_in_those_units(input_scale, output_scale, seed):
    """The inputs' rank test compared the lagged inputs with the ones column, and the regression's
    rank lstsq's cut on its largest column: a good record in small or large units was refused as
    "not persistently exciting" or "rank-deficient". The scaled record's Markov parameters, in the
    first record's units, are the first's."""
    rng = np.random.default_rng(seed)
    a, b, c = random_system(2, 2, 2, rng)
    u = rng.standard_normal((500, 2))
    y = dlsim(a, b, c, u) + 0.01 * rng.standard_normal((500, 2))
    base = identify(u, y, 0.1, asymmetric=False, indices=[1, 1]).model
    scaled = identify(u * input_scale, y * output_scale, 0.1, asymmetric=False, indices=[1, 1]).model
    first = markov(base.A, base.B, base.C, 6)
    again = markov(scaled.A, scaled.B, scaled.C, 6) * input_scale / output_scale
    assert np.max(np.abs(again - first)) <= 1e-9 * np.max(np.abs(first))


@pytest.mark.parametrize("output_scale", [1e-140, 1e-30, 1e-3, 1e3, 1e30, 1e140])
@pytest.mark.parametrize("method", ["iv", "oe"])
def test_standard_errors_follow_the_units_to_the_edge_of_float64(output_scale, method):
    """The Markov parameters' standard errors from a record with its outputs in other units are,
    in the first record's units, the first record's. Before: "iv" dropped the negative part of
    its sandwich on raw columns (K's standard errors 7 times larger in units of 1e-3), and
    overflowed near 1e100 (LinAlgError from eigh; such outputs have finite squares, so they are
    accepted); "oe" cut the rank of its information on raw columns (B's or K's variance 0 in
    units of 1e-30 or 1e30)."""
    rng = np.random.default_rng(4)
    a, b, c = random_system(2, 2, 2, rng)
    u = rng.standard_normal((500, 2))
    y = dlsim(a, b, c, u) + 0.01 * rng.standard_normal((500, 2))
    base = identify(u, y, 0.1, asymmetric=False, indices=[1, 1], method=method).model
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scaled = identify(u, y * output_scale, 0.1, asymmetric=False, indices=[1, 1], method=method).model
    _, first = markov_standard_errors(base, 6)
    _, again = markov_standard_errors(scaled, 6)
    np.testing.assert_allclose(again / output_scale, first, rtol=1e-6)
