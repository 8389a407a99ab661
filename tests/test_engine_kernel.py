"""The engine's compiled float step against its Python reference, bit for bit.

The reference is the float arithmetic the rest of the suite exercises (``valves_pair_floats``,
``dynamics_pair_floats``, ``dynamics_pair_offset_floats``); the models here are drawn at random,
not taken from the packaged ones, and the whole envs are compared with the kernel and without.
"""

from __future__ import annotations

import dataclasses
import math
import struct
import sys
import types
import warnings

import numpy as np
import pytest
from conftest import random_rollout
from hypothesis import given, settings
from hypothesis import strategies as st

import ssme_envs  # noqa: F401  (registers the environments)
from ssme_envs.envs import engine_task, engine_throttle
from ssme_envs.models import engine_step
from ssme_envs.models.engine_step import pair_step_reference, pair_table

compiled = pytest.mark.skipif(
    engine_step._KERNEL is None, reason="the compiled engine kernel is not built here"
)

values = st.floats(allow_nan=True, allow_infinity=True, width=64)
small = st.floats(-2.0, 2.0) | st.sampled_from([0.0, -0.0, 1e-310, -1e-310])
widths = st.floats(0.0, 0.05) | st.just(0.0)


def _bits(result) -> list[int | str]:
    x, linkage, valve = result
    return ["nan" if v != v else struct.unpack("<Q", struct.pack("<d", v))[0] for v in (*x, *linkage, *valve)]


@st.composite
def models(draw) -> tuple:
    """A random two-output, two-valve model's rows: any shift sources (-1: none), any gains."""
    n = draw(st.integers(2, 12))
    offsets = draw(st.booleans())
    rows = []
    for _ in range(n):
        row = (draw(st.integers(-1, n - 1)), *(draw(small) for _ in range(4)))
        rows.append((*row, draw(small)) if offsets else row)
    steps = draw(st.integers(1, 3))
    lams = [(draw(st.floats(-0.5, 0.5)), draw(st.floats(-0.5, 0.5))) for _ in range(steps)]
    return tuple(rows), lams


