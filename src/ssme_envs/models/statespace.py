"""Discrete state-space models in alpha-canonical form (their JSON: :mod:`.statespace_json`).

The alpha-canonical form (Eldem and Duyar 1989; NASA TM-104422 eqs 5-8, with H = I) of an
observable system with observability indices ``mu = (mu_1, ..., mu_p)`` is

    x(k+1) = A x(k) + B u*(k),   y(k) = C x(k),
    C = [0  I_p],   A = A_o + K C,   A_o nilpotent (zeros and ones),

where output ``i`` owns a chain of ``mu_i`` states. State ``(i, d)`` holds the part of
``y_i`` that will appear ``d`` samples from now; the chains are stored deepest block first,
so that the last ``p`` states are the outputs themselves. ``A_o`` shifts ``(i, d)`` into
``(i, d - 1)``. Row ``(i, d)`` of ``[K B]`` is the coefficient of ``[y; u*](k-1-d)`` in the
one-step equation of ``y_i(k)`` (eq 11), and the uniqueness condition (eq 8) forces
``K[(i, d), j] = 0`` whenever ``mu_i > mu_j`` and ``d < mu_i - mu_j``.

The paper's form (``H = I`` in ``C = H [0 I]``) covers the systems in which no output's
dependent row ``c_i A^mu_i`` draws on a row ``c_j A^mu_i`` of the same power. The row search
examines ``c_j A^mu_i`` before ``c_i A^mu_i`` whenever ``j < i`` and ``mu_j > mu_i``, so a
general system with these indices may use it: in the one-step equation, ``y_i(k)`` then
depends on ``y_j(k)`` itself. Those couplings are the free entries ``H[i, j]`` of a unit lower
triangular ``H`` (``j < i``, ``mu_j > mu_i``); with them

    x(k+1) = (A_o + K C) x(k) + B u*(k),   y(k) = C x(k),   C = H [0 I],

the last ``p`` states are ``w = H^-1 y`` and every system whose row search (power by power,
outputs in order) finds ``mu`` has exactly one such realization. For indices in which no
``j < i`` has ``mu_j > mu_i`` (equal indices, as Table I's (2, 2), or non-decreasing ones)
``H = I`` and the form is the paper's.

``u*`` is the input after the piecewise-linear gain of eq 36: ``lambda_i u_i`` for
``u_i >= 0`` and ``(2 - lambda_i) u_i`` for ``u_i < 0``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from ssme_envs.models.linear import (
    Dimensions,
    StateSpace,
    as_floats,
    as_matrix,
    check_dt,
    describe,
    spectral_radius,
)
from ssme_envs.models.statespace_json import dumps_compact, read_json
from ssme_envs.models.uncertainty import ParameterUncertainty

# the engine's channels, in the order its models and envs hold them: valve positions -> chamber
# pressure and mixture ratio
ENGINE_INPUTS = ("beta_opov", "beta_fpov")
ENGINE_OUTPUTS = ("pc", "mr")

# check_dt, as_matrix, dumps_compact and read_json are re-exported: models and identification import them here
__all__ = [
    "ENGINE_INPUTS",
    "ENGINE_OUTPUTS",
    "AlphaCanonicalModel",
    "AlphaStructure",
    "as_matrix",
    "asymmetric_gain",
    "check_dt",
    "dumps_compact",
    "read_json",
]


@dataclass(frozen=True)
class AlphaStructure:
    """Index bookkeeping of the alpha-canonical form for given observability indices.

    Attributes
    ----------
    indices : tuple of int
        Observability index of each output.
    states : tuple of (output, depth)
        The state ordering: deepest block first, the outputs last.
    """

    indices: tuple[int, ...]
    states: tuple[tuple[int, int], ...]

    @classmethod
    def from_indices(cls, indices: Sequence[int]) -> AlphaStructure:
        idx = tuple(int(v) for v in indices)
        if not idx or any(v < 1 for v in idx):
            raise ValueError(f"observability indices must be positive integers, got {list(indices)}")
        states = tuple((i, d) for d in range(max(idx) - 1, -1, -1) for i in range(len(idx)) if idx[i] > d)
        return cls(idx, states)

    @property
    def n_states(self) -> int:
        return len(self.states)

    @property
    def n_outputs(self) -> int:
        return len(self.indices)

    @cached_property
    def _rows(self) -> dict[tuple[int, int], int]:
        # a search of ``states`` per call made the loops over all states quadratic
        return {state: row for row, state in enumerate(self.states)}

    def position(self, output: int, depth: int) -> int:
        """Row of state ``(output, depth)``."""
        try:
            return self._rows[(output, depth)]
        except KeyError:
            where = f"(output {output}, depth {depth})"
            raise ValueError(f"no state {where} for indices {list(self.indices)}") from None

    def shift_matrix(self) -> np.ndarray:
        """The nilpotent structure matrix A_o."""
        a_o = np.zeros((self.n_states, self.n_states))
        for row, (i, d) in enumerate(self.states):
            if d >= 1:
                a_o[self.position(i, d - 1), row] = 1.0
        return a_o

    def output_matrix(self, h: np.ndarray | None = None) -> np.ndarray:
        """C = H [0 I] (H = I when not given)."""
        c = np.zeros((self.n_outputs, self.n_states))
        c[:, self.n_states - self.n_outputs :] = np.eye(self.n_outputs) if h is None else h
        return c

    def coupled_outputs(self, output: int) -> list[int]:
        """Outputs ``j`` whose current sample enters the equation of ``output`` (free ``H[output, j]``):
        those searched before it (``j < output``) with a longer chain."""
        return [j for j in range(output) if self.indices[j] > self.indices[output]]

    def free_parameters(self) -> list[tuple[str, int, int]]:
        """The free entries of K and H, in the order of each output's regression: (matrix, row, col)."""
        out = []
        for i in range(self.n_outputs):
            out += [("K", self.position(i, d), j) for j, d in self.free_output_lags(i)]
            out += [("H", i, j) for j in self.coupled_outputs(i)]
        return out

    def free_output_lags(self, output: int) -> list[tuple[int, int]]:
        """(output j, depth d) pairs whose K entry is free in the row chain of ``output`` (eq 8)."""
        mu_i = self.indices[output]
        return [
            (j, d)
            for d in range(mu_i)
            for j, mu_j in enumerate(self.indices)
            if not (mu_i > mu_j and d < mu_i - mu_j)
        ]


