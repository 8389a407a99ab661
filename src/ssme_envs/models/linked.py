"""Full-range SSME model: the five Table I point models linked over 65-109 % power.

NASA TM-104422 ends with "these point models will be linked to obtain a simplified model of the
SSME covering its full range of operation"; NASA TM-104421 linked 25 point models the same way.

- **Parameters.** The alpha-canonical form is unique, so its parameters (K, B, lambda) are
  comparable across power levels and are interpolated in power by monotone cubic (PCHIP)
  interpolation, C1 and without overshoot; below 70 % the end polynomial extrapolates. At each
  of the five levels the local model is the published one.
- **Operating points.** Outputs are normalized deviations from the 100 % point, with chamber
  pressure proportional to power (d Pc = 0.01 per % of power) and the mixture ratio held at its
  nominal value: ``y_eq(P) = (P/100 - 1, 0)``. The nominal valve schedule ``u_eq(P)`` (normalized
  valve positions, 0 at 100 %) is the one consistent with every point model's DC gain:
  ``d y_eq / dP = G(P) d u_eq / dP``, integrated from 100 %. (The mean of the up and down gains
  lambda and 2 - lambda is 1, so the schedule uses G = C (I - A)^-1 B.)
- **Dynamics between levels** (used by the throttle environment): scheduled on the commanded
  power, ``x(k+1) = A(P) x + B(P) u* + (I - A(P)) C^T c(P)`` with
  ``c(P) = y_eq(P) - G(P) u_eq(P)``: at a fixed power the local point model about its operating
  point, and on the nominal schedule ``u = u_eq(P)`` an equilibrium at ``y_eq(P)`` at every power.
"""

from __future__ import annotations

import math
from functools import cached_property

import numpy as np

from ssme_envs.models.engine import POWER_LEVELS, published_model
from ssme_envs.models.linear import describe
from ssme_envs.models.statespace import AlphaCanonicalModel

POWER_RANGE = (65.0, 109.0)  # %, the range the linked model covers (Table I spans 70-110)
_GRID_STEP = 0.01  # % of power, resolution of the nominal valve schedule's integration


class LinkedEngineModel:
    """The five published point models linked over the power range.

    Parameters
    ----------
    models : sequence of AlphaCanonicalModel, optional
        Point models with the same structure, one per power level in ``powers``
        (default: Table I at 70, 80, 90, 100, 110 %).
    powers : sequence of float, optional
        Their power levels, %, increasing.
    """

    def __init__(
        self, models: list[AlphaCanonicalModel] | None = None, powers: tuple[float, ...] | None = None
    ) -> None:
        if models is None:
            powers = tuple(float(p) for p in POWER_LEVELS)
            models = [published_model(p) for p in POWER_LEVELS]
        if powers is None or len(powers) != len(models) or len(models) < 2:
            raise ValueError("give at least two point models and their power levels")
        if any(m.observability_indices != models[0].observability_indices for m in models):
            raise ValueError("the point models must share their observability indices")
        self.powers = np.asarray(powers, dtype=float)
        if np.any(np.diff(self.powers) <= 0):
            raise ValueError("power levels must increase")
        self.template = models[0]
        from scipy.interpolate import PchipInterpolator  # here: a heavy import, needed per model

        self._k = PchipInterpolator(self.powers, np.stack([m.K for m in models]), axis=0)
        self._b = PchipInterpolator(self.powers, np.stack([m.B for m in models]), axis=0)
        self._lam = PchipInterpolator(self.powers, np.stack([m.lam for m in models]), axis=0)

    @staticmethod
    def check_power(power: float) -> float:
        """The power level as a float, or a ValueError unless a real number (not a bool or a
        string) within 65-109 %."""
        shown = describe(power)  # an int of 400 digits by its size
        if isinstance(power, bool | np.bool_) or not isinstance(
            power, int | float | np.integer | np.floating
        ):
            raise ValueError(f"power must be a number of %, got {shown}")
        try:
            value = float(power)
        except OverflowError:  # an int too large for a float: out of range
            value = math.inf
        if not POWER_RANGE[0] <= value <= POWER_RANGE[1]:
            raise ValueError(f"power must be within {POWER_RANGE[0]:g}-{POWER_RANGE[1]:g} %, got {shown}")
        return value

    def local_model(self, power: float) -> AlphaCanonicalModel:
        """The point model at a power level (the published one at 70, 80, 90, 100 %; 110 % is outside)."""
        p = self.check_power(power)
        t = self.template
        a, b, c = self.state_matrices(p)
        return AlphaCanonicalModel(
            A=a,
            B=b,
            C=c,
            dt=t.dt,
            observability_indices=t.observability_indices,
            lam=self._lam(p),
            input_names=t.input_names,
            output_names=t.output_names,
            fit={"source": f"linked model at {p:g} % power"},
        )

    def parameters(self, power: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """K, B, lambda at an array of power levels: shapes (..., n, p), (..., n, m), (..., m)."""
        p = np.clip(np.asarray(power, dtype=float), *POWER_RANGE)
        return self._k(p), self._b(p), self._lam(p)

    def state_matrices(self, power: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A(P) = A_o + K(P) C and B(P) at an array of power levels, shapes (..., n, n) and
        (..., n, m), and the constant C (p, n)."""
        k, b, _ = self.parameters(power)
        structure = self.template.structure
        c = structure.output_matrix()
        return structure.shift_matrix() + k @ c, b, c

    def dc_gain(self, power: float) -> np.ndarray:
        """Steady-state gain of the local model from u* to y, shape (p, m)."""
        return self.local_model(power).dc_gain()

    @staticmethod
    def nominal_outputs(power: np.ndarray) -> np.ndarray:
        """y_eq(P) = (P/100 - 1, 0): normalized deviations from the 100 % point, shape (..., 2)."""
        p = np.asarray(power, dtype=float)
        return np.stack([p / 100.0 - 1.0, np.zeros_like(p)], axis=-1)

    @cached_property
    def _schedule(self) -> tuple[np.ndarray, np.ndarray]:
        grid = np.arange(POWER_RANGE[0], POWER_RANGE[1] + 0.5 * _GRID_STEP, _GRID_STEP)
        a, b, c = self.state_matrices(grid)
        eye = np.eye(a.shape[-1])
        gains = c @ np.linalg.solve(eye - a, b)  # (G, p, m)
        slope = np.linalg.solve(gains, np.broadcast_to([0.01, 0.0], (grid.size, 2))[..., None])[..., 0]
        from scipy.integrate import cumulative_trapezoid

        u = cumulative_trapezoid(slope, grid, axis=0, initial=0.0)
        u -= np.array([np.interp(100.0, grid, u[:, j]) for j in range(u.shape[1])])
        return grid, u

    def nominal_valves(self, power: np.ndarray) -> np.ndarray:
        """The nominal valve schedule u_eq(P), normalized valve positions (0 at 100 %), shape (..., m)."""
        grid, u = self._schedule
        p = np.asarray(power, dtype=float)
        return np.stack([np.interp(p, grid, u[:, j]) for j in range(u.shape[1])], axis=-1)
