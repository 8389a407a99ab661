"""How many RK4 substeps a nozzle joint needs per sample: accuracy and stability rules."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ssme_envs.models.nozzle_joint import NozzleParameters


class StiffRate(NamedTuple):
    """A rate (1/s) that limits RK4's step on a joint: its name, value and the parameters
    behind it (for messages)."""

    name: str
    rate: float
    detail: str


def accuracy_rate(params: NozzleParameters, amplitude: float) -> StiffRate:
    """The rate (1/s) of :func:`recommended_substeps`: the faster of the joint's natural
    frequency ``omega_n`` and, once the joint yields, the hysteresis variable's own rate
    ``omega_n * amplitude * n / w_max`` with ``w_max = (beta_n + gamma_n)^(-1/n)`` (``inf`` where
    it overflows)."""
    norm = params.normalized()
    omega = float(np.sqrt((norm["k_el"] + norm["k_hys"]) / norm["J"]))
    load = norm["beta_n"] + norm["gamma_n"]
    detail = f"k = {norm['k_el'] + norm['k_hys']:.6g} N m/rad, J = {norm['J']:.6g} kg m^2"
    if norm["k_hys"] > 0 and load > 0:
        try:
            w_max = load ** (-1.0 / norm["n"])
        except OverflowError:  # a vanishing load: no saturation within reach
            w_max = math.inf
        hysteresis = omega * amplitude * norm["n"] / w_max if w_max > 0 else math.inf
        if hysteresis > omega:
            detail += f", beta_n + gamma_n = {load:.6g}, n = {norm['n']:.6g}, amplitude = {amplitude:g} rad"
            return StiffRate("hysteresis rate omega_n amplitude n / w_max", hysteresis, detail)
    return StiffRate("natural frequency sqrt(k/J)", omega, detail)


def recommended_substeps(
    params: NozzleParameters, dt: float, amplitude: float, step_rate: float = 0.2
) -> int:
    """RK4 substeps per sample so that ``h * rate <= step_rate`` for a motion of ``amplitude`` rad
    (an accuracy rule; :func:`integration_substeps` adds the stability rule).

    ``rate`` (:func:`accuracy_rate`) is the faster of the joint's natural frequency ``omega_n``
    and, once the joint yields, the hysteresis variable's own rate ``omega_n * amplitude * n /
    w_max`` with ``w_max = (beta_n + gamma_n)^(-1/n)``: large beta + gamma make the z equation
    stiff. The default 0.2 keeps the angle within about 2e-4 of a fine reference for Table 1's
    nozzle and for a strongly hysteretic one on a +-3 deg PRBS
    (experiments/results/nozzle_integration_accuracy.md), Table 1's within half the default
    sensor noise (1e-4 rad on 3 deg) on other torques:
    the sign switch of the Bouc-Wen law at velocity reversals, which ``rate`` does not count,
    limits RK4 to about second order there.

    Raises
    ------
    ValueError
        When the rate overflows (no finite count).
    """
    if not (amplitude > 0 and step_rate > 0 and dt > 0):
        raise ValueError("dt, amplitude and step_rate must be positive")
    fastest = accuracy_rate(params, amplitude)
    count = dt * fastest.rate / step_rate
    if not math.isfinite(count):
        raise ValueError(f"the joint's {fastest.name} overflows ({fastest.detail})")
    return max(1, int(np.ceil(count)))


# RK4's stability: on y' = lambda y one step multiplies y by R(h lambda) = 1 + z + z^2/2 + z^3/6 +
# z^4/24, and |R| <= 1 holds on [-2.785, 0] of the real axis, on [-2.828, 2.828] i of the
# imaginary axis (2 sqrt 2), and on the whole half-disc |z| <= 2.61, Re z <= 0 (the region's
# boundary comes closest to 0 at about 123 degrees, radius 2.616). A rate bound that holds for
# every eigenvalue in the left half-plane, whatever its angle, is therefore h |lambda| <= 2.61.
# The env rule keeps half of that (STABILITY_SAFETY = 0.5): the rates of stiff_rates bound a
# linearized, state-dependent Jacobian rather than give its eigenvalues (the joint's three
# rates add up in coupled modes, and the speed bound behind the hysteresis rate is an energy
# estimate), and at half the limit a step still damps a fast real mode as the flow does
# (R(-1.3) = 0.27, exp(-1.3) = 0.27) instead of ringing at the edge of the region.
RK4_REAL_AXIS_LIMIT = 2.785  # h |lambda| where RK4's stability region meets the negative real axis
RK4_IMAGINARY_AXIS_LIMIT = 2.828  # ... and the imaginary axis
RK4_HALF_DISC_LIMIT = 2.61  # radius of the largest left half-disc inside the region
STABILITY_SAFETY = 0.5
STABLE_STEP_RATE = STABILITY_SAFETY * RK4_HALF_DISC_LIMIT  # h * rate bound of the stability rule
MAX_SUBSTEPS = 10_000  # RK4 steps per env step; a plant that needs more is refused


def stiff_rates(
    params: NozzleParameters, amplitude: float, torque_limit: float, dt: float
) -> list[StiffRate]:
    """The rates (1/s) that bound the eigenvalues of the joint's Jacobian for an env that ends
    its episode once ``|x| > amplitude`` (rad) at the end of a sample of ``dt`` s, under torques
    up to ``torque_limit`` N m (finite).

    - ``stiffness``: ``sqrt((k_el + k_hys) / J)``, the natural frequency at small signal (the
      modulus of the complex pair of the linear joint);
    - ``damping``: ``b / J``, the bound of the fast real root of an overdamped joint (the roots'
      modulus never exceeds ``max(b / J, sqrt(k / J))``);
    - ``hysteresis`` (a joint with ``k_hys > 0`` only): the slope in w of the normalized Bouc-Wen
      law ``w' = v (1 - c |w|^n)``, ``c = beta_n + gamma_n sign(v w)``, as the integrators
      implement it: ``|dw'/dw| = |v| |c| n |w|^(n - 1) <= v_max (|beta_n| + gamma_n) n
      w_b^(n - 1)``, ``|beta_n| + gamma_n`` being the larger of the loading and the unloading
      ``|c|`` (gamma_n >= 0). For n < 1 the slope is larger nearer w = 0, but the term
      ``c |w|^n`` it belongs to vanishes there: no growth follows.

    The speed and travel behind the third are energy estimates, not proofs (the non-finite
    guard of the envs is the net). With ``X = amplitude``, ``T = torque_limit``:

    - ``v_0 = sqrt((k X^2 + 4 X T) / J)``: the speed inside the envelope, from the elastic energy
      at a turning point plus the torque's work over one traverse;
    - ``X_t = X + v_0 dt + T dt^2 / (2 J)``: the travel within the sample that leaves the
      envelope (the envelope is checked at the sample's end);
    - ``w_b = min(w_max, 2 X_t)``: ``|w|`` never passes ``w_max = (beta_n + gamma_n)^(-1/n)``
      from rest, and grows at most as fast as x (while loading);
    - ``v_max = sqrt((k X_t^2 + 4 X_t F) / J) + F dt / J`` with ``F = T + k_hys w_b``: the energy
      bound over that travel, plus what the torque and the hysteretic force add in one sample.

    A rate that overflows reads ``inf``.
    """
    if not (amplitude > 0 and dt > 0 and torque_limit > 0 and math.isfinite(torque_limit)):
        raise ValueError("amplitude, dt and torque_limit must be positive and finite")
    norm = params.normalized()
    j, k, k_hys = norm["J"], norm["k_el"] + norm["k_hys"], norm["k_hys"]
    rates = [
        StiffRate("stiffness rate sqrt(k/J)", math.sqrt(k / j), f"k = {k:.6g} N m/rad, J = {j:.6g} kg m^2"),
        StiffRate("damping rate b/J", norm["b"] / j, f"b = {norm['b']:.6g} N m s/rad, J = {j:.6g} kg m^2"),
    ]
    if k_hys > 0:
        beta, gamma, n = norm["beta_n"], norm["gamma_n"], norm["n"]
        x, torque = amplitude, torque_limit
        v_0 = math.sqrt((k * x * x + 4.0 * x * torque) / j)
        travel = x + v_0 * dt + 0.5 * torque * dt * dt / j
        load = beta + gamma
        log_w = math.log(2.0 * travel) if math.isfinite(travel) else math.inf
        if load > 0:
            log_w = min(log_w, -math.log(load) / n)
        w_b = math.exp(min(log_w, 700.0))
        force = torque + k_hys * w_b
        v_max = math.sqrt((k * travel * travel + 4.0 * travel * force) / j) + force * dt / j
        c_max = abs(beta) + gamma
        rate = 0.0
        if c_max > 0 and v_max > 0:  # in logs: |w|^(n - 1) over- or underflows for extreme n
            log_rate = math.log(v_max) + math.log(c_max) + math.log(n) + (n - 1.0) * log_w
            rate = math.exp(log_rate) if log_rate < 700.0 else math.inf
        detail = (
            f"beta_n = {beta:.6g}, gamma_n = {gamma:.6g}, n = {n:.6g}, |v| <= {v_max:.6g} rad/s, "
            f"|w| <= {w_b:.6g} rad"
        )
        rates.append(StiffRate("hysteresis rate |v| (|beta_n| + gamma_n) n |w|^(n-1)", rate, detail))
    return rates


def stable_substeps(
    params: NozzleParameters,
    dt: float,
    amplitude: float,
    torque_limit: float,
    step_rate: float = STABLE_STEP_RATE,
) -> tuple[float, StiffRate]:
    """RK4 steps per sample of ``dt`` s that keep ``h * rate <= step_rate`` for every rate of
    :func:`stiff_rates`: the count (a float, at least 1; ``inf`` where a rate overflowed) and
    the rate that sets it."""
    fastest = max(stiff_rates(params, amplitude, torque_limit, dt), key=lambda r: r.rate)
    count = dt * fastest.rate / step_rate
    return (float(max(1, math.ceil(count))) if math.isfinite(count) else math.inf), fastest


def integration_substeps(
    params: NozzleParameters,
    dt: float,
    amplitude: float,
    torque_limit: float,
    accuracy_step_rate: float,
    max_substeps: int = MAX_SUBSTEPS,
    sample: str = "sample",
) -> int:
    """RK4 steps per ``sample`` of ``dt`` s for an env: the larger of the accuracy rule
    (:func:`recommended_substeps` at ``accuracy_step_rate``) and the stability rule
    (:func:`stable_substeps`), for a travel of ``amplitude`` rad under torques up to
    ``torque_limit`` N m. Computed once per plant.

    Raises
    ------
    ValueError
        When more than ``max_substeps`` are needed, naming the rate and its parameters.
    """
    stable, _ = stable_substeps(params, dt, amplitude, torque_limit)
    accurate = accuracy_rate(params, amplitude)
    accurate_count = dt * accurate.rate / accuracy_step_rate
    accurate_count = float(max(1, math.ceil(accurate_count))) if math.isfinite(accurate_count) else math.inf
    count = max(stable, accurate_count)
    if count > max_substeps:
        stability = f"RK4 stability at safety {STABILITY_SAFETY:g}"
        rules = [(r, STABLE_STEP_RATE, stability) for r in stiff_rates(params, amplitude, torque_limit, dt)]
        rules.append((accurate, accuracy_step_rate, "accuracy"))
        over = sorted(
            (rule for rule in rules if dt * rule[0].rate / rule[1] > max_substeps),
            key=lambda rule: -rule[0].rate / rule[1],
        )
        causes = "; ".join(
            f"its {r.name} = {r.rate:.4g} 1/s ({r.detail}) asks for h <= {step_rate / r.rate:.3g} s "
            f"(h * rate <= {step_rate:.3g}, {why})"
            for r, step_rate, why in over
        )
        raise ValueError(
            f"nozzle plant refused: it needs {count:.3g} RK4 substeps per {dt * 1e3:g} ms {sample}, more "
            f"than {max_substeps}: {causes}"
        )
    return int(count)


def check_stable_substeps(
    params: NozzleParameters, substeps: int, dt: float, amplitude: float, torque_limit: float
) -> None:
    """Refuse (ValueError naming the rate) a given count of RK4 steps per sample of ``dt`` s
    that the stability rule (:func:`stable_substeps`) finds too few."""
    needed, fastest = stable_substeps(params, dt, amplitude, torque_limit)
    if substeps < needed:
        raise ValueError(
            f"substeps={substeps} is too few for this nozzle plant: RK4 needs {needed:.3g} per "
            f"{dt * 1e3:g} ms for its {fastest.name} = {fastest.rate:.4g} 1/s ({fastest.detail}) at "
            f"h * rate <= {STABLE_STEP_RATE:.3g}"
        )


__all__ = [
    "MAX_SUBSTEPS",
    "RK4_HALF_DISC_LIMIT",
    "RK4_IMAGINARY_AXIS_LIMIT",
    "RK4_REAL_AXIS_LIMIT",
    "STABILITY_SAFETY",
    "STABLE_STEP_RATE",
    "StiffRate",
    "accuracy_rate",
    "check_stable_substeps",
    "integration_substeps",
    "recommended_substeps",
    "stable_substeps",
    "stiff_rates",
]
