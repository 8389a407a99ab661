"""Reference signals and fault specifications for the tracking environments.

Every episode's reference and sensor noise come from uniforms its env drew at reset, so that the
random streams do not depend on how the episode is stepped. They are computed a prefix of the
episode at a time, as the episode reaches it: every kind is causal (a step's value depends on
the uniforms and the steps before it alone), so a prefix equals the same steps of the whole.
"""

from __future__ import annotations

import math
from functools import cache
from typing import NamedTuple

import numpy as np

from ssme_envs.envs.task import Uniforms

REFERENCE_KINDS = ("random_steps", "step", "ramp", "prbs", "sine_sweep", "attitude", "zero", "mixed")
# what a "mixed" episode draws from, with equal probability
MIXED_KINDS = ("random_steps", "step", "ramp", "sine_sweep", "attitude")
_BLOCK_NUMBERS = 1 << 16  # numbers per row block of normal_pairs: 256 KiB arrays, which stay in cache


def check_reference(kind: str) -> str:
    """The reference kind, or ValueError listing the valid ones (TypeError for other than a str:
    a numpy array compared with the kinds would be ambiguous, or pass as its one element)."""
    if not isinstance(kind, str):
        kinds = ", ".join(REFERENCE_KINDS)
        raise TypeError(f"reference must be a str, one of {kinds}; got {type(kind).__name__}")
    if kind not in REFERENCE_KINDS:
        raise ValueError(f"unknown reference {kind!r}; choose one of {', '.join(REFERENCE_KINDS)}")
    return kind


def uniforms_needed(kind: str, length: int, channels: int, dt: float) -> int:
    """How many uniform numbers :func:`reference_signals` consumes for one episode."""
    if kind == "zero":
        return 0
    if kind in ("random_steps", "attitude"):
        return _hold_count(length, dt) * (1 + channels)
    if kind == "sine_sweep":
        return channels
    if kind == "step":
        return 1 + channels
    if kind == "ramp":
        return 2 + channels
    if kind == "prbs":
        return length * channels + channels
    if kind == "mixed":
        return 1 + max(uniforms_needed(each, length, channels, dt) for each in MIXED_KINDS)
    raise ValueError(f"unknown reference kind {kind!r}; choose one of {', '.join(REFERENCE_KINDS)}")


