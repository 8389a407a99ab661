"""Identification on records a user may bring: a PRBS with jitter or a few odd samples, structures
that do not fit the record, and model files that claim impossible structures."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
from conftest import dlsim, eq36
from hypothesis import given, settings
from hypothesis import strategies as st

from ssme_envs.identification import identify
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
