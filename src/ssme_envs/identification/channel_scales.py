"""Equilibration of a record's channels for the subspace identifier: powers of two that bring
every input and output near unit RMS, and the model carried back to the record's units.

Without it the high-order ARX fit of DSR_e's first step drops the small channels as round-off
once their spread times the regression's own condition number nears ``1 / eps`` (poles ~1e-5
off), and ``Z``, which weighs the outputs by their units, hides a small output's modes from the
order selection.
"""

from __future__ import annotations

import math

import numpy as np

from ssme_envs.identification.innovations_model import InnovationsModel

# A record is equilibrated (see dsr_e) when the RMS values of all its channels (inputs and outputs
# together) spread beyond CHANNEL_SPREAD, or those of its outputs beyond OUTPUT_SPREAD; any other
# record gets the unscaled algorithm's results bit for bit. Measured on random stable systems of
# order 1-4 with one or two inputs and outputs (the generator of tests/test_subspace_scaling.py):
# - Round-off, any two channels: with output noise, the poles of a rescaled record agree with the
#   balanced record's to 1e-13 up to a spread of 1e9, then jump to 1e-5 at 1e10-1e11, where the
#   spread times the ARX regression's column-normalized condition number (3e4 there) nears
#   1 / eps and the rank-revealing least squares of step 1 drops the small channels. 1e6 keeps
#   three to four decades of margin, and keeps the nozzle bench records (torque against angle,
#   spread 9.4e4, condition number 3e3) on the unscaled algorithm, bit for bit, so that the
#   packaged nozzle models stay what their pipeline gave.
CHANNEL_SPREAD = 1e6
# - Order selection, outputs among themselves: Z weighs the outputs by their units, so a small
#   output's modes sit below a large one's by the spread, and on noise-free records the largest
#   drop falls between the outputs from spreads of 10^5.75 on (300 systems; median 10^7). 1e3
#   keeps 2.75 decades of margin. (With output noise the drop can fall between the outputs from
#   a spread of 30 on, a matter of weighting rather than of lost digits that no threshold
#   separates from a balanced record: pass order=, or equilibrate such a record beforehand.)
OUTPUT_SPREAD = 1e3
# - Magnitude: a balanced record far from unit size (every channel times 1e-110 or 1e110) lost
#   B and D's regression to round-off thresholds that are relative to one (refused as "the inputs
#   do not determine B and D"), while 1e-100..1e100 identified as at unit size; a record with a
#   channel's RMS outside MAGNITUDE..1 / MAGNITUDE is equilibrated too (50 decades of margin).
MAGNITUDE = 1e-50


def equilibration(u: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Exponents of the powers of two nearest each input's and output's RMS, or None when the
    record is balanced (``CHANNEL_SPREAD``, ``OUTPUT_SPREAD``) and of moderate size
    (``MAGNITUDE``) and is used as it is.

    Powers of two so that the scaling and its undoing are exact: the equilibrated record holds
    the record's own digits.
    """
    x = np.hstack([u, y])
    peak = np.max(np.abs(x), axis=0)  # > 0: check_record rejects constant channels
    rms = peak * np.sqrt(np.mean((x / peak) ** 2, axis=0))  # through the peak: x**2 may overflow
    out = rms[u.shape[1] :]
    balanced = np.max(rms) <= CHANNEL_SPREAD * np.min(rms) and np.max(out) <= OUTPUT_SPREAD * np.min(out)
    if balanced and MAGNITUDE <= np.min(rms) and np.max(rms) <= 1.0 / MAGNITUDE:
        return None
    exponents = np.round(np.log2(rms)).astype(int)
    return exponents[: u.shape[1]], exponents[u.shape[1] :]


def equilibrated(
    u: np.ndarray, y: np.ndarray
) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray] | None]:
    """The record divided by the powers of two of :func:`equilibration` (exactly), and those
    exponents; the record itself and None when it is balanced."""
    scales = equilibration(u, y)
    if scales is None:
        return u, y, None
    return np.ldexp(u, -scales[0]), np.ldexp(y, -scales[1]), scales


def restore_units(
    model: InnovationsModel, singular_values: np.ndarray, u_exp: np.ndarray, y_exp: np.ndarray
) -> tuple[InnovationsModel, np.ndarray]:
    """Model and singular values of the equilibrated record carried back to the record's units.

    With ``u = S_u u~``, ``y = S_y y~`` (diagonal, ``2**u_exp``, ``2**y_exp``), the innovations
    are ``e = S_y e~``, and with the state ``x = t x~``:
    ``A = A~``, ``B = t B~ S_u^-1``, ``C = S_y C~ / t``, ``D = S_y D~ S_u^-1``,
    ``K = t K~ S_y^-1``. ``t = sqrt(g)`` and the singular values times ``g``, where ``g`` is
    the outputs' common scale (geometric mean of ``S_y``): ``Z`` only scales with the rows of
    ``Y_f`` (the other rows of the stack set directions projected out or on, which their scale
    does not change), so for one output
    ``Z = g Z~`` and ``O = sqrt(g) O~``, and the result is the one the unscaled algorithm gives
    up to rounding, in the same state basis. With several outputs the scaled ``Z`` is not a
    multiple of the record's: the state basis and singular values are the equilibrated record's.
    """
    s_u, s_y = np.ldexp(1.0, u_exp), np.ldexp(1.0, y_exp)
    g = 2.0 ** float(np.mean(y_exp))
    t = math.sqrt(g)
    restored = InnovationsModel(
        model.A,
        t * model.B / s_u,
        s_y[:, None] * model.C / t,
        s_y[:, None] * model.D / s_u,
        t * model.K / s_y,
        model.dt,
    )
    return restored, singular_values * g


__all__ = ["CHANNEL_SPREAD", "OUTPUT_SPREAD", "equilibrated", "equilibration", "restore_units"]