@compiled
@settings(max_examples=400, deadline=None)
@given(
    model=models(),
    x_seed=st.integers(0, 2**32 - 1),
    specials=st.lists(values, min_size=7, max_size=7),
    linkage=st.tuples(small, small),
    valve=st.tuples(small, small),
    command=st.tuples(small | values, small | values),
    nominal=st.tuples(small, small),
    half=widths,
    stick=widths,
    step=st.integers(0, 2),
)
def test_the_kernel_gives_the_references_bits(model, x_seed, specials, linkage, valve, command, nominal,
                                              half, stick, step) -> None:  # fmt: skip
    rows, lams = model
    step = min(step, len(lams) - 1)
    x = np.random.default_rng(x_seed).normal(0.0, 0.1, len(rows)).tolist()
    for i, special in enumerate(specials[: len(x) // 2]):  # NaN, inf, signed zeros among the states
        x[2 * i] = special
    table, width = pair_table([(lam, rows) for lam in lams])
    args = (x, linkage, valve, *command, *nominal, half, stick)
    got = engine_step._KERNEL.pair_step(*args, table, width, step)
    assert _bits(got) == _bits(pair_step_reference(*args, lams[step], rows))


@compiled
@pytest.mark.parametrize("n", [64, 65, 300])
def test_a_model_of_many_states_gives_the_references_bits(n: int) -> None:
    """Past the kernel's stack buffer (64 states) the states go to the heap: the same bits."""
    rng = np.random.default_rng(n)
    rows = tuple((int(rng.integers(-1, n)), *rng.normal(0.0, 0.5, 5).tolist()) for _ in range(n))
    table, width = pair_table([((0.2, -0.1), rows)])
    args = (rng.normal(0.0, 0.1, n).tolist(), (0.01, -0.02), (0.0, 0.03), 0.05, -0.04, 0.01, 0.02, 1e-3, 2e-3)
    got = engine_step._KERNEL.pair_step(*args, table, width, 0)
    assert _bits(got) == _bits(pair_step_reference(*args, (0.2, -0.1), rows))


@compiled
def test_the_kernel_refuses_a_table_it_would_read_past() -> None:
    rows = ((-1, 0.1, 0.2, 0.3, 0.4), (0, 0.1, 0.2, 0.3, 0.4))
    table, width = pair_table([((0.0, 0.0), rows)])
    args = ([0.0, 0.0], (0.0, 0.0), (0.0, 0.0), 0.1, 0.1, 0.0, 0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="a step inside the table"):
        engine_step._KERNEL.pair_step(*args, table, width, 1)
    with pytest.raises(ValueError, match="a step inside the table"):
        engine_step._KERNEL.pair_step([0.0, 0.0, 0.0], *args[1:], table, width, 0)
    bad, _ = pair_table([((0.0, 0.0), ((-1, 0.1, 0.2, 0.3, 0.4), (5, 0.1, 0.2, 0.3, 0.4)))])
    with pytest.raises(ValueError, match="shift source beyond"):
        engine_step._KERNEL.pair_step(*args, bad, width, 0)
    with pytest.raises(TypeError, match="list of floats"):
        engine_step._KERNEL.pair_step((0.0, 0.0), *args[1:], table, width, 0)


@compiled
@settings(max_examples=8, deadline=None)
@given(
    env_id=st.sampled_from(["ssme_envs/EngineTracking-v0", "ssme_envs/EngineThrottle-v0"]),
    seed=st.integers(0, 2**31 - 1),
    options=st.sampled_from(
        [
            {},
            {"fault": {"kind": "stuck_valve", "index": 1, "time": 2.0}},
            {"fault": {"kind": "gain_loss", "index": 0, "time": 1.0, "magnitude": 0.5}},
            {"fault": {"kind": "sensor_bias", "index": 0, "time": 0.5, "magnitude": 0.01}},
            {"truth": {"backlash": 0.0, "stiction": 0.0}},
            {"action_scale": 0.2},
        ]
    ),
)
def test_the_engine_envs_give_the_same_bits_with_and_without_the_kernel(env_id, seed, options) -> None:
    """The single env with the kernel against the single env on the reference."""
    with_kernel = random_rollout(env_id, seed, False, 300, 1, **options)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(engine_step, "_KERNEL", None)
        reference = random_rollout(env_id, seed, False, 300, 1, **options)
    assert len(with_kernel) == len(reference)
    assert all(np.array_equal(a, b) for a, b in zip(with_kernel, reference, strict=True))


@compiled
def test_a_kernel_task_and_a_reference_task_differ_only_in_the_kernels_arguments(monkeypatch) -> None:
    with_kernel = engine_throttle.ThrottleTask.build_throttle()
    monkeypatch.setattr(engine_step, "_KERNEL", None)
    reference = engine_throttle.ThrottleTask.build_throttle()
    assert reference.kernel_args is None
    assert with_kernel.kernel_args is not None
    for f in dataclasses.fields(engine_task.EngineTask):
        if f.name not in ("kernel_args", "nonlinear") and f.compare:
            assert repr(getattr(with_kernel, f.name)) == repr(getattr(reference, f.name)), f.name


def _fake_kernel(pair_step) -> types.ModuleType:
    fake = types.ModuleType("ssme_envs.models._engine_kernel")
    fake.pair_step = pair_step
    return fake


def _reference_kernel(*args):
    """pair_step written over the reference, reading its packed table back."""
    *head, table, width, step = args
    flat = np.frombuffer(table)
    per_step = 2 + len(args[0]) * width
    block = flat[step * per_step : (step + 1) * per_step].tolist()
    rows = tuple((int(r[0]), *r[1:]) for r in np.reshape(block[2:], (-1, width)).tolist())
    return pair_step_reference(*head, block[:2], rows)


@pytest.mark.parametrize(
    "mutant",
    [
        lambda *a: _reference_kernel(*a[:5], 0.0, 0.0, *a[7:]),  # gains about zero, not the nominal
        lambda *a: _reference_kernel(*a[:7], a[7], 0.0, *a[9:]),  # no stiction
        lambda *a: (lambda r: ([math.nextafter(v, math.inf) for v in r[0]], *r[1:]))(_reference_kernel(*a)),
    ],
    ids=["nominal ignored", "stiction dropped", "one ulp off"],
)
def test_a_kernel_that_differs_from_the_reference_is_refused(monkeypatch, mutant) -> None:
    monkeypatch.delenv("SSME_ENVS_NO_KERNEL", raising=False)
    monkeypatch.setitem(sys.modules, "ssme_envs.models._engine_kernel", _fake_kernel(mutant))
    with pytest.warns(RuntimeWarning, match="compiled engine kernel differs from its reference"):
        assert engine_step.load_kernel("_engine_kernel", engine_step._kernel_agrees, "engine") is None
    faithful = _fake_kernel(_reference_kernel)  # the same bits: taken
    monkeypatch.setitem(sys.modules, "ssme_envs.models._engine_kernel", faithful)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert engine_step.load_kernel("_engine_kernel", engine_step._kernel_agrees, "engine") is faithful
