"""A nonlinear SSME valve-dynamics truth, state-scheduled and consistent with Table I.

This is a **synthetic** engine, not Rocketdyne's nonlinear simulation (which NASA TM-104422
identified its models from and which is not public). It is a small nonlinear plant whose local
behaviour is the paper's: linearized at each Table I level's operating point it has that
level's Markov parameters, and a +-0.01 PRBS on it shows that level's asymmetric gains lambda.
How it behaves between and away from those points is assumed, as listed here.

**Units.** Outputs are normalized by their 100 % power values and measured from the 100 %
point, as in :mod:`ssme_envs.models.linked`: ``y = (Pc / Pc_100 - 1, MR / MR_nom - 1)``.
Valve positions ``v`` are in normalized valve travel, measured from their 100 % trim positions.
Power ``P`` is in % of rated power, time in s, the sample time 0.04 s (``ENGINE_DT``).

**Operating points (trim).** At power ``P`` the engine rests at ``y_eq(P) = (P/100 - 1, 0)``
(chamber pressure proportional to power, nominal mixture ratio) with valves at ``v_eq(P)`` and
alpha-canonical state ``x_eq(P)`` (``C x_eq = y_eq``). Both follow from the local models:
``v_eq' = G(P)^-1 y_eq'`` and ``x_eq' = (I - A(P))^-1 B(P) v_eq'`` (derivatives in P,
``G = C (I - A)^-1 B`` the small-signal DC gain), integrated from ``x_eq(100) = 0``,
``v_eq(100) = 0`` (6-point Gauss-Legendre per 0.25 % step, cubic Hermite in between with the
exact derivatives at the nodes). ``v_eq`` is the nominal valve schedule of the linked model.

**Scheduling.** The five Table I models share their structure (indices (2, 2), ``C = [0 I]``;
the constructor checks it), so their K, B and lambda are comparable entry by entry; they are
interpolated in power by a natural cubic spline (C2), extended linearly below 70 % and above
110 % (still C2). The scheduling variable ``rho`` is an engine state: the power level implied
by the absolute chamber pressure, ``100 (1 + y_pc)``, optionally through a first-order lag of
time constant ``tau``: ``rho(k+1) = rho(k) + alpha (100 (1 + y_pc(k+1)) - rho(k))``,
``alpha = 1 - exp(-dt / tau)``. By default ``tau = 0``: the schedule follows Pc sample by
sample, so it moves exactly as fast as the engine's own chamber pressure (Table I's slowest
mode is 0.09 s); the command never enters it. ``rho`` saturates at 62.5-115 % (below about
61 % the linear extension of lambda would leave the flow curve's monotone range); operating
points are accepted in 65-110 % (the SSME's 65-109 % and Table I's 110 %).

**Dynamics.** With ``A(rho) = A_o + K(rho) C``:

    x(k+1) = x_eq(rho) + A(rho) (x(k) - x_eq(rho)) + B(rho) phi(v(k) - v_eq(rho); lambda(rho)),
    y(k) = C x(k):

the local model about the equilibrium of the power the engine is at. (With ``tau = 0`` the Pc
entry of ``x - x_eq(rho)`` is zero: Pc acts through ``x_eq(rho)``.) At ``(x_eq(P), P, v_eq(P))``
the map is at rest, and its Jacobian is ``dx+/dx = A(P)``, ``dx+/dv = B(P)`` and ``dx+/drho =
(I - A) x_eq' - B v_eq' = 0`` (the trim equations above make it so): the schedule is invisible
to first order and the linearization's Markov parameters ``C A^k B`` are Table I's.

**Valve effect.** ``phi(psi(d))`` maps a valve's departure ``d`` from its nominal position at
the current power to its effect on the engine, per valve (:mod:`ssme_envs.models.engine_valve_flow`
states both curves and what they assume): ``psi``, the valve's authority, slope 1 at the trim and
falling symmetrically away from it (calibrated, ``authority_loss=0`` removes it); ``phi``, the flow
curve, slope 1 at the trim and curved so that its chords to +-0.01 are Table I's asymmetric gains
``lambda`` and ``2 - lambda``. Both have slope 1 at ``d = 0``, so the Jacobian's B is Table I's;
the schedule and both curves are what an identified point model misses.

**Valve hardware and sensors.** The linkage backlash, valve stiction and sensor noise of
:class:`~ssme_envs.models.engine.TruthConfig` act on the valve command deviations as in the
linear truth; ``asymmetric_gains=False`` makes ``phi`` the identity (``psi`` stays: it is the
engine's).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ssme_envs.models.engine import (
    POWER_LEVELS,
    TruthConfig,
    published_model,
    sensor_noise_std,
    with_sensor_noise,
)
from ssme_envs.models.engine_step import valves_arrays
from ssme_envs.models.engine_valve_flow import (
    AUTHORITY_LOSS,
    AUTHORITY_TRAVEL,
    FLOW_AMPLITUDE,
    LAMBDA_LIMIT,
    check_authority,
    flow_characteristic,
    valve_effect,
)
from ssme_envs.models.linear import spectral_radius
from ssme_envs.models.statespace import AlphaCanonicalModel

SCHEDULE_RANGE = (62.5, 115.0)  # %, saturation of the scheduling variable
OPERATING_RANGE = (65.0, 110.0)  # %, accepted operating points
DEFAULT_SCHEDULE_LAG = 0.0  # s, time constant of the scheduling variable (0: none)
PC_PER_PERCENT = 0.01  # normalized Pc per % of power
GRID_STEP = 0.25  # %, node spacing of the parameter and trim tables
_GAUSS = np.polynomial.legendre.leggauss(6)


@dataclass(frozen=True)
class _Layout:
    """Column slices of the parameter table: K (n*p), B (n*m), lambda (m), x_eq (n), v_eq (m)."""

    n: int
    p: int
    m: int

    def slices(self) -> dict[str, slice]:
        sizes = {"K": self.n * self.p, "B": self.n * self.m, "lam": self.m, "x_eq": self.n, "v_eq": self.m}
        out, start = {}, 0
        for name, size in sizes.items():
            out[name] = slice(start, start + size)
            start += size
        return out


class NonlinearEngine:
    """The state-scheduled nonlinear engine (module docstring), N engines stepped as arrays.

    Parameters
    ----------
    models : sequence of AlphaCanonicalModel, optional
        Point models sharing one structure with ``C = [0 I]`` (default: Table I).
    powers : sequence of float, optional
        Their power levels, %, increasing (default 70, 80, 90, 100, 110).
    tau : float
        Time constant of the scheduling variable, s (0: it follows Pc without lag).
    authority_loss, authority_travel : float
        ``g`` (in [0, 1)) and ``b`` (normalized valve travel) of the valve authority ``psi``
        (:mod:`ssme_envs.models.engine_valve_flow`); ``authority_loss=0`` removes it.
    """

    def __init__(
        self,
        models: Sequence[AlphaCanonicalModel] | None = None,
        powers: Sequence[float] | None = None,
        tau: float = DEFAULT_SCHEDULE_LAG,
        authority_loss: float = AUTHORITY_LOSS,
        authority_travel: float = AUTHORITY_TRAVEL,
    ) -> None:
        if models is None:
            models, powers = [published_model(p) for p in POWER_LEVELS], POWER_LEVELS
        if powers is None or len(powers) != len(models) or len(models) < 2:
            raise ValueError("give at least two point models and their power levels")
        self.powers = np.asarray(powers, dtype=float)
        if np.any(np.diff(self.powers) <= 0):
            raise ValueError("power levels must increase")
        first = models[0]
        n, p, m = first.A.shape[0], first.n_outputs, first.n_inputs
        for model in models:
            if model.observability_indices != first.observability_indices or model.dt != first.dt:
                raise ValueError("the point models must share observability indices and sample time")
            if not np.array_equal(model.C, first.structure.output_matrix()):
                raise ValueError("the point models must have C = [0 I] (H = I)")
        if not (np.isfinite(tau) and tau >= 0):
            raise ValueError(f"tau must be a time constant >= 0 s, got {tau!r}")
        self.authority_loss, self.authority_travel = check_authority(authority_loss, authority_travel)
        self.template = first
        self.dt = first.dt
        self.tau = float(tau)
        self.alpha = 1.0 if tau == 0 else float(-np.expm1(-self.dt / tau))
        self.shift = first.structure.shift_matrix()
        self.C = first.structure.output_matrix()
        self.layout = _Layout(n, p, m)
        self._cols = self.layout.slices()
        from scipy.interpolate import CubicSpline  # here: importing scipy.interpolate costs 0.25 s

        self._spline = CubicSpline(
            self.powers,
            np.stack([np.concatenate([mo.K.ravel(), mo.B.ravel(), mo.lam]) for mo in models]),
            bc_type="natural",
        )
        self._build_table()

    # --- tables -----------------------------------------------------------------------------
    def _local(self, power: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Spline values and derivatives of (K, B, lambda) at powers, linear beyond the end levels."""
        P = np.asarray(power, dtype=float)
        ends = np.clip(P, self.powers[0], self.powers[-1])
        slope = self._spline(ends, 1)
        return self._spline(ends) + slope * (P - ends)[:, None], slope

    def _trim_slopes(self, power: np.ndarray) -> np.ndarray:
        """(x_eq', v_eq') per % of power at powers, shape (len(power), n + m)."""
        n, p, m = self.layout.n, self.layout.p, self.layout.m
        values, _ = self._local(power)
        k_gain = values[:, : n * p].reshape(-1, n, p)
        b = values[:, n * p : n * p + n * m].reshape(-1, n, m)
        resolvent = np.linalg.inv(np.eye(n) - (self.shift + k_gain @ self.C))
        gain = self.C @ resolvent @ b
        dy = np.zeros((len(values), p, 1))
        dy[:, 0, 0] = PC_PER_PERCENT
        dv = np.linalg.solve(gain, dy)
        return np.concatenate([(resolvent @ b @ dv)[..., 0], dv[..., 0]], axis=1)

    def _build_table(self) -> None:
        lo, hi = SCHEDULE_RANGE
        grid = lo + GRID_STEP * np.arange(round((hi - lo) / GRID_STEP) + 1)
        if not np.all(np.isin(self.powers, grid)):
            raise ValueError(f"power levels must lie on the {GRID_STEP} % grid within {SCHEDULE_RANGE}")
        params, dparams = self._local(grid)
        trim_slopes = self._trim_slopes(grid)
        nodes, weights = _GAUSS
        mids, half = 0.5 * (grid[1:] + grid[:-1]), 0.5 * np.diff(grid)
        points = (mids[:, None] + half[:, None] * nodes[None, :]).ravel()
        inner = self._trim_slopes(points).reshape(len(mids), len(nodes), -1)
        steps = half[:, None] * np.einsum("g,sgc->sc", weights, inner)
        trim = np.vstack([np.zeros(steps.shape[1]), np.cumsum(steps, axis=0)])
        trim -= trim[np.flatnonzero(grid == 100.0)[0]]  # x_eq(100) = 0, v_eq(100) = 0
        from scipy.interpolate import CubicHermiteSpline

        spline = CubicHermiteSpline(grid, np.hstack([params, trim]), np.hstack([dparams, trim_slopes]))
        # the piecewise cubic of the table, read by table() and by the engine envs' step: on
        # segment s (grid[s] <= rho < grid[s + 1]), column j is ((c0 t + c1) t + c2) t + c3 with
        # t = rho - grid[s] and c = coef[:, s, j]
        self.grid = grid  # (segments + 1,) %, the nodes, SCHEDULE_RANGE[0] + GRID_STEP k
        self.coef = np.ascontiguousarray(spline.c)  # (4, segments, columns)
        self.columns = self._cols  # column slices of the table: K, B, lam, x_eq, v_eq
        fine = self.table(np.linspace(lo, hi, 4 * grid.size))
        if np.max(np.abs(fine["lam"] - 1.0)) >= LAMBDA_LIMIT:
            raise ValueError(f"|lambda - 1| reaches sqrt(2) - 1 within {SCHEDULE_RANGE} %: phi not monotone")
        radius = spectral_radius(self.shift + fine["K"] @ self.C)
        if radius >= 1.0:
            raise ValueError(f"the scheduled A is unstable within {SCHEDULE_RANGE} % (radius {radius:.3f})")

    def table(self, rho: np.ndarray) -> dict[str, np.ndarray]:
        """K (N, n, p), B (N, n, m), lambda (N, m), x_eq (N, n), v_eq (N, m) at scheduling values.

        ``rho`` (%, shape (N,)) is clipped to ``SCHEDULE_RANGE`` first.
        """
        r = np.clip(np.asarray(rho, dtype=float), *SCHEDULE_RANGE)
        seg = np.minimum(((r - SCHEDULE_RANGE[0]) / GRID_STEP).astype(np.intp), self.coef.shape[1] - 1)
        t = (r - self.grid[seg])[:, None]
        c = self.coef
        vals = ((c[0, seg] * t + c[1, seg]) * t + c[2, seg]) * t + c[3, seg]
        n, p, m = self.layout.n, self.layout.p, self.layout.m
        cols = self._cols
        return {
            "K": vals[:, cols["K"]].reshape(-1, n, p),
            "B": vals[:, cols["B"]].reshape(-1, n, m),
            "lam": vals[:, cols["lam"]],
            "x_eq": vals[:, cols["x_eq"]],
            "v_eq": vals[:, cols["v_eq"]],
        }

    # --- trim and step ----------------------------------------------------------------------
    @staticmethod
    def check_power(power: np.ndarray) -> np.ndarray:
        """Operating points as a float array, or ValueError outside ``OPERATING_RANGE``."""
        P = np.atleast_1d(np.asarray(power, dtype=float))
        if P.ndim != 1 or not np.all(np.isfinite(P)):
            raise ValueError(f"power must be a number or a 1-D array of %, got {power!r}")
        if np.any(P < OPERATING_RANGE[0]) or np.any(P > OPERATING_RANGE[1]):
            raise ValueError(f"power must be within {OPERATING_RANGE[0]:g}-{OPERATING_RANGE[1]:g} %")
        return P

    def nominal_outputs(self, power: np.ndarray) -> np.ndarray:
        """y_eq(P) = (P/100 - 1, 0, ...), shape (N, p)."""
        P = np.atleast_1d(np.asarray(power, dtype=float))
        y = np.zeros((P.size, self.layout.p))
        y[:, 0] = PC_PER_PERCENT * (P - 100.0)
        return y

    def trim(self, power: float | np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Equilibrium at operating points: state x (N, n), scheduling variable rho (N,) in %,
        valve positions v (N, m) in normalized travel from the 100 % trim."""
        P = self.check_power(power)
        tab = self.table(P)
        return tab["x_eq"].copy(), P.copy(), tab["v_eq"].copy()

    def linear_model(self, power: float) -> AlphaCanonicalModel:
        """The engine's linearization about its trim at ``power`` % (65-110): ``A = A_o + K(P) C``,
        ``B(P)`` and ``lambda(P)`` of the table (the Jacobian of the one-step map, module docstring;
        Table I's model at the Table I levels)."""
        tab = self.table(self.check_power(power))
        t = self.template
        return AlphaCanonicalModel(
            A=self.shift + tab["K"][0] @ self.C,
            B=tab["B"][0],
            C=self.C,
            dt=self.dt,
            observability_indices=t.observability_indices,
            lam=tab["lam"][0],
            input_names=t.input_names,
            output_names=t.output_names,
            fit={"source": f"nonlinear engine linearized at {float(power):g} % power"},
        )

    def power_of(self, x: np.ndarray) -> np.ndarray:
        """Power implied by the chamber pressure of states x (N, n), %."""
        return 100.0 + x[:, self.layout.n - self.layout.p] / PC_PER_PERCENT

    def step(
        self, x: np.ndarray, rho: np.ndarray, v: np.ndarray, asymmetric: bool = True
    ) -> tuple[np.ndarray, np.ndarray]:
        """One sample of N engines: states x (N, n), schedule rho (N,) %, valves v (N, m).

        Returns (x, rho) at the next sample. ``asymmetric=False`` makes the flow curve linear
        (the valve authority stays).
        """
        tab = self.table(rho)
        e = x - tab["x_eq"]
        d = v - tab["v_eq"]
        flow = valve_effect(d, tab["lam"], np.sqrt, asymmetric, self.authority_loss, self.authority_travel)
        x_next = tab["x_eq"] + e @ self.shift.T
        x_next += np.einsum("nij,nj->ni", tab["K"], e[:, self.layout.n - self.layout.p :])
        x_next += np.einsum("nij,nj->ni", tab["B"], flow)
        return x_next, rho + self.alpha * (self.power_of(x_next) - rho)

    def outputs(self, x: np.ndarray) -> np.ndarray:
        """Absolute normalized outputs y = C x, shape (N, p)."""
        return x[:, self.layout.n - self.layout.p :].copy()


def simulate_nonlinear(
    engine: NonlinearEngine,
    power: float | np.ndarray,
    commands: np.ndarray,
    config: TruthConfig | None = None,
    rng: np.random.Generator | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Run the nonlinear truth from trim on valve command deviations, N runs at once.

    Parameters
    ----------
    engine : NonlinearEngine
        The plant (its tables and schedule lag).
    power : float or array of shape (N,)
        Operating point of each run, % (65-110); the runs start at its trim.
    commands : array, shape (T, m) or (N, T, m)
        Valve commands, normalized travel, as deviations from the trim valve positions.
    config : TruthConfig, optional
        Valve backlash, stiction, sensor noise and the asymmetric switch (default ``TruthConfig()``).
    rng : numpy Generator, optional
        Source of the sensor noise; required when the config has noise.

    Returns
    -------
    measured, clean : arrays of shape (T, p) or (N, T, p)
        Outputs as deviations from the operating point ``y - y_eq(power)``, normalized; ``y(k)``
        is the output before command ``k`` acts (as :func:`ssme_envs.models.engine.simulate`).
    """
    config = TruthConfig() if config is None else config
    u = np.asarray(commands, dtype=float)
    single = u.ndim == 2
    u = u[None] if single else u
    m, p = engine.layout.m, engine.layout.p
    if u.ndim != 3 or u.shape[2] != m or not np.all(np.isfinite(u)):
        raise ValueError(f"commands must be finite, shape (T, {m}) or (N, T, {m}), got {np.shape(commands)}")
    n_runs, horizon, _ = u.shape
    P = engine.check_power(power)
    if P.size == 1:
        P = np.full(n_runs, P[0])
    if P.size != n_runs:
        raise ValueError(f"{P.size} operating points for {n_runs} runs")
    noise = sensor_noise_std(config, p, rng)
    x, rho, v_trim = engine.trim(P)
    y_eq = engine.nominal_outputs(P)
    linkage = np.zeros((m, n_runs))
    valve = np.zeros((m, n_runs))
    half, stick = 0.5 * config.backlash, float(config.stiction)
    clean = np.empty((n_runs, horizon, p))
    for k in range(horizon):
        clean[:, k] = engine.outputs(x) - y_eq
        linkage, valve = valves_arrays(linkage, valve, np.array(u[:, k].T), half, stick)
        x, rho = engine.step(x, rho, v_trim + valve.T, config.asymmetric_gains)
    measured = with_sensor_noise(clean, noise, rng)
    return (measured[0], clean[0]) if single else (measured, clean)


__all__ = [
    "DEFAULT_SCHEDULE_LAG",
    "FLOW_AMPLITUDE",
    "GRID_STEP",
    "OPERATING_RANGE",
    "PC_PER_PERCENT",
    "SCHEDULE_RANGE",
    "NonlinearEngine",
    "flow_characteristic",
    "simulate_nonlinear",
]
