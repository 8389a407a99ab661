"""The nonlinear engine's valve effect: a falling valve authority and an asymmetric flow curve.

Each valve's departure ``d`` from its nominal position at the engine's current power (normalized
valve travel) acts on the engine through ``phi(psi(d))``: ``psi``, the valve's authority, then
``phi``, its flow characteristic. Both are written once, for Python floats and for arrays alike
(:func:`valve_effect` takes the square root of its carrier), so that the engine envs' float and
array steps give the same bits.

**Valve authority.** ::

    psi(d) = d (1 - g + g / sqrt(1 + (d / b)^2)),   g = AUTHORITY_LOSS,   b = AUTHORITY_TRAVEL.

Slope 1 at the trim (the linearization is untouched), falling symmetrically on both sides to
``1 - g`` far from it over a travel of about ``b``: a soft saturation of what a valve can do to
the engine once it has moved well away from where the engine's operating point puts it (the
turbopumps and preburners, not the valve, then set the flow). It is odd and monotone for any
``0 <= g < 1``. ``g = 0`` removes it (``psi(d) = d`` to the bit). The values are **calibrated,
not derived**: no public source gives the SSME's large-signal valve authority. They are the
round values for which the paper's figure 3 test (valve travel up to 0.02) shows the identified
point models about as wrong as Table II reports them against Rocketdyne's simulation, while the
+-0.01 PRBS still shows Table I's lambda
(``experiments/results/engine_authority_calibration.md`` has the figures for a grid of (g, b)
around them and for g = 0, the engine of earlier releases). The chord gain at the PRBS's +-0.01
is ``psi(0.01) / 0.01 = 0.88``: a point model identified there has about 12 % less gain than the
Jacobian.

**Flow characteristic.** ::

    phi(d) = d + (lambda - 1) a s(d / a) / s(1),   s(z) = sqrt(1 + z^2) - 1,   a = 0.01.

Eq 36 gives the response to a +-a binary input the up and down gains ``lambda B`` and
``(2 - lambda) B``; their mean ``B`` is the gain of the symmetric part, and ``C A^k B`` are
Table I's Markov parameters. ``phi`` has slope 1 at ``d = 0``, so the Jacobian's B (a symmetric
derivative) is Table I's B, and curvature ``phi''(0) = (lambda - 1) / (a (sqrt 2 - 1))``, chosen
so that the chords to ``d = +-a`` have exactly the gains ``lambda`` and ``2 - lambda``: on a
+-0.01 PRBS the curve acts as eq 36's ``u + (lambda - 1)|u|``. Behind ``psi`` the PRBS sees
``phi``'s chords at ``+-c a``, ``c = psi(a) / a = 0.88``: eq 36's lambda from them is
``1 + (lambda - 1) s(c) / (c s(1))``, 0.91 (lambda - 1) from 1, within 2.7 % of Table I's lambda
at its five levels (``tests/test_engine_valve_flow.py``). Away from the trim the curve tends to
straight lines of slopes ``1 +- (lambda - 1) / (sqrt 2 - 1)``; it is monotone while
``|lambda - 1| < sqrt 2 - 1`` (the engine checks it; at most 0.36 over 62.5-115 %). Larger
inputs see more asymmetry than eq 36 predicts (at +-0.02 of ``phi``'s own input, 0.035 of valve
travel behind ``psi``, its chord gain is ``1 + 1.49 (lambda - 1)``), smaller ones less (the
curve is smooth where eq 36 has a kink). Valve travel is not limited.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable
from typing import Any

import numpy as np

from ssme_envs.models.linear import finite_float

FLOW_AMPLITUDE = 0.01  # normalized valve travel at which phi's chords are lambda and 2 - lambda
AUTHORITY_LOSS = 0.7  # g: fraction of a valve's small-signal gain lost far from the trim
AUTHORITY_TRAVEL = 0.015  # b: normalized valve travel over which the authority falls
_S1 = math.sqrt(2.0) - 1.0  # s(1)
LAMBDA_LIMIT = _S1  # phi is monotone while |lambda - 1| stays below it


def valve_effect(
    d: Any,
    lam: Any,
    sqrt: Callable[[Any], Any],
    asymmetric: bool = True,
    loss: float = AUTHORITY_LOSS,
    travel: float = AUTHORITY_TRAVEL,
) -> Any:
    """``phi(psi(d))`` (or ``psi(d)`` with ``asymmetric`` False) on floats or arrays.

    Parameters
    ----------
    d : float or array
        Valve departures from the nominal position, normalized valve travel.
    lam : float or array broadcasting with ``d``
        Asymmetric gains lambda of the flow curve.
    sqrt : callable
        The carrier's square root (``math.sqrt`` for floats, ``np.sqrt`` for arrays; both are
        correctly rounded, so the two carriers agree to the bit).
    asymmetric : bool
        False makes ``phi`` the identity.
    loss, travel : float
        ``g`` and ``b`` of the authority ``psi``.

    Returns
    -------
    float or array like ``d``: the effect on the engine, in the units of the valve travel.
    """
    w = d / travel
    d = d * ((1.0 - loss) + loss / sqrt(1.0 + w * w))
    return _flow(d, lam, sqrt, FLOW_AMPLITUDE) if asymmetric else d


def _flow(d: Any, lam: Any, sqrt: Callable[[Any], Any], amplitude: float) -> Any:
    """``phi(d)`` on either carrier (module docstring)."""
    z = d / amplitude
    return amplitude * (z + (lam - 1.0) * (sqrt(1.0 + z * z) - 1.0) / _S1)


def _real(value: Any, name: str, condition: str, test: Callable[[float], bool]) -> float:
    """``value`` as a float (a real number, numpy's too, not a bool; -0.0 as 0.0) that passes
    ``test``, or ValueError naming ``name`` and the ``condition``."""
    try:
        number = finite_float(value, name) + 0.0
    except ValueError:
        number = math.nan  # fails every test
    if not test(number):
        huge = isinstance(value, int) and not isinstance(value, bool) and abs(value) > sys.float_info.max
        got = "an integer too large for a float" if huge else repr(value)
        raise ValueError(f"{name} must be a number {condition}, got {got}")
    return number


def check_authority(loss: Any, travel: Any) -> tuple[float, float]:
    """``(g, b)`` as floats, or ValueError unless ``0 <= g < 1`` and ``b > 0`` (both finite)."""
    return (
        _real(loss, "authority_loss", "in [0, 1)", lambda g: 0.0 <= g < 1.0),
        _real(travel, "authority_travel", "> 0 (finite, valve travel)", lambda b: b > 0.0),
    )


def valve_authority(
    d: np.ndarray, loss: float = AUTHORITY_LOSS, travel: float = AUTHORITY_TRAVEL
) -> np.ndarray:
    """``psi(d) = d (1 - g + g / sqrt(1 + (d/b)^2))`` on an array (module docstring)."""
    return valve_effect(np.asarray(d, dtype=float), 1.0, np.sqrt, False, *check_authority(loss, travel))


def flow_characteristic(d: np.ndarray, lam: np.ndarray, amplitude: float = FLOW_AMPLITUDE) -> np.ndarray:
    """Valve flow curve ``phi(d) = d + (lambda - 1) a s(d/a) / s(1)``, ``s(z) = sqrt(1 + z^2) - 1``.

    Parameters
    ----------
    d : array, shape (..., m)
        Valve departures from the nominal position, normalized valve travel.
    lam : array, shape (..., m) or (m,)
        Asymmetric gains: the chord gains to ``+-amplitude`` are ``lam`` and ``2 - lam``.
    amplitude : float
        ``a``, normalized valve travel.

    Returns
    -------
    ndarray, same shape as ``d``: the effect, in the units of the valve travel (slope 1 at 0).
    """
    return _flow(np.asarray(d, dtype=float), np.asarray(lam, dtype=float), np.sqrt, amplitude)


__all__ = [
    "AUTHORITY_LOSS",
    "AUTHORITY_TRAVEL",
    "FLOW_AMPLITUDE",
    "LAMBDA_LIMIT",
    "check_authority",
    "flow_characteristic",
    "valve_authority",
    "valve_effect",
]
