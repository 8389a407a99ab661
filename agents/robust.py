"""An LQ servo tuned for a spread of plants: the nominal design's weights chosen by scenario.

The LQ servo of :mod:`agents.lqi` is optimal for its one design model. Where the plant is known
only to within a spread, an engineer detunes it until the worst plants behave: here the
candidates are the servo with its action-change weight R times 1/4, 1/2, 1, ..., 16 and its
Kalman filter's process-noise ratio 1 or 10 %, and the one chosen has the smallest CVaR (mean of
the worst 10 %) of the episode cost over :data:`DESIGN_PLANTS` plants drawn with the spread
around the *design model* (never the plant it is judged on), on the env's own references and
noise, from seeds of their own (:data:`DESIGN_SEED`: not the evaluation's). The tuning is by
simulation of the design model, so it also sees what the servo's linear model leaves out (the
joint's hysteresis; on LauncherPitch the nozzle's own dynamics): it can beat the nominal servo
on the nominal plant too. The spread is the env's ``plant_spread`` when it has one, else
:data:`~ssme_envs.robustness.DEFAULT_SPREAD`.
"""

from __future__ import annotations

import dataclasses
import itertools
from typing import Any

import numpy as np

from agents.base import BatchController, task_of
from agents.lqi import LQIServo, design_servo
from agents.plants import linear_design, nozzle_joint
from ssme_envs.envs.nozzle_plants import rule_substeps
from ssme_envs.envs.plant_spread import NAMES, PlantSpread
from ssme_envs.robustness import DEFAULT_SPREAD, cvar, episode_costs

DESIGN_PLANTS = 64
DESIGN_SEED = 1_000_003
RATE_FACTORS = (0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0)
PROCESS_RATIOS = (1.0, 10.0)


def design_task(task: Any, source: str) -> Any:
    """The env's task on its design joint (``source``), drawing joints with the env's spread (or
    the default relative spread) around it: the ensemble the robust servo is tuned on."""
    nozzle = getattr(task, "nozzle", task)  # the launcher's nozzle task, or the nozzle task itself
    joint = nozzle_joint(task, source)
    spread = nozzle.spread
    if spread is None:
        tuned = PlantSpread.relative_spread(joint, DEFAULT_SPREAD)
    else:
        norm = joint.normalized()
        tuned = dataclasses.replace(spread, mean=np.array([norm[name] for name in NAMES]))
    substeps = (
        nozzle.substeps
        if nozzle is not task
        else max(nozzle.substeps, rule_substeps(tuned.corners(), nozzle.envelope))
    )
    designed = dataclasses.replace(nozzle, plant=joint, spread=tuned, substeps=substeps)
    return designed if nozzle is task else dataclasses.replace(task, nozzle=designed)


_TUNED: dict[str, tuple[float, float, float]] = {}  # by the ensemble's repr: one tuning per design


class _Candidates(BatchController):
    """Candidate servos side by side: candidate k acts on envs [k block, (k + 1) block)."""

    name = "robust candidates"

    def __init__(self, servos: list[BatchController], block: int) -> None:
        super().__init__()
        self.servos, self.block = servos, block

    def reset(self, seed: int | None = None, num_envs: int = 1, envs: np.ndarray | None = None) -> None:
        if envs is not None:
            raise ValueError(f"{self.name}: every episode starts together (no reset of some envs)")
        if num_envs != self.block * len(self.servos):
            raise ValueError(f"{self.name}: {len(self.servos)} blocks of {self.block} envs, got {num_envs}")
        super().reset(seed, num_envs)
        for servo in self.servos:
            servo.reset(seed, self.block)

    def compute(self, obs: np.ndarray) -> np.ndarray:
        b = self.block
        return np.concatenate([servo.act(obs[k * b : (k + 1) * b]) for k, servo in enumerate(self.servos)])


def _tuned(task: Any, source: str) -> tuple[float, float, float]:
    """(rate factor, process ratio, CVaR) of the best candidate on the design ensemble."""
    from ssme_envs.envs.vector import TrackingVectorEnv
    from ssme_envs.evaluation import rollout

    ensemble = design_task(task, source)
    key = repr(ensemble)
    if key in _TUNED:
        return _TUNED[key]
    candidates = list(itertools.product(RATE_FACTORS, PROCESS_RATIOS))

    class Ensemble(TrackingVectorEnv):
        """The ensemble once per candidate, in one vector env (one step for all of them): env j
        runs episode j mod DESIGN_PLANTS of the ensemble (its seed: seed + j mod DESIGN_PLANTS),
        so that every candidate meets the same plants and episodes as on an env of its own."""

        build_task = staticmethod(lambda: ensemble)

        def reset(self, *, seed: Any = None, options: Any = None) -> Any:
            if isinstance(seed, int):
                seed = [seed + j % DESIGN_PLANTS for j in range(self.num_envs)]
            return super().reset(seed=seed, options=options)

    env = Ensemble(DESIGN_PLANTS * len(candidates))
    servos = [RobustLQI(env, source, factor, process) for factor, process in candidates]
    costs = episode_costs(rollout(env, _Candidates(servos, DESIGN_PLANTS), "robust", DESIGN_SEED))
    scores = [cvar(block) for block in costs.reshape(len(candidates), DESIGN_PLANTS)]
    best = min((score, *candidate) for score, candidate in zip(scores, candidates, strict=True))
    _TUNED[key] = best[1], best[2], best[0]
    return _TUNED[key]


class RobustLQI(LQIServo):
    """The LQ servo of :mod:`agents.lqi` with its weights tuned for a spread of plants (module doc).

    Parameters
    ----------
    env : a NozzleTVC or LauncherPitch env (scalar or native vector)
    design : "identified" (default) or "truth", the nominal model
    rate_factor, process_ratio : the candidate to build; None (default): tuned on the ensemble
    """

    name = "robust"

    def __init__(
        self, env: Any, design: str = "identified", rate_factor: float | None = None,
        process_ratio: float | None = None,
    ) -> None:  # fmt: skip
        BatchController.__init__(self)
        if rate_factor is None or process_ratio is None:
            rate_factor, process_ratio, _ = _tuned(task_of(env), design)
        self.rate_factor, self.process_ratio = rate_factor, process_ratio
        nominal = linear_design(env, design)
        self.design = dataclasses.replace(nominal, rate_weight=nominal.rate_weight * rate_factor)
        self.servo = design_servo(self.design, 0.02, process_ratio)


__all__ = ["DESIGN_PLANTS", "PROCESS_RATIOS", "RATE_FACTORS", "RobustLQI", "design_task"]
