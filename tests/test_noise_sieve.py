"""The AR sieve of a residual record and the nozzle bootstrap that resamples through it.

Expected figures come from outside the sieve: the noise is made by scipy's ``lfilter`` from a
seeded generator, its long-run variance ratio from the generating polynomial's impulse response,
autocorrelations by numpy, and the standard errors the bootstrap should give by brute force
(J, b, k re-identified on records with fresh noise of the true process).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal
from hypothesis import given, settings
from hypothesis import strategies as st

from ssme_envs.identification import dsr_e, second_order_parameters
from ssme_envs.identification.noise_sieve import fit_sieve, max_sieve_order
from ssme_envs.identification.nozzle_residuals import output_error_colour, output_error_notes
from ssme_envs.identification.nozzle_uncertainty import dsr_e_uncertainty
from ssme_envs.models.nozzle import published_nozzle


def _ar_noise(roots: list[float], size: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Stationary AR noise with the given real poles (burn-in dropped) and its polynomial."""
    a = np.poly(roots)
    e = np.random.default_rng(seed).standard_normal(size + 2000)
    return scipy.signal.lfilter([1.0], a, e)[2000:], a


def _long_run_ratio(a: np.ndarray) -> float:
    """sum(h)^2 / sum(h^2) of the impulse response h of 1 / A(q): a brute-force sum."""
    impulse = np.zeros(20000)
    impulse[0] = 1.0
    h = scipy.signal.lfilter([1.0], a, impulse)
    return float(h.sum() ** 2 / np.sum(h * h))


def coloured_error_note(dsr_e_fit: dict) -> str | None:
    """The CLI's note on the bootstrap's shortfall, if it gives one."""
    notes = [note for note in output_error_notes(dsr_e_fit) if "standard errors" in note]
    return notes[0] if notes else None


def _autocorrelation(x: np.ndarray, lag: int) -> float:
    x = x - x.mean()
    return float(np.dot(x[lag:], x[:-lag]) / np.dot(x, x))


@settings(max_examples=25, deadline=None)
@given(
    roots=st.lists(st.floats(-0.9, 0.9), min_size=1, max_size=2),
    seed=st.integers(0, 2**32 - 1),
)
def test_the_sieve_keeps_the_colour_of_ar_noise(roots, seed):
    """On 8000 samples of AR(1) or AR(2) noise with poles in [-0.9, 0.9], the sieve's long-run
    variance ratio is within 25 % of the generating process's, and its draws have the record's
    autocorrelations at lags 1 to 3 within 0.06."""
    v, a = _ar_noise(roots, 8000, seed)
    sieve = fit_sieve(v)
    assert sieve.long_run_ratio == pytest.approx(_long_run_ratio(a), rel=0.25)
    draw = sieve.draw(np.random.default_rng(seed + 1), 8000)
    for lag in (1, 2, 3):
        assert abs(_autocorrelation(draw, lag) - _autocorrelation(v, lag)) < 0.06, lag
    assert sieve.lag1 == pytest.approx(_autocorrelation(v, 1), abs=1e-3)
    assert np.std(draw) == pytest.approx(np.std(v), rel=0.15)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_on_white_noise_the_sieve_is_the_plain_resampling(seed):
    """White noise: a long-run ratio near 1, draws without colour, and no note."""
    v = np.random.default_rng(seed).standard_normal(4000)
    sieve = fit_sieve(v)
    assert 0.6 < sieve.long_run_ratio < 1.6
    assert sieve.order <= max_sieve_order(4000)
    draw = sieve.draw(np.random.default_rng(seed), 4000)
    assert abs(_autocorrelation(draw, 1)) < 0.1
    colour = output_error_colour(v)
    boot = {"noise": "white", "noise_std": float(np.std(v))}
    assert coloured_error_note({"output_error": colour, "bootstrap": boot}) is None


