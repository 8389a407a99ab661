"""Excitation and test signals: maximum-length PRBS and the low-frequency step/ramp test.

NASA TM-104422 excites OPOV and FPOV with two uncorrelated 127-bit PRBS clocked at 0.04 s
(1.24 to 78.5 rad/s) and validates on a second pair of PRBS and on a low-frequency step and
ramp signal (its figure 3, amplitudes within +-0.02 normalized valve travel).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

# Feedback taps of Fibonacci LFSRs with maximal period 2**n - 1, one primitive polynomial per
# degree n; for n = 7 several, so that validation can use a PRBS other than the design one.
PRIMITIVE_TAPS: dict[int, tuple[tuple[int, ...], ...]] = {
    3: ((3, 2),),
    4: ((4, 3),),
    5: ((5, 3),),
    6: ((6, 5),),
    7: ((7, 6), (7, 3), (7, 4), (7, 1)),
    8: ((8, 6, 5, 4),),
    9: ((9, 5),),
    10: ((10, 7),),
    11: ((11, 9),),
    12: ((12, 11, 10, 4),),
    13: ((13, 12, 11, 8),),
    14: ((14, 13, 12, 2),),
    15: ((15, 14),),
    16: ((16, 15, 13, 4),),
}


def mls(n_bits: int = 7, variant: int = 0) -> np.ndarray:
    """One period of a maximum-length sequence of +-1, length ``2**n_bits - 1``.

    Parameters
    ----------
    n_bits : int
        Register length, 3 to 16 (7 gives the paper's 127-bit sequence).
    variant : int
        Which primitive polynomial of that degree to use (several exist for 7 bits).
    """
    if n_bits not in PRIMITIVE_TAPS:
        raise ValueError(f"n_bits must be in {min(PRIMITIVE_TAPS)}..{max(PRIMITIVE_TAPS)}, got {n_bits}")
    options = PRIMITIVE_TAPS[n_bits]
    if not 0 <= variant < len(options):
        raise ValueError(f"variant must be in 0..{len(options) - 1} for {n_bits} bits, got {variant}")
    taps = options[variant]
    register = [1] * n_bits
    period = 2**n_bits - 1
    bits = np.empty(period, dtype=np.int8)
    for k in range(period):
        bits[k] = register[-1]
        feedback = 0
        for t in taps:
            feedback ^= register[t - 1]
        register = [feedback, *register[:-1]]
    return 1.0 - 2.0 * bits


def prbs(
    n_samples: int,
    amplitude: float | Sequence[float] = 0.01,
    n_inputs: int = 2,
    n_bits: int = 7,
    clock_samples: int = 1,
    variant: int = 0,
) -> np.ndarray:
    """Mutually uncorrelated maximum-length PRBS for several inputs, repeated to ``n_samples``.

    Input ``j`` gets the sequence cyclically shifted by ``j * period // n_inputs`` bits. Shifts
    of one m-sequence have a cross-correlation of ``-1/period`` at every lag closer than the
    shift, so the inputs are uncorrelated over any system memory shorter than the shift
    (63 samples = 2.5 s for two 127-bit inputs at 0.04 s).

    Parameters
    ----------
    n_samples : int
        Length of the signal in samples.
    amplitude : float or sequence of float
        Level of each input: the signal takes the values +-amplitude.
    n_inputs : int
        Number of inputs (columns).
    n_bits : int
        Register length; the period is ``2**n_bits - 1`` bits (7: 127 bits).
    clock_samples : int
        Samples per bit (1 at the paper's 0.04 s clock and sample time).
    variant : int
        Primitive polynomial choice (see :func:`mls`); use another one for a fresh record.

    Returns
    -------
    ndarray, shape (n_samples, n_inputs)
    """
    if n_samples < 1 or n_inputs < 1 or clock_samples < 1:
        raise ValueError("n_samples, n_inputs and clock_samples must be positive")
    amp = np.broadcast_to(np.asarray(amplitude, dtype=float), (n_inputs,))
    if not np.all(np.isfinite(amp)) or np.any(amp <= 0):
        raise ValueError(f"amplitude must be positive and finite, got {amplitude!r}")
    sequence = mls(n_bits, variant)
    period = sequence.size
    bit_index = np.arange(n_samples) // clock_samples
    shifts = np.arange(n_inputs) * (period // n_inputs)
    return sequence[(bit_index[:, None] + shifts[None, :]) % period] * amp


# Breakpoints (time s, value) of the low-frequency test; a repeated time is a step. The shape
# follows figure 3 of the paper (steps and ramps within +-0.02 over about 12 s); the exact
# timings did not survive in the source, so these are our own.
_TEST_OPOV = (
    (0, 0),
    (1, 0),
    (1, 0.02),
    (3, 0.02),
    (5, -0.02),
    (6.5, -0.02),
    (6.5, 0),
    (8, 0),
    (10, 0.01),
    (12, 0.01),
)
_TEST_FPOV = (
    (0, 0),
    (2, 0),
    (2, -0.015),
    (4, -0.015),
    (7, 0.015),
    (8.5, 0.015),
    (8.5, -0.01),
    (11, 0),
    (12, 0),
)


def step_ramp_test_signal(dt: float = 0.04, duration: float = 12.0) -> np.ndarray:
    """The low-frequency step and ramp test of figure 3, shape (round(duration / dt), 2).

    Columns are (OPOV, FPOV) normalized valve deviations; after 12 s the last values hold.
    """
    if not (dt > 0 and duration > 0):
        raise ValueError("dt and duration must be positive")
    t = np.arange(round(duration / dt)) * dt
    columns = []
    for points in (_TEST_OPOV, _TEST_FPOV):
        times = np.array([p[0] for p in points], dtype=float)
        values = np.array([p[1] for p in points], dtype=float)
        # np.interp takes the right-hand value at a repeated time, so steps act at their time.
        columns.append(np.interp(t + 1e-12, times, values))
    return np.column_stack(columns)
