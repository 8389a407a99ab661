"""What the nozzle's linear model leaves of a record: a well-damped joint, an angle offset, a
hum and coloured noise, through ``ssme-envs identify nozzle --data`` and the library checks.

The records are a second-order joint ``J x'' + b x' + k x = tau`` sampled by scipy's ZOH
(``cont2discrete``) under a seeded +-3000 N m PRBS, written with numpy.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.signal
from hypothesis import given, settings
from hypothesis import strategies as st

from ssme_envs.cli import main
from ssme_envs.identification.nozzle_residuals import offset_shortfall, output_error_colour

DT, J, K = 0.008, 25.18, 1.43e5
ONE_WORKER = ("--workers", "1")


def _joint(zeta=0.1, samples=1000, extra=None, seed=0):
    """Torque and angle of the joint with damping ratio ``zeta``, white sensor noise at 2 % of the
    angle's spread, and ``extra`` (rad, (samples,)) added to the angle; and its b."""
    b = 2 * zeta * np.sqrt(K * J)
    a_c = np.array([[0.0, 1.0], [-K / J, -b / J]])
    system = scipy.signal.cont2discrete((a_c, np.array([[0.0], [1 / J]]), np.eye(1, 2), np.zeros((1, 1))), DT)
    rng = np.random.default_rng(seed)
    tau = rng.choice([-3000.0, 3000.0], size=samples)
    tau[0] = 0.0
    clean = scipy.signal.dlsim(system, tau[:, None])[1][:, 0]
    beta = clean + 0.02 * clean.std() * rng.standard_normal(samples)
    beta += 0.0 if extra is None else extra
    return tau, beta, b


def _record(path, zeta=0.1, samples=1000, extra=None, seed=0):
    """:func:`_joint`'s record as a CSV file; (path, b)."""
    tau, beta, b = _joint(zeta, samples, extra, seed)
    table = np.column_stack([np.arange(samples) * DT, tau, beta])
    np.savetxt(path, table, delimiter=",", header="t,tau,beta", comments="", fmt="%.17g")
    return path, b


def test_a_joint_damped_past_the_resonance_is_identified_without_one(tmp_path, capsys):
    """Damping ratio 0.8: the magnitude has no peak. The run succeeds (it failed writing NaN
    into model.json), J, b, k are the joint's, and the resonance is null and said to be none."""
    path, b = _record(tmp_path / "damped.csv", zeta=0.8)
    assert main(["identify", "nozzle", "--data", str(path), "--out", str(tmp_path / "out"), *ONE_WORKER]) == 0
    model = json.loads((tmp_path / "out" / "model.json").read_text())
    assert model["linear"]["J"] == pytest.approx(J, rel=0.01)
    assert model["linear"]["b"] == pytest.approx(b, rel=0.01)
    assert model["fit"]["dsr_e"]["resonance_frequency_hz"] is None
    assert "no resonance peak" in (tmp_path / "out" / "report.md").read_text()


def test_an_angle_offset_gets_a_note_naming_it(tmp_path, capsys):
    """The angle measured from 0.01 rad (after its first sample, which the at-rest check reads):
    J and k came out 5 % off with standard errors 300 times smaller than that, and nothing said
    so. (A note, not a refusal: a record cut mid-motion shows a mean too.)"""
    offset = np.full(1000, 0.01)
    offset[0] = 0.0
    path, _ = _record(tmp_path / "offset.csv", extra=offset)
    assert main(["identify", "nozzle", "--data", str(path), "--out", str(tmp_path / "out"), *ONE_WORKER]) == 0
    notes = [line for line in capsys.readouterr().out.splitlines() if "has a mean of" in line]
    assert len(notes) == 1 and notes[0].startswith("note: the linear model's output error has a mean of +")
    assert float(notes[0].split("mean of ")[1].split(" rad")[0]) == pytest.approx(0.01, rel=0.05)
    assert "offset" in notes[0] and "has a mean of" in (tmp_path / "out" / "report.md").read_text()


def test_a_hum_in_the_angle_gets_the_note(tmp_path, capsys):
    """A 3 Hz hum of 2e-3 rad (the sensor noise's std is 5e-4 rad): the white bootstrap's
    errors would cover the sensor noise only, and the CLI says so; with the sieve it does not."""
    t = np.arange(1000) * DT
    path, _ = _record(tmp_path / "hum.csv", extra=2e-3 * np.sin(2 * np.pi * 3.0 * t))
    args = ["identify", "nozzle", "--data", str(path), "--workers", "1"]
    assert main([*args, "--out", str(tmp_path / "white")]) == 0
    assert "note: the linear model's output error is coloured" in capsys.readouterr().out
    assert main([*args, "--out", str(tmp_path / "sieve"), "--bootstrap-noise", "sieve"]) == 0
    assert "note: the linear model's output error" not in capsys.readouterr().out
    model = json.loads((tmp_path / "sieve" / "model.json").read_text())
    assert model["fit"]["dsr_e"]["bootstrap"]["noise"] == "sieve"


