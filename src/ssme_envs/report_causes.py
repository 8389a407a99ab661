"""Why a controller costs more than the zero action in the main report: causes measured by the
metrics (early ends, limit cycles, time at a limit), causes computed for the scenario (the
coupled PI loop's spectral radius on the truth's linear model, the costs of the controllers a
cause compares with), a shipped policy's training options read from its config, and what runs
of the scenario showed, written down."""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

from ssme_envs.evaluation_result import ControllerMetrics, EvaluationResult

TRACKING = "ssme_envs/EngineTracking-v0"
THROTTLE = "ssme_envs/EngineThrottle-v0"
NOZZLE = "ssme_envs/NozzleTVC-v0"
LAUNCHER = "ssme_envs/LauncherPitch-v0"

# learned controllers: their names before the colon; everything else but `zero` is classical
LEARNED = ("ppo", "sac", "td3")
SATURATED = 0.05  # time at the limit (share) from which it is named as a cause

# (results, scenario, controller) -> the cause, in words
Cause = Callable[[EvaluationResult, str, str], str]


def is_classical(controller: str) -> bool:
    """Whether a controller spec names a classical design (not `zero`, not a learned policy)."""
    return controller != "zero" and controller.split(":")[0] not in LEARNED


def measured_causes(metrics: ControllerMetrics, unit: str) -> list[str]:
    """What the metrics show that raises a cost: early ends, limit cycles, actuators at their
    limits (``unit``: the outputs' unit)."""
    causes = []
    if metrics.terminations:
        causes.append(
            f"ended early in {metrics.terminations} of {metrics.episodes} episodes (each charged the "
            "cost of the steps it had left)"
        )
    for name, out in metrics.outputs.items():
        if math.isfinite(out.limit_cycle_fraction) and out.limit_cycle_fraction > 0:
            causes.append(
                f"limit cycle in {100 * out.limit_cycle_fraction:.0f} % of episodes "
                f"({out.limit_cycle_period:.2f} s, +-{out.limit_cycle_amplitude:.2g} {unit} {name})"
            )
    for name, act in metrics.actuators.items():
        if act.time_at_limit >= SATURATED:
            causes.append(f"{name} at its limit {100 * act.time_at_limit:.0f} % of the time")
    return causes


def _growth(results: EvaluationResult, scenario: str, controller: str) -> str:
    """How the unstable loop's oscillation ends, from the time FPOV spends at its limit and the
    limit cycles measured."""
    metrics = results[scenario][controller]
    at_limit = metrics.actuators["FPOV"].time_at_limit
    if at_limit >= SATURATED:
        return "the oscillation grows until FPOV hits its limit"
    cycles = any(out.limit_cycle_fraction > 0 for out in metrics.outputs.values())  # NaN: untested
    where = "into the limit cycle above" if cycles else "(no limit cycle measured)"
    return f"the oscillation grows {where}, FPOV at its limit {100 * at_limit:.0f} % of the time"


@functools.cache  # each line of a scenario's causes asks again (pi and pi:truth, four missions)
def _coupled_radii(
    env_id: str, scenario: str, gains_from: str, powers: tuple[float | None, ...]
) -> tuple[float, ...]:
    """Spectral radius of the decoupled PI's loop (SIMC gains on the ``gains_from`` design model at
    the scenario's power) closed around the whole linear truth at each of ``powers`` (None: the
    scenario's own), cross-coupling included (:func:`agents.pid.coupled_radius`)."""
    from agents.pid import coupled_radius, diagonal_simc
    from agents.plants import linear_design
    from ssme_envs.evaluation import make_env

    env = make_env(env_id, scenario, 1, None)
    try:
        kc, ki = diagonal_simc(linear_design(env, gains_from))
        return tuple(coupled_radius(linear_design(env, "truth", power=p), kc, ki) for p in powers)
    finally:
        env.close()


def _pi_coupling(results: EvaluationResult, scenario: str, controller: str) -> str:
    from agents.lqi import schedule_levels

    levels = tuple(schedule_levels("truth").tolist())
    radii = _coupled_radii(results.env_id, scenario, "identified", levels)
    unstable = [level for level, r in zip(levels, radii, strict=True) if r > 1.0]
    where = (
        f"above 1 on the linked truth at {', '.join(f'{v:g}' for v in unstable)} % of its levels "
        f"{', '.join(f'{v:g}' for v in levels)} % (largest {max(radii):.3f})"
        if unstable
        else f"below 1 at every level of the linked truth (largest {max(radii):.3f})"
    )
    return (
        "its SIMC gains, tuned loop by loop on the 100 % model with the cross-coupling ignored, close "
        f"a coupled linear loop whose spectral radius is {where}: {_growth(results, scenario, controller)}; "
        "`pi_scheduled` (each level's gains detuned until the coupled loop is stable) and the "
        "`scheduled` servo are the engineer's answers"
    )


