"""Standard errors of the nozzle's parameters: J, b, k of DSR_e, and the Bouc-Wen fit's.

The Bouc-Wen fit's come from :func:`regression_covariance` (``s^2 (J^T J)^-1`` at the optimum,
infinite for what the record does not determine). J, b, k of DSR_e come from a residual
bootstrap at fixed structure, since DSR_e gives no covariance of its own.

:func:`dsr_e_uncertainty` repeats the identification on records simulated from the identified
model and reads the covariance of (J, b, k) off the replicates:

1. **Noise.** The innovations estimate of DSR_e's first stage (the residual of the high-order
   ARX projection, :func:`ssme_envs.identification.subspace.dsr_e` step 1, at the past horizon
   the identification used and on the record scaled as DSR_e scales it, in the record's units),
   centred and inflated by ``sqrt(N_e / (N_e - P))`` for the ``P`` regression coefficients it
   cost.
2. **Replicates.** Each replicate draws ``T`` values of that noise with replacement (its own
   :class:`numpy.random.Generator` from ``SeedSequence(seed).spawn``, so the result does not
   depend on ``workers``) and adds them to the model's output under the record's torque:
   ``noise="white"`` (default) adds them as they are (output error, ``y* = G u + e*``);
   ``noise="innovations"`` passes them through the identified noise model first
   (``y* = G u + H e*`` with ``H = 1 + C (zI - A)^-1 K``). ``noise="sieve"`` draws instead from
   an AR sieve of the model's output error ``y - G u``
   (:func:`~ssme_envs.identification.noise_sieve.fit_sieve`): its autoregression's residuals
   resampled and filtered back, so the replicates' noise has the output error's colour.
3. **Re-identification** of every replicate by DSR_e with the order and both horizons fixed at
   the original's, then J, b, k by :func:`second_order_parameters`. The covariance is the
   sample covariance of the replicates (``ddof = 1``).

Why output error with the ARX residuals. The bench's noise is white sensor noise: the truth has
``K = 0``. The identified ``K`` and the order-2 model's prediction errors absorb what a
second-order model cannot describe (the anti-alias filter of the decimation, a joint's
hysteresis). Passing the noise through the identified ``H`` overstates the spread of J, b, k
over noise seeds by a factor 1.3 to 1.9 on the bench, and resampling the order-2 prediction
errors (which carry the filter's distortion) by 2.5 to 3.3 on one exploratory record; the ARX
residuals are the sensor noise up to the truncation of the ARX, and with ``noise="white"`` the
standard errors match the spread within 4 to 9 %
(experiments/results/nozzle_uncertainty_coverage.md). A record with coloured sensor noise calls
for ``noise="sieve"``: under AR(1) noise of coefficient 0.95 its intervals are within 13 % of
the spread over noise seeds, where "white" gives them 2.3 to 4.2 times too narrow and
"innovations" 1.2 to 2.8 (experiments/results/nozzle_coloured_noise.md). It counts what the
linear model leaves out (a hysteresis) as noise too.

What the standard errors cover: the estimates' scatter from the measurement noise. Not covered:
systematic errors of the model structure, the same for every noise realization: the anti-alias
filter of a decimated record (on the embedded bench with the linear joint: J -0.05 %, b
+0.14 %, k -0.07 %, 11 to 32 standard errors) and, for a hysteretic joint, the linearization
itself. With exact samples and the same noise, the 95 % intervals cover the truth 95 to 97 %
of the time (200 seeds).
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import time
from dataclasses import dataclass

import numpy as np
import scipy.signal

from ssme_envs.identification.arguments import real_record
from ssme_envs.identification.channel_scales import equilibrated
from ssme_envs.identification.metrics import fit_percent
from ssme_envs.identification.noise_sieve import ARSieve, fit_sieve
from ssme_envs.identification.subspace import SubspaceResult, dsr_e, second_order_parameters
from ssme_envs.identification.subspace_checks import arx_innovations
from ssme_envs.models.statespace import check_dt
from ssme_envs.models.uncertainty import ParameterUncertainty

PARAMETERS = ("J", "b", "k")
NOISE_MODELS = ("white", "innovations", "sieve")
DEFAULT_REPLICATES = 100
MIN_REPLICATES = 10
# More failed replicates than this fraction means the identification is fragile on this record.
MAX_FAILED_FRACTION = 0.1
_BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


@dataclass(frozen=True, eq=False)
class BootstrapUncertainty:
    """Outcome of :func:`dsr_e_uncertainty`.

    Attributes
    ----------
    estimate : ndarray (3,)
        J (kg m^2), b (N m s/rad), k (N m/rad) of the identified model.
    covariance : ndarray (3, 3)
        Sample covariance of the replicates, in the parameters' units squared.
    replicates : ndarray (R, 3)
        J, b, k of each successful replicate.
    failed : int
        Replicates whose re-identification raised (not in ``replicates``).
    noise_std : float
        Standard deviation of the resampled noise (record's output units).
    method : str
        One sentence on how the covariance was obtained.
    samples : int
        Samples of the record.
    seconds : float
        Wall time.
    """

    estimate: np.ndarray
    covariance: np.ndarray
    replicates: np.ndarray
    failed: int
    noise_std: float
    method: str
    samples: int
    seconds: float = 0.0
    parameters: tuple[str, ...] = PARAMETERS

    @property
    def standard_errors(self) -> np.ndarray:
        return np.sqrt(np.diag(self.covariance))

    def as_dict(self) -> dict[str, float]:
        """Standard errors keyed by parameter name."""
        return dict(zip(self.parameters, (float(v) for v in self.standard_errors), strict=True))

    def parameter_uncertainty(self) -> ParameterUncertainty:
        """The model.json ``uncertainty`` block of the linear model."""
        return ParameterUncertainty(self.parameters, self.covariance, self.method, self.samples)


class _Replicate:
    """One bootstrap record and its J, b, k (picklable; runs in the pool's workers)."""

    def __init__(
        self,
        u: np.ndarray,
        clean: np.ndarray,
        noise: np.ndarray,
        noise_filter: tuple[np.ndarray, np.ndarray] | None,
        dt: float,
        structure: tuple[int, int, int],
        sieve: ARSieve | None = None,
    ) -> None:
        self.u, self.clean, self.noise, self.noise_filter = u, clean, noise, noise_filter
        self.dt, self.structure, self.sieve = dt, structure, sieve

    def __call__(self, seed: np.random.SeedSequence) -> np.ndarray | None:
        rng = np.random.default_rng(seed)
        if self.sieve is not None:
            draw = self.sieve.draw(rng, self.clean.size)
        else:
            draw = self.noise[rng.integers(0, self.noise.size, self.clean.size)]
        if self.noise_filter is not None:
            draw = scipy.signal.lfilter(*self.noise_filter, draw)
        order, past, future = self.structure
        try:
            fit = dsr_e(
                self.u, self.clean + draw, self.dt, order=order, past_horizon=past, future_horizon=future
            )
            params = second_order_parameters(fit.model)
        except ValueError:
            return None
        return np.array([params[name] for name in PARAMETERS])


@contextlib.contextmanager
def _single_threaded_blas():
    """Environment that makes processes started inside it run BLAS on one thread."""
    saved = {name: os.environ.get(name) for name in _BLAS_THREADS}
    os.environ.update(dict.fromkeys(_BLAS_THREADS, "1"))
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def check_noise_model(noise: object, name: str) -> str:
    """``noise`` if it is one of :data:`NOISE_MODELS`, else a ValueError naming ``name``."""
    if not isinstance(noise, str) or noise not in NOISE_MODELS:
        raise ValueError(f"{name} must be one of {', '.join(NOISE_MODELS)}, got {noise!r}")
    return noise


def count_at_least(value: int, name: str, least: int) -> int:
    """``value`` as an int if it is an integer (not a bool) of at least ``least``, else a
    ValueError naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < least:
        raise ValueError(f"{name} must be an integer >= {least}, got {value!r}")
    return int(value)


def _siso(x: np.ndarray, name: str) -> np.ndarray:
    """One real channel (not complex, bool or masked: :func:`real_record`) as floats (T,)."""
    x = np.asarray(real_record(x, name, "channels"), dtype=float)
    if x.ndim == 2 and x.shape[1] == 1:
        x = x[:, 0]
    if x.ndim != 1:
        raise ValueError(f"{name} must be one channel, shape (T,) or (T, 1), got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{name} has NaN or inf entries")
    return x


def _record_innovations(u: np.ndarray, y: np.ndarray, past: int) -> np.ndarray:
    """DSR_e's innovations estimate of the record (its step 1), in the record's output units.

    DSR_e equilibrates a record whose channels spread widely (:func:`equilibration`) and takes
    this estimate on the equilibrated record. Taken on the record as it is, the rank-revealing
    ARX regression drops the small channel's lags as round-off once the spread times the
    regression's condition number nears ``1 / eps``: on a 1000-sample nozzle record (past
    horizon 10) the residual was 8 % off from a spread of 1e13 and 200 times the noise at 1e20,
    and the standard errors with it. The powers of two and their undoing are exact, and a
    balanced record is used as it is (its residuals bit for bit).
    """
    u_scaled, y_scaled, scales = equilibrated(u[:, None], y[:, None])
    residual = arx_innovations(u_scaled, y_scaled, past)[:, 0]
    return residual if scales is None else np.ldexp(residual, scales[1][0])


def dsr_e_uncertainty(
    u: np.ndarray,
    y: np.ndarray,
    dt: float,
    result: SubspaceResult,
    replicates: int = DEFAULT_REPLICATES,
    seed: int = 0,
    workers: int = 1,
    noise: str = "white",
) -> BootstrapUncertainty:
    """Covariance of J, b, k of a second-order DSR_e model by a residual bootstrap.

    Parameters
    ----------
    u, y : array (T,)
        The torque (N m) and angle (rad) record ``result`` was identified from.
    dt : float
        Sample time, s.
    result : SubspaceResult
        :func:`dsr_e` of the record, order 2 (its order and horizons are kept).
    replicates : int
        Bootstrap records (at least 10; the standard errors' own relative error is about
        ``1 / sqrt(2 replicates)``, 7 % for 100).
    seed : int
        Seed of the resampling: same seed, same result, for any ``workers``.
    workers : int
        Processes for the replicates (1: this process). More than one starts ``spawn`` processes
        with one BLAS thread each (multi-threaded BLAS on these small problems is slower, and
        on a loaded machine far slower); as with any spawn pool, a script calling this must
        guard its top level with ``if __name__ == "__main__":``.
    noise : {"white", "innovations", "sieve"}
        How the resampled noise enters (module docstring): "white" for white sensor noise,
        "sieve" for coloured sensor noise.

    Raises
    ------
    ValueError
        Bad arguments, a record that does not match ``result`` (its sample time, or a model
        that simulates it worse than its mean; TypeError for a ``result`` that is not a
        :class:`SubspaceResult`), a constant ``y``, a model that is not a SISO
        second-order oscillator, or more than 10 % of the replicates failing to identify.
    """
    start = time.perf_counter()
    u, y = _siso(u, "u"), _siso(y, "y")
    dt = check_dt(dt)
    replicates = count_at_least(replicates, "replicates", MIN_REPLICATES)
    workers = count_at_least(workers, "workers", 1)
    seed = count_at_least(seed, "seed", 0)
    check_noise_model(noise, "noise")
    if u.size != y.size:
        raise ValueError(f"u has {u.size} samples but y has {y.size}")
    if not isinstance(result, SubspaceResult):
        got = type(result).__name__
        raise TypeError(f"result must be the SubspaceResult of dsr_e on the record, got {got}")
    if not np.ptp(y) > 0:
        raise ValueError("y is constant: there is no response to bootstrap")
    model = result.model
    if abs(model.dt - dt) > 1e-9 * dt:
        raise ValueError(f"the model's sample time {model.dt:g} s differs from dt = {dt:g} s")
    params = second_order_parameters(model)  # SISO, order 2, an oscillator: or a ValueError
    estimate = np.array([params[name] for name in PARAMETERS])
    past = result.past_horizon
    if past >= u.size // 2:
        raise ValueError(f"the record ({u.size} samples) is too short for the past horizon {past}")

    residual = _record_innovations(u, y, past)
    coefficients = 1 + 2 * past  # u(k) and u, y at lags 1..past
    if residual.size <= 2 * coefficients:
        raise ValueError(f"the record ({u.size} samples) is too short for the past horizon {past}")
    residual = (residual - residual.mean()) * np.sqrt(residual.size / (residual.size - coefficients))
    noise_filter = None
    if noise == "innovations":
        num, den = scipy.signal.ss2tf(model.A, model.K, model.C, np.ones((1, 1)))
        noise_filter = (np.ravel(num), np.ravel(den))
    clean = model.simulate(u)[:, 0]
    fit = float(fit_percent(y, clean))
    if not fit > 0:  # the model explains less of y than y's mean: not the record it came from
        raise ValueError(
            f"the model simulates this record worse than its mean does (fit {fit:.3g} %): pass the "
            "record result was identified from"
        )
    sieve = None
    if noise == "sieve":  # the output error's colour, kept: the model's own residual, not the ARX's
        sieve = fit_sieve(y - clean)
        residual = y - clean - np.mean(y - clean)
    structure = (result.order, past, result.future_horizon)
    replicate = _Replicate(u, clean, residual, noise_filter, dt, structure, sieve)
    seeds = np.random.SeedSequence(seed).spawn(replicates)
    if workers > 1:
        # The spawned workers read the BLAS setting when they load numpy. Their first act is to
        # ignore SIGINT (a Ctrl-C reaches the whole process group; the parent handles it and
        # ends the pool): the initializer is signal.signal itself, so nothing heavy is imported
        # before it, and the replicate travels with the tasks.
        with _single_threaded_blas():
            pool = multiprocessing.get_context("spawn").Pool(
                min(workers, replicates), initializer=signal.signal, initargs=(signal.SIGINT, signal.SIG_IGN)
            )
        try:
            runs = pool.map(replicate, seeds)
        except BaseException:
            pool.terminate()  # do not wait for the remaining replicates
            raise
        finally:
            pool.close()
            pool.join()
    else:
        runs = [replicate(s) for s in seeds]
    good = np.array([r for r in runs if r is not None])
    failed = replicates - len(good)
    if failed > MAX_FAILED_FRACTION * replicates:
        raise ValueError(
            f"{failed} of {replicates} bootstrap records could not be identified as a second-order "
            "oscillator: the J, b, k of this record are fragile; check the record or the order"
        )
    if sieve is None:
        how = "as white output noise" if noise == "white" else "through the identified noise model"
        noise_source = f"the DSR_e innovations estimate resampled {how}"
    else:
        noise_source = (
            f"an AR({sieve.order}) sieve of the model's output error (its innovations resampled and "
            "filtered back)"
        )
    method = (
        f"residual bootstrap: {len(good)} records simulated from the identified model with "
        f"{noise_source}, re-identified at order {result.order}, past horizon "
        f"{past}, future horizon {result.future_horizon} (seed {seed}); sample covariance of J, b, k"
    )
    return BootstrapUncertainty(
        estimate=estimate,
        covariance=np.cov(good, rowvar=False, ddof=1),
        replicates=good,
        failed=failed,
        noise_std=float(np.std(residual)),
        method=method,
        samples=int(u.size),
        seconds=time.perf_counter() - start,
    )


def regression_covariance(jac: np.ndarray, residual_variance: float) -> np.ndarray:
    """Covariance ``s^2 (J^T J)^-1`` of a least-squares fit, infinite where J does not determine it.

    ``jac`` is the Jacobian of the residuals at the optimum (rows: samples), ``residual_variance``
    the estimate ``s^2 = SSE / (N - P)``. The columns are scaled to unit norm and ``J`` is split
    by its singular values: directions with a singular value below ``1e-8`` of the largest are
    not determined by the data, and every parameter with a weight above ``1e-6`` on one of them
    gets an infinite variance (its row and column: inf on the diagonal, NaN elsewhere) instead
    of the zero a pseudo-inverse would give it.
    """
    norms = np.linalg.norm(jac, axis=0)
    scale = np.where(norms > 0, norms, 1.0)
    _, sv, vt = np.linalg.svd(jac / scale, full_matrices=False)
    keep = sv > 1e-8 * sv[0] if sv.size and sv[0] > 0 else np.zeros(sv.shape, dtype=bool)
    basis = vt[keep].T / sv[keep]
    cov = residual_variance * (basis @ basis.T) / np.outer(scale, scale)
    loose = (norms == 0) | np.any(np.abs(vt[~keep]) > 1e-6, axis=0)
    cov[loose, :] = np.nan
    cov[:, loose] = np.nan
    cov[loose, loose] = np.inf
    return cov
