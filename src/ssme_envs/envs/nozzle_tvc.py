"""Nozzle deflection tracking through a torque actuator and a hysteretic flexible joint."""

from __future__ import annotations

from collections.abc import Callable

from ssme_envs.envs.nozzle_plants import ENV_STEP_RATE, resolve_nozzle
from ssme_envs.envs.nozzle_task import DEG, NOZZLE_OBSERVATION, NozzleTask
from ssme_envs.envs.tracking_env import TrackingEnv

OBS_NAMES = NOZZLE_OBSERVATION.names  # the observation columns, kept for existing imports


class NozzleTVCEnv(TrackingEnv):
    """Track a nozzle deflection command with the actuator torque (thrust-vector control).

    The plant is the movable nozzle of the VLS launcher's first stage: ``J x'' + b x' + F = tau``
    with the flexible joint's restoring torque F hysteretic (Bouc-Wen, Table 1 of the nozzle
    paper) by default, or linear, or any nozzle model.json; RK4 with ``substeps`` per 0.008 s step
    (3 for Table 1's joint: within half the default sensor noise of a fine-step simulation on
    3 deg motions under any torque, tested). Angles in degrees.

    The substep count is computed once per plant
    (:func:`~ssme_envs.models.nozzle.integration_substeps`): the larger of an accuracy rule
    (``h omega_n <= 0.25``, hysteresis included) and a stability rule that keeps ``h * rate <=
    1.3`` (half of RK4's 2.61 limit for any eigenvalue in the left half-plane) for the stiffness
    ``sqrt(k/J)``, the damping ``b/J`` and the Bouc-Wen hysteresis rate
    (:func:`~ssme_envs.models.nozzle.stiff_rates`).
    A plant that needs more than 10,000 substeps per step is refused with a ValueError naming
    the rate and its parameters; so is a ``substeps`` argument below the stability rule's count.
    The actuator lag and rate limit act once per step, exactly: they need no substeps (the torque
    held over a step is the lag's value at the step's end, ``e tau_(k-1) + (1 - e) u_k`` with
    ``e = exp(-dt / actuator_lag)``, then limited to ``rate_limit dt`` of change).

    ## Action Space
    ``Box(-1, 1, (1,), float32)``: the torque command as a fraction of the actuator's full scale
    (3e4 N m, about 4x the torque of a static 3 deg deflection). Optional first-order
    ``actuator_lag`` (s) and ``rate_limit`` (N m/s). Out-of-range actions are clipped; NaN or
    inf raises ValueError.

    ## Observation Space
    ``Box((6,), float32)``, finite bounds, clipped into them:

    | index | observation | unit | bound |
    |---|---|---|---|
    | 0 | measured angle (sensor noise ``sensor_noise`` rad) | deg | +-20 |
    | 1 | rate estimate (difference of measured angles; at step 1 from the rest angle 0) | deg/s | +-2000 |
    | 2 | reference | deg | +-10 |
    | 3 | tracking error (reference - measured) | deg | +-30 |
    | 4 | integral of the error (anti-windup at +-10) | deg s | +-10 |
    | 5 | previous action | - | +-1 |

    ## Rewards
    ``-0.1 e^2 - 0.1 (a_k - a_(k-1))^2`` with the error in degrees. Leaving the envelope (true
    angle beyond 6 deg) ends the episode with a penalty larger than the worst cost of all
    remaining steps, so ending early never pays.

    ## Starting State
    At rest: zero angle, rate, hysteresis state and torque.

    ## Episode End
    Termination on leaving the envelope; truncation after ``episode_seconds`` (4 s, 500 steps).
    ``gymnasium.make`` also applies the registered limit of 500 steps: for longer episodes pass
    ``max_episode_steps`` too. ``step`` after either (or before the first ``reset``) raises
    :class:`~ssme_envs.envs.tracking_env.EpisodeOverError` (through ``gymnasium.make``, before the
    first ``reset``, gymnasium's ``ResetNeeded``): call ``reset``, which takes no options (None or
    ``{}``; else TypeError or ValueError), as in ``EngineTracking-v0``.

    Non-finite state: should the plant's state overflow or turn NaN anyway (the substep rule
    is meant to prevent it; its speed bounds are estimates), the step's reward comes out NaN or
    infinite and the step ends the episode instead of handing it out: ``terminated=True``,
    ``info == {"nonfinite": True}`` (otherwise the info is ``{}``), reward ``-(horizon - t + 2)
    * step_cost_bound`` (the envelope penalty plus the worst in-envelope step, finite), and the
    observation with NaN entries 0 and infinite ones at their bounds. It ends the episode
    rather than raising because one raising sub-env would stop a whole vector env (and a
    training run), while a terminated episode resets like any other; the native vector env
    and gymnasium's ``SyncVectorEnv`` give the same values and infos (``info["nonfinite"]``
    with its ``_nonfinite`` mask, under ``final_info`` in SAME_STEP autoreset mode).

    ## Arguments
    plant : "bouc_wen" (default: Table 1's joint), "linear" (its linear row), "identified" (the
    packaged model identified from its bench test); "strong", "strong_linear",
    "strong_identified": a nozzle of our own whose Bouc-Wen joint yields at about 1.7 deg, well
    inside the +-3 deg range (not VLS data), its small-signal linear joint, and its packaged
    identified model, which the controllers' "identified" designs then use; or a nozzle
    model.json path or a model object.
    reference : "random_steps" (default), "step", "ramp", "prbs", "sine_sweep", "attitude",
    "zero", "mixed" (each episode one of random_steps, step, ramp, sine_sweep, attitude: for
    training); reference_amplitude_deg (0-3, default 3). sensor_noise (rad, default 1e-4).
    fault : ``{"kind": "gain_loss", "time": 2.0, "magnitude": 0.5}`` or ``{"kind": "sensor_bias",
    "time": 2.0, "magnitude": 0.005}`` (rad). episode_seconds, actuator_lag, rate_limit, substeps
    (1-10,000; default the rule's count). render_mode : "human" or "rgb_array".
    plant_spread : None (default: one plant), a number in (0, 0.5], or "uncertainty": each
    episode runs on a joint of its own. A number s multiplies J, b, k_el, k_hys, beta_n and gamma_n
    (the normalized Bouc-Wen parameters) by independent factors exp(s z), z standard normal
    truncated at +-3 (the exponent n is kept); "uncertainty" draws them from the covariance of the
    model.json the plant comes from (plant="identified", "strong_identified", a path or a model),
    standard deviations times uncertainty_scale (default 1), truncated at +-3 sigma. The draw uses
    the episode's generator after its noise and references (those stay what they are without a
    spread), so the native vector env equals SyncVectorEnv and a seed fixes the plant; the
    substep count is sized for the worst joint the spread can reach. The controllers still
    design on the nominal model. See :mod:`ssme_envs.envs.plant_spread` and ``ssme-envs evaluate
    --monte-carlo``.
    """

    output_names = ("nozzle angle",)
    display_scale = DEG
    display_units = ("deg", "fraction of full scale")
    build_task: Callable[..., NozzleTask] = staticmethod(NozzleTask.build)

    action_meaning = "the torque command"


__all__ = ["DEG", "ENV_STEP_RATE", "OBS_NAMES", "NozzleTVCEnv", "NozzleTask", "resolve_nozzle"]
