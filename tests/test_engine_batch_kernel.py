"""The engine's compiled batch step against the float step, env by env, bit for bit.

The float step on the Python reference (no kernel) is what the scalar env runs; the compiled
batch step must give each env its bits: the vector env then equals ``SyncVectorEnv``. States,
actions, steps and faults are drawn at random, NaN and infinities among the states, episodes
at different steps (the gathered rows of the throttle's schedule) and at one.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import random_rollout
from hypothesis import given, settings
from hypothesis import strategies as st

import ssme_envs  # noqa: F401  (registers the environments)
from ssme_envs.envs import engine_compiled
from ssme_envs.envs.engine_task import EnginePlant, EngineState, EngineTask
from ssme_envs.envs.engine_throttle import ThrottleTask
from ssme_envs.envs.task import FLOATS, GATHER
from ssme_envs.models import engine_step

compiled = pytest.mark.skipif(
    not engine_step.has_batch(engine_step._KERNEL), reason="the compiled batch step is not built here"
)
PROFILE = [(0.0, 100.0), (2.0, 100.0), (4.0, 75.0), (6.0, 75.0)]  # 150 steps of the schedule
FAULTS = [
    None,
    {"kind": "stuck_valve", "time": 1.0, "index": 0},
    {"kind": "stuck_valve", "time": 0.0, "index": 1},
    {"kind": "gain_loss", "time": 1.0, "index": 1, "magnitude": 0.3},
    {"kind": "sensor_bias", "time": 1.0, "index": 0, "magnitude": -0.02},
    {"kind": "sensor_bias", "time": 0.0, "index": 1, "magnitude": 0.01},
]


def _tasks(throttle: bool, fault: dict | None, truth: dict) -> tuple[EngineTask, EngineTask]:
    """The task with the compiled batch step, and the same task on the Python reference."""
    build = (
        (lambda: ThrottleTask.build_throttle(profile=PROFILE, fault=fault, truth=truth))
        if throttle
        else (lambda: EngineTask.build(fault=fault, truth=truth, reference="prbs"))
    )
    task = build()
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(engine_step, "_KERNEL", None)
        reference = build()
    assert task.batch_args is not None and reference.batch_args is None
    return task, reference


def _bits(values) -> list:
    return ["nan" if v != v else np.float64(v).view(np.int64).item() for v in values]


def _state_floats(state: EngineState, j: int) -> EngineState:
    """Env ``j`` of a batch state as the float step holds it."""
    (x, linkage, valve), integral, prev, held = state
    return EngineState(
        EnginePlant(x[:, j].tolist(), tuple(linkage[:, j].tolist()), tuple(valve[:, j].tolist())),
        (float(integral[0][j]), float(integral[1][j])),
        (float(prev[0][j]), float(prev[1][j])),
        float(held[j]),
    )


def _flat(state: EngineState) -> list:
    (x, linkage, valve), integral, prev, held = state
    return [*x, *linkage, *valve, *integral, *prev, held]


@compiled
@settings(max_examples=60, deadline=None)
@given(
    throttle=st.booleans(),
    fault=st.sampled_from(FAULTS),
    truth=st.sampled_from([{}, {"backlash": 0.0, "stiction": 0.0}, {"stiction": 0.05}]),
    n=st.integers(1, 300),
    synced=st.booleans(),
    seed=st.integers(0, 2**32 - 1),
    special=st.sampled_from([np.nan, np.inf, -np.inf, -0.0, 1e300]),
)
def test_the_compiled_batch_step_gives_every_env_the_float_steps_bits(
    throttle, fault, truth, n, synced, seed, special
) -> None:
    task, reference = _tasks(throttle, fault, truth)
    rng = np.random.default_rng(seed)
    x = rng.normal(0.0, 0.05, (task.n_states, n))
    x[rng.integers(task.n_states), rng.integers(n)] = special  # a NaN, an infinity, a signed zero
    nominal = task.offset_table[0][:, None] if task.offset_table is not None else 0.0
    linkage = nominal + rng.normal(0.0, 0.01, (2, n))
    valve = linkage + rng.normal(0.0, 0.005, (2, n))
    state = EngineState(
        EnginePlant(x, linkage, valve),
        tuple(rng.uniform(-150.0, 150.0, (2, n))),  # beyond the integrals' clip at times
        tuple(rng.uniform(-1.0, 1.0, (2, n))),
        rng.normal(0.0, 0.05, n),
    )
    start = rng.integers(1, task.horizon + 1)
    t = np.full(n, start) if synced else rng.integers(1, task.horizon + 1, n)
    if task.fault_step >= 0 and not synced:  # the steps about the fault's start
        for j, shift in zip(rng.integers(0, n, 3), range(3), strict=True):
            t[j] = min(max(task.fault_step + shift, 1), task.horizon)
    elif task.fault_step >= 0 and rng.random() < 0.5:
        t[:] = min(max(task.fault_step + rng.integers(0, 3), 1), task.horizon)
    action = rng.uniform(-1.0, 1.0, (2, n))
    ref = rng.uniform(-0.05, 0.05, (2, n)) if rng.random() < 0.5 else rng.uniform(-0.05, 0.05, (2, 1))
    noise = rng.normal(0.0, 1.0, (2, n)).astype(np.float32)
    floats = [_state_floats(state, j) for j in range(n)]  # before the batch step writes in place

    new, values, reward, terminated = task.step(state, action, t, ref, noise, GATHER)

    assert values.dtype == np.float32 and values.shape == (10, n)
    for j in range(n):
        r = ref[:, j if ref.shape[1] == n else 0].tolist()
        want = reference.step(floats[j], action[:, j].tolist(), int(t[j]), r, noise[:, j].tolist(), FLOATS)
        got_state = _state_floats(new, j)
        assert _bits(_flat(got_state)) == _bits(_flat(want[0])), f"state of env {j}"
        with np.errstate(over="ignore"):  # 1e300 is inf in float32, in both
            want_values = np.array(want[1], dtype=np.float32)
        assert _bits(values[:, j].tolist()) == _bits(want_values.tolist()), f"values of env {j}"
        assert _bits([reward[j]]) == _bits([want[2]]) and bool(terminated[j]) == bool(want[3])


@compiled
@pytest.mark.parametrize("env_id", ["ssme_envs/EngineTracking-v0", "ssme_envs/EngineThrottle-v0"])
@pytest.mark.parametrize("fault", FAULTS[:2] + FAULTS[3:5])
def test_the_vector_env_gives_the_same_bits_with_the_compiled_step_and_numpys(env_id, fault) -> None:
    """Episodes ending at different steps (large actions), so that the rows are gathered."""
    options = {"action_scale": 0.2, **({"fault": fault} if fault else {})}
    if env_id.endswith("Throttle-v0"):
        options["profile"] = PROFILE
    with_kernel = random_rollout(env_id, 5, True, 400, 16, **options)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(engine_compiled, "batch_args", lambda *args, **kwargs: None)
        numpy_step = random_rollout(env_id, 5, True, 400, 16, **options)
    assert all(np.array_equal(a, b) for a, b in zip(with_kernel, numpy_step, strict=True))


def _call(task: EngineTask, n: int, **change) -> tuple:
    """A valid task_batch call on ``n`` envs, with arguments replaced by ``change``; the state
    arrays in it, to see that a refused call leaves them."""
    args = task.batch_args
    names = (
        "x", "linkage", "valve", "integral0", "integral1", "held", "prev0", "prev1", "action", "t",
        "r0", "r1", "z0", "z1", "values", "reward", "terminated", "config", "table", "offsets",
    )  # fmt: skip
    state = (np.zeros((task.n_states, n)), np.zeros((2, n)), np.zeros((2, n)), *np.zeros((5, n)))
    values = dict(zip(names[:9], (*state, np.zeros((2, n))), strict=True))
    values.update(
        t=np.ones(n, dtype=np.int64),
        r0=np.zeros(n),
        r1=np.zeros(1),
        z0=np.zeros(n, np.float32),
        z1=np.zeros(n, np.float32),
        values=np.empty((10, n), np.float32),
        reward=np.empty(n),
        terminated=np.empty(n, bool),
        config=args.config,
        table=args.table,
        offsets=args.offsets,
    )
    values.update(change)
    return tuple(values[name] for name in names)


@compiled
@pytest.mark.parametrize(
    ("change", "error", "match"),
    [
        ({"x": np.zeros((5, 4), np.float32)}, ValueError, "x: a C-contiguous array"),
        ({"x": np.zeros((5, 8))[:, ::2]}, ValueError, "contiguous"),
        ({"linkage": np.zeros((2, 3))}, ValueError, "linkage"),
        ({"z0": np.zeros(4)}, ValueError, "z0"),
        ({"r0": np.zeros(3)}, ValueError, "references of N envs or one"),
        ({"t": np.zeros(4, np.int32)}, ValueError, "t: "),
        ({"values": np.zeros((10, 4))}, ValueError, "values"),
        ({"config": np.zeros(3)}, ValueError, "config"),
        ({"table": b"\0" * 8}, ValueError, "a table of a step or more"),
        ({"table": "rows"}, TypeError, "table: bytes"),
        ({"terminated": np.zeros(4, np.int8)}, ValueError, "terminated"),
    ],
)
def test_the_batch_kernel_refuses_arguments_that_do_not_fit(change, error, match) -> None:
    task, _ = _tasks(False, None, {})
    with pytest.raises(error, match=match):
        engine_step._KERNEL.task_batch(*_call(task, 4, **change))


@compiled
def test_a_refused_step_leaves_the_state_as_it_was() -> None:
    """Steps outside the schedule, and a shift source beyond the states, are refused before any
    state is written."""
    throttle, _ = _tasks(True, None, {})
    for bad_t in (0, throttle.horizon + 2):
        args = _call(throttle, 3, t=np.array([1, bad_t, 2]), x=np.full((throttle.n_states, 3), 0.25))
        with pytest.raises(ValueError, match="outside the nominal valves"):
            engine_step._KERNEL.task_batch(*args)
        assert (args[0] == 0.25).all() and (args[3] == 0.0).all()
    task, _ = _tasks(False, None, {})
    rows = ((-1, 0.1, 0.2, 0.3, 0.4),) * (task.n_states - 1) + ((task.n_states, 0.1, 0.2, 0.3, 0.4),)
    bad, _ = engine_step.pair_table([((0.0, 0.0), rows)])
    args = _call(task, 2, table=bad, x=np.full((task.n_states, 2), 0.5))
    with pytest.raises(ValueError, match="shift source beyond"):
        engine_step._KERNEL.task_batch(*args)
    assert (args[0] == 0.5).all()
    with pytest.raises(ValueError, match="shift source beyond"):
        engine_step._KERNEL.plant_batch(*args[:3], np.zeros((2, 2)), args[9], args[17], bad, args[19])
