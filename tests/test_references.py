"""Reference signals and sensor noise of the episodes: shapes, documented properties, and the
same bits for an episode drawn alone as in a batch."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from ssme_envs.envs.references import (
    MIXED_KINDS,
    REFERENCE_KINDS,
    normal_pairs,
    normal_rows,
    reference_signals,
    uniforms_needed,
    unit_normals,
)

DT, LENGTH = 0.04, 251
AMPLITUDE = np.array([0.01, 0.02])


def _draw(kind: str, k: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    uniforms = np.random.default_rng(seed).random((uniforms_needed(kind, LENGTH, 2, DT), k))
    return uniforms, reference_signals(kind, uniforms, LENGTH, AMPLITUDE, DT)


@pytest.mark.parametrize("kind", REFERENCE_KINDS)
def test_an_episode_alone_equals_the_same_episode_in_a_batch(kind):
    uniforms, batch = _draw(kind, 64)
    assert batch.shape == (2, LENGTH, 64)
    for i in (0, 17, 63):
        alone = reference_signals(kind, uniforms[:, i : i + 1], LENGTH, AMPLITUDE, DT)
        assert np.array_equal(alone[:, :, 0], batch[:, :, i])
    assert np.all(np.abs(batch) <= AMPLITUDE[:, None, None])


def test_random_steps_hold_1_to_3_s():
    _, refs = _draw("random_steps", 200)
    for c in range(2):
        for i in range(200):
            changes = np.flatnonzero(np.diff(refs[c, :, i]) != 0) + 1
            holds = np.diff(np.concatenate([[0], changes]))
            assert np.all((holds >= 25) & (holds <= 75)), holds
    levels = refs[:, 0, :] / AMPLITUDE[:, None]
    assert stats.kstest(levels.ravel(), "uniform", args=(-1, 2)).pvalue > 1e-3


def test_step_ramp_and_prbs_shapes():
    _, steps = _draw("step", 100)
    for i in range(100):
        first = np.flatnonzero(steps[0, :, i] != 0)
        assert first.size == 0 or (first[0] < 0.4 * LENGTH and np.all(np.diff(first) == 1))
        assert first.size == 0 or first[-1] == LENGTH - 1
    _, ramps = _draw("ramp", 100)
    for i in range(100):
        moving = np.flatnonzero(np.diff(ramps[0, :, i]) != 0)
        assert moving.size == 0 or 25 <= moving.size <= 100
        assert np.all(np.diff(np.abs(ramps[0, :, i])) >= -1e-15)  # heads monotonically to its level
    _, prbs = _draw("prbs", 200)
    assert np.all(np.abs(prbs) == AMPLITUDE[:, None, None])
    switches = np.mean(np.diff(prbs, axis=1) != 0)
    assert switches == pytest.approx(DT / 0.5, rel=0.05)  # 0.08 per step, 100,000 chances


def test_mixed_draws_each_kind_equally_and_builds_it_from_the_rest_of_its_column():
    uniforms, refs = _draw("mixed", 1000)
    choice = np.floor(uniforms[0] * len(MIXED_KINDS)).astype(int)
    counts = np.bincount(choice, minlength=len(MIXED_KINDS))
    assert stats.chisquare(counts).pvalue > 1e-3
    for i in (0, 1, 2, 500, 999):
        kind = MIXED_KINDS[choice[i]]
        own = uniforms[1 : 1 + uniforms_needed(kind, LENGTH, 2, DT), i : i + 1]
        assert np.array_equal(refs[:, :, i], reference_signals(kind, own, LENGTH, AMPLITUDE, DT)[:, :, 0])


def test_unit_normals_are_standard_normal_and_batch_independent():
    uniforms = np.random.default_rng(3).random((502, 300), dtype=np.float32)
    normals = unit_normals(uniforms)
    assert normals.dtype == np.float32 and normals.shape == uniforms.shape
    assert np.all(np.isfinite(normals))
    assert stats.kstest(normals.ravel().astype(float), "norm").pvalue > 1e-3
    assert abs(np.corrcoef(normals[:251].ravel(), normals[251:].ravel())[0, 1]) < 0.01
    for i in (0, 150, 299):
        assert np.array_equal(unit_normals(np.ascontiguousarray(uniforms[:, i : i + 1]))[:, 0], normals[:, i])


def test_every_step_and_ramp_episode_moves():
    """The shape checks above accept an episode without a step or ramp: every drawn episode has
    one, so those checks always run on a real step or ramp."""
    _, steps = _draw("step", 100)
    _, ramps = _draw("ramp", 100)
    for i in range(100):
        assert np.flatnonzero(steps[0, :, i] != 0).size > 0
        assert np.flatnonzero(np.diff(ramps[0, :, i]) != 0).size > 0


def _random_steps_by_loop(uniforms: np.ndarray, length: int, amplitude: np.ndarray, dt: float) -> np.ndarray:
    """random_steps as documented, one episode and one step at a time: hold j lasts round(1/dt)
    plus floor(u_j (round(3/dt) - round(1/dt) + 1)) steps at level (2 u - 1) amplitude of its
    channel's row count + j channels + c."""
    channels, k = amplitude.size, uniforms.shape[1]
    shortest, longest = round(1.0 / dt), round(3.0 / dt)
    count = -(-length // shortest)
    refs = np.empty((channels, length, k))
    for i in range(k):
        hold, end = 0, shortest + int(np.floor(uniforms[0, i] * (longest - shortest + 1)))
        for step in range(length):
            if step >= end:
                hold += 1
                end += shortest + int(np.floor(uniforms[hold, i] * (longest - shortest + 1)))
            for c in range(channels):
                refs[c, step, i] = (2.0 * uniforms[count + hold * channels + c, i] - 1.0) * amplitude[c]
    return refs


@settings(max_examples=60, deadline=None)
@given(
    dt=st.sampled_from([0.008, 0.02, 0.04, 0.25, 1.0]),
    length=st.integers(1, 400),
    channels=st.integers(1, 3),
    k=st.integers(1, 20),
    cut=st.tuples(st.floats(0, 1), st.floats(0, 1)),
    into=st.booleans(),
    seed=st.integers(0, 2**32 - 1),
)
def test_random_steps_blocks_equal_a_step_by_step_loop(dt, length, channels, k, cut, into, seed):
    rng = np.random.default_rng(seed)
    amplitude = 0.5 + rng.random(channels)
    uniforms = rng.random((uniforms_needed("random_steps", length, channels, dt), k), dtype=np.float32)
    uniforms = uniforms.astype(np.float64)  # as the tasks pass them
    start = min(int(cut[0] * length), length - 1)
    stop = start + 1 + int(cut[1] * (length - start - 1))
    expected = _random_steps_by_loop(uniforms, length, amplitude, dt)[:, start:stop]
    table = np.full((channels, length + 3, k + 2), np.nan)  # a view into a larger table, as the vector env's
    out = table[:, start:stop, 1 : k + 1] if into else None
    block = reference_signals("random_steps", uniforms, length, amplitude, dt, start, stop, out)
    assert block.tobytes() == np.ascontiguousarray(expected).tobytes()
    if into:
        assert block is out and np.isnan(table[:, :, 0]).all() and np.isnan(table[:, stop:]).all()


@pytest.mark.parametrize("kind", REFERENCE_KINDS)
def test_every_kind_writes_into_out_the_bits_it_returns(kind):
    uniforms, whole = _draw(kind, 9)
    for start, stop in ((0, 16), (16, 32), (64, LENGTH)):
        table = np.zeros((2, LENGTH, 9))
        block = reference_signals(kind, uniforms, LENGTH, AMPLITUDE, DT, start, stop, table[:, start:stop])
        assert np.shares_memory(block, table)
        assert table[:, start:stop].tobytes() == whole[:, start:stop].tobytes()


def test_normals_write_into_out_the_bits_they_return():
    uniforms = np.random.default_rng(5).random((2 * 40, 7), dtype=np.float32)
    whole = unit_normals(uniforms)
    table = np.zeros((3, 40, 7), dtype=np.float32)
    normal_pairs(uniforms, 40, 8, 24, table[1:, 8:24])
    assert table[1, 8:24].tobytes() == whole[8:24].tobytes()
    assert table[2, 8:24].tobytes() == whole[48:64].tobytes()
    row = np.zeros((16, 7), dtype=np.float32)
    assert normal_rows(uniforms, 40, 30, 46, row) is row
    assert row.tobytes() == whole[30:46].tobytes()
