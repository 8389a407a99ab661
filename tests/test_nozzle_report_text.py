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
