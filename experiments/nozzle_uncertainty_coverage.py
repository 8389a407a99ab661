"""Coverage of the nozzle's standard errors over noise seeds of the bench experiment.

J, b, k from DSR_e with the residual-bootstrap standard errors of ``dsr_e_uncertainty`` (the
library defaults: 100 replicates, white output noise), on the linear joint of Table 1, whose
J, b, k are the truth, for ``--seeds`` noise seeds, with two acquisitions of the same motion and
the same sensor noise:

* **bench**: the bench as ``bench_experiment`` simulates it (noise at 2.5 kHz, anti-alias FIR
  filter, decimation by 20);
* **bench, bias-corrected**: the bench's estimates minus the acquisition chain's bias at the
  estimate (``acquisition_bias`` over ``BIAS_DRAWS`` simulated noisy acquisitions, what
  ``identify_nozzle(bench_noise=...)`` does; standard errors the bench's times
  sqrt(1 + 1/BIAS_DRAWS));
* **ideal sampler**: the same decimated noise added to the exact samples of the angle at
  Ts = 0.008 s (no anti-alias filter acting on the motion), which the second-order ZOH model
  describes exactly.

Then the Bouc-Wen fit's regression standard errors on Table 1's Bouc-Wen joint over
``--bouc-wen-seeds`` seeds, both acquisitions. Writes
experiments/results/nozzle_uncertainty_coverage.md.

    python experiments/nozzle_uncertainty_coverage.py [--seeds 200] [--bouc-wen-seeds 12]
        [--acquisitions bench,ideal]
"""

from __future__ import annotations

import os

# one BLAS thread per process: the replicates' small factorizations run slower on more (and a
# loaded machine makes multi-threaded BLAS crawl); set before numpy loads
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import multiprocessing  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from ssme_envs.identification.bouc_wen import NORMALIZED_NAMES, fit_bouc_wen  # noqa: E402
from ssme_envs.identification.nozzle_pipeline import (  # noqa: E402
    BIAS_DRAWS,
    DECIMATION,
    SENSOR_NOISE,
    acquire,
    acquisition_bias,
    bench_motion,
)
from ssme_envs.identification.nozzle_uncertainty import (  # noqa: E402
    DEFAULT_REPLICATES,
    MIN_REPLICATES,
    PARAMETERS,
    dsr_e_uncertainty,
)
from ssme_envs.identification.subspace import dsr_e, second_order_parameters  # noqa: E402
from ssme_envs.models.nozzle import NOZZLE_DT, published_nozzle  # noqa: E402
from ssme_envs.outputs import write_text  # noqa: E402
from ssme_envs.script_options import comma_choices, int_within, max_workers, output_file, script_parser  # noqa: E402

OUT = Path(__file__).resolve().parent / "results" / "nozzle_uncertainty_coverage.md"
Z95 = 1.959963984540054
SEED_OFFSET = 1000  # noise seeds SEED_OFFSET, SEED_OFFSET + 1, ...
INNOVATIONS_SEEDS = 50  # seeds on which the noise="innovations" variant is compared
MEASURED = {"bench": "bench", "ideal": "ideal sampler"}  # --acquisitions: name in the tables
CORRECTED = "bench, bias-corrected"

_MOTION: dict[str, np.ndarray] = {}


def measured(angle: np.ndarray, seed: int, acquisition: str) -> np.ndarray:
    """The angle record at Ts under one acquisition (same noise draw for both)."""
    if acquisition == "bench":
        return acquire(angle, seed)
    return angle[::DECIMATION] + acquire(np.zeros_like(angle), seed)


def linear_seed(job: tuple[int, int, tuple[str, ...]]) -> dict[str, np.ndarray]:
    """Estimates and standard errors of J, b, k for one noise seed, each acquisition."""
    seed, replicates, acquisitions = job
    tau, angle = _MOTION["tau"], _MOTION["angle"]
    out = {}
    for acquisition in acquisitions:
        y = measured(angle, seed, acquisition)
        result = dsr_e(tau, y, NOZZLE_DT, order=2)
        params = second_order_parameters(result.model)
        boot = dsr_e_uncertainty(tau, y, NOZZLE_DT, result, replicates=replicates, seed=seed)
        name = MEASURED[acquisition]
        out[name] = np.array([[params[p] for p in PARAMETERS], boot.standard_errors])
        out[f"{name} seconds"] = np.array(boot.seconds)
        if seed - SEED_OFFSET < INNOVATIONS_SEEDS:
            other = dsr_e_uncertainty(
                tau, y, NOZZLE_DT, result, replicates=replicates, seed=seed, noise="innovations"
            )
            out[f"{name} innovations"] = other.standard_errors
        if acquisition == "bench":
            jbk = tuple(params[p] for p in PARAMETERS)
            bias = acquisition_bias(tau, jbk, SENSOR_NOISE, BIAS_DRAWS, seed)
            corrected = [params[p] - bias[p] for p in PARAMETERS]
            out[CORRECTED] = np.array([corrected, boot.standard_errors * np.sqrt(1 + 1 / BIAS_DRAWS)])
            out[f"{CORRECTED} seconds"] = out["bench seconds"]
            if "bench innovations" in out:
                out[f"{CORRECTED} innovations"] = out["bench innovations"]
    return out


