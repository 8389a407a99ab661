"""The two costs the Bouc-Wen fit minimizes: the equation error of its global search (filtered
signals, the hysteretic path along the measured angle, the linear parameters by least squares)
and the output error of its refinement, whose Jacobian columns are simulated in a process pool.
Apart from :mod:`.bouc_wen`, which runs the search and the refinement and judges the result."""

from __future__ import annotations

import multiprocessing
import signal

import numpy as np
import scipy.interpolate
import scipy.signal

from ssme_envs.models.nozzle import simulate_nozzle

NORMALIZED_NAMES = ("J", "b", "k_el", "k_hys", "beta_n", "gamma_n", "n")
_UPSAMPLE = 2  # path increments per sample when integrating w along the measured angle


def _svf(signal: np.ndarray, dt: float, wf: float, order: int) -> np.ndarray:
    """s^order (wf / (s + wf))^3 applied to a sampled signal (bilinear discretization)."""
    num = np.zeros(order + 1)
    num[0] = wf**3
    den = np.poly([-wf, -wf, -wf])
    bz, az, _ = scipy.signal.cont2discrete((num, den), dt, method="bilinear")
    return scipy.signal.lfilter(np.ravel(bz), az, signal, axis=-1)


class _EquationError:
    """Equation-error cost of shape candidates with J, b, k_el, k_hys solved by least squares."""

    def __init__(self, tau: np.ndarray, x: np.ndarray, dt: float, wf: float) -> None:
        t = np.arange(x.size) * dt
        fine_t = np.linspace(0.0, t[-1], (x.size - 1) * _UPSAMPLE + 1)
        self.dx = np.diff(scipy.interpolate.CubicSpline(t, x)(fine_t))
        self.dt, self.wf = dt, wf
        skip = int(np.ceil(10.0 / (wf * dt)))  # let the filter transient die out
        self.keep = slice(skip, None)
        shared = np.column_stack([_svf(x, dt, wf, 2), _svf(x, dt, wf, 1), _svf(x, dt, wf, 0)])[self.keep]
        self.scale = np.linalg.norm(shared, axis=0)
        self.q, self.r = np.linalg.qr(shared / self.scale)
        target = _svf(tau, dt, wf, 0)[self.keep]
        self.target = target - self.q @ (self.q.T @ target)
        self.linear_cost = float(self.target @ self.target)
        self.filtered_tau = target

    def hysteresis_path(self, beta_n: np.ndarray, gamma_n: np.ndarray, power: np.ndarray) -> np.ndarray:
        """w(k) along the measured path for each candidate (midpoint rule in x), shape (P, T)."""
        w = np.zeros_like(beta_n)
        out = np.empty((beta_n.size, self.dx.size // _UPSAMPLE + 1))
        out[:, 0] = 0.0
        gamma_up, gamma_down = gamma_n, -gamma_n  # gamma sign(dx w) = (+-gamma) sign(w)
        # |w| never exceeds the loading asymptote; clipping keeps the explicit rule stable when a
        # candidate's hysteresis is stiff against the path increments.
        w_max = (beta_n + gamma_n) ** (-1.0 / power)
        for i, d in enumerate(self.dx.tolist()):
            g = gamma_up if d > 0 else gamma_down
            mid = np.clip(w + 0.5 * d * (1.0 - np.abs(w) ** power * (beta_n + g * np.sign(w))), -w_max, w_max)
            w = np.clip(w + d * (1.0 - np.abs(mid) ** power * (beta_n + g * np.sign(mid))), -w_max, w_max)
            if (i + 1) % _UPSAMPLE == 0:
                out[:, (i + 1) // _UPSAMPLE] = w
        return out

    def costs(
        self, beta_n: np.ndarray, gamma_n: np.ndarray, power: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Relative equation error (1 = no better than linear) and k_hys of each candidate."""
        fw = _svf(self.hysteresis_path(beta_n, gamma_n, power), self.dt, self.wf, 0)[:, self.keep]
        resid_w = fw - (fw @ self.q) @ self.q.T
        denom = np.einsum("ij,ij->i", resid_w, resid_w)
        projection = resid_w @ self.target
        k_hys = projection / np.where(denom > 0, denom, 1.0)
        cost = (self.linear_cost - k_hys * projection) / self.linear_cost
        return np.where((k_hys > 0) & (denom > 0), cost, 1.0), k_hys

    def linear_part(self, fw: np.ndarray | None, k_hys: float) -> np.ndarray:
        """J, b, k_el for a given filtered w path and k_hys (or the linear joint when fw is None)."""
        rhs = self.filtered_tau - (0.0 if fw is None else k_hys * fw)
        coef = np.linalg.solve(self.r, self.q.T @ rhs)
        return coef / self.scale


def _shape_from_search(z: np.ndarray, amplitude: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(log10 w_max / amplitude, split, n) -> beta_n, gamma_n, n; z has shape (3, P)."""
    w_max = amplitude * 10.0 ** z[0]
    power = z[2]
    load = w_max ** (-power)
    return z[1] * load, (1.0 - z[1]) * load, power


class _Simulator:
    """Simulated angle of normalized parameter vectors on one torque record (picklable)."""

    def __init__(self, tau: np.ndarray, dt: float, torque_limit: float) -> None:
        self.tau, self.dt, self.torque_limit = tau, dt, torque_limit

    def __call__(self, theta: np.ndarray, substeps: int) -> np.ndarray:
        params = dict(zip(NORMALIZED_NAMES, theta, strict=True))
        return simulate_nozzle(params, self.tau, self.dt, substeps=substeps, torque_limit=self.torque_limit)


_WORKER: dict[str, _Simulator] = {}


def _init_worker(simulator: _Simulator) -> None:
    # Ctrl-C goes to the whole process group: the parent handles it and ends the pool.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    np.seterr(over="ignore", invalid="ignore")  # as fit_bouc_wen's: overflowing candidates are dropped
    _WORKER["simulate"] = simulator


def _run_worker(job: tuple[np.ndarray, int]) -> np.ndarray:
    return _WORKER["simulate"](*job)


class _Residuals:
    """Output-error residuals with a forward-difference Jacobian whose columns run in a pool."""

    def __init__(self, simulator: _Simulator, measured: np.ndarray, pool, substeps: int) -> None:
        self.simulate, self.measured, self.pool, self.substeps = simulator, measured, pool, substeps
        self._last: tuple[bytes, np.ndarray] | None = None

    def __call__(self, theta: np.ndarray) -> np.ndarray:
        if self._last is None or self._last[0] != theta.tobytes():
            self._last = (theta.tobytes(), self.simulate(theta, self.substeps) - self.measured)
        return self._last[1]

    def jacobian(self, theta: np.ndarray, columns: int | None = None) -> np.ndarray:
        """Forward differences in the first ``columns`` parameters (all by default)."""
        base = self(theta)
        steps = 1e-7 * np.maximum(np.abs(theta), 1e-3)
        count = theta.size if columns is None else columns
        jobs = [(theta + np.eye(theta.size)[i] * steps[i], self.substeps) for i in range(count)]
        runs = (
            self.pool.map(_run_worker, jobs) if self.pool is not None else (self.simulate(*j) for j in jobs)
        )
        return np.column_stack(
            [(run - self.measured - base) / h for run, h in zip(runs, steps[:count], strict=True)]
        )


def _make_pool(workers: int, simulator: _Simulator):
    if workers <= 1:
        return None
    try:
        context = multiprocessing.get_context("fork")
    except ValueError:  # platforms without fork: stay in this process
        return None
    return context.Pool(workers, initializer=_init_worker, initargs=(simulator,))