def test_the_note_names_coloured_noise_where_the_bootstrap_did_not_keep_its_colour():
    v, a = _ar_noise([0.95], 4000, 5)
    colour = output_error_colour(v)
    assert colour["long_run_ratio"] == pytest.approx(_long_run_ratio(a), rel=0.35)  # 39 for 0.95
    innovations = float(np.std(v) * np.sqrt(1 - 0.95**2))  # what the ARX residuals would be
    for noise in ("white", "innovations"):
        boot = {"noise": noise, "noise_std": innovations}
        note = coloured_error_note({"output_error": colour, "bootstrap": boot})
        assert note is not None and note.startswith("note: ") and "--bootstrap-noise sieve" in note
        assert f"bootstrapped with {noise} noise" in note and "\n" not in note
        assert ("times as large as the white noise" in note) == (noise == "white")  # 3.2 times
    boot = {"noise": "sieve", "noise_std": innovations}
    assert coloured_error_note({"output_error": colour, "bootstrap": boot}) is None
    exact = output_error_colour(np.zeros(100))
    flat = {"lag1_autocorrelation": 0.0, "sieve_order": 0, "long_run_ratio": 1.0}
    assert exact == {"mean": 0.0, "std": 0.0, **flat}
    noiseless = {"noise": "white", "noise_std": 0.0}
    assert coloured_error_note({"output_error": exact, "bootstrap": noiseless}) is None
    assert output_error_colour(np.r_[np.zeros(50), np.nan]) is None  # an unstable model's simulation


@pytest.mark.parametrize("misfit", ["ramp", "slow sine"])
def test_a_smooth_misfit_is_drawn_with_its_variance_and_called_coloured(misfit):
    """A smooth output error (a drift the linear model leaves, little sensor noise): the draws
    carry the record's variance (numpy's), not the sliver the filtered record keeps, and the
    long-run ratio calls it coloured."""
    t = np.arange(4000)
    noise = 1e-3 * np.random.default_rng(2).standard_normal(t.size)
    v = (1e-3 * t if misfit == "ramp" else np.sin(2 * np.pi * t / 3000)) + noise
    sieve = fit_sieve(v)
    draws = np.concatenate([sieve.draw(np.random.default_rng(k), t.size) for k in range(50)])
    assert np.var(draws) == pytest.approx(np.var(v), rel=0.25)
    assert sieve.long_run_ratio > 100
    boot = {"noise": "white", "noise_std": 1e-3}
    assert coloured_error_note({"output_error": output_error_colour(v), "bootstrap": boot})


def test_a_hum_or_an_error_larger_than_the_resampled_noise_gets_the_note():
    """A narrow-band output error (a hum) has a long-run ratio below 1 but a lag 1 near 1; an
    error five times the white noise the bootstrap resampled (an ARX that explained it away)
    is named with that factor, colour or not."""
    t = np.arange(4000) * 0.008
    hum = 0.005 * np.sin(2 * np.pi * 3.0 * t)
    colour = output_error_colour(hum)
    assert colour["long_run_ratio"] < 1 and colour["lag1_autocorrelation"] > 0.9
    note = coloured_error_note({"output_error": colour, "bootstrap": {"noise": "white", "noise_std": 1e-17}})
    assert note is not None and "coloured" in note and "times as large" in note
    white = np.random.default_rng(1).standard_normal(4000)
    boot = {"noise": "white", "noise_std": float(np.std(white)) / 5}
    note = coloured_error_note({"output_error": output_error_colour(white), "bootstrap": boot})
    assert note is not None and "coloured" not in note and "5 times as large" in note


def test_draws_start_stationary():
    """AR(1) 0.99 noise: the first sample of 400 draws of 20 samples each has the process's
    stationary variance (sigma^2 / (1 - a^2), computed from the fitted coefficient), as the
    last does: the burn-in settles the filter."""
    v, _ = _ar_noise([0.99], 20000, 4)
    sieve = fit_sieve(v)
    a = -sieve.denominator[1]
    stationary = np.var(sieve.innovations) / (1 - a * a) if sieve.order == 1 else np.var(v)
    draws = np.array([sieve.draw(np.random.default_rng(k), 20) for k in range(400)])
    assert np.var(draws[:, 0]) == pytest.approx(stationary, rel=0.25)
    assert np.var(draws[:, -1]) == pytest.approx(stationary, rel=0.25)