def asymmetric_gain(u: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """Piecewise-linear input gain of eq 36, applied along the last axis.

    Parameters
    ----------
    u : array, shape (..., m)
        Input deviations (normalized valve positions).
    lam : array, shape (m,)
        Gains for positive deviations; negative ones get ``2 - lam``.
    """
    u = np.asarray(u, dtype=float)
    return u + (np.asarray(lam, dtype=float) - 1.0) * np.abs(u)


@dataclass
class AlphaCanonicalModel(Dimensions):
    """A discrete engine model ``x(k+1) = A x + B u*``, ``y = C x`` in alpha-canonical form.

    Parameters
    ----------
    A, B, C : ndarray
        State-space matrices, shapes (n, n), (n, m), (p, n).
    dt : float
        Sample time in seconds.
    observability_indices : tuple of int
        One per output; they sum to n.
    lam : ndarray, shape (m,)
        Asymmetric input gains of eq 36 (1.0 means symmetric).
    input_names, output_names : tuple of str
        Column names of the record the model describes.
    fit : dict
        Fit figures (SEE, NRMSE) and provenance; free-form, JSON-serializable.
    uncertainty : ParameterUncertainty, optional
        Covariance of the free parameters (:meth:`parameter_names`) from the identification.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    dt: float
    observability_indices: tuple[int, ...]
    lam: np.ndarray
    input_names: tuple[str, ...] = ENGINE_INPUTS
    output_names: tuple[str, ...] = ENGINE_OUTPUTS
    fit: dict[str, Any] = field(default_factory=dict)
    uncertainty: ParameterUncertainty | None = None

    def __post_init__(self) -> None:
        self.A = as_matrix(self.A, "A", (None, None))
        n = self.A.shape[0]
        if self.A.shape[1] != n:
            raise ValueError(f"A must be square, got shape {self.A.shape}")
        self.B = as_matrix(self.B, "B", (n, None))
        self.C = as_matrix(self.C, "C", (None, n))
        m, p = self.B.shape[1], self.C.shape[0]
        self.dt = check_dt(self.dt)
        indices = tuple(self.observability_indices)
        if len(indices) != p or sum(int(v) for v in indices) != n:  # before the structure is built:
            # a corrupt file's 1e9 would make a tuple of 1e9 states
            raise ValueError(
                f"observability_indices {describe(list(indices))} need {len(indices)} outputs and "
                f"{describe(sum(int(v) for v in indices))} states, the matrices have {p} and {n}"
            )
        self.observability_indices = AlphaStructure.from_indices(indices).indices
        lam = as_floats(self.lam, "lambda", f"a list of {m} finite gains")
        if lam.size != m or not np.all(np.isfinite(lam)):
            raise ValueError(f"lambda must hold {m} finite gains, got {describe(self.lam)}")
        self.lam = lam.reshape(-1)
        self.input_names = tuple(str(v) for v in self.input_names)
        self.output_names = tuple(str(v) for v in self.output_names)
        if len(self.input_names) != m or len(self.output_names) != p:
            raise ValueError(
                f"{len(self.input_names)} input names and {len(self.output_names)} output names "
                f"for a model with {m} inputs and {p} outputs"
            )
        for kind, names in (("input", self.input_names), ("output", self.output_names)):
            if len(set(names)) != len(names):  # a record's columns are read by these names
                raise ValueError(f"the {kind} names {list(names)} name a channel twice")

    @property
    def structure(self) -> AlphaStructure:
        return AlphaStructure.from_indices(self.observability_indices)

    @property
    def H(self) -> np.ndarray:
        """The output coupling of ``C = H [0 I]`` (identity in the paper's form)."""
        return self.C[:, self.A.shape[0] - self.C.shape[0] :].copy()

    @property
    def K(self) -> np.ndarray:
        """Output-injection (deadbeat observer) gain: ``A = A_o + K C``, so the last p columns of A
        are ``K H``."""
        last = self.A[:, self.A.shape[0] - self.C.shape[0] :]
        h = self.H
        if np.array_equal(h, np.eye(h.shape[0])):
            return last.copy()
        import scipy.linalg  # here: importing it costs about a tenth of a second, first make included

        return scipy.linalg.solve_triangular(h, last.T, trans="T", lower=True, unit_diagonal=True).T

    def parameter_names(self) -> list[str]:
        """Names of the free parameters: K and H entries the form leaves free, all of B, lambda."""
        names = [f"{mat}[{r},{c}]" for mat, r, c in self.structure.free_parameters()]
        names += [f"B[{r},{c}]" for r in range(self.B.shape[0]) for c in range(self.B.shape[1])]
        return names + [f"lambda[{j}]" for j in range(self.n_inputs)]

    def parameter_vector(self) -> np.ndarray:
        """The free parameters' values, in the order of :meth:`parameter_names`."""
        mats = {"K": self.K, "H": self.H}
        free = [mats[mat][r, c] for mat, r, c in self.structure.free_parameters()]
        return np.concatenate([free, self.B.ravel(), self.lam])

    def with_parameters(self, values: np.ndarray) -> AlphaCanonicalModel:
        """The same structure with other free-parameter values (e.g. a draw from the uncertainty)."""
        values = np.asarray(values, dtype=float)
        s = self.structure
        free = s.free_parameters()
        if values.shape != (len(free) + self.B.size + self.n_inputs,):
            raise ValueError(
                f"expected {len(free) + self.B.size + self.n_inputs} parameters, got {values.shape}"
            )
        k_gain, h = np.zeros_like(self.K), np.eye(self.n_outputs)
        for (mat, r, c), v in zip(free, values, strict=False):
            (k_gain if mat == "K" else h)[r, c] = v
        c_mat = s.output_matrix(h)
        b = values[len(free) : len(free) + self.B.size].reshape(self.B.shape)
        return AlphaCanonicalModel(
            A=s.shift_matrix() + k_gain @ c_mat,
            B=b,
            C=c_mat,
            dt=self.dt,
            observability_indices=self.observability_indices,
            lam=values[len(free) + self.B.size :],
            input_names=self.input_names,
            output_names=self.output_names,
        )

    def markov_parameters(self, count: int) -> np.ndarray:
        """``C A^k B`` for k = 0..count-1, shape (count, p, m)."""
        out = np.empty((count, self.n_outputs, self.n_inputs))
        ak_b = self.B.copy()
        for k in range(count):
            out[k] = self.C @ ak_b
            ak_b = self.A @ ak_b
        return out

    def spectral_radius(self) -> float:
        return spectral_radius(self.A)

    def gains_outside_range(self) -> np.ndarray:
        """Indices of the inputs whose lambda lies outside (0, 2), where the valve gain on one side
        of the operating point changes sign (``u* = u + (lambda - 1)|u|``)."""
        return np.flatnonzero(~((self.lam > 0.0) & (self.lam < 2.0)))

    def dc_gain(self) -> np.ndarray:
        """Steady-state gain from u* to y, shape (p, m)."""
        n = self.A.shape[0]
        return self.C @ np.linalg.solve(np.eye(n) - self.A, self.B)

    def sample(self, rng: np.random.Generator, count: int) -> list[AlphaCanonicalModel]:
        """``count`` models with parameters drawn from the uncertainty block (Gaussian)."""
        rows = self.uncertain_rows()
        mean = self.parameter_vector()
        return [
            self.with_parameters(self.filled(draw)) for draw in self.uncertainty.draws(mean[rows], rng, count)
        ]

    def uncertain_rows(self) -> list[int]:
        """Positions in :meth:`parameter_vector` of the parameters the uncertainty block covers."""
        if self.uncertainty is None:
            raise ValueError("the model has no uncertainty block")
        names = self.parameter_names()
        return [names.index(name) for name in self.uncertainty.parameters]

    def filled(self, values: np.ndarray) -> np.ndarray:
        """The full parameter vector with the uncertain ones replaced by ``values``."""
        full = self.parameter_vector()
        full[self.uncertain_rows()] = values
        return full

    def alpha_canonical_residual(self) -> float:
        """Largest violation of eqs 5-8 with ``C = H [0 I]`` (0 for a model exactly in the form)."""
        s = self.structure
        a_o = s.shift_matrix()
        k_gain = self.K  # a copy or a triangular solve: once, not per entry
        h = np.eye(s.n_outputs)
        for i in range(s.n_outputs):
            for j in s.coupled_outputs(i):
                h[i, j] = self.C[i, s.n_states - s.n_outputs + j]
        errs = [np.max(np.abs(self.C - s.output_matrix(h))), np.max(np.abs(self.A - a_o - k_gain @ self.C))]
        for i in range(s.n_outputs):
            free = set(s.free_output_lags(i))
            for d in range(s.indices[i]):
                fixed = [j for j in range(s.n_outputs) if (j, d) not in free]
                if fixed:
                    errs.append(np.max(np.abs(k_gain[s.position(i, d), fixed])))
        return float(max(errs))

    def state_space(self) -> StateSpace:
        """The model as the package's one state-space type (D = 0; the input is ``u*``, after the
        asymmetric gain of eq 36)."""
        return StateSpace(self.A, self.B, self.C, self.dt)

    # JSON (schema ssme-envs/engine-model) lives in statespace_json; these keep the model's API.
    def to_dict(self) -> dict[str, Any]:
        from ssme_envs.models.statespace_json import engine_model_to_dict

        return engine_model_to_dict(self)

    @classmethod
    def from_dict(cls, data: Any, source: str = "model") -> AlphaCanonicalModel:
        """Build a model from its JSON dictionary, checking everything a user file can get wrong."""
        from ssme_envs.models.statespace_json import engine_model_from_dict

        return engine_model_from_dict(cls, data, source)

    def save(self, path: str | Path) -> None:
        from ssme_envs.models.statespace_json import save_engine_model

        save_engine_model(self, path)

    @classmethod
    def load(cls, path: str | Path) -> AlphaCanonicalModel:
        return cls.from_dict(read_json(path), source=str(path))