def _hold_count(length: int, dt: float) -> int:
    return -(-length // round(1.0 / dt))  # holds of at least 1 s cover the episode


def _hold_steps(dt: float) -> tuple[int, int]:
    """The shortest and longest hold of random_steps, in steps: 1 s and 3 s."""
    return round(1.0 / dt), round(3.0 / dt)


class StreamLayout(NamedTuple):
    """Where one step's unit noise and random_steps reference lie in a one-channel episode's
    draw, so that a step's values can be made alone (:mod:`ssme_envs.envs.episode_streams`):
    noise row t is row t of ``normal_rows(draw, half, ...)``; the reference's ``holds`` hold
    lengths are the uniforms at ``refs_at``, ``shortest + floor(u (longest - shortest + 1))``
    steps each, and their levels the next ``holds``, ``(2 u - 1) amplitude``."""

    half: int
    refs_at: int
    holds: int
    shortest: int
    longest: int
    amplitude: float

    @classmethod
    def random_steps(cls, length: int, dt: float, amplitude: float) -> StreamLayout:
        """The layout of an episode of ``length`` steps drawn as the nozzle task draws it: the
        noise's Box-Muller pairs (``length`` rounded up to even), then the reference's uniforms."""
        pairs = length + length % 2
        return cls(pairs // 2, pairs, _hold_count(length, dt), *_hold_steps(dt), amplitude)


def reference_signals(
    kind: str,
    uniforms: np.ndarray,
    length: int,
    amplitude: np.ndarray,
    dt: float,
    start: int = 0,
    stop: int | None = None,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """References of k episodes of ``length`` steps, their steps [start, stop) (default: all),
    shape (channels, stop - start, k) (written into ``out`` where given), from uniforms in [0, 1)
    of shape (:func:`uniforms_needed`, k), for deviations within +-amplitude per channel. The
    episode axis is last, the layout in which the vector envs read one step of every env. Steps
    [start, stop) equal the same steps of the whole episode; they cost in proportion to ``stop -
    start`` for random_steps, to ``stop`` for the kinds whose level depends on every step before
    (attitude, prbs).

    Kinds
    -----
    random_steps : piecewise constant, levels uniform in +-amplitude, held 1 to 3 s.
    step : zero, then one step to a random level at a random time in the first 40 % of the episode.
    ramp : zero, then a ramp to a random level over 1 to 4 s, starting in the first 30 %.
    prbs : +-amplitude per channel, switching with probability dt / 0.5 s each step.
    sine_sweep : a sine from 0.2 Hz to 5 Hz (frequency linear in time over the episode), its
        amplitude uniform in 50-100 % of ``amplitude``.
    attitude : smooth commands like an attitude controller's: random steps through a critically
        damped second-order filter with a 1 Hz natural frequency.
    zero : regulation about the operating point.
    mixed : each episode one of random_steps, step, ramp, sine_sweep, attitude, equally likely
        (a training distribution that covers the evaluation scenarios).

    Every episode is computed from its own column alone, so one episode drawn by itself equals
    the same episode drawn in a batch.
    """
    stop = length if stop is None else stop
    if kind == "random_steps":  # straight into ``out``
        return _random_steps(uniforms, length, amplitude, dt, start, stop, out)
    refs = _reference_block(kind, uniforms, length, amplitude, dt, start, stop)
    if out is None:
        return refs
    out[...] = refs
    return out


def _reference_block(
    kind: str, uniforms: np.ndarray, length: int, amplitude: np.ndarray, dt: float, start: int, stop: int
) -> np.ndarray:
    """:func:`reference_signals` of every kind but random_steps, a new array."""
    k, channels = uniforms.shape[1], amplitude.size
    steps = np.arange(start, stop)[:, None]
    scale = amplitude[:, None, None]
    if kind == "zero":
        return np.zeros((channels, stop - start, k))
    if kind == "mixed":
        choice = np.minimum((uniforms[0] * len(MIXED_KINDS)).astype(np.intp), len(MIXED_KINDS) - 1)
        refs = np.empty((channels, stop - start, k))
        for index, each in enumerate(MIXED_KINDS):
            episodes = np.flatnonzero(choice == index)
            if episodes.size:
                need = uniforms_needed(each, length, channels, dt)
                picked = uniforms[1 : 1 + need][:, episodes]
                refs[:, :, episodes] = reference_signals(each, picked, length, amplitude, dt, start, stop)
        return refs
    if kind == "sine_sweep":
        time = np.arange(start, stop) * dt
        f0, f1, duration = 0.2, 5.0, max((length - 1) * dt, dt)  # the whole episode's sweep
        wave = np.sin(2.0 * np.pi * (f0 * time + (f1 - f0) * time**2 / (2.0 * duration)))
        level = (0.5 + 0.5 * uniforms) * amplitude[:, None]
        return wave[None, :, None] * level[:, None, :]
    if kind == "attitude":
        held = reference_signals("random_steps", uniforms, length, amplitude, dt, 0, stop)
        from scipy import signal  # here: importing it costs more than making an env

        return signal.lfilter(*_attitude_filter(dt), held, axis=1)[:, start:]
    if kind == "step":
        at = np.floor(uniforms[0] * max(1, int(0.4 * length)))
        level = (2.0 * uniforms[1:] - 1.0) * amplitude[:, None]
        return np.where(steps >= at, level[:, None, :], 0.0)
    if kind == "ramp":
        at = np.floor(uniforms[0] * max(1, int(0.3 * length)))
        span = round(1.0 / dt) + np.floor(uniforms[1] * (round(4.0 / dt) - round(1.0 / dt) + 1))
        level = (2.0 * uniforms[2:] - 1.0) * amplitude[:, None]
        return np.clip((steps - at) / span, 0.0, 1.0) * level[:, None, :]
    if kind == "prbs":
        flips = (uniforms[: length * channels] < min(1.0, dt / 0.5)).reshape(channels, length, k)[:, :stop]
        flips = flips.copy()  # accumulated in place
        first = np.where(uniforms[length * channels :] < 0.5, -1.0, 1.0)
        for c in range(channels):
            _accumulate_rows(flips[c], np.logical_xor)  # odd number of flips so far
        return np.where(flips[:, start:], -1.0, 1.0) * first[:, None, :] * scale
    raise ValueError(f"unknown reference kind {kind!r}; choose one of {', '.join(REFERENCE_KINDS)}")


def _random_steps(
    uniforms: np.ndarray, length: int, amplitude: np.ndarray, dt: float, start: int, stop: int,
    out: np.ndarray | None,
) -> np.ndarray:  # fmt: skip
    """:func:`reference_signals`' random_steps, into ``out`` if given."""
    k, channels = uniforms.shape[1], amplitude.size
    count = _hold_count(length, dt)
    shortest, longest = _hold_steps(dt)
    # hold j ends at step (j + 1) shortest or later: only the first `live` can end in the block
    live = min(count, (stop - 1) // shortest)
    refs = np.empty((channels, stop - start, k)) if out is None else out
    if live == 0:  # the block lies in the first hold (a reset's first block): its levels, held
        level = 2.0 * uniforms[count : count + channels] - 1.0
        level *= amplitude.reshape(channels, 1)
        refs[...] = level[:, None, :]
        return refs
    ends = shortest + np.floor(uniforms[:live] * (longest - shortest + 1)).astype(np.intp)
    _accumulate_rows(ends)  # integer sums: cumsum's bits, without its strided walk
    # flat index of (hold, episode) at every step: episode i at hold j is j k + i; the block
    # starts from the holds ended by its first step and moves on by k at each new hold, so
    # that a block costs its own steps, not the episode's prefix
    index = np.empty((stop - start, k), dtype=np.intp)
    index[0] = np.arange(k)
    if start:  # no hold ends at step 0
        index[0] += k * np.add.reduce(ends <= start, axis=0, dtype=np.intp)
    rows, cols = np.nonzero((ends > start) & (ends < stop))
    if rows.size:
        index[1:] = 0
        index[ends[rows, cols] - start, cols] = k
        _accumulate_rows(index)
    else:  # no hold ends in the block
        index[1:] = index[0]
    for c in range(channels):  # mode "clip" (indices are in range) writes without buffering
        level = 2.0 * uniforms[count + c : count + (live + 1) * channels : channels] - 1.0
        level *= amplitude[c]  # hold h's row is count + h channels + c
        np.take(level, index, out=refs[c], mode="clip")
    return refs


@cache
def _attitude_filter(dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold discretization of w^2 / (s + w)^2, w = 2 pi rad/s, unit DC gain."""
    omega = 2.0 * np.pi
    from scipy import signal

    num, den, _ = signal.cont2discrete(([omega**2], [1.0, 2.0 * omega, omega**2]), dt, method="zoh")
    return np.ravel(num), np.asarray(den, dtype=float)


def _accumulate_rows(table: np.ndarray, operation: np.ufunc = np.add) -> None:
    """Running ``operation`` down the rows of a (steps, k) table, in place. Many episodes go row
    by row: numpy's accumulate along axis 0 walks one column at a time, strided, an order of
    magnitude slower then; for a few it is the faster (same results: integer and boolean)."""
    if table.shape[1] < 16:
        operation.accumulate(table, axis=0, out=table)
        return
    for row in range(1, table.shape[0]):
        operation(table[row - 1], table[row], out=table[row])


def unit_normals(uniforms: np.ndarray) -> np.ndarray:
    """Standard normal float32 numbers from uniform float32 ones in [0, 1), by the Box-Muller
    transform: an even number of rows, (2 r, ...) -> (2 r, ...), rows i and r + i paired."""
    return normal_rows(uniforms, uniforms.shape[0] // 2, 0, uniforms.shape[0])


def normal_rows(
    uniforms: Uniforms, half: int, start: int, stop: int, out: np.ndarray | None = None
) -> np.ndarray:
    """Rows [start, stop) of ``unit_normals(uniforms[: 2 half])``, (stop - start, ...) float32,
    from the uniforms they pair alone: row i < half is ``R(u_i) cos(2 pi u_half+i)``, row
    half + i is ``R(u_i) sin(2 pi u_half+i)``, ``R(u) = sqrt(-2 log(1 - u))``.

    Elementwise float32 work on contiguous copies (numpy's SIMD loops then give every element
    the same bits wherever it sits): an env drawn alone gets the same bits as in a batch, and a
    block of rows the same bits as the whole. Cosine and sine rows of overlapping pairs share
    their radii and angles. Written into ``out`` where given."""
    parts = []  # (wave, first pair, end pair), in row order
    if start < half:
        parts.append((np.cos, start, min(stop, half)))
    if stop > half:
        parts.append((np.sin, max(start, half) - half, stop - half))
    if out is None:
        out = np.empty((stop - start, *uniforms.shape[1:]), dtype=np.float32)
    lo, hi = min(p[1] for p in parts), max(p[2] for p in parts)
    shared = _radius_and_angle(uniforms, half, lo, hi) if _overlap(parts) else None
    row = 0
    for wave, first, end in parts:
        if shared is None:
            radius, angle = _radius_and_angle(uniforms, half, first, end)
        else:
            radius, angle = (a[first - lo : end - lo] for a in shared)
        _waves(wave, radius, angle, out[row : row + end - first])
        row += end - first
    return out


def normal_pairs(
    uniforms: Uniforms, half: int, start: int, stop: int, out: np.ndarray | None = None
) -> np.ndarray:
    """The cosine and sine normals of the pairs [start, stop): rows [start, stop) and [half +
    start, half + stop) of ``unit_normals(uniforms[: 2 half])`` (see :func:`normal_rows`), (2,
    stop - start, ...) float32 (written into ``out`` where given), each pair's radius and angle
    computed once."""
    if out is None:
        out = np.empty((2, stop - start, *uniforms.shape[1:]), dtype=np.float32)
    # pairs a few rows at a time where a row holds many envs: their temporaries then stay in
    # cache, where a whole block of thousands of envs spills to memory and faults in fresh pages
    # (elementwise work: the same bits in any rows)
    rows = max(1, _BLOCK_NUMBERS // max(1, math.prod(uniforms.shape[1:])))
    for lo in range(start, stop, rows):
        hi = min(stop, lo + rows)
        radius, angle = _radius_and_angle(uniforms, half, lo, hi)
        _waves(np.cos, radius, angle, out[0, lo - start : hi - start])
        _waves(np.sin, radius, angle, out[1, lo - start : hi - start])
    return out


def _overlap(parts: list) -> bool:
    return len(parts) == 2 and parts[0][1] < parts[1][2] and parts[1][1] < parts[0][2]


def _radius_and_angle(uniforms: Uniforms, half: int, start: int, stop: int) -> tuple[np.ndarray, np.ndarray]:
    """``R(u_i)`` and ``2 pi u_half+i`` for the pairs i in [start, stop), float32."""
    radius = np.ascontiguousarray(uniforms[start:stop], dtype=np.float32)
    # in place where the read made a new array (the vector envs' draws), else into a new one:
    # the uniforms may be the caller's (a slice of an array is a view, its base set)
    radius = np.negative(radius, out=radius if radius.base is None else None)
    np.log1p(radius, out=radius)  # 1 - u in (0, 1]
    radius *= -2.0
    np.sqrt(radius, out=radius)
    angle = np.ascontiguousarray(uniforms[half + start : half + stop], dtype=np.float32)
    return radius, np.multiply(angle, np.float32(2.0 * np.pi), out=angle if angle.base is None else None)


def _waves(wave: np.ufunc, radius: np.ndarray, angle: np.ndarray, out: np.ndarray) -> None:
    """``out = radius wave(angle)``, in place."""
    wave(angle, out=out)
    out *= radius
