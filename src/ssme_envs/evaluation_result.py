"""The typed result of :func:`ssme_envs.evaluation.evaluate`.

An :class:`EvaluationResult` holds ``{scenario: {controller: ControllerMetrics}}`` and, as a
separate field, one :class:`~ssme_envs.evaluation.Rollout` per pair for plotting. The metric
classes also read like the dicts they replace (``m["outputs"]["Pc"]["iae"]``): the reports and
the studies index them by name, and :meth:`ControllerMetrics.to_dict` is exactly the mapping that
results.json holds. Nothing reads results.json back: an older file (with ``saturated_steps``, the
count of requested actions beyond +-1, where ``time_at_limit`` now stands) is a record only.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import asdict, dataclass, field, fields
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ssme_envs.evaluation import Rollout


class _ByName:
    """Read access to a dataclass's fields by name, as for the dict it replaces."""

    def __getitem__(self, key: str) -> Any:
        if key not in self.keys():
            raise KeyError(key)
        return getattr(self, key)

    def __contains__(self, key: object) -> bool:
        return key in self.keys()

    def keys(self) -> list[str]:
        return [f.name for f in fields(self)]  # type: ignore[arg-type]

    def to_dict(self) -> dict[str, Any]:
        """The fields as plain (nested) dicts, in declaration order: the results.json layout."""
        return asdict(self)  # type: ignore[call-overload]


@dataclass(frozen=True)
class OutputMetrics(_ByName):
    """Tracking metrics of one output, means over the episodes.

    Attributes
    ----------
    iae, ise, itae : float
        Integrals of the absolute, squared and time-weighted absolute error.
    steady_state_error : float
        Mean absolute error over the last 10 % (at least one step) of each episode's own
        steps, averaged over the episodes: an episode that ended early counts its last steps.
    rise_time, settling_time, overshoot : float
        Step metrics over the episodes whose reference is one step (NaN when there is none).
    limit_cycle_fraction : float
        Share (0-1) of the episodes with a persistent oscillation of the error while the
        references hold still (:func:`ssme_envs.metrics.limit_cycle`), among those with a window
        long enough to test (NaN when none had one).
    limit_cycle_period, limit_cycle_amplitude : float
        Median period (s) and sine-equivalent amplitude (the output's unit) over the episodes
        with one (NaN when none).
    limit_cycle_longest_period : float
        Median over the tested episodes of the longest period their windows could show, s: no
        limit cycle found means none up to it (NaN when none was tested).
    """

    iae: float
    ise: float
    itae: float
    steady_state_error: float
    rise_time: float
    settling_time: float
    overshoot: float
    limit_cycle_fraction: float
    limit_cycle_period: float
    limit_cycle_amplitude: float
    limit_cycle_longest_period: float


@dataclass(frozen=True)
class ActuatorMetrics(_ByName):
    """Wear and limits of one actuator, means over the episodes.

    Attributes
    ----------
    effort_rms : float
        RMS of the applied action (fraction of full scale) over the alive steps.
    travel, reversals : float
        Summed absolute moves and changes of direction per episode.
    time_at_limit : float
        Share (0-1) of each episode's alive steps at which the applied action sits at +-1
        (within :data:`ssme_envs.metrics.AT_LIMIT_TOL` of full scale), averaged.
    """

    effort_rms: float
    travel: float
    reversals: float
    time_at_limit: float


@dataclass(frozen=True)
class ControllerMetrics(_ByName):
    """Everything measured of one controller on one scenario.

    Attributes
    ----------
    episodes : int
        Episodes run.
    return_mean, return_std : float
        Episode return over the episodes.
    cost_mean, cost_cvar90 : float
        Episode cost (minus the return): mean, and mean of the worst 10 %.
    terminations : int
        Episodes that ended before the horizon.
    outputs, actuators : dict
        Per-output and per-actuator metrics, by name.
    """

    episodes: int
    return_mean: float
    return_std: float
    cost_mean: float
    cost_cvar90: float
    terminations: int
    outputs: dict[str, OutputMetrics] = field(default_factory=dict)
    actuators: dict[str, ActuatorMetrics] = field(default_factory=dict)


@dataclass(eq=False)  # Mapping's equality: field-wise == would compare rollout arrays
class EvaluationResult(Mapping[str, dict[str, ControllerMetrics]]):
    """Metrics of every controller on every scenario of one env, and the rollouts behind them.

    Indexing by scenario name gives ``{controller: ControllerMetrics}``; iterating gives the
    scenario names in the order they were run.

    Attributes
    ----------
    env_id : str
        The env evaluated.
    scenarios : dict
        ``{scenario: {controller: ControllerMetrics}}``.
    rollouts : dict
        ``{(scenario, controller): Rollout}``, one per pair, for plotting.
    """

    env_id: str
    scenarios: dict[str, dict[str, ControllerMetrics]] = field(default_factory=dict)
    rollouts: dict[tuple[str, str], Rollout] = field(default_factory=dict)

    def __getitem__(self, scenario: str) -> dict[str, ControllerMetrics]:
        return self.scenarios[scenario]

    def __iter__(self) -> Iterator[str]:
        return iter(self.scenarios)

    def __len__(self) -> int:
        return len(self.scenarios)

    def add(self, scenario: str, controller: str, metrics: ControllerMetrics, run: Rollout) -> None:
        """Record one controller's metrics and rollout on one scenario."""
        self.scenarios.setdefault(scenario, {})[controller] = metrics
        self.rollouts[(scenario, controller)] = run

    def runs(self, scenario: str) -> dict[str, Rollout]:
        """The rollouts of every controller on ``scenario``, by controller."""
        return {name: self.rollouts[(scenario, name)] for name in self.scenarios[scenario]}

    def to_dict(self) -> dict[str, dict[str, dict[str, Any]]]:
        """``{scenario: {controller: metrics dict}}``: what results.json holds under "scenarios"."""
        return {s: {c: m.to_dict() for c, m in rows.items()} for s, rows in self.scenarios.items()}


__all__ = ["ActuatorMetrics", "ControllerMetrics", "EvaluationResult", "OutputMetrics"]
