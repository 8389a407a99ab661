"""The nozzle family's compiled score and observation against the float step, env by env.

The float step (FLOATS, Python floats) is what the scalar env runs; the batch step with the
compiled scoring must give each env its bits, so the vector env equals ``SyncVectorEnv``. The
states, actions, steps, references, noise, faults and weights are drawn at random; the task's
numpy batch step is held to the same bits with the kernel switched off.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ssme_envs.envs import nozzle_compiled
from ssme_envs.envs.launcher_pitch import LAUNCHER_DT, LauncherState, LauncherTask
from ssme_envs.envs.nozzle_task import NOZZLE_DT, NozzleState, NozzleTask
from ssme_envs.envs.task import FLOATS, GATHER

KERNEL = nozzle_compiled.score_kernel(measured=True)
compiled = pytest.mark.skipif(KERNEL is None, reason="the compiled scoring is not built here")

finite = st.floats(-1e3, 1e3, allow_nan=False)
small = st.floats(-0.3, 0.3, allow_nan=False)  # rad: inside and outside the envelopes


def _task(launcher: bool, fault: dict | None, noise: float):
    if launcher:
        return LauncherTask.build_launcher(fault=fault, sensor_noise=noise, episode_seconds=1.0)
    return NozzleTask.build(fault=fault, sensor_noise=noise, episode_seconds=1.0)


@st.composite
def cases(draw: st.DrawFn) -> tuple:
    launcher = draw(st.booleans())
    dt = LAUNCHER_DT if launcher else NOZZLE_DT
    kind = draw(st.sampled_from([None, "sensor_bias", "gain_loss"]))
    fault = None
    if kind is not None:
        magnitude = draw(st.floats(-0.01, 0.01) if kind == "sensor_bias" else st.floats(0.1, 1.0))
        fault = {"kind": kind, "time": draw(st.integers(0, 40)) * dt, "magnitude": magnitude}
    noise = draw(st.sampled_from([0.0, 1e-4, 0.01]))
    n = draw(st.integers(1, 9))
    rows = st.lists(
        st.tuples(
            small,  # angle (nozzle) or attitude (launcher)
            st.floats(-5.0, 5.0),  # its rate
            st.floats(-10.0, 10.0) | st.sampled_from([-10.0, 10.0, 9.999999, -0.0]),  # integral
            st.floats(-1.0, 1.0),  # previous action
            st.floats(-1.0, 1.0) | st.sampled_from([-1.0, 1.0, 0.0, -0.0]),  # action
            st.integers(1, 50),  # step
            st.floats(-0.06, 0.06),  # reference, rad
            st.floats(-6.0, 6.0),  # unit noise
            small,  # the launcher's nozzle deflection, or the nozzle's last measurement
        ),
        min_size=n,
        max_size=n,
    )
    return launcher, fault, noise, draw(rows)


def _float_state(launcher: bool, row: tuple):
    x, v, integral, prev, _, _, _, _, other = row
    if launcher:
        return LauncherState((other, 0.0, 0.0), x, v, integral, prev)
    return NozzleState((x, v, 0.0), 0.0, other, integral, prev)


def _batch_state(launcher: bool, rows: list):
    x, v, integral, prev, _, _, _, _, other = (np.array(c, dtype=np.float64) for c in zip(*rows, strict=True))
    zero = np.zeros(len(rows))
    if launcher:
        return LauncherState(np.array([other, zero, zero]), x, v, integral, prev)
    return NozzleState(np.array([x, v, zero]), zero.copy(), other, integral, prev)


def _bits(a) -> bytes:
    return np.asarray(a).tobytes()


def _batch_step(task, launcher: bool, rows: list):
    state = _batch_state(launcher, rows)
    cols = list(zip(*rows, strict=True))
    action = np.array([cols[4]], dtype=np.float64)
    t = np.array(cols[5], dtype=np.int64)
    ref, noise = np.array([cols[6]]), np.array([cols[7]])
    state, obs, reward, terminated = task.step(state, action, t, ref, noise, GATHER)
    table = obs if isinstance(obs, np.ndarray) else np.array([np.asarray(o, np.float32) for o in obs])
    return state, table.astype(np.float32, copy=False), reward, terminated


@compiled
@settings(max_examples=80, deadline=None)
@given(cases())
def test_compiled_scoring_gives_the_float_steps_bits(case: tuple) -> None:
    launcher, fault, noise, rows = case
    task = _task(launcher, fault, noise)
    floats = [task.step(_float_state(launcher, r), (r[4],), r[5], (r[6],), (r[7],), FLOATS) for r in rows]
    state, values, reward, terminated = _batch_step(task, launcher, rows)
    assert isinstance(values, np.ndarray) and values.dtype == np.float32  # the kernel's table
    assert _bits(values) == _bits(np.array([obs for _, obs, _, _ in floats], dtype=np.float32).T)
    assert _bits(reward) == _bits([r for _, _, r, _ in floats])
    assert terminated.tolist() == [d for *_, d in floats]
    assert _bits(state.integral) == _bits([s.integral for s, *_ in floats])
    assert _bits(state.prev) == _bits([s.prev for s, *_ in floats])
    if not launcher:
        assert _bits(state.m_prev) == _bits([s.m_prev for s, *_ in floats])
    with pytest.MonkeyPatch.context() as patch:  # numpy's batch step: the same bits
        patch.setattr(nozzle_compiled, "score_kernel", lambda measured: None)
        _, numpy_values, numpy_reward, numpy_terminated = _batch_step(task, launcher, rows)
    assert _bits(numpy_values) == _bits(values)
    assert _bits(numpy_reward) == _bits(reward) and numpy_terminated.tolist() == terminated.tolist()


@compiled
def test_the_check_refuses_a_kernel_one_ulp_off() -> None:
    """The import-time check can fail: a kernel whose rewards are one ulp off, or whose
    observation drops the sensor bias, is refused."""

    class OffByOne:
        def __init__(self, column: int | None) -> None:
            self.column = column

        def score_batch(self, *args):
            KERNEL.score_batch(*args)
            values, reward = args[9], args[10]
            if self.column is None:
                reward[:] = np.nextafter(reward, math.inf)
            else:
                values[self.column] = np.nextafter(values[self.column], np.float32(math.inf))

    assert nozzle_compiled._kernel_agrees(KERNEL, measured=True)
    assert nozzle_compiled._kernel_agrees(KERNEL, measured=False)
    for measured in (True, False):
        assert not nozzle_compiled._kernel_agrees(OffByOne(None), measured=measured)
        assert not nozzle_compiled._kernel_agrees(OffByOne(1), measured=measured)


@compiled
@pytest.mark.parametrize("measured", [True, False])
def test_the_check_refuses_a_kernel_that_misses_the_restarts_first_observations(measured: bool) -> None:
    """Restarting envs' columns are checked against the task's ``initial_observation``: a kernel
    that steps them as the others, or rounds their error column one float32 ulp up, is refused."""

    class Stepping:
        def score_batch(self, *args):
            KERNEL.score_batch(*args[:13])

    class ErrorOff:
        def score_batch(self, *args):
            KERNEL.score_batch(*args)
            values, restarting = args[9], args[13]
            if restarting is not None:
                values[3, restarting] = np.nextafter(values[3, restarting], np.float32(math.inf))

    assert not nozzle_compiled._kernel_agrees(Stepping(), measured=measured)
    assert not nozzle_compiled._kernel_agrees(ErrorOff(), measured=measured)


@compiled
@pytest.mark.parametrize(
    ("position", "bad", "message"),
    [
        (0, np.zeros(3, dtype=np.float32), "x"),
        (2, np.zeros(5), "prev"),
        (3, np.zeros(4), "t"),
        (6, np.zeros(4)[::-1][::2], "integral"),
        (8, np.zeros(3), "extra"),
        (9, np.zeros((7, 4), dtype=np.float32), "values"),
        (11, np.zeros(4), "terminated"),
        (12, np.zeros(5), "config"),
        (13, np.zeros(4), "restarting"),
        (13, np.zeros(5, dtype=bool), "restarting"),
    ],
)
def test_the_kernel_names_a_bad_argument(position: int, bad: np.ndarray, message: str) -> None:
    n = 4
    args = [
        np.zeros(n), np.zeros(n), np.zeros(n), np.ones(n, dtype=np.int64), np.zeros(n), np.zeros(n),
        np.zeros(n), np.zeros(n), None, np.zeros((6, n), dtype=np.float32), np.zeros(n),
        np.zeros(n, dtype=bool), NozzleTask.build().score_config, np.zeros(n, dtype=bool),
    ]  # fmt: skip
    args[position] = bad
    with pytest.raises((ValueError, BufferError), match=message):
        KERNEL.score_batch(*args)
    with pytest.raises(TypeError, match="score_batch"):
        KERNEL.score_batch(*args[:-2])
