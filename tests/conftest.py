"""Shared helpers for the tests: independent reference computations, never the code under test."""

from __future__ import annotations

import numpy as np


def markov(a: np.ndarray, b: np.ndarray, c: np.ndarray, count: int) -> np.ndarray:
    """C A^k B by explicit matrix powers."""
    return np.array([c @ np.linalg.matrix_power(a, k) @ b for k in range(count)])


def eq36(u: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """Eq 36 of the paper written out branch by branch."""
    return np.where(u >= 0, lam * u, (2.0 - lam) * u)


def dlsim(a, b, c, u):
    """Zero-state response of x(k+1) = A x + B u, y = C x, by scipy.signal."""
    from scipy.signal import dlsim as _dlsim

    m, p = b.shape[1], c.shape[0]
    _, y, _ = _dlsim((a, b, c, np.zeros((p, m)), 1.0), u)
    return y.reshape(-1, p)


# Options of every env that make its episodes short: truncations within a few dozen steps.
SHORT_EPISODES = {
    "ssme_envs/EngineTracking-v0": {"episode_seconds": 2.0, "action_scale": 0.2},
    "ssme_envs/EngineThrottle-v0": {
        "profile": [(0.0, 100.0), (1.0, 100.0), (2.0, 90.0)],
        "action_scale": 0.2,
    },
    "ssme_envs/NozzleTVC-v0": {"episode_seconds": 0.4},
    "ssme_envs/LauncherPitch-v0": {"episode_seconds": 1.0},
}
