"""Parameter uncertainty of identified models: a Gaussian over named parameters.

The block a model.json carries as ``uncertainty``::

    {"parameters": ["K[2,0]", ..., "lambda[1]"],   # names of the model's free parameters
     "covariance": [[...], ...],                     # their joint covariance (P x P)
     "standard_errors": [...],                       # sqrt of its diagonal, for reading
     "method": "...", "samples": N}

The mean is the model itself: the names say which entries of the model the rows describe.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ssme_envs.models.linear import boolean_text, describe, refuse_non_numbers, refuse_unknown_keys

_BLOCK_KEYS = frozenset(("parameters", "covariance", "method", "samples", "standard_errors"))
# Covariances are symmetric positive semi-definite up to round-off; eigenvalues below this
# fraction of the largest count as zero when drawing.
PSD_TOL = 1e-9


@dataclass(frozen=True, eq=False)
class ParameterUncertainty:
    """Covariance of a model's free parameters (the model holds their values).

    Parameters
    ----------
    parameters : tuple of str
        Parameter names, e.g. ``"K[2,0]"``, ``"B[0,1]"``, ``"lambda[0]"``.
    covariance : ndarray, shape (P, P)
        Joint covariance, in the parameters' units squared.
    method : str
        How it was obtained (for the reader).
    samples : int
        Samples of the record it came from.
    """

    parameters: tuple[str, ...]
    covariance: np.ndarray
    method: str = ""
    samples: int = 0

    def __post_init__(self) -> None:
        names = tuple(str(v) for v in self.parameters)
        object.__setattr__(self, "parameters", names)
        try:
            cov = np.array(self.covariance, dtype=float)
        except (TypeError, ValueError):
            raise ValueError("uncertainty.covariance must be a numeric matrix") from None
        refuse_non_numbers(self.covariance, "uncertainty.covariance")  # true, "1.5" and null convert
        size = len(names)
        if cov.shape != (size, size):
            raise ValueError(f"uncertainty.covariance has shape {cov.shape}, expected {size} x {size}")
        if not np.all(np.isfinite(cov)):
            raise ValueError("uncertainty.covariance contains NaN or inf")
        scale = max(float(np.max(np.abs(cov), initial=0.0)), 1e-300)
        if np.max(np.abs(cov - cov.T), initial=0.0) > 1e-9 * scale:
            raise ValueError("uncertainty.covariance is not symmetric")
        if size and np.min(np.linalg.eigvalsh(cov)) < -1e-6 * scale:
            raise ValueError("uncertainty.covariance is not positive semi-definite")
        if len(set(names)) != size:
            raise ValueError("uncertainty.parameters repeats a name")
        object.__setattr__(self, "covariance", cov)

    @property
    def standard_errors(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    def draws(self, mean: np.ndarray, rng: np.random.Generator, count: int) -> np.ndarray:
        """``count`` parameter vectors from N(mean, covariance), shape (count, P)."""
        values, vectors = np.linalg.eigh(self.covariance)
        root = vectors * np.sqrt(np.clip(values, PSD_TOL * max(values.max(initial=0.0), 0.0), None))
        return mean + rng.standard_normal((count, len(self.parameters))) @ root.T

    def propagate(self, fn: Callable[[np.ndarray], np.ndarray], mean: np.ndarray) -> np.ndarray:
        """Covariance of ``fn(parameters)`` by the delta method (central differences).

        Returns an array of shape ``fn(mean).shape * 2`` flattened to (F, F).
        """
        jac = jacobian(fn, mean)
        return jac @ self.covariance @ jac.T

    def to_dict(self) -> dict[str, Any]:
        return {
            "parameters": list(self.parameters),
            "covariance": self.covariance.tolist(),
            "standard_errors": self.standard_errors.tolist(),
            "method": self.method,
            "samples": self.samples,
        }

    @classmethod
    def from_dict(cls, data: Any, known: Sequence[str], source: str = "model") -> ParameterUncertainty:
        """Read the block; ``known`` are the parameter names the model has."""
        if not isinstance(data, dict):
            raise ValueError(f"{source}: uncertainty must be an object")
        for key in ("parameters", "covariance"):
            if key not in data:
                raise ValueError(f"{source}: uncertainty lacks {key!r}")
        refuse_unknown_keys(data, _BLOCK_KEYS, f"{source}: uncertainty: ")
        names = data["parameters"]
        if not isinstance(names, list) or not all(isinstance(v, str) for v in names):
            raise ValueError(f"{source}: uncertainty.parameters must be a list of strings")
        unknown = sorted(set(names) - set(known))
        if unknown:
            raise ValueError(f"{source}: uncertainty names parameters the model lacks: {', '.join(unknown)}")
        method, samples = data.get("method", ""), data.get("samples", 0)
        if isinstance(samples, bool):
            raise ValueError(f"{source}: uncertainty.samples is {boolean_text(samples)}, not an integer")
        if not isinstance(method, str) or not isinstance(samples, int):
            raise ValueError(f"{source}: uncertainty.method must be a string and samples an integer")
        if samples < 0:
            raise ValueError(f"{source}: uncertainty.samples must be >= 0, got {describe(samples)}")
        try:
            return cls(tuple(names), data["covariance"], method, samples)
        except ValueError as exc:
            raise ValueError(f"{source}: {exc}") from None


def check_standard_errors(listed: Any, uncertainty: ParameterUncertainty, name: str) -> None:
    """The ``standard_errors`` a file lists beside a covariance (``name`` in messages): ValueError
    unless numbers equal to the square roots of its diagonal (to 1e-9 relative)."""
    try:
        values = np.array(listed, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"{name} must be a list of numbers") from None
    refuse_non_numbers(listed, name)
    expected = uncertainty.standard_errors
    if values.shape != expected.shape or not np.allclose(values, expected, rtol=1e-9, atol=0.0):
        raise ValueError(
            f"{name} {describe(listed)} disagree with the square roots of the covariance's diagonal"
        )


def jacobian(fn: Callable[[np.ndarray], np.ndarray], x: np.ndarray, rel_step: float = 1e-6) -> np.ndarray:
    """d fn / d x by central differences, shape (F, P) with F = fn(x).size."""
    x = np.asarray(x, dtype=float)
    base = np.ravel(fn(x))
    jac = np.empty((base.size, x.size))
    for k in range(x.size):
        h = rel_step * max(abs(x[k]), 1e-3)
        up, down = x.copy(), x.copy()
        up[k] += h
        down[k] -= h
        jac[:, k] = (np.ravel(fn(up)) - np.ravel(fn(down))) / (2 * h)
    return jac
