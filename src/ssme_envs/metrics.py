"""Actuator saturation, limit-cycle detection and step-response metrics on rollouts: pure
functions of arrays.

Saturation is read from the actions the env applied (after its clip to [-1, 1]), never from what
a controller requested: a controller that clips its own output requests no more than full scale,
yet holds its actuator at the stop.

A limit cycle is a self-sustained oscillation of the loop while the reference holds still, the
signature of backlash or stiction under integral action, or of a loop oscillating between its
actuator limits. The detector reads the autocorrelation of the error over each stretch of constant
reference (after its first quarter, the transient), as control-loop performance monitoring does
(Thornhill and Hägglund, Control Eng. Practice 5, 1997; Thornhill, Huang and Zhang, J. Process
Control 13, 2003): white sensor noise decorrelates within one sample, a persistent oscillation
keeps its autocorrelation at every multiple of its period.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import scipy.signal

from ssme_envs.models.linear import describe

# an applied action within this share of full scale from the limit sits at the limit: wide enough
# for the float32 rounding of the command the env receives (6e-8), far below any real move
AT_LIMIT_TOL = 1e-6


def saturation_fraction(
    actions: np.ndarray, alive: np.ndarray, limit: float = 1.0, tol: float = AT_LIMIT_TOL
) -> np.ndarray:
    """Fraction of each episode's alive steps at which an actuator sits at its limit.

    Parameters
    ----------
    actions : ndarray, shape (T, N) or (T,)
        The applied actions of one actuator (fraction of full scale), time-major.
    alive : ndarray of bool, same shape
        Which steps belong to each episode; the others are not counted.
    limit : float
        The actuator's limit (same unit as ``actions``); at it means ``|a| >= limit * (1 - tol)``.
    tol : float
        Tolerance, as a fraction of ``limit``, within [0, 1).

    Returns
    -------
    ndarray, shape (N,) or ()
        Fraction (0-1) of each episode's alive steps at the limit.
    """
    a = np.asarray(actions, dtype=np.float64)
    live = np.asarray(alive)
    if live.dtype != bool:
        raise TypeError(f"alive must be a boolean array, got dtype {live.dtype}")
    if a.ndim not in (1, 2) or a.shape != live.shape:
        raise ValueError(
            f"actions must be (T,) or (T, N) with alive of the same shape, got {a.shape}, {live.shape}"
        )
    if not (math.isfinite(limit) and limit > 0):
        raise ValueError(f"limit must be a positive finite number, got {describe(limit)}")
    if not (0 <= tol < 1):
        raise ValueError(f"tol must be within [0, 1), got {describe(tol)}")
    if not np.isfinite(a[live]).all():
        raise ValueError("actions hold NaN or inf at an alive step")
    steps = live.sum(axis=0)
    if np.any(steps == 0):
        raise ValueError("an episode has no alive step: its fraction at the limit is undefined")
    at_limit = (np.abs(a) >= limit * (1.0 - tol)) & live
    return at_limit.sum(axis=0) / steps


class LimitCycle(NamedTuple):
    """What :func:`limit_cycle` found in one signal.

    Attributes
    ----------
    found : bool
        A persistent oscillation in at least one window.
    tested : bool
        At least one window was long enough to test.
    period : float or None
        Period of the oscillation, s (None when none was found).
    amplitude : float or None
        Its sine-equivalent amplitude, sqrt(2) x the RMS of its periodic part, in the signal's
        unit; white noise adds nothing to it (None when none was found).
    correlation : float
        Autocorrelation of the window at the period (0 when none was found).
    longest_period : float
        The longest period the tested windows could show (a third of the longest), s (0 when
        none was tested): "none found" holds for periods up to it.
    """

    found: bool
    tested: bool
    period: float | None
    amplitude: float | None
    correlation: float
    longest_period: float


NO_CYCLE = LimitCycle(False, False, None, None, 0.0, 0.0)


def limit_cycle(
    signal: np.ndarray,
    alive: np.ndarray,
    dt: float,
    reference: np.ndarray | None = None,
    *,
    settle: float = 0.25,
    min_samples: int = 40,
    z: float = 4.0,
    min_correlation: float = 0.5,
    min_power_ratio: float = 0.5,
) -> LimitCycle:
    """Whether ``signal`` oscillates persistently while its reference holds still.

    The windows are the stretches of alive steps with a constant ``reference`` (the whole alive
    signal without one), less their first ``settle`` share (the transient). A window of
    ``n >= min_samples`` samples is linearly detrended and its unbiased autocorrelation rho(k)
    computed. The candidate period P is the peak of rho's first positive lobe after its first zero
    crossing, within n / 3 (three cycles at least in the window). It is an oscillation when

    - rho(P) >= ``min_correlation``: rho(P) is the periodic part's share of the window's power,
      so 0.5 asks it to carry at least as much power as the noise;
    - rho(P) >= ``z / sqrt(n - P)``: z standard deviations of white noise's rho at that lag;
    - rho passes both bounds again at 2P where 2P is within n / 2 (noise through a damped loop
      correlates at one period, less at two; a loop damped below about 0.1 rings on its noise
      all but persistently and may still pass);
    - it persists: its power (the half's mean square less the noise power, (1 - rho(P)) x the
      window's) in the second half of the window is at least ``min_power_ratio`` x that in the
      first, which a decaying response fails.

    Parameters
    ----------
    signal : ndarray, shape (T,)
        The signal, e.g. a tracking error.
    alive : ndarray of bool, shape (T,)
        The steps that count.
    dt : float
        Sample time, s.
    reference : ndarray, shape (T,) or (T, k), optional
        The reference(s) at each sample; a change of any starts a new window.
    settle : float
        Share of each window dropped at its start, within [0, 1).
    min_samples : int
        Shortest window tested (at least 8).
    z, min_correlation, min_power_ratio : float
        The thresholds above.

    Returns
    -------
    LimitCycle
        The period and amplitude of the window with the strongest autocorrelation at its period;
        ``tested`` and ``longest_period`` over all windows.
    """
    x = np.asarray(signal, dtype=np.float64)
    live = np.asarray(alive)
    if live.dtype != bool:
        raise TypeError(f"alive must be a boolean array, got dtype {live.dtype}")
    if x.ndim != 1 or live.shape != x.shape:
        raise ValueError(f"signal must be (T,) with alive of the same shape, got {x.shape}, {live.shape}")
    if not np.isfinite(x[live]).all():
        raise ValueError("signal holds NaN or inf at an alive step")
    try:
        good_dt = math.isfinite(dt) and dt > 0
    except (OverflowError, TypeError):  # an int beyond a float's range, or no number
        good_dt = False
    if not good_dt:
        raise ValueError(f"dt must be a positive finite time in s, got {describe(dt)}")
    if not 0 <= settle < 1:
        raise ValueError(f"settle must be within [0, 1), got {describe(settle)}")
    if not (isinstance(min_samples, int) and min_samples >= 8):
        raise ValueError(f"min_samples must be an integer >= 8, got {describe(min_samples)}")
    if not (z > 0 and 0 < min_correlation < 1 and 0 < min_power_ratio <= 1):
        raise ValueError("z must be > 0, min_correlation within (0, 1), min_power_ratio within (0, 1]")
    start = np.ones_like(live)  # where a new window starts
    if reference is not None:
        ref = np.asarray(reference, dtype=np.float64)
        if ref.ndim not in (1, 2) or len(ref) != len(x):
            raise ValueError(f"reference must be (T,) or (T, k) with T = {len(x)}, got {ref.shape}")
        ref = ref.reshape(len(x), -1)
        start[1:] = np.any(ref[1:] != ref[:-1], axis=1)
    else:
        start[1:] = False
    start |= np.concatenate(([True], ~live[:-1]))
    best, longest = NO_CYCLE, 0.0
    for window in np.split(np.arange(len(x)), np.flatnonzero(start)[1:]):
        window = window[live[window]]
        window = window[int(settle * len(window)) :]
        if len(window) < min_samples:
            continue
        longest = max(longest, (len(window) // 3) * dt)
        found = _periodic(x[window], dt, z, min_correlation, min_power_ratio)
        if found is None:
            best = best._replace(tested=True)
        elif found[2] > best.correlation:
            best = LimitCycle(True, True, *found, 0.0)
    return best._replace(longest_period=longest)


def _periodic(
    x: np.ndarray, dt: float, z: float, min_correlation: float, min_power_ratio: float
) -> tuple[float, float, float] | None:
    """(period s, amplitude, rho at the period) of a persistent oscillation of x, or None."""
    # a swing within a few float32 roundings of the signal's size (the observations' precision)
    # is no motion
    floor = 64 * np.finfo(np.float32).eps * float(np.abs(x).max())
    x = scipy.signal.detrend(x, type="linear")
    n = len(x)
    power = float(x @ x) / n
    if power == 0 or power <= floor**2:
        return None
    # periods up to a third of the window (three cycles at least make an oscillation
    # persistent), their doubles up to half of it
    reach = n // 3 + 2
    lags = np.arange(max(reach, n // 2 + 1))
    acov = scipy.signal.correlate(x, x, mode="full", method="fft")[n - 1 : n - 1 + len(lags)] / (n - lags)
    rho = acov / power

    def significant(lag: int) -> bool:
        return bool(rho[lag - 1 : lag + 2].max() >= max(min_correlation, z / math.sqrt(n - lag)))

    # the candidate period: the peak of the first positive lobe after the first zero crossing
    negative = np.flatnonzero(rho[1:] <= 0)
    if negative.size == 0:
        return None
    down = negative[0] + 1
    positive = np.flatnonzero(rho[down:] > 0)
    if positive.size == 0:
        return None
    up = down + positive[0]
    ends = np.flatnonzero(rho[up:reach] <= 0)
    end = up + ends[0] if ends.size else reach
    if up >= end:
        return None
    k = up + int(np.argmax(rho[up:end]))
    if k + 1 >= reach or not significant(k):  # k is the lobe's peak: rho[k] is the max
        return None
    left, mid, right = rho[k - 1], rho[k], rho[k + 1]
    curvature = left - 2 * mid + right
    shift = 0.5 * (left - right) / curvature if curvature < 0 else 0.0
    # a periodic signal correlates as well two periods on; noise through a resonance decays
    twice = round(2 * (k + shift))
    if twice + 1 < len(rho) and not significant(twice):
        return None
    noise = power * (1.0 - rho[k])
    half = n // 2
    early = float(x[:half] @ x[:half]) / half - noise
    late = float(x[half:] @ x[half:]) / (n - half) - noise
    if early <= 0 or late < min_power_ratio * early:
        return None
    return (k + shift) * dt, math.sqrt(2.0 * acov[k]), float(rho[k])


def step_metrics(t: np.ndarray, y: np.ndarray, final: float | None = None, threshold: float = 0.02) -> dict:
    """Rise time (10-90 %), settling time (within ``threshold`` of the final value for good),
    overshoot (% of the final value) of a step response y(t) starting from 0; the final value
    is y's last unless given. The definitions of python-control's ``step_info``."""
    final = float(y[-1]) if final is None else float(final)
    if final == 0 or not np.isfinite(final):
        return {"rise_time": np.nan, "settling_time": np.nan, "overshoot": np.nan}
    sign = np.sign(final)
    lower = np.flatnonzero(sign * (y - 0.1 * final) >= 0)
    upper = np.flatnonzero(sign * (y - 0.9 * final) >= 0)
    rise = t[upper[0]] - t[lower[0]] if upper.size and lower.size else np.nan
    outside = np.flatnonzero(np.abs(y / final - 1.0) >= threshold)
    settled = 0 if outside.size == 0 else outside[-1] + 1
    settling = t[settled] if settled < len(t) else np.nan
    overshoot = max(0.0, 100.0 * (np.max(sign * y) - abs(final)) / abs(final))
    return {"rise_time": float(rise), "settling_time": float(settling), "overshoot": float(overshoot)}


def step_response(t: np.ndarray, y: np.ndarray, r: np.ndarray, alive: np.ndarray) -> dict[str, float]:
    """Step metrics averaged over the episodes whose reference is one step (NaN otherwise)."""
    found = []
    for i in range(y.shape[1]):
        jumps = np.flatnonzero(np.diff(r[:, i]) != 0)
        if len(jumps) != 1 or not alive[:, i].all():
            continue
        at = jumps[0]  # the reference changes between obs rows at and at + 1 (step at)
        size = r[at + 1, i] - r[at, i]
        base = y[at - 1, i] if at > 0 else 0.0
        response = y[at:, i] - base
        if len(response) < 10:
            continue
        found.append(step_metrics(t[at:] - t[at], response / size, final=1.0))
    if not found:
        return {"rise_time": np.nan, "settling_time": np.nan, "overshoot": np.nan}
    summary = {}
    for key in found[0]:
        values = np.array([f[key] for f in found])
        summary[key] = float(np.nanmean(values)) if np.isfinite(values).any() else np.nan
    return summary


__all__ = [
    "AT_LIMIT_TOL",
    "NO_CYCLE",
    "LimitCycle",
    "limit_cycle",
    "saturation_fraction",
    "step_metrics",
    "step_response",
]
