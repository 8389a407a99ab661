"""Faults an episode can inject: a stuck valve, a sensor bias or a loss of valve gain, from a
given time on, checked as the envs take them."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ssme_envs.envs.task import MAX_EPISODE_SECONDS, check_keys, real_number, shown

FAULT_KINDS = ("stuck_valve", "sensor_bias", "gain_loss")
# s: no env's episode is longer; refused here, a later (or infinite) time would overflow the
# rounding to a step before the env's own "beyond the episode" check
MAX_FAULT_TIME = MAX_EPISODE_SECONDS


@dataclass(frozen=True)
class Fault:
    """A fault injected at a given time.

    kind : "stuck_valve" (valve ``index`` holds, from ``time`` on, the command of the first step
        at or after ``round(time / dt)``), "sensor_bias"
        (output ``index`` reads ``magnitude`` too high, normalized units), or "gain_loss"
        (valve ``index`` moves only ``magnitude`` times its command).
    time : s after reset.
    """

    kind: str
    time: float
    index: int = 0
    magnitude: float = 0.0

    def step(self, dt: float, horizon: int) -> int:
        """The step the fault's time rounds to (``round(time / dt)``), checked to lie before the last
        of a ``horizon``-step episode's steps (a fault acts from the step after it, a sensor bias
        from that step on); ValueError naming the time and the times that do."""
        step = round(self.time / dt)
        if step >= horizon:
            raise ValueError(
                f"fault time {self.time:g} s is beyond the episode ({horizon * dt:g} s) or at its last "
                f"step (it rounds to step {step} of {dt:g} s, and the episode has {horizon}): give a time "
                f"below {(horizon - 0.5) * dt:g} s"
            )
        return step

    @staticmethod
    def sensor_bias(fault: Fault | None) -> float:
        """The size of ``fault``'s sensor bias (0 for no fault or another kind): what the bound on
        a step's tracking error adds."""
        return abs(fault.magnitude) if fault is not None and fault.kind == "sensor_bias" else 0.0

    @classmethod
    def parse(
        cls,
        spec: Mapping[str, Any] | Fault | None,
        n_valves: int,
        n_outputs: int,
        kinds: Sequence[str] = FAULT_KINDS,
    ) -> Fault | None:
        """A Fault from a dict like ``{"kind": "sensor_bias", "time": 4, "index": 0, "magnitude": 0.005}``
        (or a Fault, checked), or None; ``kinds``: the kinds the env takes (a subset of
        :data:`FAULT_KINDS`), the only ones its messages offer. ValueError naming the bad field."""
        if spec is None or isinstance(spec, Fault):
            fault = spec
        elif isinstance(spec, Mapping):
            check_keys("fault", spec, ("kind", "time", "index", "magnitude"))
            if "kind" not in spec or "time" not in spec:
                raise ValueError("fault needs 'kind' and 'time'")
            defaults = {"stuck_valve": 0.0, "sensor_bias": 0.005, "gain_loss": 0.5}
            kind = _fault_kind(spec["kind"], kinds)
            fault = cls(kind, spec["time"], spec.get("index", 0), spec.get("magnitude", defaults[kind]))
        else:
            raise ValueError(f"fault must be a dict or None, got {type(spec).__name__}")
        if fault is None:
            return None
        _fault_kind(fault.kind, kinds)
        time = real_number(fault.time)
        if time is None or not 0.0 <= time <= MAX_FAULT_TIME:  # NaN fails the comparisons
            raise ValueError(
                f"fault time must be a number of seconds in 0-{MAX_FAULT_TIME:g}, got {shown(fault.time)}"
            )
        limit = n_outputs if fault.kind == "sensor_bias" else n_valves
        index = fault.index
        if (
            isinstance(index, bool | np.bool_)
            or not isinstance(index, int | np.integer)
            or not 0 <= index < limit
        ):
            raise ValueError(f"fault index must be an integer in 0..{limit - 1}, got {shown(index)}")
        magnitude = real_number(fault.magnitude)
        if magnitude is None or not np.isfinite(magnitude):
            raise ValueError(f"fault magnitude must be a finite number, got {shown(fault.magnitude)}")
        if fault.kind == "sensor_bias" and abs(magnitude) > 0.05:
            raise ValueError(
                f"sensor_bias magnitude is a normalized deviation within +-0.05, got {shown(fault.magnitude)}"
            )
        if fault.kind == "gain_loss" and not 0.0 <= magnitude <= 1.0:
            raise ValueError(
                f"gain_loss magnitude is the remaining gain, within 0-1, got {shown(fault.magnitude)}"
            )
        return cls(fault.kind, time, int(index), magnitude)  # numpy numbers as Python ones


def _fault_kind(kind: Any, kinds: Sequence[str]) -> str:
    """``kind`` if it is one of ``kinds``, else ValueError listing them. A str is checked first:
    ``in`` on an array compares elementwise (a 1-element array passed, then failed as a dict key)."""
    if not isinstance(kind, str):
        raise ValueError(
            f"fault kind must be a str, one of {', '.join(kinds)}; got {type(kind).__name__} {shown(kind)}"
        )
    if kind not in kinds:
        raise ValueError(f"unknown fault kind {kind!r}; choose one of {', '.join(kinds)}")
    return kind


__all__ = ["FAULT_KINDS", "MAX_FAULT_TIME", "Fault"]
