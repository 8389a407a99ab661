"""The nozzle report's acquisition-bias sentence gives the bias with its sign: what the data give
(the DSR_e transfer function) minus the corrected J, b, k (it printed the correction, the opposite
sign, under the word "bias")."""

from __future__ import annotations

import json
import re
from importlib import resources

import pytest

from ssme_envs.identification.nozzle_report import bias_text


def test_the_bias_printed_is_the_estimate_minus_the_corrected_value():
    data = json.loads(
        (resources.files("ssme_envs") / "models" / "data" / "nozzle_identified.json").read_text()
    )
    tf = data["fit"]["dsr_e"]["transfer_function"]
    num, den = tf["numerator"], tf["denominator"]  # J x'' + b x' + k x = tau: (1/J) / (s^2 + b/J s + k/J)
    raw_j = den[0] / num[-1]
    raw = {"J": raw_j, "b": den[1] * raw_j, "k": den[2] * raw_j}
    text = bias_text(data["fit"]["dsr_e"]["acquisition_bias"], "fit.dsr_e.acquisition_bias")
    printed = dict(re.findall(r"(\b[Jbk]) ([+-][0-9.e+-]+)", text))
    assert set(printed) == {"J", "b", "k"}
    for name in "Jbk":
        assert float(printed[name]) == pytest.approx(raw[name] - data["linear"][name], rel=1e-3), name


def test_the_packaged_models_output_error_colour_is_the_bench_records():
    """``fit.dsr_e.output_error``'s lag-1 autocorrelation is numpy's of the bench record's angle
    minus the packaged linear model's simulation (the bench regenerated from its seed)."""
    import numpy as np

    from ssme_envs.identification.nozzle_bench import DEFAULT_SEED, bench_experiment
    from ssme_envs.models.nozzle import identified_nozzle, published_nozzle

    model = identified_nozzle()
    record = bench_experiment(published_nozzle("bouc_wen"), seed=DEFAULT_SEED)
    lin = model.linear
    x, sim = np.zeros(2), np.empty(record.tau.size)
    a, b, c = (np.asarray(lin[key]) for key in "ABC")
    for k, u in enumerate(record.tau):  # the deterministic part, stepped by hand
        sim[k] = (c @ x)[0] + lin["D"][0][0] * u
        x = a @ x + b[:, 0] * u
    v = record.beta - sim
    v = v - v.mean()
    lag1 = np.dot(v[1:], v[:-1]) / np.dot(v, v)
    colour = model.fit["dsr_e"]["output_error"]
    assert colour["lag1_autocorrelation"] == pytest.approx(lag1, abs=1e-9)
    assert colour["long_run_ratio"] > 4  # coloured: the hysteresis the linear model leaves out


@pytest.mark.parametrize(
    ("bench", "noise", "says"),
    [
        (True, "white", "The bench's sensor noise is white"),
        (False, "white", "advice"),
        (False, "innovations", "advice"),
        (False, "sieve", None),
    ],
)
def test_the_report_says_what_the_colour_means_for_the_standard_errors(bench, noise, says):
    from ssme_envs.identification.nozzle_report import _colour_sentence

    fit = {
        "output_error": {"std": 1e-3, "lag1_autocorrelation": 0.95, "sieve_order": 1, "long_run_ratio": 39.0},
        "bootstrap": {"noise": noise, "noise_std": 0.001},
        **({"acquisition_bias": {"J": 0.0, "b": 0.0, "k": 0.0}} if bench else {}),
    }
    text = _colour_sentence(fit)
    figures = "lag-1 autocorrelation 0.95, long-run variance 39 times its variance (1 for white noise), AR(1)"
    assert figures + " sieve" in text
    advice = "`--bootstrap-noise sieve` resamples it with its colour"
    for phrase in ("The bench's sensor noise is white", advice):
        assert (phrase in text) == (phrase == (advice if says == "advice" else says)), phrase
    assert _colour_sentence({"bootstrap": {"noise": "white"}}) == ""  # a model.json from before
