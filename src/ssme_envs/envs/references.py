"""Reference signals and fault specifications for the tracking environments.

Every generator takes a seeded numpy Generator and returns a whole episode at reset, so that the
per-step cost is an index and the random streams do not depend on how the episode is stepped.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

REFERENCE_KINDS = ("random_steps", "step", "ramp", "prbs", "zero")
FAULT_KINDS = ("stuck_valve", "sensor_bias", "gain_loss")


def uniforms_needed(kind: str, length: int, channels: int, dt: float) -> int:
    """How many uniform numbers :func:`reference_signals` consumes for one episode."""
    if kind == "zero":
        return 0
    if kind == "random_steps":
        return _hold_count(length, dt) * (1 + channels)
    if kind == "step":
        return 1 + channels
    if kind == "ramp":
        return 2 + channels
    if kind == "prbs":
        return length * channels + channels
    raise ValueError(f"unknown reference kind {kind!r}; choose one of {', '.join(REFERENCE_KINDS)}")


def _hold_count(length: int, dt: float) -> int:
    return -(-length // round(1.0 / dt))  # holds of at least 1 s cover the episode


def reference_signals(
    kind: str, uniforms: np.ndarray, length: int, amplitude: np.ndarray, dt: float
) -> np.ndarray:
    """References of k episodes, shape (k, length, channels), from uniforms in [0, 1) of shape
    (k, :func:`uniforms_needed`), for deviations within +-amplitude per channel.

    Kinds
    -----
    random_steps : piecewise constant, levels uniform in +-amplitude, held 1 to 3 s.
    step : zero, then one step to a random level at a random time in the first 40 % of the episode.
    ramp : zero, then a ramp to a random level over 1 to 4 s, starting in the first 30 %.
    prbs : +-amplitude per channel, switching with probability dt / 0.5 s each step.
    zero : regulation about the operating point.

    Every episode is computed from its own row alone, so one episode drawn by itself equals the
    same episode drawn in a batch.
    """
    k, channels = uniforms.shape[0], amplitude.size
    steps = np.arange(length)
    if kind == "zero":
        return np.zeros((k, length, channels))
    if kind == "random_steps":
        count = _hold_count(length, dt)
        shortest, longest = round(1.0 / dt), round(3.0 / dt)
        holds = shortest + np.floor(uniforms[:, :count] * (longest - shortest + 1)).astype(np.int64)
        levels = (2.0 * uniforms[:, count:].reshape(k, count, channels) - 1.0) * amplitude
        ends = np.cumsum(holds, axis=1)
        starts = np.zeros((k, length + 1), dtype=np.int64)  # 1 where a new hold begins
        rows, cols = np.nonzero(ends < length)
        starts[rows, ends[rows, cols]] = 1
        segment = np.cumsum(starts[:, :length], axis=1) + (np.arange(k) * count)[:, None]
        return levels.reshape(k * count, channels)[segment]
    if kind == "step":
        at = np.floor(uniforms[:, 0] * max(1, int(0.4 * length)))
        level = (2.0 * uniforms[:, 1:] - 1.0) * amplitude
        return (steps[None, :] >= at[:, None])[:, :, None] * level[:, None, :]
    if kind == "ramp":
        at = np.floor(uniforms[:, 0] * max(1, int(0.3 * length)))
        span = round(1.0 / dt) + np.floor(uniforms[:, 1] * (round(4.0 / dt) - round(1.0 / dt) + 1))
        level = (2.0 * uniforms[:, 2:] - 1.0) * amplitude
        ramp = np.clip((steps[None, :] - at[:, None]) / span[:, None], 0.0, 1.0)
        return ramp[:, :, None] * level[:, None, :]
    if kind == "prbs":
        flips = uniforms[:, : length * channels].reshape(k, length, channels) < min(1.0, dt / 0.5)
        start = np.where(uniforms[:, length * channels :] < 0.5, -1.0, 1.0)
        signs = np.where(np.cumsum(flips, axis=1) % 2 == 0, 1.0, -1.0) * start[:, None, :]
        return signs * amplitude
    raise ValueError(f"unknown reference kind {kind!r}; choose one of {', '.join(REFERENCE_KINDS)}")


@dataclass(frozen=True)
class Fault:
    """A fault injected at a given time.

    kind : "stuck_valve" (valve ``index`` holds its command from ``time`` on), "sensor_bias"
        (output ``index`` reads ``magnitude`` too high, normalized units), or "gain_loss"
        (valve ``index`` moves only ``magnitude`` times its command).
    time : s after reset.
    """

    kind: str
    time: float
    index: int = 0
    magnitude: float = 0.0

    @classmethod
    def parse(cls, spec: Mapping[str, Any] | Fault | None, n_valves: int, n_outputs: int) -> Fault | None:
        """A Fault from a dict like ``{"kind": "sensor_bias", "time": 4, "index": 0, "magnitude": 0.005}``."""
        if spec is None or isinstance(spec, Fault):
            fault = spec
        elif isinstance(spec, Mapping):
            unknown = sorted(set(spec) - {"kind", "time", "index", "magnitude"})
            if unknown:
                raise ValueError(f"fault: unknown key(s) {', '.join(unknown)}")
            if "kind" not in spec or "time" not in spec:
                raise ValueError("fault needs 'kind' and 'time'")
            defaults = {"stuck_valve": 0.0, "sensor_bias": 0.005, "gain_loss": 0.5}
            kind = spec["kind"]
            if kind not in FAULT_KINDS:
                raise ValueError(f"unknown fault kind {kind!r}; choose one of {', '.join(FAULT_KINDS)}")
            fault = cls(kind, spec["time"], spec.get("index", 0), spec.get("magnitude", defaults[kind]))
        else:
            raise ValueError(f"fault must be a dict or None, got {type(spec).__name__}")
        if fault is None:
            return None
        if fault.kind not in FAULT_KINDS:
            raise ValueError(f"unknown fault kind {fault.kind!r}; choose one of {', '.join(FAULT_KINDS)}")
        if not isinstance(fault.time, int | float) or not np.isfinite(fault.time) or fault.time < 0:
            raise ValueError(f"fault time must be a number of seconds >= 0, got {fault.time!r}")
        limit = n_outputs if fault.kind == "sensor_bias" else n_valves
        if not isinstance(fault.index, int) or not 0 <= fault.index < limit:
            raise ValueError(f"fault index must be an integer in 0..{limit - 1}, got {fault.index!r}")
        if not isinstance(fault.magnitude, int | float) or not np.isfinite(fault.magnitude):
            raise ValueError(f"fault magnitude must be a finite number, got {fault.magnitude!r}")
        if fault.kind == "sensor_bias" and abs(fault.magnitude) > 0.05:
            raise ValueError(
                f"sensor_bias magnitude is a normalized deviation within +-0.05, got {fault.magnitude!r}"
            )
        if fault.kind == "gain_loss" and not 0.0 <= fault.magnitude <= 1.0:
            raise ValueError(
                f"gain_loss magnitude is the remaining gain, within 0-1, got {fault.magnitude!r}"
            )
        return fault
