"""Reference signals and sensor noise of the episodes: shapes, documented properties, and the
same bits for an episode drawn alone as in a batch."""

import numpy as np
import pytest
from scipy import stats

from ssme_envs.envs.references import (
    MIXED_KINDS,
    REFERENCE_KINDS,
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
