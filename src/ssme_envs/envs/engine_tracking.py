"""Chamber pressure and mixture ratio tracking at one SSME power level."""

from __future__ import annotations

from ssme_envs.envs.engine_task import (
    ENGINE_OBSERVATION,
    EngineTask,
    design_model,
    resolve_plant,
    resolve_truth,
)
from ssme_envs.envs.tracking_env import TrackingEnv

OBS_NAMES = ENGINE_OBSERVATION.names  # the observation columns, kept for existing imports


class EngineTrackingEnv(TrackingEnv):
    """Track chamber pressure (Pc) and mixture ratio (MR) with the OPOV and FPOV valves.

    The plant is an SSME point model (NASA TM-104422) at one power level, 0.04 s per step: by
    default the truth (the linked published model at ``power`` with the lambda gains of eq 36,
    valve backlash and stiction, sensor noise), or an identified design model, or any engine
    model.json. Quantities are deviations from the operating point; percentages are of the
    100 % point values (d Pc = 0.01 is 1 %).

    ## Action Space
    ``Box(-1, 1, (2,), float32)``: OPOV and FPOV valve commands; the valve deviation is
    ``action * action_scale`` (default 0.02 normalized valve travel). Out-of-range actions are
    clipped; NaN or inf raises ValueError.

    ## Observation Space
    ``Box((10,), float32)``, finite bounds, clipped into them:

    | index | observation | unit | bound |
    |---|---|---|---|
    | 0, 1 | measured Pc, MR deviation | % | +-50 |
    | 2, 3 | Pc, MR reference | % | +-50 |
    | 4, 5 | tracking errors (reference - measured) | % | +-100 |
    | 6, 7 | integrals of the errors (anti-windup at +-100) | % s | +-100 |
    | 8, 9 | previous action | - | +-1 |

    ## Rewards
    ``-0.1 (e_pc^2 + e_mr^2) - 0.1 |a_k - a_(k-1)|^2`` with errors in %: about -0.1 per step
    for 1 % errors. Leaving the envelope (a noise-free Pc or MR tracking error above 10 %) ends the
    episode with a penalty larger than the worst cost of all remaining steps, so ending early
    never pays.

    ## Starting State
    The operating point (zero deviations, valves at their nominal positions).

    ## Episode End
    Termination on leaving the envelope; truncation after ``episode_seconds`` (10 s, 250 steps).
    ``gymnasium.make`` also applies the registered limit of 250 steps: for longer episodes pass
    ``max_episode_steps`` too. ``step`` after ``terminated`` or ``truncated`` (or before the first
    ``reset``) raises :class:`~ssme_envs.envs.tracking_env.EpisodeOverError` (a ``ValueError``
    and an ``AssertionError``, as gymnasium's ``SyncVectorEnv`` refuses it in DISABLED autoreset
    mode): call ``reset``. Through ``gymnasium.make``, a step before the first ``reset`` meets
    gymnasium's ``OrderEnforcing`` wrapper first, which raises ``gymnasium.error.ResetNeeded``.
    (gymnasium's ``TimeLimit`` wrapper does not check: behind a limit shorter than the episode the
    env steps on.) ``reset`` takes no options: ``options`` must be None or ``{}``, else TypeError
    (not a dict) or ValueError (naming the unknown keys).

    ## Arguments
    power : 65-109 %, default 100. plant : "truth" (default: the linked published model at
    ``power``), "identified" (at 70, 80, 90, 100 %), a model.json path or a model (its dt within
    0.001-0.5 s, an episode at most 1e6 steps), or "nonlinear": the synthetic nonlinear engine
    of :mod:`ssme_envs.models.engine_nonlinear` (consistent with Table I's local models, not
    Rocketdyne's simulation; a ``NonlinearEngine`` object also serves, e.g. with a schedule lag
    or ``authority_loss=0``), started at its trim at ``power``, its parameters scheduled on the
    power implied by its own chamber pressure; the valve effects and sensor noise of ``truth``
    act as on the linear plant, ``asymmetric_gains=False`` makes its valve flow curve linear
    (its valve authority, which falls away from the trim, stays), and a controller's ``"truth"``
    design model is its linearization at ``power``. truth : TruthConfig or dict
    (asymmetric_gains, backlash and stiction within 0-0.4 valve travel, sensor_noise within
    0-0.05 normalized), the effects added to the plant.
    reference : "random_steps" (default), "step", "ramp", "prbs", "sine_sweep", "attitude",
    "zero", "mixed" (each episode one of random_steps, step, ramp, sine_sweep, attitude);
    reference_amplitude (normalized, default 0.01).
    fault : e.g. ``{"kind": "stuck_valve", "time": 4.0, "index": 0}``, ``{"kind": "sensor_bias",
    "time": 4.0, "index": 0, "magnitude": 0.005}``, ``{"kind": "gain_loss", "time": 4.0,
    "index": 1, "magnitude": 0.5}``. episode_seconds, action_scale. render_mode : "human" or
    "rgb_array".
    """

    output_names = ("Pc", "MR")
    build_task = staticmethod(EngineTask.build)


__all__ = ["OBS_NAMES", "EngineTask", "EngineTrackingEnv", "design_model", "resolve_plant", "resolve_truth"]