def _pi_bucket(results: EvaluationResult, scenario: str, controller: str) -> str:
    identified, truth = (
        _coupled_radii(results.env_id, scenario, gains, (None,))[0] for gains in ("identified", "truth")
    )
    cure = (
        "tuning at the operating point does not make it stable, detuning does (EngineThrottle's "
        "`pi_scheduled`)"
        if truth >= 1.0
        else "tuned on the truth here the loop is stable"
    )
    return (
        "the SIMC gains, tuned loop by loop with the cross-coupling ignored, close a coupled loop on "
        f"the truth's linear model here of spectral radius {identified:.3f} (gains tuned on the "
        f"identified model) and {truth:.3f} (tuned on the truth here): "
        f"{_growth(results, scenario, controller)}; {cure}"
    )


def _stuck_coupled(results: EvaluationResult, scenario: str, controller: str) -> str:
    from ssme_envs.evaluation import SCENARIOS

    rows = results[scenario]
    zero = rows["zero"].cost_mean
    when = SCENARIOS[results.env_id][scenario]["fault"]["time"]
    said = (
        f"once OPOV sticks (at {when:g} s) its coupled gain still sets FPOV as if OPOV answered, so "
        "FPOV chases the Pc error along its own direction and drives MR away"
    )
    if controller != "lq:truth" and "lq:truth" in rows and rows["lq:truth"].cost_mean > zero:
        lq = rows["lq:truth"]
        said += (
            f". Integral windup is not the cause: `lq:truth`, with negligible integral action and OPOV "
            f"at its limit {100 * lq.actuators['OPOV'].time_at_limit:.0f} % of the time, costs "
            f"{lq.cost_mean / zero:.2f}x the zero action too"
        )
    if "pi" in rows:
        said += f". The decoupled PI (FPOV on MR alone) costs {rows['pi'].cost_mean / zero:.2f}x"
    return said


def _said(text: str) -> Cause:
    return lambda results, scenario, controller: text


_STRONG_PID = (
    "on the strong joint, which yields past about 1.7 deg, the PID (placed on the small-signal "
    "stiffness, no reference feedforward) overshoots at the sweep's fast end to 5-6 deg where the "
    "reference peaks below 3 deg and leaves the +-6 deg envelope; on the same joint's linear twin "
    "it stays inside"
)
_MISSIONS = ("mission", "mission_noise_off", "mission_linear", "mission_nonlinear")
# (env, scenario, controller) -> why it costs more than the zero action: computed for the
# scenario, or what runs of it showed; the measured lines come with it
WRITTEN_CAUSES: dict[tuple[str, str, str], Cause] = {
    **{(THROTTLE, s, "pi"): _pi_coupling for s in _MISSIONS},
    **{(TRACKING, s, c): _pi_bucket for s in ("bucket", "nonlinear_bucket") for c in ("pi", "pi:truth")},
    **{(TRACKING, "stuck_valve", c): _stuck_coupled for c in ("lqi", "lqi:truth", "lq:truth")},
    (NOZZLE, "sine_sweep_strong", "pid"): _said(_STRONG_PID),
}


def options_text(options: dict) -> str:
    """Env options as TOML writes them inline: ``plant = "identified", truth = {backlash = 0.0}``."""
    from ssme_envs.outputs import toml_value

    return ", ".join(f"{k} = {toml_value(v)}" for k, v in options.items())


def training_cause(results: EvaluationResult, scenario: str, controller: str) -> str | None:
    """Why a shipped policy may not cope with a scenario's fault, read from its training config
    (``config.toml`` beside the policy): the env options it was trained with, where they set no
    fault, and for a residual policy its base design's cost here. None for other controllers and
    scenarios."""
    from ssme_envs.evaluation import SCENARIOS

    fault = SCENARIOS.get(results.env_id, {}).get(scenario, {}).get("fault")
    if fault is None or controller.split(":")[0] not in LEARNED:
        return None
    from agents.run_config import load_config
    from agents.shipped import shipped_specs

    directory = shipped_specs(results.env_id).get(controller)
    if directory is None:  # a run of the user's: its options are not ours to read
        return None
    config = load_config(directory / "config.toml")
    options = config.get("env_options", {})
    if "fault" in options:
        return None
    trained = options_text(options) or "the env's defaults"
    said = (
        f"trained without faults (agents/policies/{directory.name}/config.toml: {trained}): it has never "
        f"met a {fault['kind'].replace('_', ' ')}"
    )
    base = config.get("residual")
    rows = results[scenario]
    if base is None or base not in rows or "zero" not in rows:
        return said
    share = rows[base].cost_mean / rows["zero"].cost_mean
    return f"a correction to `{base}`, which costs {share:.2f}x the zero action here; {said}"


def written_cause(results: EvaluationResult, scenario: str, controller: str) -> str | None:
    """The cause computed or written down for a controller on a scenario, or a shipped policy's
    training options (:func:`training_cause`); None where there is neither."""
    cause = WRITTEN_CAUSES.get((results.env_id, scenario, controller))
    return cause(results, scenario, controller) if cause else training_cause(results, scenario, controller)


__all__ = [
    "LAUNCHER",
    "LEARNED",
    "NOZZLE",
    "SATURATED",
    "THROTTLE",
    "TRACKING",
    "WRITTEN_CAUSES",
    "Cause",
    "is_classical",
    "measured_causes",
    "options_text",
    "training_cause",
    "written_cause",
]
