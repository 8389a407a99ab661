"""Nearly collinear inputs in the alpha-canonical ``identify``: a noisy record whose inputs barely
excite some input direction gave B entries up to 3e5 (an engine record with beta_fpov = beta_opov
plus 1e-9 noise, against about 0.5), shown only by the standard errors; now such a record is
refused as DSR_e refuses it, naming the inputs by their names. The limit follows the noise: a
noise-free record still identifies the gain along the weak direction.

The records are ``test_subspace_defects.collinear_record``'s (``conftest.random_system`` simulated by
``scipy.signal.dlsim``); the expected frequency responses are computed here from the system.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import dlsim, random_system
from hypothesis import given, settings
from hypothesis import strategies as st
from test_identification_structures import observability_indices
from test_subspace_defects import collinear_record, frequency_response, noisy

from ssme_envs.identification import identify


@settings(deadline=None, max_examples=15)
@given(
    seed=st.integers(0, 2**32 - 1),
    m=st.integers(2, 3),
    log_delta=st.floats(-6.0, -4.0),
    noise=st.floats(0.01, 0.3),
    method=st.sampled_from(["iv", "ls", "oe"]),
)
def test_nearly_collinear_noisy_inputs_are_refused_by_name(seed, m, log_delta, noise, method):
    _, u, y = collinear_record(seed, m, 10.0**log_delta, noise)
    names = ("opov", "fpov", "third")[:m]
    with pytest.raises(ValueError, match="nearly collinear") as info:
        identify(u, y, 1.0, method=method, input_names=names)
    message = str(info.value)
    assert all(name in message for name in names)
    assert "not determined by this record" in message


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_limit_follows_the_noise(seed):
    """u1 = w u0 + 1e-6 independent noise: without output noise the record determines the gain
    along the weak direction (frequency response right to 1e-5 of its peak, the true indices
    given), with 1 % output noise it does not and the record is refused."""
    (a, b, c), u, y_clean = collinear_record(seed, 2, 1e-6, 0.0)
    indices = observability_indices(a, c)
    model = identify(u, y_clean, 1.0, indices=indices, asymmetric=False, uncertainty=False).model
    truth = frequency_response(a, b, c)
    found = frequency_response(model.A, model.B, model.C)
    assert np.max(np.abs(found - truth)) < 1e-5 * np.max(np.abs(truth))
    y_noisy = noisy(y_clean, 0.01, np.random.default_rng(seed))
    with pytest.raises(ValueError, match="inputs u0, u1 are nearly collinear"):
        identify(u, y_noisy, 1.0, indices=indices, asymmetric=False)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_inputs_correlated_but_well_excited_are_kept(seed):
    """u1 = u0 + 0.3 independent noise (correlation 0.96) at 10 % output noise: the weak direction
    is excited 5 times less than the strong one, its gain determined to a few %; not refused."""
    rng = np.random.default_rng(seed)
    a, b, c = random_system(3, 2, 2, rng)
    u = rng.standard_normal((1000, 2))
    u[:, 1] = u[:, 0] + 0.3 * rng.standard_normal(1000)
    y = noisy(dlsim(a, b, c, u), 0.1, rng)
    identify(u, y, 1.0, uncertainty=False)


@pytest.mark.parametrize(("input_unit", "output_unit"), [(1e-9, 1e6), (1e6, 1e-9), (1.0, 1.0)])
def test_the_noise_behind_the_limit_does_not_depend_on_the_units(input_unit, output_unit):
    """Inputs correlated at 0.05 independent noise, 0.1 % output noise, in units far apart: the
    record identifies as at unit scale (the noise estimate's ARX fit, on raw channels, dropped the
    tiny inputs and counted their response as 69 % noise, refusing it); the same inputs with 10 %
    output noise and 1e-5 independent noise are refused in any units."""
    rng = np.random.default_rng(1)
    a, b, c = random_system(3, 2, 2, rng)
    u = rng.standard_normal((1000, 2))
    u[:, 1] = u[:, 0] + 0.05 * rng.standard_normal(1000)
    y = noisy(dlsim(a, b, c, u), 1e-3, rng)
    identify(u * input_unit, y * output_unit, 1.0, uncertainty=False, asymmetric=False)
    u[:, 1] = u[:, 0] + 1e-5 * rng.standard_normal(1000)
    y = noisy(dlsim(a, b, c, u), 0.1, rng)
    with pytest.raises(ValueError, match="nearly collinear"):
        identify(u * input_unit, y * output_unit, 1.0, uncertainty=False, asymmetric=False)