@settings(max_examples=15, deadline=None)
@given(a=st.floats(0.0, 0.95), seed=st.integers(0, 2**32 - 1))
def test_coloured_noise_is_not_taken_for_an_offset(a, seed):
    """The output error of DSR_e's model on a 4000-sample record with AR(1) sensor noise up to
    0.95 (as it comes, not centred): its mean stays inside its spread, and no note; the same
    record measured from an offset of three noise spreads gets one."""
    from ssme_envs.identification import dsr_e

    rng = np.random.default_rng(seed)
    noise = scipy.signal.lfilter([1.0], [1.0, -a], rng.standard_normal(4000))
    noise *= 5e-4 / noise.std()
    for shift, noted in ((0.0, False), (1.5e-3, True)):
        extra = noise + shift
        extra[0] = 0.0  # at rest at zero at the first sample, as the CLI asks
        tau, beta, _ = _joint(samples=4000, extra=extra, seed=seed % 1000)
        model = dsr_e(tau, beta, DT, order=2).model
        error = output_error_colour(beta - model.simulate(tau[:, None])[:, 0])
        assert (offset_shortfall({"output_error": error}) is not None) == noted, (shift, error["mean"])


def _arrays(tmp_path):
    path, _ = _record(tmp_path / "r.csv")
    table = np.loadtxt(path, delimiter=",", skiprows=1)
    return table[:, 1], table[:, 2]


@pytest.mark.parametrize(
    ("change", "error", "match"),
    [
        ({"u": "complex"}, TypeError, "u must be real numbers"),
        ({"u": "bool"}, TypeError, "u must be real numbers"),
        ({"result": None}, TypeError, "result must be the SubspaceResult of dsr_e"),
        ({"y": "swapped"}, ValueError, "worse than its mean"),
        ({"y": "constant"}, ValueError, "y is constant"),
        ({"seed": -1}, ValueError, "seed must be an integer >= 0"),
        ({"seed": 1.5}, ValueError, "seed must be an integer >= 0"),
        ({"seed": True}, ValueError, "seed must be an integer >= 0"),
        ({"seed": None}, ValueError, "seed must be an integer >= 0"),
    ],
)
def test_the_bootstrap_refuses_what_is_not_its_record(tmp_path, change, error, match):
    """Each of these gave standard errors before (a swapped record: J +- 3e-7; an unseeded run:
    another result each time) or numpy's message."""
    from ssme_envs.identification import dsr_e
    from ssme_envs.identification.nozzle_uncertainty import dsr_e_uncertainty

    u, y = _arrays(tmp_path)
    args = {"u": u, "y": y, "dt": DT, "result": dsr_e(u, y, DT, order=2), "replicates": 10, "seed": 0}
    values = {"complex": u + 1j * u, "bool": u > 0, "swapped": u, "constant": np.zeros_like(y)}
    for key, value in change.items():
        args[key] = values.get(value, value) if isinstance(value, str) else value
    with pytest.raises(error, match=match):
        dsr_e_uncertainty(**args)


@pytest.mark.parametrize(
    ("option", "match"),
    [
        ({"seed": 2**32}, r"seed must be at most 2\*\*32 - 1"),
        ({"seed": "7"}, "seed must be an integer"),
        ({"workers": "1"}, "workers must be an integer >= 1"),
        ({"normalization_A": float("inf")}, "normalization_A must be a positive finite number"),
    ],
)
def test_identify_nozzle_names_a_bad_option(tmp_path, option, match):
    """Refused by name (the seed before any work: it failed after the bootstrap, in numpy's
    words; an infinite normalization wrote "A = inf" into the model and the report)."""
    from ssme_envs.identification.nozzle_bench import NozzleRecord
    from ssme_envs.identification.nozzle_pipeline import identify_nozzle

    u, y = _arrays(tmp_path)
    with pytest.raises(ValueError, match=match):
        identify_nozzle(NozzleRecord(u, y, DT, "tau", "beta"), **{"workers": 1, "replicates": 0, **option})


def test_a_model_naming_a_channel_twice_is_refused():
    from ssme_envs.models.engine import identified_model

    model = identified_model(90)
    doc = model.to_dict()
    doc["output_names"] = [doc["output_names"][0]] * 2
    with pytest.raises(ValueError, match="name a channel twice"):
        type(model).from_dict(doc)


def test_a_fit_far_below_zero_is_printed_in_significant_digits():
    from ssme_envs.identification.nozzle_report import _percent

    assert _percent(91.234) == "91.23" and _percent(-3.2e150) == "-3.2e+150"
