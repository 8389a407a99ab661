"""PRBS and the low-frequency test signal, checked against the defining properties."""

from __future__ import annotations

import numpy as np
import pytest

from ssme_envs.signals import PRIMITIVE_TAPS, mls, prbs, step_ramp_test_signal


def _circular_autocorrelation(s: np.ndarray) -> np.ndarray:
    return np.real(np.fft.ifft(np.abs(np.fft.fft(s)) ** 2)).round().astype(int)


@pytest.mark.parametrize("n_bits", sorted(PRIMITIVE_TAPS))
def test_every_register_gives_a_maximum_length_sequence(n_bits):
    for variant in range(len(PRIMITIVE_TAPS[n_bits])):
        s = mls(n_bits, variant)
        period = 2**n_bits - 1
        assert s.size == period
        assert s.sum() == -1  # one more -1 than +1 (2**(n-1) ones in the register output)
        # Two-valued autocorrelation (period at lag 0, -1 elsewhere) holds only for m-sequences.
        acf = _circular_autocorrelation(s)
        assert acf[0] == period
        assert np.all(acf[1:] == -1)


def test_paper_prbs_is_127_bits_and_inputs_uncorrelated():
    u = prbs(127, amplitude=[0.01, 0.02])
    assert u.shape == (127, 2)
    np.testing.assert_array_equal(np.unique(np.abs(u[:, 0])), [0.01])
    np.testing.assert_array_equal(np.unique(np.abs(u[:, 1])), [0.02])
    a, b = np.sign(u[:, 0]), np.sign(u[:, 1])
    for lag in range(-20, 21):
        cross = float(a @ np.roll(b, lag))
        assert cross == -1.0  # -1/127 normalized: uncorrelated over any 20-sample memory


def test_fresh_prbs_differs_and_clock_holds_bits():
    a, b = prbs(254), prbs(254, variant=1)
    assert not np.array_equal(a, b)
    slow = prbs(20, n_inputs=1, clock_samples=4)
    assert np.all(slow[0:4] == slow[0]) and np.all(slow[4:8] == slow[4])


def test_prbs_rejects_bad_amplitude():
    with pytest.raises(ValueError, match="amplitude"):
        prbs(100, amplitude=0.0)
    with pytest.raises(ValueError, match="n_bits"):
        mls(2)


def test_step_ramp_signal_shape_and_content():
    u = step_ramp_test_signal(0.04)
    assert u.shape == (300, 2)
    assert np.max(np.abs(u)) == pytest.approx(0.02)
    du = np.abs(np.diff(u, axis=0))
    assert np.sum(du > 0.005) >= 4  # steps
    ramp_slope = 0.04 / 2 * 0.04  # the OPOV ramp from +0.02 to -0.02 over 2 s, per sample
    assert np.any(np.isclose(du[:, 0], ramp_slope, rtol=1e-9))
    assert u[0].tolist() == [0.0, 0.0]