def test_same_seed_same_draws():
    sieve = fit_sieve(_ar_noise([0.7], 1000, 1)[0])
    first = sieve.draw(np.random.default_rng(9), 500)
    assert first.tobytes() == sieve.draw(np.random.default_rng(9), 500).tobytes()


@pytest.mark.parametrize(
    ("values", "max_order", "match"),
    [
        (np.ones((10, 2)), None, "one channel"),
        (np.ones(5), None, "at least 8 samples"),
        (np.r_[np.zeros(20), np.nan], None, "NaN or inf"),
        (np.ones(40), None, "constant"),
        (np.arange(40.0), 11, r"max_order must be an integer in 0\.\.10"),
        (np.arange(40.0), 2.5, "max_order must be an integer"),
        (np.arange(40.0), True, "max_order must be an integer"),
    ],
)
def test_bad_residuals_are_refused(values, max_order, match):
    with pytest.raises(ValueError, match=match):
        fit_sieve(values, max_order)


DT, SAMPLES = 0.008, 2000


def _joint_record(seed: int, noise: np.ndarray | None = None):
    """Table 1's linear joint by scipy's ZOH under a +-3000 N m PRBS, with ``noise`` added."""
    p = published_nozzle("linear")
    a = np.array([[0.0, 1.0], [-p.k / p.J, -p.b / p.J]])
    b = np.array([[0.0], [1.0 / p.J]])
    system = scipy.signal.cont2discrete((a, b, np.array([[1.0, 0.0]]), np.zeros((1, 1))), DT)
    u = np.random.default_rng(seed).choice([-3000.0, 3000.0], size=(SAMPLES, 1))
    clean = scipy.signal.dlsim(system, u)[1][:, 0]
    return u[:, 0], clean


@pytest.mark.slow
def test_the_sieve_bootstrap_gives_the_scatter_of_fresh_coloured_noise():
    """AR(1) 0.95 sensor noise at 10 % of the angle's spread, one PRBS: the standard errors of
    J, b, k from the sieve bootstrap (30 replicates) against their scatter over 30 records with
    fresh noise of the true process (brute force). They agree within the two estimates' own
    scatter (within a factor 1.6); the white resampling's are more than twice too narrow for J
    and k."""
    u, clean = _joint_record(0)
    scale = 0.1 * clean.std()

    def noisy(seed: int) -> np.ndarray:
        v, _ = _ar_noise([0.95], SAMPLES, seed)
        return clean + scale * v / v.std()

    def jbk(y: np.ndarray) -> list[float]:
        p = second_order_parameters(dsr_e(u, y, DT, order=2).model)
        return [p["J"], p["b"], p["k"]]

    brute = np.std([jbk(noisy(100 + k)) for k in range(30)], axis=0, ddof=1)
    y = noisy(1)
    fit = dsr_e(u, y, DT, order=2)
    sieve = dsr_e_uncertainty(u, y, DT, fit, replicates=30, seed=3, noise="sieve").standard_errors
    white = dsr_e_uncertainty(u, y, DT, fit, replicates=30, seed=3).standard_errors
    assert np.all(sieve / brute > 1 / 1.6) and np.all(sieve / brute < 1.6), sieve / brute
    # (resampling the output error itself as white noise falls in that window too, on J and k
    # short and on b long: the sieve's colour is held by the tests above)
    assert brute[0] / white[0] > 2 and brute[2] / white[2] > 2, brute / white


def test_the_cli_offers_the_bootstraps_noise_models_with_the_librarys_default():
    """The CLI writes the choices out (it does not import identification): they are the
    library's, and its default is ``identify_nozzle``'s."""
    import argparse
    import inspect

    from ssme_envs.cli import build_parser
    from ssme_envs.identification.jobs import identify_nozzle
    from ssme_envs.identification.nozzle_uncertainty import NOISE_MODELS

    def sub(parser: argparse.ArgumentParser, name: str) -> argparse.ArgumentParser:
        (commands,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        return commands.choices[name]

    nozzle = sub(sub(build_parser(), "identify"), "nozzle")
    (option,) = [a for a in nozzle._actions if a.dest == "bootstrap_noise"]
    assert tuple(option.choices) == NOISE_MODELS
    assert option.default == inspect.signature(identify_nozzle).parameters["bootstrap_noise"].default