def wilson(hits: int, total: int) -> tuple[float, float]:
    """95 % Wilson score interval of a binomial proportion, %."""
    p = hits / total
    denom = 1 + Z95**2 / total
    centre = (p + Z95**2 / (2 * total)) / denom
    half = Z95 * np.sqrt(p * (1 - p) / total + Z95**2 / (4 * total**2)) / denom
    return 100 * (centre - half), 100 * (centre + half)


def coverage_table(names, truth, estimates: np.ndarray, ses: np.ndarray) -> list[str]:
    lines = [
        "| parameter | truth | mean estimate | mean se | empirical std | mean se / std | "
        "(mean - truth) / mean se | coverage % (95 % range) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for i, name in enumerate(names):
        est, se = estimates[:, i], ses[:, i]
        hits = int(np.sum(np.abs(est - truth[i]) <= Z95 * se))
        low, high = wilson(hits, est.size)
        spread = est.std(ddof=1)
        lines.append(
            f"| {name} | {truth[i]:.6g} | {est.mean():.6g} | {se.mean():.3g} | {spread:.3g} | "
            f"{se.mean() / spread:.2f} | {(est.mean() - truth[i]) / se.mean():.1f} | "
            f"{100 * hits / est.size:.1f} ({low:.1f}-{high:.1f}) |"
        )
    return lines


def linear_section(seeds: int, replicates: int, workers: int, acquisitions: tuple[str, ...]) -> list[str]:
    truth_params = published_nozzle("linear")
    truth = np.array([truth_params.J, truth_params.b, truth_params.k])
    tau, angle = bench_motion(truth_params)
    _MOTION.update(tau=tau, angle=angle)
    start = time.perf_counter()
    jobs = [(SEED_OFFSET + s, replicates, acquisitions) for s in range(seeds)]
    with multiprocessing.get_context("fork").Pool(workers) as pool:
        runs = []
        for k, run in enumerate(pool.imap(linear_seed, jobs), 1):
            runs.append(run)
            if k % 20 == 0:
                print(f"  {k}/{seeds} seeds, {time.perf_counter() - start:.0f} s", flush=True)
    lines = [
        "## J, b, k of DSR_e: residual-bootstrap standard errors",
        "",
        f"Linear joint of Table 1 (J = {truth[0]:g} kg m^2, b = {truth[1]:g} N m s/rad, "
        f"k = {truth[2]:g} N m/rad), "
        f"the default bench motion (PRBS torque, +-3 deg, N = {tau.size}), sensor noise std "
        f"{SENSOR_NOISE:g} rad at 2.5 kHz, noise seeds {SEED_OFFSET}..{SEED_OFFSET + seeds - 1}. Each "
        f"seed: `dsr_e(order=2)`, then `dsr_e_uncertainty` with {replicates} replicates (seed = the noise "
        "seed). Coverage: the fraction of seeds whose interval estimate +- 1.96 se contains the truth, "
        "with its 95 % Wilson range.",
        "",
    ]
    tables = [a for a in ("bench", CORRECTED, "ideal sampler") if a in runs[0]]
    for acquisition in tables:
        est = np.array([r[acquisition][0] for r in runs])
        se = np.array([r[acquisition][1] for r in runs])
        secs = np.array([float(r[f"{acquisition} seconds"]) for r in runs])
        what = {
            "bench": "as `bench_experiment` makes it: anti-alias FIR filter and decimation by 20",
            CORRECTED: "the bench's estimates minus the acquisition bias simulated at each estimate "
            f"({BIAS_DRAWS} noisy acquisitions)",
            "ideal sampler": "the exact samples of the angle plus the same decimated sensor noise",
        }[acquisition]
        lines += [
            f"### {acquisition}: {what}",
            "",
            *coverage_table(PARAMETERS, truth, est, se),
            "",
            f"Bootstrap cost: median {np.median(secs):.2f} s per record on one core (one BLAS thread).",
            "",
        ]
        innov = np.array([r[f"{acquisition} innovations"] for r in runs if f"{acquisition} innovations" in r])
        spread = est.std(axis=0, ddof=1)
        white = se[: len(innov)].mean(axis=0) / spread
        ratio = innov.mean(axis=0) / spread
        lines += [
            f"Noise model of the bootstrap, on the first {len(innov)} seeds (mean se over the empirical std "
            "of all seeds): "
            + ", ".join(
                f"{p}: white {w:.2f}, innovations {v:.2f}"
                for p, w, v in zip(PARAMETERS, white, ratio, strict=True)
            )
            + ".",
            "",
        ]
    return lines


def bouc_wen_section(seeds: int, workers: int, acquisitions: tuple[str, ...]) -> list[str]:
    truth_params = published_nozzle("bouc_wen")
    norm = truth_params.normalized()
    truth = np.array([norm[n] for n in NORMALIZED_NAMES])
    tau, angle = bench_motion(truth_params)
    lines = [
        "## Bouc-Wen joint",
        "",
    ]
    # DSR_e's J, b, k on the hysteretic joint against its small-signal values (noise-free record).
    params = second_order_parameters(dsr_e(tau, acquire(angle, 0, noise_std=0.0), NOZZLE_DT, order=2).model)
    small = [truth_params.J, truth_params.b, truth_params.small_signal_stiffness]
    lines += [
        "DSR_e on Table 1's Bouc-Wen joint, noise-free bench record: "
        + ", ".join(
            f"{p} {params[p]:.5g} against the small-signal {s:.5g} ({100 * (params[p] / s - 1):+.2f} %)"
            for p, s in zip(PARAMETERS, small, strict=True)
        )
        + ". The linear model of a hysteretic joint is an amplitude-dependent approximation, so its "
        "J, b, k have no true value to cover: the coverage above is measured on the linear joint.",
        "",
    ]
    if seeds == 0:
        return lines
    lines += [
        f"Regression standard errors of the normalized Bouc-Wen parameters (`fit_bouc_wen`, seed = noise "
        f"seed, {workers} workers) over noise seeds {SEED_OFFSET}..{SEED_OFFSET + seeds - 1}:",
        "",
    ]
    for acquisition in acquisitions:
        est, se = [], []
        start = time.perf_counter()
        for s in range(seeds):
            y = measured(angle, SEED_OFFSET + s, acquisition)
            fit = fit_bouc_wen(tau, y, NOZZLE_DT, seed=SEED_OFFSET + s, workers=workers)
            est.append([fit.normalized[n] for n in NORMALIZED_NAMES])
            se.append([fit.standard_errors[n] for n in NORMALIZED_NAMES])
        print(f"  Bouc-Wen, {acquisition}: {time.perf_counter() - start:.0f} s", flush=True)
        lines += [
            f"### {MEASURED[acquisition]}",
            "",
            *coverage_table(NORMALIZED_NAMES, truth, np.array(est), np.array(se)),
            "",
        ]
    return lines


def main() -> None:
    parser = script_parser(__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int_within(1), default=200)
    parser.add_argument("--replicates", type=int_within(MIN_REPLICATES), default=DEFAULT_REPLICATES)
    parser.add_argument(
        "--bouc-wen-seeds", type=int_within(0), default=12, help="0: no Bouc-Wen section (default: 12)"
    )
    parser.add_argument("--workers", type=int_within(1, max_workers()), default=2)
    parser.add_argument(
        "--acquisitions",
        type=comma_choices(MEASURED),
        default="bench,ideal",
        help="comma-separated: bench, ideal",
    )
    parser.add_argument("--out", type=output_file, default=OUT)
    args = parser.parse_args()
    chosen = tuple(args.acquisitions.split(","))  # comma_choices stripped the items
    start = time.perf_counter()
    lines = [
        "# Coverage of the nozzle's standard errors",
        "",
        "Command: `python experiments/nozzle_uncertainty_coverage.py"
        + (f" --seeds {args.seeds}" if args.seeds != 200 else "")
        + (f" --replicates {args.replicates}" if args.replicates != DEFAULT_REPLICATES else "")
        + (f" --bouc-wen-seeds {args.bouc_wen_seeds}" if args.bouc_wen_seeds != 12 else "")
        + (f" --acquisitions {args.acquisitions}" if chosen != tuple(MEASURED) else "")
        + "`.",
        "",
    ]
    lines += linear_section(args.seeds, args.replicates, args.workers, chosen)
    lines += bouc_wen_section(args.bouc_wen_seeds, args.workers, chosen)
    lines += [f"Total time {time.perf_counter() - start:.0f} s on {args.workers} processes.", ""]
    write_text(args.out, "\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
