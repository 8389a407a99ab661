"""The truth plant: linear part against scipy, valve nonlinearities against plain loops."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import dlsim, eq36

from ssme_envs.models import EngineCore, TruthConfig, published_model, simulate
from ssme_envs.signals import prbs


def _valve_reference(command: np.ndarray, backlash: float, stiction: float) -> np.ndarray:
    """Scalar play operator followed by stick-slip, written out sample by sample."""
    linkage = valve = 0.0
    out = []
    for c in command:
        if c - linkage > backlash / 2:
            linkage = c - backlash / 2
        elif linkage - c > backlash / 2:
            linkage = c + backlash / 2
        if abs(linkage - valve) > stiction:
            valve = linkage
        out.append(valve)
    return np.array(out)


def test_ideal_truth_matches_scipy_dlsim():
    model = published_model(90)
    u = prbs(300, amplitude=[0.01, 0.015])
    _, clean = simulate(model, u, TruthConfig.ideal())
    expected = dlsim(model.A, model.B, model.C, eq36(u, model.lam))
    np.testing.assert_allclose(clean, expected, rtol=1e-12, atol=1e-14)


def test_symmetric_switch_drops_lambda():
    model = published_model(70)
    u = prbs(200)
    config = TruthConfig(asymmetric_gains=False, backlash=0.0, stiction=0.0, sensor_noise=(0.0, 0.0))
    _, clean = simulate(model, u, config)
    np.testing.assert_allclose(clean, dlsim(model.A, model.B, model.C, u), rtol=1e-12, atol=1e-14)


def test_valves_follow_backlash_and_stiction():
    rng = np.random.default_rng(5)
    t = np.arange(600)
    command = 0.01 * np.sin(2 * np.pi * t / 150) + 0.002 * rng.standard_normal(600)
    commands = np.column_stack([command, -0.5 * command])
    config = TruthConfig(backlash=2e-3, stiction=1e-3, sensor_noise=(0.0, 0.0))
    core = EngineCore(published_model(100), config, n=1)
    valves = np.array([core.step(commands[k : k + 1]).copy()[0] for k in range(600)])
    for j in range(2):
        np.testing.assert_allclose(valves[:, j], _valve_reference(commands[:, j], 2e-3, 1e-3), atol=1e-15)
    assert np.any(np.diff(valves[:, 0]) == 0)  # it sticks
    assert np.max(np.abs(valves[:, 0] - command)) <= 2e-3 / 2 + 1e-3 + 1e-15


def test_batched_runs_equal_single_runs():
    model = published_model(110)
    config = TruthConfig(backlash=1e-3, stiction=5e-4, sensor_noise=(0.0, 0.0))
    rng = np.random.default_rng(0)
    u = 0.01 * rng.standard_normal((4, 120, 2))
    _, batch = simulate(model, u, config)
    for i in range(4):
        _, single = simulate(model, u[i], config)
        np.testing.assert_array_equal(batch[i], single)


def test_noise_is_seeded_and_sized():
    model = published_model(100)
    u = prbs(5000)
    config = TruthConfig(sensor_noise=(1e-3, 2e-3))
    a, clean = simulate(model, u, config, np.random.default_rng(7))
    b, _ = simulate(model, u, config, np.random.default_rng(7))
    np.testing.assert_array_equal(a, b)
    np.testing.assert_allclose((a - clean).std(axis=0), [1e-3, 2e-3], rtol=0.05)
    with pytest.raises(ValueError, match="rng"):
        simulate(model, u, config)


def test_bad_commands_and_config():
    model = published_model(100)
    with pytest.raises(ValueError, match="shape"):
        simulate(model, np.zeros((10, 3)), TruthConfig.ideal())
    with pytest.raises(ValueError, match="NaN"):
        simulate(model, np.full((10, 2), np.nan), TruthConfig.ideal())
    with pytest.raises(ValueError, match="backlash"):
        TruthConfig(backlash=-1.0)


@pytest.mark.parametrize("power", [70, 80, 90, 100.0])
def test_truth_plant_at_a_level_is_the_linked_model_there(power):
    """The env's plant "truth" at a Table I level (taken without the interpolators) equals the
    linked model's local model there, to the bit."""
    from ssme_envs.envs.engine_task import resolve_plant
    from ssme_envs.models.linked import LinkedEngineModel

    plant, linked = resolve_plant("truth", power), LinkedEngineModel().local_model(power)
    for name in ("A", "B", "C", "lam"):
        assert np.array_equal(getattr(plant, name), getattr(linked, name)), name
    assert plant.dt == linked.dt and plant.observability_indices == linked.observability_indices
    with pytest.raises(ValueError, match="within 65-109"):
        resolve_plant("truth", 110)


def test_making_the_default_env_imports_no_heavy_scipy_module():
    """``import ssme_envs`` and a first ``gymnasium.make`` of EngineTracking leave
    scipy.interpolate, scipy.signal and scipy.linalg unimported (a fresh interpreter)."""
    import subprocess
    import sys

    code = (
        "import sys, gymnasium as gym, ssme_envs\n"
        "gym.make('ssme_envs/EngineTracking-v0').reset(seed=0)\n"
        "heavy = ('scipy.interpolate', 'scipy.signal', 'scipy.linalg')\n"
        "print(' '.join(m for m in heavy if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""
